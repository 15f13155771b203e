"""The skin-temperature floor of the display: the best any controller could
do on a touch, to put the controllers' figures beside.

``telethermal bench skin-floor`` (:func:`run`): the floor with the real
Peltier module behind the pad (its pumping limits, the junction's heat
capacity; ``control/preconditioning.py``), per material of fingertip-7,
from three idles (the object's temperature, the best idle for the known
material, the product's idle policy for an unknown object), a sweep of
the module's Qmax and the flux film's resistance, and the floor of a
display that learns the material only at the slave's decision
(``control/decision_floor.py``) against the decision's time.

The earlier floor (the junction held in the skin band, no pumping limit,
once printed by ``bench render``) was removed: it bounded a temperature the
skin never touches and counted no pumping limit, so it was no floor.
"""

from __future__ import annotations

import dataclasses
import datetime
import platform
import time
from pathlib import Path

import numpy as np

from telethermal.errors import BenchError
from telethermal.jsonfile import write_json

# ---------------------------------------------------------------- bench skin-floor
SWEEP_QMAX = (0.5, 1.0, 2.0, 4.0, 8.0)
SWEEP_FILM_R = (1.0, 0.5, 0.25)
TARGET_K = 0.3
SCENE = "fingertip-7"
#: Decision times (s after contact) for the floor of a display that learns
#: the material then; the slave commits to its first decision 0.05-0.13 s
#: after contact on fingertip-7 (bench render's ``decision_from_s``).
DECISION_S = (0.0, 0.05, 0.1, 0.15)


def _final(hw, touch, scene, material: str, idle_c: float, plants: dict) -> dict:
    """The floor on 5 ms slots from ``idle_c``, bounds iterated on the
    nonlinear module, which verifies it."""
    from telethermal.control import display_floor

    key = id(hw)
    if key not in plants:
        plants[key] = display_floor.JunctionPlant(hw, touch)
    plant = plants[key]
    target = display_floor.direct_skin_c(scene, material, touch, plant.n)
    return display_floor.best_touch(hw, plant, target, idle_c).summary(target)


def _module(hw) -> dict:
    p = hw.params
    spec = p.spec
    return {"name": spec.name, "imax_a": spec.imax_a, "vmax_v": spec.vmax_v,
            "qmax_w": spec.qmax_w, "dtmax_k": spec.dtmax_k, "source": spec.source,
            "area_m2": spec.area_m2, "seebeck_v_k": p.seebeck_v_k,
            "resistance_ohm": p.resistance_ohm, "conductance_w_k": p.conductance_w_k,
            "cold_heat_j_k": p.cold_heat_j_k, "heat_sink": hw.sink.spec.name,
            "driver": {"current_limit_a": hw.driver.current_limit_a,
                       "supply_v": hw.driver.supply_v}}


def _materials(scene, hw, touch, idles: dict, step) -> dict:
    plants: dict = {}
    policy_c = idles["minimax"]["idle_c"]
    out = {}
    for m in scene.materials:
        step(f"floors: {m}")
        at_object = _final(hw, touch, scene, m, touch.object_c, plants)
        policy = _final(hw, touch, scene, m, policy_c, plants)
        searched = _final(hw, touch, scene, m, idles["preconditioned"][m]["idle_c"], plants)
        # The best known-material idle is at least as good as every idle tried.
        best = min((searched, at_object, policy), key=lambda r: r["floor_k"])
        out[m] = {"floor_k": policy["floor_k"], "floor_at_object_k": at_object["floor_k"],
                  "floor_preconditioned_k": best["floor_k"],
                  "idle_policy_c": policy_c, "idle_object_c": touch.object_c,
                  "idle_preconditioned_c": best["idle_c"],
                  "policy": policy, "at_object": at_object, "preconditioned": best}
    return out


def _sweep(scene, touch, qmax_scales, film_scales, step) -> list[dict]:
    from telethermal.control import preconditioning as pc
    from telethermal.control import display_floor

    rows = []
    for film in film_scales:
        for scale in qmax_scales:
            step(f"sweep: Qmax x{scale:g}, film R x{film:g}")
            hw = display_floor.hardware(scene, qmax_scale=scale, film_r_scale=film)
            search = pc.FloorSearch(scene, hw, touch)
            idle, subset = pc.minimax_idle(search)
            final = _final(hw, touch, scene, "aluminium", idle, {})
            film_layer = hw.pad_layers[0]
            rows.append({"qmax_w": hw.params.spec.qmax_w, "imax_a": hw.params.spec.imax_a,
                         "qmax_scale": scale, "film_r_scale": film,
                         "film_r_m2k_w": film_layer.thickness_m /
                         film_layer.material.conductivity_w_mk,
                         "aluminium_floor_k": final["floor_k"], "idle_policy_c": idle,
                         "minimax_decided_by": subset, "aluminium": final})
    return rows


def _decision(search, idle_c: float, times, step) -> dict:
    from telethermal.control.decision_floor import decision_floor

    rows = []
    for td in times:
        step(f"decision floor: material learnt {td:g} s after contact")
        t0 = time.perf_counter()
        f = decision_floor(search.hw, search.plant, search.targets, idle_c, td).summary()
        rows.append({**f, "solve_s": time.perf_counter() - t0})
    return {"idle_c": idle_c, "grid_s": search.plant.grid_s,
            "criterion": "minimax over the scene's materials, the heat pumped before the "
                         "decision the same for all; floor_worst_k: on this model (10 ms "
                         "slots, linear junction, hot side at the idle's, nominal operator, "
                         "every material learnt at decision_s) no controller does better on "
                         "its worst material; per_material_k: each material on that minimax "
                         "trajectory (not a bound per material)",
            "rows": rows}


def _verdict(rows) -> str:
    met = [r for r in rows if r["aluminium_floor_k"] <= TARGET_K]
    if not met:
        return (f"no change in the sweep brings aluminium's first-touch floor to "
                f"<= {TARGET_K} K (best {min(r['aluminium_floor_k'] for r in rows):.2f} K)")
    return "aluminium's first-touch floor <= %.1f K with: " % TARGET_K + "; ".join(
        f"Qmax {r['qmax_w']:.1f} W (x{r['qmax_scale']:g}) and film R x{r['film_r_scale']:g} "
        f"({r['aluminium_floor_k']:.2f} K)" for r in met)


def run(progress=None, quick: bool = False, scene_name: str = SCENE) -> dict:
    from telethermal.control import preconditioning as pc
    from telethermal.control import display_floor
    from telethermal.physics.scene import load_scene

    step = progress or (lambda _msg: None)
    t0 = time.perf_counter()
    scene = load_scene(scene_name)
    if "aluminium" not in scene.materials:       # the sweep's figure is aluminium's floor
        raise BenchError(f"bench skin-floor --scene {scene_name}: the Qmax and film sweep is "
                         f"on aluminium, which the scene has no object of (it has "
                         f"{', '.join(scene.materials)})")
    hw, touch = display_floor.hardware(scene), display_floor.nominal_touch(scene)
    step("idle search")
    search = pc.FloorSearch(scene, hw, touch)
    idles = pc.search_idles(search, **({"step_k": 7.0} if quick else {}))
    t_search = time.perf_counter()
    materials = _materials(scene, hw, touch, idles, step)
    t_floors = time.perf_counter()
    qmax, film = ((1.0, 8.0), (1.0, 0.25)) if quick else (SWEEP_QMAX, SWEEP_FILM_R)
    sweep = _sweep(scene, touch, qmax, film, step)
    t_sweep = time.perf_counter()
    decision = _decision(search, idles["minimax"]["idle_c"],
                         (0.0, 0.1) if quick else DECISION_S, step)
    t_end = time.perf_counter()
    mm, ex = idles["minimax"], idles["expected"]
    policy = {
        "criterion": "minimax: the worst floor over the scene's materials (equally likely)",
        "rule": "idle_c = object_c + fraction * (finger_c - object_c), clipped to the skin band",
        "fraction": mm["fraction_of_finger_minus_object"], "offset_k": mm["offset_k"],
        "idle_c": mm["idle_c"], "worst_floor_k": max(v["floor_k"] for v in materials.values()),
        "expected_choice": {**ex, "criterion": "the mean floor over the materials"},
        "sentence": (f"For an unknown object the pad idles {abs(mm['offset_k']):.1f} K "
                     f"{'below' if mm['offset_k'] < 0 else 'above'} the object's measured "
                     f"temperature ({mm['fraction_of_finger_minus_object']:+.2f} of the "
                     f"finger-object difference), which minimises the worst first-touch "
                     f"floor over {', '.join(scene.materials)}; minimising the mean instead "
                     f"gives {ex['offset_k']:+.1f} K.")}
    return {
        "scene": scene.name, "module": _module(hw), "touch": {
            **dataclasses.asdict(touch),
            "note": "the scene's nominal operator (mean finger temperature, nominal skin, "
                    "nominal force's contact conductance), object at room temperature"},
        "contact_s": display_floor.CONTACT_S, "grid_s": display_floor.GRID_S,
        "search_grid_s": pc.SEARCH_GRID_S,
        "bound_margin": display_floor.BOUND_MARGIN, "quick": quick, "idle_policy": policy,
        "method": {
            "plant": "pad stack + junction node (cold_heat_j_k/area) on the fingertip, "
                     "LayeredContact's cells, exact per 5 ms slot, input q_j = -Qc/area",
            "bounds": "Qc over the driver's admissible current at the slot's junction and "
                      "hot-side temperatures, less a margin of bound_margin of the range; "
                      "iterated on the nonlinear module's temperatures (ThermoelectricStack "
                      "on fan-40 driven by the realising current), which counts violations",
            "idle_state_searched": "pad and junction uniform at one temperature in the "
                                   "skin band 15-43 C, held by the module in air",
            "searches": "10 ms slots, 3 bound rounds, lsq_linear trf (tol 1e-6), Th at the "
                        "idle's steady hot side; floors reported on 5 ms slots with bvls"},
        "materials": materials, "idle_search": idles, "sweep": sweep,
        "sweep_verdict": _verdict(sweep), "decision": decision,
        "timings": {"idle_search_s": t_search - t0, "floors_s": t_floors - t_search,
                    "sweep_s": t_sweep - t_floors, "decision_s": t_end - t_sweep,
                    "total_s": t_end - t0},
        "machine": f"{platform.node()} ({platform.machine()}, {platform.python_version()})",
        "date": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")}


def plot(report: dict, out_png) -> Path:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax, ax2, ax3) = plt.subplots(1, 3, figsize=(18, 4.8))
    mats = list(report["materials"])
    x = np.arange(len(mats))
    for i, (key, label) in enumerate((("floor_at_object_k", "idle at the object's temperature"),
                                      ("floor_k", "idle policy (unknown object)"),
                                      ("floor_preconditioned_k", "best idle, material known"))):
        ax.bar(x + (i - 1) * 0.27, [report["materials"][m][key] for m in mats], 0.27,
               label=label)
    ax.axhline(TARGET_K, color="r", ls=":", lw=0.8, label=f"{TARGET_K} K")
    ax.set_xticks(x, mats, rotation=20, fontsize=8)
    ax.set_ylabel("skin temperature RMS error floor (K), 3 s")
    ax.set_title(f"{report['module']['name']}: floor per material", fontsize=9)
    ax.legend(fontsize=7)
    ax.grid(alpha=0.3, axis="y")
    for film in sorted({r["film_r_scale"] for r in report["sweep"]}, reverse=True):
        rows = [r for r in report["sweep"] if r["film_r_scale"] == film]
        ax2.plot([r["qmax_w"] for r in rows], [r["aluminium_floor_k"] for r in rows], "o-",
                 label=f"film R x{film:g} ({rows[0]['film_r_m2k_w']:.1e} m^2 K/W)")
    ax2.axhline(TARGET_K, color="r", ls=":", lw=0.8)
    ax2.set_xscale("log")
    ax2.set_xlabel("module Qmax (W; Imax scaled with it)")
    ax2.set_ylabel("aluminium first-touch floor (K)")
    ax2.set_title("sweep: pumping and flux film", fontsize=9)
    ax2.legend(fontsize=7)
    ax2.grid(alpha=0.3, which="both")
    _plot_decision(ax3, report)
    fig.suptitle(f"telethermal bench skin-floor - {report['date']}", fontsize=9)
    fig.tight_layout()
    out_png = Path(out_png)
    out_png.parent.mkdir(parents=True, exist_ok=True)
    from telethermal.jsonfile import write_figure
    write_figure(fig, out_png, dpi=110)
    plt.close(fig)
    return out_png


def _plot_decision(ax, report: dict) -> None:
    rows = (report.get("decision") or {}).get("rows") or []
    if not rows:
        ax.set_axis_off()
        return
    td = [r["decision_s"] for r in rows]
    for i, m in enumerate(report["materials"]):
        ax.plot(td, [r["per_material_k"][m] for r in rows], ".-", lw=0.8, color=f"C{i}",
                label=m)
    ax.plot(td, [r["floor_worst_k"] for r in rows], "k-", lw=2.0,
            label="worst material (the floor)")
    ax.axhline(TARGET_K, color="r", ls=":", lw=0.8)
    ax.set_xlabel("material learnt at (s after contact)")
    ax.set_ylabel("skin RMS error (K), idle policy")
    ax.set_title("floor when the material is learnt at the decision (minimax)", fontsize=9)
    ax.legend(fontsize=7)
    ax.grid(alpha=0.3)


def run_and_save(json_path, png_path, quick: bool = False, command: str = "",
                 progress=None, scene: str = SCENE) -> dict:
    """Run on ``scene`` (a shipped name or a scene file), plot to
    ``png_path``, write the JSON (with ``command`` and the plot)."""
    report = run(progress=progress, quick=quick, scene_name=scene)
    report["command"] = command
    report["png"] = str(plot(report, png_path))
    write_json(json_path, report)
    return report



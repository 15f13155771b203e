"""``telethermal bench physics``: speed against error of the contact models.

Rows (one per model, grid and step, on the shipped scenes' contacts):

- ``layered`` on a ladder of grids, and ``crank-nicolson`` on the default grid
  at several steps: the fingertip's contacts against the closed form (both
  bodies taken semi-infinite, the scene's contact conductance); the pads'
  stacked contacts against a 4x-refined layered run (no closed form exists).
- ``analytic``: the closed form for every finite object, against a
  4x-refined layered run of that real object: the error of the
  semi-infinite assumption itself, which is what the model choice weighs
  (``chosen`` says whether the scene uses the closed form for that contact).

Plus the figures the physics issue targets: the default model's error and
cost per simulated second, a batch of 70 one-second trials at 1 kHz, both
databases of the first paper, and the heat balance over a 60 s run.
Runtimes are the best of ``repeats`` runs (the machine is shared).
"""

from __future__ import annotations

import dataclasses
import datetime
import math
import platform
import tempfile
import time
from pathlib import Path
from typing import Callable

import numpy as np

from telethermal.jsonfile import write_json
from telethermal.physics.contact import contact_flux_w_m2
from telethermal.physics.layered import Boundary, Layer, LayeredContact, crank_nicolson
from telethermal.physics.materials import get_material
from telethermal.physics.model import AnalyticContact, layered_model
from telethermal.physics.scene import (Scene, finger_contact_model, load_scene,
                                       pad_contact_model)

GRIDS = ((0.4, 1.3), (0.2, 1.2), (0.1, 1.15), (0.05, 1.1), (0.025, 1.05))


def _best_time(fn: Callable[[], object], repeats: int):
    best, value = math.inf, None
    for _ in range(repeats):
        start = time.perf_counter()
        value = fn()
        best = min(best, time.perf_counter() - start)
    return best, value


def _rel_error(q, ref, mask):
    return float(np.max(np.abs(q[mask] - ref[mask]) / np.abs(ref[mask])))


def _row(model, scene, contact, dx, dt, err, runtime, reference, **extra):
    return {"model": model, "scene": scene, "contact": contact, "dx_m": dx, "dt_s": dt,
            "max_rel_error": err, "runtime_s": runtime, "reference": reference, **extra}


def finger_rows(scene: Scene, repeats: int) -> list[dict]:
    """Skin against each object: layered ladder and CN against the closed form."""
    rows = []
    finger = scene.finger
    t = np.arange(1, int(finger.contact_duration_s * scene.sample_rate_hz) + 1) / scene.sample_rate_hz
    mask = t >= 0.05
    skin = get_material("skin")
    h = finger.contact_conductance_w_m2k
    for obj in scene.objects:
        mat = get_material(obj.material)
        exact = contact_flux_w_m2(t, 1.0, 0.0, skin.effusivity, mat.effusivity, h)
        sides = ([Layer(skin, math.inf)], [Layer(mat, math.inf)])
        for res, growth in GRIDS:
            model = LayeredContact(*sides, Boundary(), Boundary(), t[0], t[-1], res, growth)
            runtime, out = _best_time(lambda: model.solve(t, 1.0, 0.0, h), repeats)
            rows.append(_row("layered", scene.name, f"skin|{obj.material}", model.grid.min_dx_m,
                             1.0 / scene.sample_rate_hz, _rel_error(out.flux_w_m2[0], exact, mask),
                             runtime, "closed form", n_cells=model.grid.n_cells))
        # Crank-Nicolson on the same grid, over the first 10 s (its cost grows
        # with the step count; the early, steep part is where it errs).
        model = LayeredContact(*sides, Boundary(), Boundary(), t[0], t[-1], *GRIDS[2])
        head = t <= 10.0
        for substeps in (1, 10):
            dt = 1.0 / (scene.sample_rate_hz * substeps)
            n = int(head.sum()) * substeps
            runtime, (tc, qc) = _best_time(lambda: crank_nicolson(model, dt, n, 1.0, 0.0, h), 1)
            rows.append(_row("crank-nicolson", scene.name, f"skin|{obj.material}",
                             model.grid.min_dx_m, dt,
                             _rel_error(qc[substeps - 1::substeps], exact[head], mask[head]),
                             runtime, "closed form, 0.05-10 s", n_cells=model.grid.n_cells))
        if obj.thickness_m < math.inf:
            finite = LayeredContact([Layer(skin, math.inf)], [Layer(mat, obj.thickness_m)],
                                    Boundary(), Boundary(), t[0], t[-1], 0.025, 1.04)
            ref = finite.solve(t, 1.0, 0.0, h).flux_w_m2[0]
            analytic = AnalyticContact(skin, mat)
            runtime, out = _best_time(lambda: analytic.solve(t, 1.0, 0.0, h), repeats)
            rows.append(_row("analytic", scene.name, f"skin|{obj.material}", 0.0, 0.0,
                             _rel_error(out.flux_w_m2[0], ref, mask), runtime,
                             f"layered, {obj.thickness_m} m object, 4x refined",
                             chosen=finger_contact_model(scene, obj)[1].kind == "analytic"))
    return rows


def pad_rows(scene: Scene, repeats: int) -> list[dict]:
    """The pad's stack against each object: layered ladder against 4x refinement."""
    rows = []
    rate = scene.sample_rate_hz
    t = np.arange(1, int(scene.pad.contact_duration_s * rate) + 1) / rate
    mask = t >= 0.05
    h = scene.pad.contact_conductance_w_m2k
    for obj in scene.objects:
        default, _ = pad_contact_model(scene, obj)
        sides = (scene.pad.layers, [Layer(get_material(obj.material), obj.thickness_m)])
        backs = (default.back_a, default.back_b)
        ref_model = LayeredContact(*sides, *backs, t[0], t[-1], GRIDS[-1][0] / 4, 1.0125)
        ref = ref_model.solve(t, 1.0, 0.0, h).flux_w_m2[0]
        for res, growth in GRIDS[:-1]:
            model = LayeredContact(*sides, *backs, t[0], t[-1], res, growth)
            runtime, out = _best_time(lambda: model.solve(t, 1.0, 0.0, h), repeats)
            rows.append(_row("layered", scene.name, f"pad|{obj.material}", model.grid.min_dx_m,
                             1.0 / rate, _rel_error(out.flux_w_m2[0], ref, mask), runtime,
                             "layered, 4x refined", n_cells=model.grid.n_cells))
    return rows


def default_figures(scene: Scene, repeats: int) -> dict:
    """The grid the simulator picks for the scene tolerance, on skin against
    each object taken semi-infinite, against the closed form, 0.05-60 s."""
    t = np.arange(1, int(60.0 * scene.sample_rate_hz) + 1) / scene.sample_rate_hz
    mask = t >= 0.05
    skin = get_material("skin")
    worst, cost, per_material = 0.0, 0.0, {}
    for obj in scene.objects:
        mat = get_material(obj.material)
        for h in (scene.finger.contact_conductance_w_m2k, math.inf):
            sides = ([Layer(skin, math.inf)], [Layer(mat, math.inf)])
            model, _ = _forced_layered(sides, t[0], t[-1], scene.tolerance_rel, h)
            runtime, out = _best_time(lambda: model.solve(t, 1.0, 0.0, h), repeats)
            exact = contact_flux_w_m2(t, 1.0, 0.0, skin.effusivity, mat.effusivity, h)
            err = _rel_error(out.flux_w_m2[0], exact, mask)
            per_material[f"{obj.material}, h={h:g}"] = err
            worst, cost = max(worst, err), max(cost, runtime / t[-1])
    return {"max_rel_error": worst, "runtime_s_per_simulated_s": cost,
            "tolerance_rel": scene.tolerance_rel, "window_s": [0.05, float(t[-1])],
            "sample_rate_hz": scene.sample_rate_hz, "per_contact": per_material}


def _forced_layered(sides, t_min, t_max, tol, h):
    """The layered model choose_model would build if the closed form were not allowed."""
    return layered_model(*sides, Boundary(), Boundary(), t_min, t_max, tol, h, "forced for the bench")


def batch_figures(scene: Scene, repeats: int) -> dict:
    """70 one-second trials at 1 kHz: the first paper's pad database at 1 kHz.

    The model choice (a refinement ladder, once per scene and process) is
    timed apart from the simulation of the trials (physics and sensors)."""
    from telethermal.data.generate import pad_database
    from telethermal.physics.model import choose_model
    from telethermal.physics.scene import describe_models

    fast = dataclasses.replace(scene, sample_rate_hz=1000.0, pre_contact_s=0.0,
                               pad=dataclasses.replace(scene.pad, contact_duration_s=1.0,
                                                       trials_per_material=10))
    choose_model.cache_clear()
    choice_s, _ = _best_time(lambda: [describe_models(fast)], 1)
    runtime, trials = _best_time(lambda: pad_database(fast, np.random.default_rng(0)), repeats)
    return {"trials": len(trials), "seconds_each": 1.0, "sample_rate_hz": 1000.0,
            "runtime_s": runtime, "model_choice_s": choice_s,
            "note": "runtime_s: physics and sensors of all trials, model already chosen; "
                    "no file output"}


def database_figures(scene: Scene, repeats: int) -> dict:
    """Both databases of the first paper: simulation alone, and with the CSV files."""
    from telethermal.data.generate import finger_database, generate_databases, pad_database
    sim, _ = _best_time(lambda: (pad_database(scene, np.random.default_rng(0)),
                                 finger_database(scene, np.random.default_rng(0))), repeats)
    with tempfile.TemporaryDirectory() as tmp:
        total, summary = _best_time(lambda: generate_databases(
            scene, Path(tmp) / "db", overwrite=True), 1)
    return {"simulation_s": sim, "with_csv_files_s": total,
            "trials": {k: v["trials"] for k, v in summary["datasets"].items()}}


def heat_balance(scene: Scene) -> dict:
    """60 s of the pad (junction held) on aluminium that loses heat to the room."""
    obj = scene.objects[0]
    model = LayeredContact(scene.pad.layers, [Layer(get_material(obj.material), obj.thickness_m)],
                           Boundary("isothermal"), Boundary("convective", scene.room_temp_c, 10.0),
                           0.01, 60.0)
    t = np.linspace(0.0, 60.0, 6001)
    out = model.solve(t, scene.room_temp_c + 10, scene.room_temp_c + 2, 3000.0, energy=True)
    return {"contact": f"pad|{obj.material}", "seconds": 60.0,
            "energy_in_j_m2": float(out.energy_in_j_m2[0, -1]),
            "energy_stored_j_m2": float(out.energy_stored_j_m2[0, -1]),
            "relative_error": float(out.heat_balance_error()[0])}


def run(repeats: int = 3, progress: Callable[[str], None] | None = None) -> dict:
    """Every figure of the physics benchmark, as a JSON-ready dict."""
    step = progress or (lambda _msg: None)
    fingertip = load_scene("fingertip-7")
    gripper = load_scene("gripper-case-I-pro")
    rows = []
    step("fingertip contacts")
    rows += finger_rows(fingertip, repeats)
    step("pad stacks")
    rows += pad_rows(fingertip, repeats) + pad_rows(gripper, repeats)
    step("default model")
    default = default_figures(fingertip, repeats)
    step("batch of 70 trials")
    batch = batch_figures(fingertip, repeats)
    step("databases")
    databases = database_figures(fingertip, 1)
    step("heat balance")
    balance = heat_balance(fingertip)
    return {"machine": f"{platform.node()} ({platform.machine()}, {platform.python_implementation()} "
                       f"{platform.python_version()})",
            "date": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
            "rows": rows, "default": default, "batch_70x1s_1khz": batch,
            "databases_fingertip_7": databases, "heat_balance_60s": balance}


def plot(report: dict, out_png: str | Path) -> Path:
    """Error against runtime, one marker per model."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 5.5))
    markers = {"layered": "o", "crank-nicolson": "s", "analytic": "^"}
    for model, marker in markers.items():
        pts = [(r["runtime_s"], max(r["max_rel_error"], 1e-16)) for r in report["rows"]
               if r["model"] == model]
        if pts:
            x, y = zip(*pts)
            ax.scatter(x, y, marker=marker, label=model, alpha=0.7)
    d = report["default"]
    ax.axhline(d["max_rel_error"], color="k", lw=0.8, ls="--",
               label=f"default model, worst contact ({d['max_rel_error']:.1e})")
    ax.axhline(5e-3, color="r", lw=0.8, ls=":", label="target 0.5 %")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("runtime of one contact (s)")
    ax.set_ylabel("max relative flux error, t >= 0.05 s")
    ax.set_title(f"telethermal bench physics - {report['date']}\n{report['machine']}", fontsize=9)
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8)
    fig.tight_layout()
    out_png = Path(out_png)
    out_png.parent.mkdir(parents=True, exist_ok=True)
    from telethermal.jsonfile import write_figure
    write_figure(fig, out_png, dpi=110)
    plt.close(fig)
    return out_png


def run_and_save(json_path: str | Path, png_path: str | Path, repeats: int = 3,
                 command: str = "", progress: Callable[[str], None] | None = None) -> dict:
    """Run the benchmark, plot it to ``png_path`` and write the JSON report
    (with ``command`` and the plot's path); returns the report."""
    report = run(repeats=repeats, progress=progress)
    report["command"] = command
    report["png"] = str(plot(report, png_path))
    write_json(json_path, report)
    return report



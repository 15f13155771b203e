"""``telethermal bench faults``, simulated-clock part: every delay, jitter
and loss row, every material of the scene, several seeds, every rendering
mode on the very same touches (:mod:`telethermal.sim.network`).

Modes, per touch:

``compensated``
    The first touch of an object: the master holds the pad at the object's
    temperature until the slave's estimates arrive (``before`` of the
    display config), then renders the slave's curves from its own onset.
``naive``
    The same touch, the master tracking the latest flux setpoint the slave
    streams (the baseline).
``repeat``
    A later touch of the same object (another operator draw, seed + 1000):
    the slave announces what it identified on the first touch (object
    memory), so the master renders from t = 0.
``oracle``
    The repeat touch with the master told the true material at its onset
    and no network: the floor of any compensation (the pad's and sensors'
    own lag is all that is left).

Windows: ``blind`` from the master's contact to the first estimate of the
slave reaching it, ``after_news`` from then to the end, ``whole``. Each
figure is the mean over touches of the RMS flux error relative to the
direct contact's peak; ``sd`` its spread over touches.
"""

from __future__ import annotations

import functools
import math
from dataclasses import replace

import numpy as np

from telethermal.sim.channel import Direction
from telethermal.teleop.memory import ObjectMemory
from telethermal.sim.network import NetworkSpec, run_network_touch

#: (name, Direction of both ways): the rows a network model can carry.
ROWS = [
    ("delay 0 ms", {}),
    ("delay 10 ms", {"delay_s": 0.01}),
    ("delay 50 ms", {"delay_s": 0.05}),
    ("delay 100 ms", {"delay_s": 0.1}),
    ("delay 200 ms", {"delay_s": 0.2}),
    ("delay 500 ms", {"delay_s": 0.5}),
    ("delay 200 ms, jitter 20 ms, loss 5 %", {"delay_s": 0.2, "jitter": "normal",
                                              "jitter_s": 0.02, "loss": 0.05}),
    ("delay 500 ms, loss 5 %", {"delay_s": 0.5, "loss": 0.05}),
    ("loss 20 %", {"delay_s": 0.005, "loss": 0.2}),
    ("jitter 50 ms", {"delay_s": 0.05, "jitter": "uniform", "jitter_s": 0.025}),
]
ZERO = "delay 0 ms"
WAN = "delay 200 ms, jitter 20 ms, loss 5 %"
#: Ablations measured on the zero-delay and WAN rows only.
ABLATION_ROWS = (ZERO, WAN)
WINDOWS = ("blind", "after_news", "whole")
REPEAT_SEED_OFFSET = 1000


def _stats(values) -> dict:
    v = np.asarray([x for x in values if x is not None and math.isfinite(x)], dtype=float)
    if not len(v):
        return {"mean": None, "sd": None, "n": 0}
    return {"mean": float(v.mean()), "sd": float(v.std(ddof=1)) if len(v) > 1 else 0.0,
            "n": int(len(v))}


def _mode_stats(touches: list[dict]) -> dict:
    out = {w: _stats(t[f"flux_rms_error_rel_{w}"] for t in touches) for w in WINDOWS}
    out["blind_s"] = _stats(t["blind_s"] for t in touches)
    out["temp_rms_error_c"] = _stats(t["temp_rms_error_c"] for t in touches)
    out["safety_events"] = int(sum(t["safety_events"] for t in touches))
    out["identified_right"] = float(np.mean([t["identified"] == t["material"]
                                             for t in touches]))
    out["by_material"] = {m: _stats(t["flux_rms_error_rel_whole"] for t in touches
                                    if t["material"] == m)
                          for m in sorted({t["material"] for t in touches})}
    return out


def _keep(summary: dict) -> dict:
    keys = ("material", "seed", "mode", "identified", "first_news_s", "blind_s",
            "render_start_s", "flux_rms_error_rel_blind", "flux_rms_error_rel_after_news",
            "flux_rms_error_rel_whole", "temp_rms_error_c", "safety_events")
    return {k: summary[k] for k in keys}


#: A unit of work: (kind, row name or None for the oracle, material). Kinds:
#: "modes" (the compensated, naive and repeat touches), "before" (the other
#: pre-decision rendering), "lossless" (the estimates sent lossless),
#: "oracle".


def units(names, materials) -> list[tuple[str, str | None, str]]:
    """Every unit of the simulated part: the oracle, then per row its modes
    and (the zero-delay and WAN rows) its ablations, each per material."""
    out = [("oracle", None, m) for m in materials]
    for name in names:
        out += [("modes", name, m) for m in materials]
        if name in ABLATION_ROWS:
            out += [("before", name, m) for m in materials]
            if name != ZERO:
                out += [("lossless", name, m) for m in materials]
    return out


def run_unit(touch, unit, link: dict | None, config, seeds) -> dict:
    """The touches of one unit in this process (``touch`` makes one and
    returns its summary): the kept fields of each touch by mode and, for
    "modes", how many repeat touches found the object remembered."""
    kind, _, m = unit
    if kind == "oracle":
        return {"touches": {"oracle": [_keep(touch(m, s + REPEAT_SEED_OFFSET, NetworkSpec(),
                                                   mode="oracle")) for s in seeds]}}
    spec = NetworkSpec.symmetric(Direction(**link))
    if kind == "before":
        other = "prior" if config.before == "hold" else "hold"
        return {"touches": {f"before {other}": [
            _keep(touch(m, s, spec, config=replace(config, before=other))) for s in seeds]}}
    if kind == "lossless":
        ordered = NetworkSpec(spec.slave_to_master, spec.master_to_slave, estimates="lossless")
        return {"touches": {"estimates lossless": [_keep(touch(m, s, ordered))
                                                   for s in seeds]}}
    modes: dict[str, list] = {"compensated": [], "naive": [], "repeat": []}
    remembered = 0
    for s in seeds:
        memory = ObjectMemory()
        modes["compensated"].append(_keep(touch(m, s, spec, object_id=m, memory=memory)))
        modes["naive"].append(_keep(touch(m, s, spec, mode="naive")))
        remembered += memory.recall(m) is not None
        modes["repeat"].append(_keep(touch(m, s + REPEAT_SEED_OFFSET, spec, object_id=m,
                                           memory=memory, network_seed=s)))
    return {"touches": modes, "remembered": remembered}


def assemble(results: dict, rows, materials, seeds) -> dict:
    """The oracle and the rows from every unit's touches (``results`` keyed
    by unit), gathered material by material, seed by seed: the order one
    process makes them in, so that every mean is summed in the same order."""
    def gather(kind, name, mode):
        return [t for m in materials for t in results[(kind, name, m)]["touches"][mode]]

    out: dict = {"rows": {}, "oracle": _mode_stats(gather("oracle", None, "oracle"))}
    for name, link in rows:
        modes = {k: gather("modes", name, k) for k in ("compensated", "naive", "repeat")}
        remembered = sum(results[("modes", name, m)]["remembered"] for m in materials)
        row = {"profile": link, "modes": {k: _mode_stats(v) for k, v in modes.items()},
               "repeat_with_memory": remembered / (len(materials) * len(seeds)),
               "touches": modes}
        if name in ABLATION_ROWS:
            before = next(iter(results[("before", name, materials[0])]["touches"]))
            row["ablations"] = {before: _mode_stats(gather("before", name, before))}
            if name != ZERO:
                row["ablations"]["estimates lossless"] = _mode_stats(
                    gather("lossless", name, "estimates lossless"))
        out["rows"][name] = row
    return out


def run(scene, identifier_path, generator_path, config, materials, seeds, contact_s: float,
        rows=ROWS, jobs: int = 2, progress=None, executor=None) -> dict:
    """The simulated section of the report: its units (row, part, material)
    swept on ``executor`` (:mod:`telethermal.bench.executor`; None: a pool of
    ``jobs`` worker processes, each loading the model files once; jobs and
    results cross as JSON), then the rows, the oracle and the summary."""
    from telethermal.bench.executor import describe, open_executor, sweep

    rows, materials = list(rows), list(materials)
    job = {"scene": scene.ref or scene.name, "identifier": str(identifier_path),
           "generator": str(generator_path), "seeds": list(seeds), "contact_s": contact_s,
           "links": dict(rows), "rate_hz": config.rate_hz, "before": config.before}
    work = units([n for n, _ in rows], materials)
    own = executor is None
    executor = open_executor("process", jobs) if own else executor
    announced: set = set()

    def step(call: tuple) -> None:              # one step per row, as its first unit ends
        kind, row, _ = call[1]
        if progress is not None and kind == "modes" and row not in announced:
            announced.add(row)
            progress(f"simulated: {row}")

    try:
        ran_on = describe(executor)
        finished = sweep(executor, unit_job, [(job, list(u)) for u in work], done=step,
                     label=lambda c: "simulated: " + " ".join(x for x in c[1] if x))
    finally:
        if own:
            executor.shutdown(cancel_futures=True)
    results = {tuple(u): r for u, r in zip(work, finished)}
    out = assemble(results, rows, materials, seeds)
    out.update({"materials": materials, "seeds": list(seeds), "contact_s": contact_s,
                "rate_hz": config.rate_hz, "before": config.before, "executor": ran_on})
    out["summary"] = summary(out)
    return out


@functools.lru_cache(maxsize=4)
def _touches(scene_ref: str, identifier_path: str, generator_path: str, rate_hz: float,
             before: str):
    """A worker's scene, models and display config, loaded once per process."""
    from telethermal.ident.registry import load_model
    from telethermal.physics.scene import load_scene, with_finger
    from telethermal.render.generator import load_generator
    from telethermal.render.sampled import sample_curves
    from telethermal.teleop.display_config import DisplayConfig

    scene = with_finger(load_scene(scene_ref))
    identifier = load_model(identifier_path)
    generator = load_generator(generator_path)
    curves = sample_curves(generator, [m for m in generator.materials
                                       if m in identifier.classes_])
    return scene, identifier, curves, DisplayConfig(rate_hz=rate_hz, before=before)


def unit_job(job: dict, unit: list) -> dict:
    """One unit's touches (:func:`run_unit`) on the models ``job`` names: a
    sweep's job, in whichever process the executor runs it."""
    scene, identifier, curves, config = _touches(job["scene"], job["identifier"],
                                                 job["generator"], job["rate_hz"],
                                                 job["before"])
    touch = lambda m, seed, spec, **kw: run_network_touch(               # noqa: E731
        scene, m, identifier, curves, kw.pop("config", config), spec, seed=seed,
        contact_s=job["contact_s"], **kw).summary
    return run_unit(touch, tuple(unit), job["links"].get(unit[1]), config, job["seeds"])


def _mean(out: dict, row: str, mode: str, window: str) -> float | None:
    r = out["rows"].get(row)
    return None if r is None else r["modes"][mode][window]["mean"]


def _ratio(a, b):
    return None if a is None or not b else a / b


def summary(out: dict) -> dict:
    """The issue's figures: ratios of mean errors (each mode against itself
    at zero delay; the repeat touch against the oracle floor)."""
    oracle = out["oracle"]["whole"]["mean"]
    repeat = {name: _ratio(r["modes"]["repeat"]["whole"]["mean"], oracle)
              for name, r in out["rows"].items()}
    worst = max((v for v in repeat.values() if v is not None), default=None)
    return {
        "ratio_setting": WAN,
        "first_touch_after_news_ratio_200ms": _ratio(_mean(out, WAN, "compensated", "after_news"),
                                                     _mean(out, ZERO, "compensated",
                                                           "after_news")),
        # Against the same reference as the compensated ratio: the
        # (compensated) zero-delay error on that window.
        "naive_after_news_ratio_200ms": _ratio(_mean(out, WAN, "naive", "after_news"),
                                               _mean(out, ZERO, "compensated", "after_news")),
        "naive_after_news_ratio_200ms_own_zero": _ratio(_mean(out, WAN, "naive", "after_news"),
                                                        _mean(out, ZERO, "naive", "after_news")),
        "naive_after_news_ratio_200ms_to_compensated_200ms": _ratio(
            _mean(out, WAN, "naive", "after_news"), _mean(out, WAN, "compensated", "after_news")),
        "first_touch_whole_ratio_200ms": _ratio(_mean(out, WAN, "compensated", "whole"),
                                                _mean(out, ZERO, "compensated", "whole")),
        "naive_whole_ratio_200ms": _ratio(_mean(out, WAN, "naive", "whole"),
                                          _mean(out, ZERO, "naive", "whole")),
        "repeat_touch_ratio_to_oracle_max": worst,
        "repeat_touch_ratio_to_oracle": repeat,
        "oracle_whole": oracle,
        "safety_events": int(sum(m["safety_events"] for r in out["rows"].values()
                                 for m in r["modes"].values())),
    }

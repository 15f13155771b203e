"""``telethermal bench record``: what recording costs the master's loop
at its default rate. The same real-clock session (same seeds) without and
with recording, alternated; the loop's busy time per period, its deadline misses, and the
recorder's own ``log`` call, beside the period budget."""

from __future__ import annotations

import datetime
import platform
import tempfile
import time
from pathlib import Path

import numpy as np

from telethermal.control.loop import DEFAULT_RATE_HZ
from telethermal.jsonfile import write_json
from telethermal.physics.scene import load_scene, with_finger
from telethermal.bench.models import bench_models
from telethermal.sim.inprocess import run_session


def run(rounds: int = 3, contact_s: float = 3.0, progress=None, models=None) -> dict:
    """The report; ``models``: a folder of ``telethermal models`` for
    fingertip-7 (:func:`telethermal.bench.models.bench_models`; None:
    trained here)."""
    step = progress or (lambda _m: None)
    scene = with_finger(load_scene("fingertip-7"))
    ident, gen, provenance = bench_models(scene, models)
    rows = {"without": [], "with": []}
    period_s = 1.0 / DEFAULT_RATE_HZ
    log_calls = []
    with tempfile.TemporaryDirectory() as tmp:
        for r in range(rounds):
            for mode in ("without", "with"):
                step(f"round {r + 1}, {mode} recording")
                path = Path(tmp) / f"r{r}.mcap" if mode == "with" else None
                s = run_session(scene, "wood", ident, gen, contact_s=contact_s, seed=r,
                                realtime=True, record=path).summary
                loop = s["loop"]
                rows[mode].append({"busy_p50_us": loop.get("busy_p50_us"),
                                   "busy_mean_us": loop.get("busy_mean_us"),
                                   "busy_p99_us": loop["busy_p99_us"],
                                   "deadline_misses": loop["deadline_misses"],
                                   "steps": loop["steps"],
                                   # counters and error; not the temporary file's path
                                   "recording": {k: v for k, v in
                                                 (s.get("recording") or {}).items()
                                                 if k != "path"}})
        # The recorder's call alone, as the loop makes it once per period
        # (the news unchanged, as in most periods).
        from telethermal.record.recording import Recorder
        from telethermal.record.recorder import SessionRecorder
        from telethermal.devices.readings import PadSensors
        from telethermal.teleop.master import MasterStep, Phase, SlaveNews
        rec = SessionRecorder(Recorder(Path(tmp) / "calls.mcap", "bench"))
        news = SlaveNews(24.0)
        for k in range(5000):
            sensors = PadSensors(-1234.5 + k, 30.1, 4.0)
            t_s = k * period_s
            step_ = MasterStep(t_s, Phase.RENDER, True, -1200.0, 25.0, 25.0, False)
            t0 = time.perf_counter()
            rec.period(t_s, period_s, sensors, news, step_)
            log_calls.append(time.perf_counter() - t0)
            time.sleep(2e-4)
        rec.close()

    def mean(mode, key):
        return float(np.mean([x[key] for x in rows[mode]]))

    period_us = period_s * 1e6
    calls = np.asarray(log_calls) * 1e6
    extra = mean("with", "busy_mean_us") - mean("without", "busy_mean_us")
    return {
        "rounds": rows, "contact_s": contact_s, "rate_hz": DEFAULT_RATE_HZ,
        "models": provenance,
        "busy_mean_us": {m: mean(m, "busy_mean_us") for m in rows},
        "busy_p99_us": {m: mean(m, "busy_p99_us") for m in rows},
        "deadline_misses": {m: int(sum(x["deadline_misses"] for x in rows[m])) for m in rows},
        "steps": {m: int(sum(x["steps"] for x in rows[m])) for m in rows},
        "log_call_p50_us": float(np.percentile(calls, 50)),
        "log_call_p99_us": float(np.percentile(calls, 99)),
        "extra_busy_per_period_us": extra,
        "cost_of_period_budget": extra / period_us,
        "log_call_of_period_budget": float(np.mean(calls)) / period_us,
        "machine": f"{platform.node()} ({platform.machine()}, "
                   f"{platform.python_implementation()} {platform.python_version()})",
        "date": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
    }


def run_and_save(json_path, rounds: int = 3, contact_s: float = 3.0, command: str = "",
                 progress=None, models=None) -> dict:
    """Run the benchmark and write the JSON report (with ``command``);
    returns the report."""
    report = run(rounds=rounds, contact_s=contact_s, progress=progress, models=models)
    report["command"] = command
    write_json(json_path, report)
    return report



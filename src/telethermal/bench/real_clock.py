"""``bench render``'s real-clock rows: the master's loop on this machine's
clock, its timing pooled over whole touches until a row has enough periods
for a miss rate of 0.1 % to be a count."""

from __future__ import annotations

import numpy as np

from telethermal.teleop.display_setup import add_limits

from telethermal.control.loop import combined_summary, master_step_summary, realtime
from telethermal.teleop.display_config import DisplayConfig
from telethermal.sim.inprocess import run_session

#: The master's own loop on the real clock at these rates, each row pooled
#: over this many periods or more (whole steel touches).
REAL_CLOCK_RATES_HZ = (100.0, 200.0, 500.0, 1000.0)
REAL_CLOCK_PERIODS = 6800


def real_clock_row(scene, identifier, generator, rate_hz: float, mode, contact_s: float,
                   limits: dict, periods: int = REAL_CLOCK_PERIODS, priority: int = 0) -> dict:
    """Steel touches (the scene's first object where it has no steel) on the real clock at ``rate_hz`` (seeds 1, 2, ...) until
    the loop has run ``periods``, its timing pooled over them
    (:func:`combined_summary`): a miss rate of 0.1 % is then a count of
    some, whatever the rate. ``limits``: the bench's module-limit counts,
    added to. ``mode``: ``"master"`` (the world's time not charged to the
    loop) or True (everything on the loop's thread). ``priority``: the
    loop's thread at SCHED_FIFO this priority for the row (0: normal
    scheduling); the row's ``realtime_priority`` is what was granted
    (``realtime_refused``: why not). At SCHED_FIFO the simulated world
    (slave, plants, sensors) runs on the same thread, its time not charged
    to the loop ("master" mode): it holds that thread's core where a lab's
    master would hold it for its step alone; the kernel's real-time
    throttling (``sched_rt_runtime_us``) leaves the rest of the machine its
    share."""
    if periods < 1:
        raise ValueError(f"a real-clock row needs periods >= 1, got {periods}")
    runs, steps_s, flux = [], [], []
    config = DisplayConfig(rate_hz=rate_hz)
    material = "steel" if "steel" in scene.materials else scene.materials[0]
    with realtime(priority) as (granted, refused):
        while sum(len(r.starts_s) for r in runs) < periods:
            res = run_session(scene, material, identifier, generator, config,
                              contact_s=contact_s, seed=len(runs) + 1, realtime=mode)
            add_limits(limits, res.summary["module"])
            runs.append(res.loop_stats)
            steps_s.extend(res.master_step_s)
            flux.append(res.summary["flux_rms_error_rel"])
            clock = res.summary["clock"]
    return {"rate_hz": rate_hz, "material": material, "clock": clock, "sessions": len(runs),
            "contact_s": contact_s,
            "realtime_priority": granted, **({"realtime_refused": refused} if refused else {}),
            **combined_summary(runs), **master_step_summary(steps_s, rate_hz),
            "flux_rms_error_rel": float(np.mean(flux))}

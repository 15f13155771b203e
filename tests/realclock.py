"""What a test may assert of a touch that ran on the real clock.

A touch between service processes runs the master's display loop on the
real clock. When the machine stalls the master's process, the loop's next
period integrates the whole stall (the simulated pad driven open loop at the
last current, in catch-up physics steps) and the supervisor does its job: a
clamp, or the safe state when the surface left the band. How many safety
events such a touch has, and how far its flux is from direct contact, are
therefore real-clock outcomes a loaded machine changes (CI's loaded runs
have failed such asserts). They are counted by ``telethermal bench faults``
(its processes rows: safety events, errors within the simulated spread) and
asserted on the simulated clock, where the same session code runs
deterministically: ``tests/integration/test_session.py``,
``tests/unit/test_sim_network.py``, and ``tests/integration/test_master_drivers.py``,
which holds the service's own touch period equal, bit for bit, to those.

What load cannot change is asserted here: no fault a stall cannot cause (a
reading or setpoint that is not finite, missing or stale, a stuck sensor,
a reading out of the plausible range), and no safety event at all in a
touch whose loop kept every deadline without a stall."""

from __future__ import annotations

import math

from telethermal.control.safety import Fault

#: The faults a stalled display loop can cause: the surface driven past the
#: band through the stall (any devices), and on the emulated boards the
#: Peltier board's own 0.1 s watchdog, whose trip reads as a flux that is not
#: finite (e3f78ae; tests/unit/test_devices.py checks it on the simulated clock).
STALL_FAULTS = {"sim": {Fault.SURFACE_OUT_OF_BAND.value},
                "emulated": {Fault.SURFACE_OUT_OF_BAND.value, Fault.FLUX_NOT_FINITE.value}}


def stalled(loop: dict) -> bool:
    """Whether the touch's display loop recorded a stall or a missed deadline."""
    return loop["stalls"] > 0 or loop["deadline_misses"] > 0


def assert_safe_under_load(s: dict, devices: str = "sim") -> None:
    """The safety outcome of one real-clock touch (a networked touch's
    summary or the master's ``touch`` reply) that load cannot change."""
    counts = s["safety_event_counts"]
    faults = {k for k in counts if k in {f.value for f in Fault}}
    assert faults <= STALL_FAULTS[devices], (faults, counts, s["loop"])
    if s["safety_events"] or faults:
        # A safety event only with the stall that explains it on record.
        assert stalled(s["loop"]), (counts, s["loop"])
        if Fault.FLUX_NOT_FINITE.value in faults:
            # The board's watchdog: it tripped, after a period past its 0.1 s.
            assert s["device_counters"]["driver_board"]["watchdog_trips"] >= 1, s
            assert s["loop"]["period_max_us"] > 0.1e6, s["loop"]


def assert_rendered(s: dict) -> None:
    """A real-clock touch rendered a decision: the master rendered from the
    slave's news and its flux error against direct contact is a number (its
    size is a real-clock figure: see the module's docstring)."""
    assert s["render_start_s"] is not None, s
    assert math.isfinite(s["flux_rms_error_rel"]), s

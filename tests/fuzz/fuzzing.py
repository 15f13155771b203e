"""The fuzz suite's two hypothesis profiles and its tally.

Both are bounded by the number of examples, never by wall time (the
machine is shared): ``fuzz-short`` runs in the normal suite, ``fuzz-long``
under ``make fuzz`` (``TELETHERMAL_FUZZ=long``). Each reader's test counts
its cases and how they ended in :data:`TALLY`; the run's end prints it
and, with ``TELETHERMAL_FUZZ_STATS=FILE``, writes it as JSON."""

from __future__ import annotations

import atexit
import json
import os
from collections import Counter, defaultdict

from hypothesis import HealthCheck, settings

# No example database: each run stands alone (a file made in one run, a
# model's bytes, is not the next run's, so its saved examples would not replay).
settings.register_profile("fuzz-short", max_examples=40, deadline=None, derandomize=True,
                          database=None,
                          suppress_health_check=[HealthCheck.too_slow,
                                                 HealthCheck.data_too_large])
settings.register_profile("fuzz-long", max_examples=2000, deadline=None, database=None,
                          suppress_health_check=[HealthCheck.too_slow,
                                                 HealthCheck.data_too_large])

PROFILE = "fuzz-long" if os.environ.get("TELETHERMAL_FUZZ") == "long" else "fuzz-short"


def fuzz_settings(scale: float = 1.0) -> settings:
    """The profile's settings, ``scale`` times its examples (a reader whose
    case costs more runs fewer)."""
    parent = settings.get_profile(PROFILE)
    return settings(parent, max_examples=max(1, int(parent.max_examples * scale)))


#: reader -> outcome -> cases ("served", "refused", ...).
TALLY: dict[str, Counter] = defaultdict(Counter)
#: reader -> {"largest": (peak bytes, file bytes) of the load with the
#: largest peak; "ratio": (peak / size, peak, size) of the largest ratio
#: among files of at least RATIO_FROM_BYTES (below, the fixed cost of a
#: load, tens of KB, is no ratio to speak of)}.
PEAKS: dict[str, dict] = defaultdict(dict)
RATIO_FROM_BYTES = 4096


def keep_peak(reader: str, peak: int, size: int) -> None:
    kept = PEAKS[reader]
    kept["largest"] = max(kept.get("largest", (0, 0)), (peak, size))
    if size >= RATIO_FROM_BYTES:
        kept["ratio"] = max(kept.get("ratio", (0.0, 0, 0)), (round(peak / size, 2), peak, size))


@atexit.register
def _report() -> None:
    """At the end of the run (no conftest here: another test folder's
    conftest is imported by name), the tally printed and written."""
    if not TALLY:
        return
    stats = {"profile": PROFILE, "readers": {k: dict(v) for k, v in sorted(TALLY.items())},
             "peak_memory": {k: v for k, v in sorted(PEAKS.items())}}
    print("\nfuzz", json.dumps(stats))
    path = os.environ.get("TELETHERMAL_FUZZ_STATS")
    if path:
        with open(path, "w") as f:
            json.dump(stats, f, indent=1)

"""bench render's bookkeeping: which sessions the product's safety count holds."""

from telethermal.bench.render import _safety_counts
from telethermal.teleop.master import DEFAULT_GAINS


def _rows(*events):
    return [{"safety_events": n} for n in events]


def test_the_product_count_holds_every_default_gains_session_and_no_study_row():
    report = {
        "rate": [{"rows": _rows(0, 1)}], "controller": [{"rows": _rows(0)}],
        "before": [{"rows": _rows(2)}],
        "gains": [{"gains": "the shipped ones", "pad_resistance_belief": 1.3,
                   "kp": DEFAULT_GAINS.kp, "ki": DEFAULT_GAINS.ki, "kd": DEFAULT_GAINS.kd,
                   "rows": _rows(4)},
                  {"gains": "PI 1e-3/3e-2", "pad_resistance_belief": 1.3,
                   "kp": 1e-3, "ki": 3e-2, "kd": 0.0, "rows": _rows(13, 0)},
                  {"gains": "P 1e-4", "pad_resistance_belief": 1.0,
                   "kp": 1e-4, "ki": 0.0, "kd": 0.0, "rows": _rows(0)}]}
    out = _safety_counts(report, _rows(8))          # repeated touches, pad at the object
    # 1 (rate) + 2 (before) + 4 (default gains, pad model off) + 8 (more rows)
    assert out["safety_events"] == 15 and out["safety_events_sessions"] == 6
    assert out["safety_events_gain_study"] == {"PI 1e-3/3e-2, pad model x1.3": 13,
                                               "P 1e-4, pad model x1": 0}

"""bench render's bookkeeping: which sessions the product's safety count holds."""

import pytest

from telethermal.bench.render import _safety_counts
from telethermal.teleop.display_config import DEFAULT_GAINS


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


def test_the_junction_loops_stops_and_rearms_are_counted_beside_safety_events():
    """A product session whose junction loop stopped (and re-armed at idle)
    is counted in ``junction_stops``/``junction_rearms``; a gain-study row's
    is not (its gains are not shipped)."""
    stopped = {"safety_events": 0, "junction_stops": 1, "junction_rearms": 1}
    report = {"rate": [{"rows": [stopped, *_rows(0)]}], "controller": [], "before": [],
              "gains": [{"gains": "P 1e-4", "pad_resistance_belief": 1.0, "kp": 1e-4,
                         "ki": 0.0, "kd": 0.0, "rows": [dict(stopped)]}]}
    out = _safety_counts(report, [])
    assert out["junction_stops"] == 1 and out["junction_rearms"] == 1


def _limit_row(largest_a, over_imax, reversals):
    requested = {"requested_over_imax_periods": over_imax, "largest_request_a": largest_a,
                 "voltage_over_supply_periods": 0, "voltage_over_vmax_periods": 0}
    return {"module_limits": {"current_exceeded": 0, "hot_side_exceeded": 0,
                              "reversals": reversals, "contact_s": 2.0, "ripple_rms_a": 0.1,
                              "requested": requested}}


def test_the_limits_key_is_the_shipped_displays_alone():
    """The static controller's and the gain study's requests (not shipped)
    stay in their rows: ``limits`` pools only the default controller's
    sessions (issue 43's targets are on the shipped display)."""
    from telethermal.bench.render import limits_of, shipped_limits
    from telethermal.teleop.display_config import DisplayConfig

    shipped = DisplayConfig().feedforward_model
    other = next(m for m in ("static", "impedance") if m != shipped)
    report = {"controller": [{"feedforward_model": other, "rows": [_limit_row(10.78, 400, 40)]},
                             {"feedforward_model": shipped,
                              "rows": [_limit_row(6.0, 0, 2), _limit_row(7.0, 0, 4)]}],
              "gains": [{"rows": [_limit_row(12.0, 50, 30)]}]}
    lim = shipped_limits(report)
    assert lim["sessions"] == 2 and lim["current_requested_over_imax_periods"] == 0
    assert lim["largest_request_a"] == 7.0
    assert lim["reversals_per_s"] == 6 / 4.0
    assert shipped in lim["configuration"]
    assert limits_of(report["controller"][0]["rows"])["largest_request_a"] == 10.78


def test_dry_air_has_no_dew_point_and_the_bench_says_so():
    """A scene at 0 % RH (no dew point: the logarithm of 0): the bench's
    dew section reports none instead of crashing at the end, and its text
    says dry air; at 50 % it reports the Magnus dew point (24 C: 12.9 C)."""
    from dataclasses import replace

    from telethermal.bench.render import dew_report
    from telethermal.bench.render_text import dew_line
    from telethermal.physics.scene import load_scene

    scene = load_scene("fingertip-7")
    pooled = {"sessions": 0, "min_idle_minus_dew_k": float("inf")}
    dry = dew_report(replace(scene, room_humidity_pct=0.0), pooled)
    assert dry["dew_point_c"] is None
    assert "dry air, no dew point" in dew_line(dry)
    humid = dew_report(replace(scene, room_humidity_pct=50.0, room_temp_c=24.0), pooled)
    assert abs(humid["dew_point_c"] - 12.9) < 0.1


def test_the_dew_margin_is_the_true_surfaces_with_nothing_on_the_pad():
    """The margin is measured on the pad's true surface over the periods
    with no contact (before it and after the release), not on the command:
    a surface that sags 2 K under the dew point after the release is
    reported 2 K under it; the contact's colder surface (under the finger,
    no air) is not counted; dry air has none."""
    import numpy as np

    from telethermal.sim.inprocess import idle_surface_minus_dew_k

    t = np.arange(-0.2, 3.0, 0.01)
    surface = np.full(t.shape, 22.0)
    surface[(t >= 0) & (t < 2.0)] = 10.0        # under the finger
    surface[t >= 2.5] = 18.0                     # after the release
    trace = {"t_s": t, "pad_surface_c": surface}
    assert idle_surface_minus_dew_k(trace, 2.0, 20.0) == -2.0
    assert idle_surface_minus_dew_k(trace, 2.0, None) is None


def test_a_session_adds_to_its_runs_totals_and_to_no_other(trained_models, monkeypatch):
    # The totals were module globals: another bench's sessions in the same
    # process (bench render --as-built's) were added to bench render's.
    from telethermal.bench import render_sessions as rs
    from telethermal.physics.scene import load_scene
    from telethermal.teleop.display_config import DisplayConfig
    from telethermal.physics.scene import with_finger

    monkeypatch.setattr(rs, "CONTACT_S", 0.5)
    scene = with_finger(load_scene("fingertip-7"))
    ident, gen = trained_models.pair(scene, 0)
    mine = rs.Totals()
    row = rs.session_row(scene, "steel", ident, gen, DisplayConfig(), 1, totals=mine)
    rs.session_row(scene, "steel", ident, gen, DisplayConfig(), 1)      # no totals
    # The session without totals added nothing to this run's.
    assert mine.limits["sessions"] == 1 and mine.dew["sessions"] == 1
    assert mine.limits["current_exceeded"] == row["module_limits"]["current_exceeded"]
    assert mine.limits["contact_s"] == row["module_limits"]["contact_s"] > 0


def test_a_display_config_crosses_to_a_worker_whole_or_is_refused():
    from telethermal.bench.render import GAIN_SETS
    from telethermal.bench.render_sessions import config_fields, display_config
    from telethermal.teleop.display_config import DisplayConfig

    import json
    for config in (DisplayConfig(), DisplayConfig(rate_hz=50.0, idle="object"),
                   DisplayConfig(gains=GAIN_SETS["PI 1e-3/1e-2"], r_pad_belief=1.3,
                                 feedforward_model="static", before="hold")):
        assert display_config(json.loads(json.dumps(config_fields(config)))) == config
    with pytest.raises(ValueError, match="cannot carry"):
        config_fields(DisplayConfig(blend_s=0.3))

"""``bench unseen``'s rendered columns (issue 30 part 4): what the master
reads for the oracle and the closed set, the per-material summary and the
issue's rendering targets (hand-made figures: each verdict both ways)."""

import math

import pytest

from telethermal.bench import unseen_render as ur
from telethermal.ident.anytime import NEW_MATERIAL, Estimate, Label, Reason
from telethermal.physics.materials import get_material
from telethermal.teleop.master import SlaveNews
from telethermal.teleop.rendering import Estimated, estimated_target


def _news(estimate):
    return SlaveNews(24.0, estimate, ("marble", "graphite"))


NEW = Estimate(1.0, (0.5, 0.5), Label(NEW_MATERIAL), 0.9, True, Reason.NEW_MATERIAL,
               effusivity_w_s05_m2k=1400.0, effusivity_lo_w_s05_m2k=1300.0,
               effusivity_hi_w_s05_m2k=1500.0, nearest="marble")
NAMED = Estimate(0.3, (0.99, 0.01), Label("graphite"), 0.99, True, Reason.CONFIDENT)


@pytest.mark.parametrize("before", [None, NAMED, NEW])
def test_the_oracle_reads_the_true_effusivity_decided_whatever_the_slave_said(before):
    news = ur.oracle_filter("glass")(_news(before), 0.0)
    assert news.estimate.decided and news.estimate.label.is_new
    assert estimated_target(news.estimate) == Estimated(get_material("glass").effusivity)
    assert news.object_temp_c == 24.0 and news.classes == ("marble", "graphite")


def test_the_closed_set_renders_a_new_material_as_its_nearest_class_and_nothing_else():
    named = ur.closed_set_filter(_news(NEW), 1.0).estimate
    assert named.label == "marble" and named.decided and named.reason == Reason.CONFIDENT
    assert estimated_target(named) is None          # rendered from marble's curve
    for other in (None, NAMED):
        assert ur.closed_set_filter(_news(other), 1.0).estimate is other
    assert ur.news_filter("estimate", "glass") is None
    with pytest.raises(ValueError, match="rendering mode"):
        ur.news_filter("nearest", "glass")


def _row(material, seed, est, ora, closed):
    row = {"material": material, "seed": seed, "identified": "marble", "decision_from_s": 0.1}
    for mode, (f, k) in zip(ur.MODES, (est, ora, closed)):
        row[mode] = {"flux_rms_rel": f, "skin_rms_k": k, "flux_rms_first_s_rel": f,
                     "flux_rms_from_decision_rel": f, "render_start_s": 0.1,
                     "safety_events": 0}
    return row


def test_summary_is_the_median_per_mode_with_its_spread():
    rows = [_row("glass", s, (0.01 * s, 0.1 * s), (0.02, 0.2), (0.03, math.nan))
            for s in (1, 2, 4)]
    out = ur.summarise(rows)
    assert out["flux_rms_rel"] == pytest.approx({"estimate": 0.02, "oracle": 0.02,
                                                 "closed_set": 0.03})
    assert out["skin_rms_k"]["estimate"] == pytest.approx(0.2)
    assert out["skin_rms_k"]["closed_set"] is None   # no finite figure
    assert out["rendered"]["spread"]["flux_rms_rel"]["estimate"]["max"] == pytest.approx(0.04)
    assert out["rendered"]["touches"] == 3 and out["rendered"]["identified"] == {"marble": 3}


def _material(trained, est, ora, closed, sd=0.0):
    fig = {"estimate": est, "oracle": ora, "closed_set": closed}
    spread = {"closed_set": {"sd": sd, "min": 0, "max": 0}}
    return {"trained": trained, "flux_rms_rel": fig, "skin_rms_k": fig,
            "rendered": {"spread": {"flux_rms_rel": spread, "skin_rms_k": spread}}}


def test_rendering_targets_are_the_issues_quoted_thresholds():
    t = ur.targets({
        "near": _material(False, 1.2, 1.0, 1.3),      # <= 1.25x, below a 1.3x closed set
        "over": _material(False, 1.3, 1.0, 1.3),      # 1.3x the oracle
        "tie": _material(False, 1.26, 1.0, 1.26),     # above 1.25x: closed set not beaten
        "easy": _material(False, 1.1, 1.0, 1.05),     # closed set within 1.25x: not required
        "same": _material(True, 1.0, 0.8, 0.97, sd=0.05),
        "worse": _material(True, 1.0, 0.8, 0.9, sd=0.05),
        "not run": {"trained": False, "flux_rms_rel": "not_run", "rendered": None}})
    verdict = {m: v["skin_rms_k"]["met"] for m, v in t["unseen"].items()}
    assert verdict == {"near": True, "over": False, "tie": False, "easy": True}
    assert t["unseen"]["easy"]["flux_rms_rel"]["below_closed_set"] is None
    assert t["unseen"]["near"]["flux_rms_rel"]["estimate_over_oracle"] == pytest.approx(1.2)
    assert {m: v["flux_rms_rel"]["no_worse_within_spread"] for m, v in t["trained"].items()} \
        == {"same": True, "worse": False}

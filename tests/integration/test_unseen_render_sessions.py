"""``bench unseen``'s rendered columns on real sessions: the oracle's
display tracks the closed form of the touched material's true effusivity
from the master's contact onset; the closed set changes nothing where the
slave named a trained class; a tiny bench run writes the issue's fields."""

import json

import numpy as np
import pytest

from telethermal.bench import unseen, unseen_render as ur
from telethermal.physics.materials import get_material
from telethermal.physics.scene import load_scene, with_finger
from telethermal.teleop.display_setup import display_model_args
from telethermal.teleop.rendering import Estimated
from telethermal.sim.inprocess import run_session

SCENE = with_finger(load_scene("fingertip-7"))


@pytest.fixture(scope="module")
def models(trained_models):
    return trained_models.pair(SCENE, 0)


def test_the_oracle_renders_the_true_effusivitys_closed_form_from_onset(models):
    identifier, generator = models
    res = run_session(SCENE, "marble", identifier, generator, contact_s=0.6, seed=3,
                      news_filter=ur.news_filter("oracle", "marble"))
    s, tr = res.summary, res.trace
    onset = s["master_onset_s"]       # the debounced onset's start
    # Rendered from the period the display detected the contact: it never
    # held, nor tracked a posterior mixture.
    phases = [p for p in tr["phase"] if p is not None]
    assert phases[0] == "idle" and set(phases[phases.index("render"):]) <= {"render", "idle"}
    assert "contact" not in phases
    rendering = np.array([p == "render" for p in tr["phase"]])
    assert s["render_start_s"] == pytest.approx(tr["t_s"][rendering][0])
    assert onset < s["render_start_s"] <= onset + 0.05
    t = tr["t_s"][rendering]
    # The display's setpoint: the flux a nominal finger (through the scene's
    # contact conductance, read by the pad's sensor) exchanges with a
    # semi-infinite object of marble's table effusivity, times the gap the
    # master knows (the object's IR reading less the finger's).
    gap_k = s["object_ir_c"] - s["operator"]["finger_ir_c"]
    want = Estimated(get_material("marble").effusivity).normalised(
        t - onset, display_model_args(SCENE)["contact_conductance_w_m2k"],
        SCENE.sensors.flux_lag_s) * gap_k
    np.testing.assert_allclose(tr["desired_flux_w_m2"][rendering], want, rtol=1e-9, atol=1e-9)


def test_the_closed_set_is_the_live_path_where_the_slave_names_a_trained_class(models):
    identifier, generator = models
    live, closed = (run_session(SCENE, "wood", identifier, generator, contact_s=0.6, seed=4,
                                news_filter=ur.news_filter(mode, "wood")).summary
                    for mode in ("estimate", "closed_set"))
    assert live["identified"] == "wood"
    for key in ur.KEYS.values():
        assert closed[key] == live[key]


@pytest.mark.slow          # over 10 s here: make test-all and CI run it
def test_a_tiny_bench_run_reports_the_rendered_columns_and_their_targets(tmp_path):
    path = tmp_path / "u.json"
    unseen.run_and_save(path, seeds=1, quick=True, unseen="glass")
    d = json.loads(path.read_text())
    assert d["rendering"]["touches_per_material"] == ur.TOUCHES_PER_SEED_QUICK
    assert d["rendering"]["flux_rms_rel_is"] == "flux_rms_error_rel_whole"
    assert set(d["materials"]) == set(d["trained"]) | {"glass"}
    for m, r in d["materials"].items():
        for key in ur.TARGET_KEYS:
            assert set(r[key]) == set(ur.MODES)
            assert all(v > 0 for v in r[key].values()), (m, key, r[key])
        assert r["rendered"]["touches"] == 1
    t = d["targets"]["rendering"]
    assert set(t["unseen"]) == {"glass"} and set(t["trained"]) == set(d["trained"])
    assert isinstance(t["unseen"]["glass"]["skin_rms_k"]["met"], bool)
    from telethermal.bench.markdown import Page
    from telethermal.bench.unseen_text import section as unseen_section

    section = "\n".join(unseen_section(d, Page(tmp_path, tmp_path, draw=False)))
    assert "| glass |" in section and "flux estimate / oracle / closed set" in section
    assert "x the oracle, closed set" in section

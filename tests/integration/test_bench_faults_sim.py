"""``bench faults``' simulated part end to end: the rows swept over worker
processes (models by file, jobs and results as JSON), the statistics and
the summary's ratios recomputed from the rows; the same report in one
process."""

import json

import pytest

from telethermal.bench import faults_sim
from telethermal.bench.executor import SerialExecutor
from telethermal.errors import BenchError
from telethermal.physics.scene import load_scene, with_finger
from telethermal.teleop.display_config import DisplayConfig


@pytest.mark.slow          # over 10 s here: make test-all and CI run it
def test_simulated_rows_in_two_workers(tmp_path, trained_models):
    scene = with_finger(load_scene("fingertip-7"))
    ident, gen = trained_models.files(scene, 0)
    rows = [r for r in faults_sim.ROWS if r[0] in (faults_sim.ZERO, faults_sim.WAN)]
    seen = []
    out = faults_sim.run(scene, ident, gen, DisplayConfig(), ["wood"], [1], 1.0, rows,
                         jobs=2, progress=seen.append)
    json.dumps(out)                                      # all of it is plain data
    # The same sweep in this process gives the same report (issue 45).
    here = faults_sim.run(scene, ident, gen, DisplayConfig(), ["wood"], [1], 1.0, rows,
                          executor=SerialExecutor())
    assert (here.pop("executor"), out.pop("executor")) == ("this process", "2 worker processes")
    assert json.dumps(here, sort_keys=True) == json.dumps(out, sort_keys=True)
    assert list(out["rows"]) == [faults_sim.ZERO, faults_sim.WAN]
    assert any("simulated" in s for s in seen)
    zero, wan = out["rows"][faults_sim.ZERO], out["rows"][faults_sim.WAN]
    for row in (zero, wan):
        assert set(row["modes"]) == {"compensated", "naive", "repeat"}
        assert all(m["safety_events"] == 0 for m in row["modes"].values())
    # The zero-delay row has no loss, so no "estimates lossless" ablation.
    assert set(zero["ablations"]) == {"before hold"}
    assert set(wan["ablations"]) == {"before hold", "estimates lossless"}
    s = out["summary"]
    mean = lambda row, mode, w: row["modes"][mode][w]["mean"]          # noqa: E731
    assert s["first_touch_after_news_ratio_200ms"] == pytest.approx(
        mean(wan, "compensated", "after_news") / mean(zero, "compensated", "after_news"))
    assert s["naive_after_news_ratio_200ms"] == pytest.approx(
        mean(wan, "naive", "after_news") / mean(zero, "compensated", "after_news"))
    assert s["first_touch_whole_ratio_200ms"] == pytest.approx(
        mean(wan, "compensated", "whole") / mean(zero, "compensated", "whole"))
    oracle = out["oracle"]["whole"]["mean"]
    assert s["repeat_touch_ratio_to_oracle_max"] == pytest.approx(
        max(mean(r, "repeat", "whole") for r in (zero, wan)) / oracle)
    # The blind window is the delay's: the first news at 200 ms comes after
    # a round trip (0.4 s) and the identification's first window.
    assert zero["modes"]["compensated"]["blind_s"]["mean"] < 0.1
    assert wan["modes"]["compensated"]["blind_s"]["mean"] > 0.4


def test_a_failing_worker_is_reported(tmp_path):
    scene = with_finger(load_scene("fingertip-7"))
    with pytest.raises(BenchError, match=r"unit_job\(simulated: oracle wood\) failed: .*missing"):
        faults_sim.run(scene, tmp_path / "missing.npz", tmp_path / "missing-gen.npz",
                       DisplayConfig(), ["wood"], [1], 1.0, faults_sim.ROWS[:1], jobs=1)

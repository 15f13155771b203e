"""``bench faults`` in parts (processes, figures; its section is in faults_text): the command line
still finds what it uses in ``telethermal.bench.faults``."""

from telethermal.bench import faults, faults_plot, faults_procs, faults_sim


def test_the_facade_exports_what_the_command_line_uses():
    assert faults.run.__module__ == "telethermal.bench.faults"
    assert faults.plot is faults_plot.plot
    assert faults.SETTINGS is faults_procs.SETTINGS
    assert faults.SETTINGS[0][0] == "delay 0 ms" == faults_sim.ROWS[0][0]


def test_the_processes_rows_keep_their_names_and_order():
    # Names are keys of the JSON (rows' "fault", the summary's settings).
    assert [name for name, _ in faults.SETTINGS] == [
        "delay 0 ms", "delay 200 ms", "delay 200 ms, jitter 20 ms, loss 5 %", "loss 20 %",
        "2 s partition mid-contact", "slave crash and restart mid-contact",
        "master crash and restart mid-contact"]


def test_delays_replace_the_pure_delay_rows_of_both_parts_and_keep_the_rest():
    import pytest

    from telethermal.errors import BenchError

    delays = faults.parse_delays("30, 150,0,30")
    assert delays == [0.0, 30.0, 150.0]                      # 0 always, sorted, once
    rows = faults.with_delays(faults_sim.ROWS, delays)
    assert [n for n, _ in rows[:3]] == ["delay 0 ms", "delay 30 ms", "delay 150 ms"]
    assert rows[0][1] == {} and rows[1][1] == {"delay_s": 0.03}
    kept = [n for n, link in faults_sim.ROWS if set(link) - {"delay_s"}]
    assert [n for n, _ in rows[3:]] == kept                  # jitter, loss: unchanged
    assert faults_sim.WAN in kept                            # the summary's row stays
    procs = [n for n, _ in faults.with_delays(faults.SETTINGS, delays)]
    assert procs[:3] == ["delay 0 ms", "delay 30 ms", "delay 150 ms"]
    assert "delay 200 ms" not in procs and "2 s partition mid-contact" in procs
    assert faults.with_delays(faults.SETTINGS, None) == list(faults.SETTINGS)
    for bad, says in (("30,abc", "'abc' is not a delay"), ("-5", "-5 ms is outside"),
                      ("5000", "5000 ms is outside")):
        with pytest.raises(BenchError, match=says):
            faults.parse_delays(bad)


def test_the_benches_take_a_scene_from_the_command_line(monkeypatch, tmp_path):
    """--scene reaches every bench that runs on a scene (the run itself is
    measured by hand: a lab scene's bench faults --quick takes 30 s)."""
    from telethermal.bench import render, skin_floor
    from telethermal.cli import main

    seen = {}

    def fake(name):
        def run(*args, **kwargs):
            seen[name] = kwargs.get("scene_name", kwargs.get("scene"))
            raise SystemExit(0)
        return run

    monkeypatch.setattr(render, "run_and_save", fake("render"))
    monkeypatch.setattr(skin_floor, "run_and_save", fake("skin-floor"))
    monkeypatch.setattr(faults, "run", fake("faults"))
    for bench in ("render", "skin-floor", "faults"):
        try:
            main(["bench", bench, "--json", str(tmp_path / "x.json"), "--scene", "lab.toml"])
        except SystemExit:
            pass
    assert seen == {"render": "lab.toml", "skin-floor": "lab.toml", "faults": "lab.toml"}
    assert main(["bench", "faults", "--json", str(tmp_path / "x.json"), "--delays", "x"]) == 2


def test_a_process_touch_is_judged_against_a_spread_of_two_simulated_touches_or_more():
    """Within mean +- 2 sd of the simulated touches of its material; one
    simulated touch (bench-quick's --seeds 1) is a point, no spread: not
    judged, and said so, where it read "0 of 4"."""
    def sim(n, sd):
        stats = {"wood": {"mean": 0.05, "sd": sd, "n": n}}
        return {"rows": {"delay 0 ms": {"modes": {m: {"by_material": stats}
                                                   for m in ("compensated", "naive")}}}}
    rows = [{"fault": "delay 0 ms", "safety_events": 0, "recovered": True,
             "runs": {"trajectory": [{"material": "wood", "flux_rms_error_rel_whole": 0.052}],
                      "setpoints": [{"material": "wood", "flux_rms_error_rel_whole": 0.08}]}}]
    two = faults_procs.confirm(rows, sim(2, 0.005))
    assert two["processes_within_simulated_spread"] == "1 of 2"
    one = faults_procs.confirm(rows, sim(1, 0.0))
    assert one["processes_within_simulated_spread"].startswith(
        "0 of 0 (2 not judged: one simulated touch of their material, no spread")
    assert one["processes_confirm"] == {}

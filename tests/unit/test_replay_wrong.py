"""``replay`` on well-formed but wrong recordings (issue 47): the probe
found 15 of 41 crashed with a traceback. Each case here is a real session's
recording with one value changed; each is a RecordingError naming the file
(exit 2 from the CLI), or, where what was wrong was skipped, a replay that
says it is damaged and never identical."""

from __future__ import annotations

import copy

import pytest

from telethermal.cli import main
from telethermal.physics.scene import load_scene, with_finger
from telethermal.record.recording import Recorder, RecordingError, read_recording
from telethermal.teleop.display_config import DisplayConfig
from telethermal.teleop.replay import replay
from telethermal.sim.inprocess import run_session

SCENE = with_finger(load_scene("fingertip-7"))


@pytest.fixture(scope="module")
def recorded(trained_models, tmp_path_factory):
    path = tmp_path_factory.mktemp("rec") / "session.mcap"
    run_session(SCENE, "plexiglass", *trained_models.pair(SCENE, 0),
                DisplayConfig(feedforward_model="static"), contact_s=0.4, seed=2, record=path)
    return path


def rewrite(src, dst, config=None, topics=None, raw_config: str | None = None):
    """``src`` written again with its config and topics edited."""
    rec = read_recording(src)
    conf, tops = copy.deepcopy(rec.config), copy.deepcopy(rec.topics)
    if config:
        config(conf)
    if topics:
        topics(tops)
    out = Recorder(dst, rec.role, conf, rec.attachments)
    if raw_config is not None:
        out._writer.add_metadata("config", {"json": raw_config})
    for topic, items in tops.items():
        for t_s, message in items:
            out.log(topic, t_s, message)
    out.close()
    return dst


def _first(tops, topic):
    return tops[topic][0][1]


def _set_display(key, value):
    return lambda c: c["display"].__setitem__(key, value)


CASES = {
    "gains {}": dict(config=_set_display("gains", {})),
    "gains of text": dict(config=_set_display("gains", "fast")),
    "rate_hz 1e308": dict(config=_set_display("rate_hz", 1e308)),
    "rate_hz 0": dict(config=_set_display("rate_hz", 0)),
    "no display": dict(config=lambda c: c.pop("display")),
    "pad resistance text": dict(config=lambda c: c.__setitem__("pad_resistance_m2k_w", "x")),
    "finger_ir_c text": dict(config=lambda c: c.__setitem__("finger_ir_c", "hot")),
    "sampled_curves 5": dict(config=lambda c: c.__setitem__("sampled_curves", 5)),
    "config not JSON": dict(raw_config="{not json"),
    "short estimate": dict(topics=lambda t: next(
        m for _, m in t["/master/news"] if m["estimate"] is not None).__setitem__(
            "estimate", [0.1])),
    "periods column short": dict(topics=lambda t: _first(t, "/master/periods")["flux_w_m2"]
                                 .pop()),
    "periods k0 text": dict(topics=lambda t: _first(t, "/master/periods").__setitem__(
        "k0", "zero")),
    "samples flux short": dict(topics=lambda t: _first(t, "/slave/samples").__setitem__(
        "heat_flux_W_m2", [1.0])),
    "object_ir_c None": dict(topics=lambda t: _first(t, "/slave/samples").__setitem__(
        "object_ir_c", None)),
    "estimate of text": dict(topics=lambda t: _first(t, "/slave/estimates").__setitem__(
        "estimate", "decided")),
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_a_wrong_recording_is_a_clear_error_never_a_traceback(recorded, tmp_path, case,
                                                              capsys):
    path = rewrite(recorded, tmp_path / "wrong.mcap", **CASES[case])
    try:
        summary = replay(path)["summary"]
    except RecordingError as exc:
        assert str(path) in str(exc)
        out = tmp_path / "out"
        assert main(["replay", str(path), "--out", str(out)]) == 2
        assert str(path) in capsys.readouterr().err
        assert not out.exists() or not any(out.iterdir())         # nothing written
        return
    # Replayed: only where what was wrong was itself skipped and said so.
    assert summary["damaged"] or summary["notes"], summary
    assert not summary.get("identical")


def test_periods_that_are_not_a_map_are_skipped_counted_and_not_identical(recorded, tmp_path):
    def edit(t):
        t["/master/periods"][3] = (t["/master/periods"][3][0], {"k0": 1})
    path = rewrite(recorded, tmp_path / "list.mcap", topics=edit)
    with pytest.raises(RecordingError, match=str(path)):
        replay(path)


def test_the_unchanged_copy_replays_identical(recorded, tmp_path):
    path = rewrite(recorded, tmp_path / "same.mcap")
    summary = replay(path)["summary"]
    assert summary["identical"] and summary["damaged"] is None


def test_a_recording_cut_before_its_first_period_says_so(recorded, tmp_path, trained_models):
    """A recording cut short (a copy stopped at 20 kB): its attachments,
    written at its end, are gone, and the touch holds no period; the error
    said only "no generator.npz attached", and with models given the replay
    had printed "0 periods replayed" and exited 0."""
    data = recorded.read_bytes()
    cut = tmp_path / "cut.mcap"
    for size in (len(data) // 8, 20_000):
        cut.write_bytes(data[:size])
        rec = read_recording(cut)
        if not rec.truncated or rec.messages("/master/periods"):
            continue                       # this cut kept a period: not the case here
        with pytest.raises(RecordingError, match=r"was cut.*attachments.*are lost"):
            replay(cut)
        with pytest.raises(RecordingError, match="holds no period to replay.*was cut"):
            replay(cut, *trained_models.pair(SCENE, 0))
        return
    pytest.fail("no cut of the recording lost every period: the case was not built")


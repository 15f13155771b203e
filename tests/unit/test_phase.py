"""The display's phases are an enum whose values are the strings recordings,
the view stream and the status already hold: packed, written and read back
they are those plain strings, byte for byte (issue 20)."""

import json
from pathlib import Path

import msgpack
import pytest
from mcap.reader import make_reader

from telethermal.devices.readings import PadSensors
from telethermal.record.recorder import SessionRecorder, periods
from telethermal.record.recording import Recorder, read_recording
from telethermal.teleop.master import MasterStep, Phase, SlaveNews
from telethermal.wire.codec import decode, encode
from telethermal.wire.golden import messages

PROTO = Path(__file__).resolve().parents[2] / "proto"

#: The strings recordings made before the enum hold (PROTOCOL.md: phase).
RECORDED = ("idle", "contact", "render", "link lost")


def test_the_values_are_the_recorded_strings():
    assert [p.value for p in Phase] == list(RECORDED)
    for phase, plain in zip(Phase, RECORDED):
        assert phase == plain and hash(phase) == hash(plain)
        assert str(phase) == f"{phase}" == "%s" % phase == plain
        assert Phase(plain) is phase


@pytest.mark.parametrize("phase", list(Phase))
def test_msgpack_packs_a_phase_as_the_plain_string(phase):
    plain = str.__str__(phase)                  # the bare str, not the enum member
    assert type(plain) is str
    packed = msgpack.packb(phase, use_bin_type=True)
    assert packed == msgpack.packb(plain, use_bin_type=True)
    back = msgpack.unpackb(packed, raw=False)
    assert type(back) is str and back == plain
    assert json.dumps(phase) == json.dumps(plain)


def test_a_view_batch_with_a_phase_is_the_golden_vector():
    message = messages()["measurement_batch"]
    assert message["phase"] == "render"
    wire = encode({**message, "phase": Phase.RENDER})
    assert wire == (PROTO / "golden" / "measurement_batch.msgpack").read_bytes()
    assert type(decode(wire)["phase"]) is str


def _record(path, phases) -> None:
    rec = SessionRecorder(Recorder(path, "session"))
    news = SlaveNews(24.0)
    for k, phase in enumerate(phases):
        rec.period(k * 1e-3, 1e-3, PadSensors(-100.0 - k, 30.0, 5.0), news,
                   MasterStep(k * 1e-3, phase, True, -90.0, 25.0, 25.0, False))
    rec.close()


def _message_bytes(path, topic):
    with open(path, "rb") as fh:
        return [m.data for _, channel, m in make_reader(fh).iter_messages()
                if channel.topic == topic]


def test_recorded_phases_are_byte_identical_to_plain_strings(tmp_path):
    # 4 x 13 periods: several batches, each phase on both sides of a batch edge.
    members = [p for p in Phase for _ in range(13)]
    plain = [str.__str__(p) for p in members]
    _record(tmp_path / "enum.mcap", members)
    _record(tmp_path / "plain.mcap", plain)
    a = _message_bytes(tmp_path / "enum.mcap", "/master/periods")
    b = _message_bytes(tmp_path / "plain.mcap", "/master/periods")
    assert len(a) == 3 and a == b
    column = [row["phase"] for row in periods(read_recording(tmp_path / "enum.mcap"))]
    assert column == plain and all(type(p) is str for p in column)


def test_a_recorded_session_replays_the_same_phase_column(tmp_path, trained_models):
    # A whole touch: the phases the recording holds are plain strings, and
    # the replay's (Phase members) compare equal to them period by period.
    from telethermal.physics.scene import load_scene
    from telethermal.teleop.display_config import DisplayConfig
    from telethermal.teleop.replay import replay
    from telethermal.sim.inprocess import run_session
    from telethermal.physics.scene import with_finger

    scene = with_finger(load_scene("fingertip-7"))
    path = tmp_path / "session.mcap"
    result = run_session(scene, "plexiglass", *trained_models.pair(scene, 0), DisplayConfig(), contact_s=0.5, seed=2,
                         record=path)
    recorded = [row["phase"] for row in periods(read_recording(path))]
    assert all(type(p) is str for p in recorded)
    assert {"idle", "contact", "render"} <= set(recorded) <= set(RECORDED)
    assert recorded == list(result.trace["phase"])
    again = replay(path)
    assert again["replayed"]["phase"] == again["recorded"]["phase"]
    assert again["summary"]["identical"]

"""The device protocols' golden vectors (``proto/golden/serial``,
``proto/golden/can``): the committed files are what the generator writes,
and the Python codecs read and write them both ways. The reference
firmware is held to the same files (``tests/integration/test_firmware.py``)."""

import json
from pathlib import Path

import pytest

from telethermal.devices import golden
from telethermal.devices.frames import BoardFrame, FrameError, decode, encode
from telethermal.devices.peltier import DB

GOLDEN = Path(__file__).resolve().parents[2] / "proto" / "golden"


def committed(sub: str) -> dict[str, tuple[bytes, dict]]:
    return {p.stem: (p.read_bytes(), json.loads(p.with_suffix(".json").read_text()))
            for p in sorted((GOLDEN / sub).glob("*.bin"))}


def test_the_committed_vectors_are_what_the_generator_writes(tmp_path):
    golden.write(tmp_path)
    for sub in ("serial", "can"):
        made = sorted(p.name for p in (tmp_path / sub).iterdir())
        assert made == sorted(p.name for p in (GOLDEN / sub).iterdir()), sub
        for name in made:
            assert (tmp_path / sub / name).read_bytes() == (GOLDEN / sub / name).read_bytes(), \
                f"{sub}/{name} differs from the generator: rerun python -m " \
                "telethermal.devices.golden proto/golden"


@pytest.mark.parametrize("name", sorted(golden.SERIAL_EXAMPLES))
def test_serial_vector_both_ways(name):
    wire, fields = committed("serial")[name]
    assert wire.endswith(b"\x00") and b"\x00" not in wire[:-1]
    assert encode(BoardFrame(**fields)) == wire
    assert decode(wire[:-1]) == BoardFrame(**fields)


@pytest.mark.parametrize("name", sorted(golden.CAN_EXAMPLES))
def test_can_vector_both_ways(name):
    data, fields = committed("can")[name]
    message = DB.get_message_by_name(fields["message"])
    assert (message.frame_id, message.length) == (fields["frame_id"], fields["dlc"]) == \
        (fields["frame_id"], len(data))
    assert message.encode(fields["signals"], strict=name not in golden.OUT_OF_RANGE) == data
    assert message.decode(data, decode_choices=False) == fields["signals"]
    assert message.decode(data, decode_choices=False, scaling=False) == fields["raw"]


def test_the_vectors_cover_what_they_claim():
    serial = {name: BoardFrame(**f) for name, (_, f) in committed("serial").items()}
    assert {f.type for f in serial.values()} == {1, 2}
    assert {f.status for f in serial.values()} >= {0, 3, 5, 6, 7}
    assert any(f.seq == 0xFFFF and f.t_us == 0xFFFF_FFFF for f in serial.values())
    assert set(committed("can")) == set(golden.CAN_EXAMPLES)
    assert {f["message"] for _, f in committed("can").values()} == \
        {m.name for m in DB.messages}


def test_a_corrupted_serial_vector_is_refused():
    wire, fields = committed("serial")["sample"]
    bad = bytearray(wire)
    bad[10] ^= 0x04
    assert encode(BoardFrame(**fields)) != bytes(bad)
    with pytest.raises(FrameError) as err:
        decode(bytes(bad[:-1]))
    assert err.value.kind == "crc"

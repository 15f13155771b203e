"""bench/firmware.py's parsing and report lines, without QEMU: SLCAN lines
as the core sends them, and the row's lines when the tools are missing."""

from telethermal.bench import firmware
from telethermal.devices.peltier import CMD, DB

HEARTBEAT = DB.get_message_by_name("PELTIER_HEARTBEAT")


def test_slcan_frames_keep_stamped_frames_in_order_and_skip_the_rest():
    beat = HEARTBEAT.encode({"state": 5, "version": 2}).hex().upper()
    text = (b"t70120002\r"                                  # before Z1: no stamp
            b"\r\x07\x07"                                   # an answer, two refusals
            + f"t7012{beat}EA5F\r".encode()                 # 59999 ms
            + f"t7012{beat}0000\r".encode()                 # wrapped to 0
            + b"t70120G020001\r")                           # not hex: skipped
    got = firmware.slcan_frames(text)
    assert [(ms, name) for ms, name, _ in got] == [(59999, "PELTIER_HEARTBEAT"),
                                                    (0, "PELTIER_HEARTBEAT")]
    assert got[0][2] == {"state": 5, "version": 2}


def test_slcan_cmd_is_the_dbc_frame_in_hex():
    line = firmware.slcan_cmd(3, 2.5)
    assert line == b"t1014" + CMD.encode({"enable": 1, "counter": 3, "current_a": 2.5,
                                          "version": 2}).hex().upper().encode() + b"\r"


def test_the_row_says_what_is_missing():
    assert firmware.lines({"skipped": "missing qemu-system-arm (apt-get install "
                                      "qemu-system-arm)"}) == [
        "qemu: skipped, missing qemu-system-arm (apt-get install qemu-system-arm)"]


def test_the_instruction_clock_is_the_parts_clock_times_the_icount_step():
    # 168 MHz SysTick counts over 2**3 ns per instruction.
    assert abs(firmware.SYSTICK_PER_INSTRUCTION - 168e6 * 8e-9) < 1e-12


def test_missing_tools_are_named_with_their_apt_packages(monkeypatch):
    from telethermal.devices import qemu

    monkeypatch.setattr(qemu.shutil, "which", lambda name: None)
    assert qemu.missing() == [("qemu-system-arm", "qemu-system-arm"),
                              ("arm-none-eabi-gcc", "gcc-arm-none-eabi"), ("make", "make")]

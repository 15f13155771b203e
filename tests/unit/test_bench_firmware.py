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


def test_the_instruction_clock_is_the_parts_clock_times_the_icount_step():
    # 168 MHz SysTick counts over 2**3 ns per instruction.
    assert abs(firmware.SYSTICK_PER_INSTRUCTION - 168e6 * 8e-9) < 1e-12


def test_missing_tools_are_named_with_their_apt_packages(monkeypatch):
    from telethermal.devices import qemu

    monkeypatch.setattr(qemu.shutil, "which", lambda name: None)
    assert qemu.missing() == [("qemu-system-arm", "qemu-system-arm"),
                              ("arm-none-eabi-gcc", "gcc-arm-none-eabi"), ("make", "make")]


class FakeCore:
    """The figures a core's symbols hold, in SysTick counts."""

    def __init__(self, **counts):
        self.counts = counts

    def read_u32(self, name):
        return self.counts[name]


def loop_of(own_instructions, isr_counts=42, per_unit_instructions=3000, monkeypatch=None,
            overhead_counts=21):
    """The figures of a core whose worst one-unit iteration, worst per-unit
    cost in a burst, worst interrupt and interrupt overhead are these
    (SysTick counts are 1.344 per instruction: 42 counts = 31.25
    instructions, 21 = 15.625)."""
    from telethermal.devices import qemu_elf

    monkeypatch.setattr(qemu_elf, "symbols", lambda elf: {n: n for n in (
        "board_loop_worst_cycles", "board_isr_worst_cycles", "board_loop_count",
        "board_loop_bursts", "board_loop_worst_unit_cycles", "board_isr_overhead_cycles",
        "board_aside_worst_cycles")})
    per = firmware.SYSTICK_PER_INSTRUCTION
    return firmware.loop_figures(FakeCore(
        board_loop_worst_cycles=round(own_instructions * per),
        board_isr_worst_cycles=isr_counts, board_loop_count=5000,
        board_loop_bursts=2, board_loop_worst_unit_cycles=round(per_unit_instructions * per),
        board_isr_overhead_cycles=overhead_counts, board_aside_worst_cycles=9000),
        "elf")


def test_the_loop_bound_adds_the_interrupts_the_line_can_bring_in_an_iteration(monkeypatch):
    # 4000 instructions at 3 cycles: 12000 cycles. An interrupt: its span
    # (31.25 instructions) and what lies outside it (15.625) at 3 cycles,
    # 140.625, plus the exception's 39 cycles: 179.625. A byte every
    # 10/921600 s = 10.85 us, each with a receive and a transmit interrupt,
    # and one SysTick. From 12000 + 3 x 179.625: 74.6 us, 7 bytes + 1 -> 17
    # interrupts, 15053.625 cycles, 89.6 us, 9 + 1 -> 21, 15772.125 cycles
    # (93.9 us: 9 + 1 again): the fixed point, 21 interrupts, under the
    # tenth of the period (16800).
    r = loop_of(4000, monkeypatch=monkeypatch)
    assert r["interrupts_in_an_iteration_on_silicon"] == 21
    assert abs(r["worst_cycles_bound"] - 15772.125) <= 1 and r["under_a_tenth"]
    assert abs(r["isr_cycles_bound"] - 179.625) <= 1
    assert r["bursts"] == 2 and r["worst_instructions_per_unit_in_a_burst"] == 3000
    # 4500: 16912.875 -> 23 interrupts, 17631.375 (fixed): over the tenth.
    r = loop_of(4500, monkeypatch=monkeypatch)
    assert r["interrupts_in_an_iteration_on_silicon"] == 23
    assert abs(r["worst_cycles_bound"] - 17631.375) <= 1 and not r["under_a_tenth"]
    # The interrupt's overhead counts: without it, 4500 instructions are
    # 13500 + 21 x (93.75 + 39) = 16287.75 (fixed at 21), under.
    r = loop_of(4500, monkeypatch=monkeypatch, overhead_counts=0)
    assert abs(r["worst_cycles_bound"] - 16287.75) <= 1 and r["under_a_tenth"]


def test_an_overhead_the_core_did_not_measure_is_refused(monkeypatch):
    import pytest

    with pytest.raises(RuntimeError, match="board_isr_overhead_cycles"):
        loop_of(4000, monkeypatch=monkeypatch, overhead_counts=0xFFFFFFFF)


def test_a_bursts_cost_per_unit_counts_when_it_is_the_worse(monkeypatch):
    # One-unit iterations at 4000 instructions, but a burst's per-unit cost
    # at 4500: the bound is 4500's (above), over the tenth.
    r = loop_of(4000, per_unit_instructions=4500, monkeypatch=monkeypatch)
    assert r["worst_instructions"] == 4000
    assert abs(r["worst_cycles_bound"] - 17631.375) <= 1 and not r["under_a_tenth"]


def test_the_benchmark_page_shows_the_row_and_a_loop_over_its_budget(monkeypatch):
    loop = loop_of(4500, monkeypatch=monkeypatch)
    row = {"machine": "netduinoplus2", "part": "STM32F405RG", "sysclk_hz": 168e6,
           "icount_shift": 3, "sizes": {"tt_board": {"flash": 6244, "ram": 2396}},
           "peltier_loop": loop_of(4000, monkeypatch=monkeypatch), "board_loop": loop,
           "watchdog": {"trips": 20, "trials": 20, "delay_ms_min": 100, "delay_ms_max": 101,
                        "limit_ms": 100}}
    text = "\n".join(firmware.report_lines(row))
    assert "| tt_board | 6,244 B | 2,396 B |" in text
    assert "| peltier loop | 5000 | 4,000 | 21 x 180 cycles | 15,772 | 16,800 | yes |" in text
    assert "| board loop | 5000 | 4,500 | 23 x 180 cycles | 17,631 | 16,800 | NO |" in text
    assert "20 trips in 20 trials, 100-101 ms" in text
    assert firmware.report_lines({"skipped": "missing make (apt-get install make)"}) == [
        "The firmware on QEMU: skipped, missing make (apt-get install make)."]

"""The reference firmware measured on QEMU's STM32F405 (``bench devices``'
``qemu`` row; the scenarios the processor-in-the-loop tests also run):

* flash and RAM of each image (``arm-none-eabi-size``);
* the worst loop iteration of each application, from the core's own count
  (``board_loop_worst_cycles``, read through QEMU's monitor), its UART
  interrupts counted apart (see :func:`loop_figures`). Under
  ``-icount shift=3`` QEMU advances the core's clock 8 ns per instruction,
  so SysTick's 168 MHz count is 1.344 per instruction: the figure is an
  instruction count. QEMU models no pipeline or wait states; on silicon an
  instruction takes 1 cycle (most data processing), 2 (a load or store)
  or up to 4 (a taken branch; ARM DDI 0439 table 3-1), so the budget is
  checked at 3 cycles per instruction, a pessimistic mean;
* the Peltier driver's watchdog: bursts of commands at 100 Hz, then
  silence, ``trials`` times; the delay from the answer to the last command
  to the watchdog's status, both stamped by the core (SLCAN timestamps).
  The driver trips at the first poll more than 100 ms after the one that
  handled the command; the answer's stamp is taken when it is sent, which
  can be the next millisecond when that poll crossed one, so a delay
  measured this way is 100 or 101 ms on an idle host. The idle core's
  clock follows the host's (``-icount sleep=on``): a loaded host that
  leaves QEMU unscheduled for a millisecond steps it, and a delay then
  reads more (102 seen once in a CI rehearsal).
"""

from __future__ import annotations

import math
import re
import time
from pathlib import Path

from telethermal.devices import qemu, qemu_elf
from telethermal.devices.peltier import CMD, DB

#: The part's clock and QEMU's instruction clock (2**ICOUNT_SHIFT ns).
SYSCLK_HZ = 168_000_000
SYSTICK_PER_INSTRUCTION = SYSCLK_HZ * 2 ** qemu.ICOUNT_SHIFT * 1e-9
#: Cycles per instruction assumed for the budget on silicon (see above).
CYCLES_PER_INSTRUCTION_BOUND = 3
#: What an interrupt costs on silicon that no instruction count shows: the
#: exception's entry, 12 cycles from the request to the handler's first
#: instruction with zero-wait-state memory (ARM's Cortex-M4 documentation,
#: "interrupt latency"), and its return, counted at the entry's 12 again; and
#: three fetches from flash the accelerator may miss, at 5 wait states each
#: (RM0090 table 10: 168 MHz at 2.7-3.6 V): the vector, the handler's first
#: instruction, the instruction returned to. A bound.
EXCEPTION_CYCLES = 12 + 12 + 3 * 5
#: The loops' periods: the Peltier driver polls every millisecond; the
#: sensor board frames a sample every millisecond (1 kHz).
LOOP_PERIOD_S = 1e-3
#: One byte's time on the link to the PC (921600 baud, 10 bits a byte).
LINK_BYTE_S = 10 / 921_600
#: The master's command period (100 Hz), for the bursts: pacing only.
COMMAND_PERIOD_S = 0.01


def slcan_cmd(counter: int, current_a: float, enable: int = 1) -> bytes:
    """A ``PELTIER_CMD`` as the PC's SLCAN line."""
    data = CMD.encode({"enable": enable, "counter": counter & 0xF, "current_a": current_a,
                       "version": 2}, strict=False)
    return f"t{CMD.frame_id:03X}{len(data)}{data.hex().upper()}\r".encode()


def slcan_frames(text: bytes) -> list[tuple[int, str, dict]]:
    """The core's SLCAN frames sent with timestamps (after ``Z1``), in order,
    as (core ms modulo 60000, message name, signals decoded by cantools)."""
    out = []
    for line in re.split(rb"[\r\x07]", text):        # BEL ends a refused line
        m = re.fullmatch(rb"t([0-9A-F]{3})([0-8])([0-9A-F]*)", line)
        if m is None or len(m.group(3)) != 2 * int(m.group(2)) + 4:
            continue
        body = m.group(3)
        message = DB.get_message_by_frame_id(int(m.group(1), 16))
        out.append((int(body[-4:], 16), message.name,
                    message.decode(bytes.fromhex(body[:-4].decode()), decode_choices=False)))
    return out


def open_peltier(core: qemu.QemuCore) -> tuple[qemu.PtyLine, qemu.PtyLine]:
    """The Peltier image's link and plant, once it is up (its boot heartbeat
    and the H-bridge off from reset), SLCAN timestamps on."""
    link, plant = qemu.PtyLine(core.link_path), qemu.PtyLine(core.plant_path)
    link.until(rb"t70120002\r")
    plant.until(rb"set 0 0 0\n")
    link.write(b"Z1\r")
    link.until(rb"^[^\x07]*?\r")
    return link, plant


def watchdog_trials(link: qemu.PtyLine, plant: qemu.PtyLine, trials: int = 20,
                    burst: int = 6) -> dict:
    """Bursts of ``burst`` commands (1.25 A) about ``COMMAND_PERIOD_S``
    apart, each followed by silence until the H-bridge goes off. Returns
    the trips (watchdog statuses), each one's delay after the answer to the
    command before it (core ms), and every change of the H-bridge (``set``
    lines: core ms, enabled, mA)."""
    for _ in range(trials):
        for k in range(burst):
            link.write(slcan_cmd(k, 1.25))
            time.sleep(COMMAND_PERIOD_S)
        plant.until(rb"set \d+ 0 0\n")
    link.read(0.05)
    trips, delays, last_ms = [], [], None
    for ms, name, status in slcan_frames(link.log):
        if name == "PELTIER_STATUS" and status["enabled"]:
            last_ms = ms                                    # the answer to a command
        elif name == "PELTIER_STATUS" and status["watchdog"] and last_ms is not None:
            trips.append((ms, status))
            delays.append((ms - last_ms) % 60_000)          # the stamps wrap at 60 s
    changes = [tuple(map(int, m)) for m in re.findall(rb"set (\d+) (\d) (-?\d+)\n", plant.log)]
    return {"trips": trips, "delays_ms": delays, "changes": changes}


def loop_figures(core: qemu.QemuCore, elf: Path) -> dict:
    """The worst loop iteration the firmware measured so far, and the
    budget it is held to on silicon.

    The core leaves its UART interrupts out of an iteration and counts them
    apart (``board.h``): QEMU models no baud rate, so a burst the host wrote
    at once lands in one iteration, as many interrupts and, for the Peltier
    driver, as many command frames as the host stalled over. The iteration's
    own cost is the worse of the worst one-unit iteration and the worst
    per-unit cost of an iteration that handled several (on silicon the loop
    wakes at each byte, so it handles one; the burst's per unit is kept as
    a bound all the same). On silicon the link's bytes come at most every
    :data:`LINK_BYTE_S`, each with a receive and a transmit interrupt at
    most; those that fall inside the iteration (plus one pending each way)
    lengthen it, which lets more in: the count is iterated to its fixed
    point; SysTick's, once a millisecond, adds one more (an iteration
    under a tenth of the period holds at most one). An interrupt costs its
    worst span, what the core measured at boot outside that span
    (``board_isr_overhead_cycles``: the handler's entry and bookkeeping),
    at :data:`CYCLES_PER_INSTRUCTION_BOUND`, and :data:`EXCEPTION_CYCLES`.
    The bound is held against a tenth of the period. The
    processor-in-the-loop stand-in's own work (``plant.c``: its text lines
    for the ADCs and the H-bridge) is left out by the core and its worst
    span recorded (``board_aside_worst_cycles``)."""
    sym = qemu_elf.symbols(elf)

    def instructions(name: str) -> float:
        return core.read_u32(sym[name]) / SYSTICK_PER_INSTRUCTION

    one, per_unit = instructions("board_loop_worst_cycles"), \
        instructions("board_loop_worst_unit_cycles")
    isr = instructions("board_isr_worst_cycles")
    if core.read_u32(sym["board_isr_overhead_cycles"]) == 0xFFFFFFFF:
        raise RuntimeError(f"{elf}: the core's interrupt overhead was not measured at boot "
                           "(board_isr_overhead_cycles): no loop bound without it")
    overhead = instructions("board_isr_overhead_cycles")
    own_cycles = max(one, per_unit) * CYCLES_PER_INSTRUCTION_BOUND
    isr_cycles = (isr + overhead) * CYCLES_PER_INSTRUCTION_BOUND + EXCEPTION_CYCLES
    budget = SYSCLK_HZ * LOOP_PERIOD_S / 10
    bound = own_cycles + 3 * isr_cycles
    for _ in range(100):                            # to the fixed point (or past the budget)
        interrupts = 2 * (math.ceil(bound / SYSCLK_HZ / LINK_BYTE_S) + 1) + 1  # + SysTick
        bound, previous = own_cycles + interrupts * isr_cycles, bound
        if bound == previous or bound > 10 * budget:
            break
    return {"iterations": core.read_u32(sym["board_loop_count"]),
            "worst_instructions": round(one), "worst_isr_instructions": round(isr),
            "isr_overhead_instructions": round(overhead), "isr_cycles_bound": round(isr_cycles),
            "worst_stand_in_instructions_left_out": round(instructions("board_aside_worst_cycles")),
            "bursts": core.read_u32(sym["board_loop_bursts"]),
            "worst_instructions_per_unit_in_a_burst": round(per_unit),
            "interrupts_in_an_iteration_on_silicon": interrupts,
            "worst_cycles_bound": round(bound),
            "period_cycles": round(SYSCLK_HZ * LOOP_PERIOD_S), "tenth_of_period_cycles":
                round(budget),
            "under_a_tenth": bound < budget}


def _board(core: qemu.QemuCore, samples: int) -> int:
    """``samples`` plant lines through the sensor board image, in windows
    of 20; returns the frames that came back (boot frame included)."""
    link, plant = qemu.PtyLine(core.link_path), qemu.PtyLine(core.plant_path)
    try:
        link.until(rb"\x00")                                # the boot frame: UARTs up
        for i in range(0, samples, 20):
            n = min(20, samples - i)
            plant.write(b"".join(f"s {-4410.5 + j} 412.25 25 2.125 7\n".encode()
                                 for j in range(i, i + n)))
            guard = time.monotonic() + 30                   # a hang guard
            while link.log.count(b"\x00") < i + n + 1 and time.monotonic() < guard:
                link.read(0.005)
        return link.log.count(b"\x00")
    finally:
        link.close()
        plant.close()


def measure(build_dir: str | Path, trials: int = 20, board_samples: int = 200) -> dict:
    """The ``qemu`` row: sizes, loop figures, watchdog; or what is missing."""
    gone = qemu.missing()
    if gone:
        return {"skipped": "missing " + ", ".join(f"{w} (apt-get install {p})"
                                                  for w, p in gone)}
    images = qemu.build_images(build_dir)
    row = {"machine": qemu.MACHINE, "icount_shift": qemu.ICOUNT_SHIFT,
           "sysclk_hz": SYSCLK_HZ, "part": "STM32F405RG (1 MB flash, 128 KB SRAM)",
           "sizes": {name: qemu_elf.image_size(elf) for name, elf in images.items()}}
    with qemu.QemuCore(images["tt_peltier"]) as core:
        link, plant = open_peltier(core)
        try:
            w = watchdog_trials(link, plant, trials)
        finally:
            link.close()
            plant.close()
        row["peltier_loop"] = loop_figures(core, images["tt_peltier"])
    delays = w["delays_ms"]
    row["watchdog"] = {"trials": trials, "trips": len(w["trips"]), "delay_ms_min": min(delays),
                       "delay_ms_max": max(delays), "limit_ms": 100,
                       "within_100_ms_and_a_period": all(
                           100 <= d <= 100 + 1000 * COMMAND_PERIOD_S for d in delays)}
    with qemu.QemuCore(images["tt_board"]) as core:
        frames = _board(core, board_samples)
        row["board_loop"] = {**loop_figures(core, images["tt_board"]), "frames": frames}
    return row


def report_lines(q: dict) -> list[str]:
    """The ``qemu`` row as ``bench devices`` prints it and the benchmark
    page shows it (markdown: one renderer for both)."""
    if "skipped" in q:
        return [f"The firmware on QEMU: skipped, {q['skipped']}."]
    lines = [f"The reference firmware on QEMU's {q['machine']} ({q['part']}, "
             f"{q['sysclk_hz'] / 1e6:g} MHz; `-icount shift={q['icount_shift']}`):", "",
             "| image | flash | RAM |", "|---|---|---|"]
    lines += [f"| {name} | {s['flash']:,} B | {s['ram']:,} B |" for name, s in q["sizes"].items()]
    lines += ["", "| loop | iterations | worst instructions | interrupts on silicon x bound "
                  "| worst cycles, bound | a tenth of the period | under |",
              "|---|---|---|---|---|---|---|"]
    for name in ("peltier_loop", "board_loop"):
        r = q[name]
        lines.append(f"| {name.replace('_', ' ')} | {r['iterations']} | "
                     f"{r['worst_instructions']:,} | "
                     f"{r['interrupts_in_an_iteration_on_silicon']} x "
                     f"{r.get('isr_cycles_bound', '?')} cycles | {r['worst_cycles_bound']:,} | "
                     f"{r['tenth_of_period_cycles']:,} | {'yes' if r['under_a_tenth'] else 'NO'} |")
    w = q["watchdog"]
    lines += ["", f"Watchdog: {w['trips']} trips in {w['trials']} trials, "
                  f"{w['delay_ms_min']}-{w['delay_ms_max']} ms after the last command "
                  f"(limit {w['limit_ms']} ms plus one 10 ms command period)."]
    return lines

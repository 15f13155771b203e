"""The reference firmware (``firmware/``) on the host: compiled with the
system C compiler, held to the Python side's golden vectors both ways, run
as the sensor board on one end of a pty with the project's serial driver on
the other, and as the Peltier driver on a script of CAN frames with a
simulated clock (its watchdog).

Skipped, with the reason, where no C compiler is found (``CC``, ``cc`` or
``gcc``)."""

from __future__ import annotations

import inspect
import json
import os
import random
import shutil
import struct
import subprocess
import time
import tty
from pathlib import Path

import can
import pytest

from telethermal.devices.emulators import PeltierEmulator
from telethermal.devices.frames import TYPE_BOOT, TYPE_SAMPLE
from telethermal.devices.active_pad import ActivePadDriver
from telethermal.devices.board import SensorBoard
from telethermal.devices.peltier import CMD, DB, PeltierDriver

ROOT = Path(__file__).resolve().parents[2]
FIRMWARE = ROOT / "firmware"
GOLDEN = ROOT / "proto" / "golden"
CFLAGS = ["-std=c11", "-Wall", "-Wextra", "-Werror", "-pedantic", "-O2"]
#: What a lab's cross compiler will be stricter about: the portable part
#: alone, freestanding, with conversion and prototype warnings as errors.
STRICT = ["-ffreestanding", "-Wconversion", "-Wsign-conversion", "-Wshadow",
          "-Wstrict-prototypes", "-Wmissing-prototypes", "-Wcast-qual", "-Wdouble-promotion"]
#: The driver's watchdog, as the project's emulator and proto/CAN.md have it.
WATCHDOG_MS = round(1000 * inspect.signature(PeltierEmulator).parameters["watchdog_s"].default)


def compiler() -> str:
    cc = os.environ.get("CC") or shutil.which("cc") or shutil.which("gcc")
    if not cc:
        pytest.skip("no C compiler: neither $CC nor cc nor gcc is on PATH; the firmware "
                    "tests need one (e.g. apt-get install gcc libc6-dev)")
    return cc


@pytest.fixture(scope="module")
def tt_host(tmp_path_factory) -> Path:
    """The host build of the firmware, compiled into a temporary folder."""
    cc = compiler()
    exe = tmp_path_factory.mktemp("firmware") / "tt_host"
    sources = sorted(FIRMWARE.glob("src/*.c")) + sorted(FIRMWARE.glob("host/*.c"))
    build = subprocess.run([cc, *CFLAGS, "-o", str(exe), *map(str, sources)],
                           capture_output=True, text=True)
    assert build.returncode == 0, f"{cc} failed:\n{build.stderr}"
    return exe


def run(exe: Path, *args: str, stdin: str = "") -> str:
    done = subprocess.run([str(exe), *args], input=stdin, capture_output=True, text=True,
                          timeout=60)
    assert done.returncode == 0, f"tt_host {' '.join(args)}: {done.stderr}"
    return done.stdout


def vectors(sub: str) -> dict[str, tuple[bytes, dict]]:
    found = {p.stem: (p.read_bytes(), json.loads(p.with_suffix(".json").read_text()))
             for p in sorted((GOLDEN / sub).glob("*.bin"))}
    assert found, f"no golden vectors in {GOLDEN / sub}"
    return found


def float_arg(value: float) -> str:
    """A float for the C side's strtof, exactly (hexadecimal where finite)."""
    return value.hex() if value == value and abs(value) != float("inf") else repr(value)


V2_FIELDS = ("ir_object_c", "ir_ambient_c", "pad_drive")


def serial_line(f: dict) -> str:
    """A record's fields for tt_host serial-encode; version 2's extra fields
    are there when the JSON has them."""
    extra = [float_arg(f[k]) for k in V2_FIELDS] if V2_FIELDS[0] in f else []
    return " ".join([str(f["version"]), str(f["type"]), str(f["seq"]), str(f["t_us"]),
                     *(float_arg(f[k]) for k in ("flux_uv", "tc_uv", "cj_c", "force_n")),
                     str(f["status"]), *extra])


def encode_serial(exe: Path, fields: list[dict]) -> list[bytes]:
    out = run(exe, "serial-encode", stdin="".join(serial_line(f) + "\n" for f in fields))
    return [bytes.fromhex(line) for line in out.split()]


# ------------------------------------------------------------------ basics
def test_selftest_crc_check_value_and_cobs_reference_vectors(tt_host):
    assert run(tt_host, "selftest").strip().endswith("0 failed")


def test_the_portable_part_builds_freestanding_with_strict_warnings(tmp_path):
    cc = compiler()
    for source in sorted(FIRMWARE.glob("src/*.c")):
        build = subprocess.run([cc, *CFLAGS, *STRICT, "-c", "-o", str(tmp_path / "x.o"),
                                str(source)], capture_output=True, text=True)
        assert build.returncode == 0, f"{source.name}:\n{build.stderr}"


def test_the_portable_part_includes_no_mcu_or_hosted_header():
    freestanding = {"stdint.h", "stddef.h", "stdbool.h", "float.h", "limits.h"}
    for source in sorted(FIRMWARE.glob("src/*.[ch]")):
        for line in source.read_text().splitlines():
            if line.startswith("#include <"):
                assert line[10:-1] in freestanding, f"{source.name}: {line}"


# ------------------------------------------------------------------ golden vectors
def test_every_serial_golden_vector_encodes_byte_for_byte(tt_host):
    golden = vectors("serial")
    assert {f["version"] for _, f in golden.values()} == {1, 2}
    made = encode_serial(tt_host, [fields for _, fields in golden.values()])
    assert len(made) == len(golden)
    differ = [name for (name, (wire, _)), mine in zip(golden.items(), made) if wire != mine]
    assert not differ, f"the firmware's frames differ from the golden vectors: {differ}"


def test_a_corrupted_serial_vector_is_detected(tt_host):
    wire, fields = vectors("serial")["sample"]
    for i in (0, 5, len(wire) - 2):
        bad = bytearray(wire)
        bad[i] ^= 0x01
        assert encode_serial(tt_host, [fields]) != [bytes(bad)]
    changed = dict(fields, force_n=fields["force_n"] + 1.0)
    assert encode_serial(tt_host, [changed]) != [wire]


def message_of(fields: dict):
    return DB.get_message_by_name(fields["message"])


def can_golden_round_trip(run_codec) -> int:
    """Every CAN golden vector decoded and encoded by ``run_codec(script)``
    (the firmware's ``can-codec`` mode on some core, its output), each
    field and byte as the vector says; how many vectors."""
    golden = vectors("can")
    decoded = run_codec("".join(f"decode {f['frame_id']:x} {data.hex()}\n"
                                for data, f in golden.values())).splitlines()
    encoded = run_codec("".join(
        f"encode {f['frame_id']:x} " + " ".join(str(f["raw"][s.name])
                                               for s in message_of(f).signals) + "\n"
        for _, f in golden.values())).split()
    assert len(decoded) == len(encoded) == len(golden)
    for (name, (data, fields)), line, mine in zip(golden.items(), decoded, encoded):
        message, *pairs = line.split()
        assert message == fields["message"], name
        assert {k: int(v) for k, v in (p.split("=") for p in pairs)} == fields["raw"], name
        assert bytes.fromhex(mine) == data, name
    return len(golden)


#: Lines each codec mode refuses (exit 2, naming the line), the host's
#: 64-bit and the core's 32-bit unsigned long alike: a field missing or one
#: too many, a number out of its field's range (t_us past 32 bits, past 64),
#: a negative or malformed number, an unknown verb or CAN id, bad hex.
REFUSED = {
    "serial-encode": ["2 1 0 0 1 2 3 4", "2 1 0 0 1 2 3 4 0 5", "2 1 0 0 1 2 3 4 0 5 6 7 8",
                      "2 1 0 4294967296 1 2 3 4 0", "2 1 0 18446744073709551616 1 2 3 4 0",
                      "-1 1 0 0 1 2 3 4 0", "2 1 1x 0 1 2 3 4 0", "2 1 65536 0 1 2 3 4 0"],
    "can-codec": ["decode zz 00", "decode 101 0g", "decode 800 00", "frobnicate 101 00",
                  "decode", "encode 101 1 x"],
}


@pytest.mark.parametrize("mode,line", [(m, x) for m, lines in REFUSED.items() for x in lines])
def test_a_malformed_line_is_refused_naming_it(tt_host, mode, line):
    done = subprocess.run([str(tt_host), mode], input=line + "\n", capture_output=True,
                          text=True, timeout=60)
    assert done.returncode == 2, (line, done.stdout, done.stderr)
    assert f"{mode}: line 1:" in done.stderr and line in done.stderr


def test_every_can_golden_vector_both_ways(tt_host):
    assert can_golden_round_trip(lambda script: run(tt_host, "can-codec", stdin=script)) >= 27


def test_a_corrupted_can_vector_is_detected(tt_host):
    data, fields = vectors("can")["cmd_cool"]
    bad = bytearray(data)
    bad[1] ^= 0x01
    line = run(tt_host, "can-codec", stdin=f"decode 101 {bytes(bad).hex()}\n")
    decoded = {k: int(v) for k, v in (p.split("=") for p in line.split()[1:])}
    assert decoded != fields["raw"]
    assert decoded["current_a"] == fields["raw"]["current_a"] ^ 1


# ------------------------------------------------------------------ the pty round trip
def f32(value: float) -> float:
    return struct.unpack("<f", struct.pack("<f", value))[0]


def f32_bits(value: float) -> int:
    return struct.unpack("<I", struct.pack("<f", value))[0]


def random_value(rng: random.Random) -> float:
    """A float32 of every kind: typical readings, zeros (zero bytes for
    COBS), any bit pattern but NaN's, the specials."""
    kind = rng.random()
    if kind < 0.5:
        return f32(rng.gauss(0.0, 3000.0))
    if kind < 0.6:
        return rng.choice([0.0, -0.0, 1.0, -1.0, 0.5, 256.0])
    if kind < 0.98:
        while True:
            value = struct.unpack("<f", struct.pack("<I", rng.getrandbits(32)))[0]
            if value == value:
                return value
    return rng.choice([float("inf"), float("-inf"), float("nan")])


def random_samples(n: int, seed: int, version: int = 1) -> list[dict]:
    """Sample fields, seeded; the clock starts near its wrap so that it wraps."""
    rng = random.Random(seed)
    t_us = 2**32 - 1000 * (n // 2)
    out = []
    for _ in range(n):
        t_us = (t_us + rng.randrange(0, 2000)) & 0xFFFF_FFFF
        sample = {"t_us": t_us, "flux_uv": random_value(rng), "tc_uv": random_value(rng),
                  "cj_c": f32(rng.uniform(-10.0, 60.0)), "force_n": random_value(rng),
                  "status": rng.choice([7, 7, 7, rng.randrange(8)])}
        if version == 2:
            sample.update(ir_object_c=random_value(rng), ir_ambient_c=random_value(rng),
                          pad_drive=random_value(rng),
                          status=rng.choice([15, 15, 31, 47, rng.randrange(64)]))
        out.append(sample)
    return out


def frame_key(f) -> tuple:
    extra = tuple(f32_bits(getattr(f, k)) for k in V2_FIELDS) if f.version == 2 else ()
    return (f.version, f.type, f.seq, f.t_us, f32_bits(f.flux_uv), f32_bits(f.tc_uv),
            f32_bits(f.cj_c), f32_bits(f.force_n), f.status) + extra


def expected_keys(samples: list[dict], cj_c: float, version: int = 1) -> list[tuple]:
    boot = (version, TYPE_BOOT, 0, 0, 0, 0, f32_bits(cj_c), 0, 0) + \
        ((0, 0, 0) if version == 2 else ())
    return [boot] + [(version, TYPE_SAMPLE, (i + 1) & 0xFFFF, s["t_us"], f32_bits(s["flux_uv"]),
                      f32_bits(s["tc_uv"]), f32_bits(s["cj_c"]), f32_bits(s["force_n"]),
                      s["status"]) + (tuple(f32_bits(s[k]) for k in V2_FIELDS)
                                      if version == 2 else ())
                     for i, s in enumerate(samples)]


def pty_round_trip(exe: Path, samples: list[dict], tmp_path: Path, *args: str):
    """The host firmware writes frames into a pty's master end; the
    project's SensorBoard driver reads its slave end by path. Returns the
    frames the driver decoded, its counters and the firmware's exit code."""
    script = tmp_path / "samples.txt"
    script.write_text("".join(
        f"{s['t_us']} {float_arg(s['flux_uv'])} {float_arg(s['tc_uv'])} "
        f"{float_arg(s['cj_c'])} {float_arg(s['force_n'])} {s['status']}"
        + "".join(f" {float_arg(s[k])}" for k in V2_FIELDS if k in s) + "\n"
        for s in samples))
    master, slave = os.openpty()
    tty.setraw(slave)                       # no line discipline on the frames
    board = SensorBoard(os.ttyname(slave))
    got = []
    feed = board.reader.feed

    def capture(data: bytes):
        frames = feed(data)
        got.extend(frames)
        return frames

    board.reader.feed = capture
    try:
        with script.open("rb") as stdin:
            proc = subprocess.Popen([str(exe), "board", "--cj", "25", *args], stdin=stdin,
                                    stdout=master, stderr=subprocess.PIPE)
        guard = time.monotonic() + 120       # a hang guard, not a measurement
        quiet = 0
        while time.monotonic() < guard and quiet < 5:
            before = len(got)
            board.poll(wait_s=0.02)
            if proc.poll() is not None and len(got) == before and board.reader.counters[
                    "frames"] == len(got):
                quiet += 1
        proc.wait(timeout=10)
        stderr = proc.stderr.read().decode()
        proc.stderr.close()
    finally:
        board.close()
        os.close(master)
        os.close(slave)
    return got, board.all_counters, proc.returncode, stderr


@pytest.mark.parametrize("version", [1, 2])
def test_ten_thousand_random_frames_through_a_pty_without_a_mismatch(tt_host, tmp_path,
                                                                     version):
    samples = random_samples(10_000, seed=18, version=version)
    got, counters, code, stderr = pty_round_trip(tt_host, samples, tmp_path,
                                                 "--version", str(version))
    assert code == 0, stderr
    expected = expected_keys(samples, 25.0, version)
    received = [frame_key(f) for f in got]
    mismatches = sum(a != b for a, b in zip(expected, received)) + \
        abs(len(expected) - len(received))
    first = next((i for i, (a, b) in enumerate(zip(expected, received)) if a != b), None)
    assert mismatches == 0, f"{mismatches} mismatches; first at frame {first}: " \
        f"{expected[first] if first is not None else ''} != " \
        f"{received[first] if first is not None else ''}; counters {counters}"
    assert counters["frames"] == counters[f"frames_v{version}"] == 10_001
    assert counters["boots"] == 1
    assert {k: counters[k] for k in ("crc", "garbage", "version", "seq_gaps", "lost_frames",
                                     "overlong")} == dict.fromkeys(
        ("crc", "garbage", "version", "seq_gaps", "lost_frames", "overlong"), 0)
    assert f"{len(samples) + 1} frames written, 0 refused" in stderr


def test_the_round_trip_catches_a_corrupted_line(tt_host, tmp_path):
    """One bit flipped in every 97th frame on the line: the driver refuses
    exactly those frames and counts the gaps, and the comparison sees them."""
    samples = random_samples(2000, seed=7)
    got, counters, code, _ = pty_round_trip(tt_host, samples, tmp_path,
                                            "--corrupt-every", "97")
    corrupted = {i for i in range(len(samples) + 1) if (i + 1) % 97 == 0}
    expected = [k for i, k in enumerate(expected_keys(samples, 25.0)) if i not in corrupted]
    assert code == 0
    assert [frame_key(f) for f in got] == expected
    assert counters["crc"] + counters["garbage"] >= len(corrupted) > 0
    assert counters["seq_gaps"] == counters["lost_frames"] == len(corrupted)


# ------------------------------------------------------------------ the Peltier driver
def pad_cmd(counter: int, current_a: float, enable: int = 1, pump: int = 0,
            heater_duty: float = 0.0) -> str:
    message = DB.get_message_by_name("PAD_CMD")
    data = message.encode({"enable": enable, "pump": pump, "counter": counter & 0xF,
                           "current_a": current_a, "heater_duty": heater_duty,
                           "version": 2})
    return f"rx {message.frame_id:x} {data.hex()}\n"


def cmd(counter: int, current_a: float, enable: int = 1, version: int = 2) -> str:
    data = CMD.encode({"enable": enable, "counter": counter & 0xF, "current_a": current_a,
                       "version": version})
    return f"rx {CMD.frame_id:x} {data.hex()}\n"


def peltier_trace(exe: Path, script: str, *args: str) -> list[tuple]:
    """The firmware's output as (ms, 'set', enabled, ma), (ms, 'water', pump,
    duty_raw) and (ms, 'tx', name, signals decoded by cantools from the DBC)."""
    events = []
    for line in run(exe, "peltier", *args, stdin=script).splitlines():
        kind, ms, *rest = line.split()
        if kind == "done":
            continue
        if kind in ("set", "water"):
            events.append((int(ms), kind, int(rest[0]), int(rest[1])))
        else:
            message = DB.get_message_by_frame_id(int(rest[0], 16))
            events.append((int(ms), "tx", message.name,
                           message.decode(bytes.fromhex(rest[1]), decode_choices=False)))
    return events


def test_watchdog_disables_the_element_after_the_documented_time_not_before(tt_host):
    assert WATCHDOG_MS == 100
    last_cmd_ms = 500
    script = "t 0\n"
    for i, ms in enumerate(range(10, last_cmd_ms + 1, 10)):
        script += cmd(i, 1.25) + f"t {ms}\n"
    script += "".join(f"t {ms}\n" for ms in range(last_cmd_ms + 1, 800))
    script += cmd(0, 1.5) + "t 800\n"                    # commands resume
    events = peltier_trace(tt_host, script)
    sets = [e for e in events if e[1] == "set"]
    assert sets[0] == (0, "set", 0, 0)                   # starts disabled, no current
    assert sets[1] == (10, "set", 1, 1250)               # the first command enables it
    off = [e for e in sets if e[0] > 0 and e[2] == 0]
    trip_ms = last_cmd_ms + WATCHDOG_MS + 1              # the first ms *after* 100 ms of silence
    assert off[0] == (trip_ms, "set", 0, 0), sets        # not before
    assert all(e[2] == 1 for e in sets if 0 < e[0] < trip_ms)
    statuses = [e for e in events if e[2] == "PELTIER_STATUS"]
    trip = next(s for s in statuses if s[0] == trip_ms)
    assert trip[3]["watchdog"] == 1 and trip[3]["enabled"] == 0
    assert trip[3]["current_a"] == 0.0 and trip[3]["junction_c"] == 25.0   # passive: the sink's
    assert all(s[3]["watchdog"] == 0 for s in statuses if s[0] < trip_ms)
    beats = [e for e in events if e[2] == "PELTIER_HEARTBEAT"]
    assert beats[0][:2] == (0, "tx") and beats[0][3]["state"] == 0       # boot, once
    assert [b[3]["state"] for b in beats if 0 < b[0] < trip_ms] == [5] * 6   # operational
    assert all(b[3]["state"] == 128 for b in beats if trip_ms < b[0] < 800)
    assert all(b[0] - a[0] == 100 for a, b in zip(beats, beats[1:]))
    # Resumed: the flag clears and the new setpoint is applied at once.
    assert sets[-1] == (800, "set", 1, 1500)
    assert statuses[-1][3]["watchdog"] == 0 and statuses[-1][3]["enabled"] == 1


def test_each_command_is_answered_and_currents_are_clamped(tt_host):
    script = "t 0\n" + cmd(1, 20.0) + "t 1\n" + cmd(2, 2.0, enable=0) + "t 2\n" + \
        cmd(3, 4.0, version=1) + "t 3\n" + "rx 101 0100\n" + "t 4\n" + \
        "rx 123 0102030405060708\n" + "t 5\n" + cmd(4, -20.0) + "t 6\n"
    events = peltier_trace(tt_host, script)
    sets = [e for e in events if e[1] == "set"]
    # +-8.5 A (Imax); disabled: 0 A.
    assert sets[1:] == [(1, "set", 1, 8500), (2, "set", 0, 0), (6, "set", 1, -8500)]
    statuses = [e for e in events if e[2] == "PELTIER_STATUS"]
    assert [s[0] for s in statuses] == [1, 2, 6]     # version 1, short and foreign: no answer
    assert [s[3]["counter"] for s in statuses] == [0, 1, 2]
    assert statuses[0][3]["current_a"] == 8.5 and statuses[0][3]["junction_c"] == 8.0


def test_over_temperature_disables_until_acknowledged(tt_host):
    script = "t 0\n" + cmd(1, 1.0) + "t 1\n" + "meas 3500 7100 -4000 1\n" + "t 2\n" + \
        cmd(2, 1.0) + "t 3\n" + cmd(3, 1.0, enable=0) + "t 4\n" + \
        "meas 3300 2500 0 1\n" + cmd(4, 1.0, enable=0) + "t 5\n" + cmd(5, 1.0) + "t 6\n"
    events = peltier_trace(tt_host, script)
    sets = [e for e in events if e[1] == "set"]
    assert sets[1:] == [(1, "set", 1, 1000), (2, "set", 0, 0), (4, "set", 0, 0),
                        (5, "set", 0, 0), (6, "set", 1, 1000)]
    status = {e[0]: e[3] for e in events if e[2] == "PELTIER_STATUS"}
    assert status[2]["over_temp"] == 1 and status[2]["enabled"] == 0
    assert status[3]["over_temp"] == 1 and status[3]["enabled"] == 0   # still hot: refused
    assert status[4]["over_temp"] == 1                                  # hot: not cleared
    assert status[5]["over_temp"] == 0                                  # cool + enable 0
    assert status[6]["enabled"] == 1


@pytest.mark.parametrize("pad", [False, True], ids=["PeltierDriver", "ActivePadDriver"])
def test_the_projects_driver_trusts_the_firmware_and_sees_its_watchdog(tt_host, pad):
    """The firmware on a python-can virtual bus (a bridge forwards frames to
    and from tt_host's text lines), the project's PeltierDriver (or, for the
    slave's active pad, ActivePadDriver) on the same bus, one simulated
    clock: healthy while commanding, and unhealthy with the watchdog flagged
    once the commands stop for more than 100 ms."""
    channel = f"firmware-{os.getpid()}-{time.monotonic_ns()}"
    now_s = [0.0]
    driver = (ActivePadDriver if pad else PeltierDriver)(f"virtual:{channel}",
                                                         clock=lambda: now_s[0])
    bridge = can.Bus(interface="virtual", channel=channel, receive_own_messages=False)
    proc = subprocess.Popen([str(tt_host), "peltier", *(["--pad"] if pad else [])],
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
                            bufsize=1)
    applied, water = [], []

    def step(ms: int) -> None:
        now_s[0] = ms / 1000
        while (msg := bridge.recv(0.0)) is not None:
            proc.stdin.write(f"rx {msg.arbitration_id:x} {bytes(msg.data).hex()}\n")
        proc.stdin.write(f"t {ms}\n")
        proc.stdin.flush()
        for line in proc.stdout:
            kind, _, *rest = line.split()
            if kind == "done":
                break
            if kind == "tx":
                bridge.send(can.Message(arbitration_id=int(rest[0], 16),
                                        data=bytes.fromhex(rest[1]), is_extended_id=False))
            elif kind == "set":
                applied.append((ms, int(rest[0]), int(rest[1])))
            elif kind == "water":
                water.append((ms, int(rest[0]), int(rest[1])))
        driver.poll()

    last_cmd_ms = 300
    healthy = {}
    try:
        for ms in range(0, 700):
            if 10 <= ms <= last_cmd_ms and ms % 10 == 0:
                assert driver.command(-0.5, pump=True, heater_duty=0.5) if pad else \
                    driver.command(1.25)
            step(ms)
            healthy[ms] = driver.healthy
        c = dict(driver.counters)              # before close() sends its disable
    finally:
        proc.stdin.close()
        proc.wait(timeout=10)
        proc.stdout.close()
        driver.close()
        bridge.shutdown()
    trip_ms = last_cmd_ms + WATCHDOG_MS + 1
    assert not healthy[5] and all(healthy[ms] for ms in range(10, trip_ms)), healthy
    assert not any(healthy[ms] for ms in range(trip_ms, 700))
    assert driver.status.faults == ("watchdog",) and not driver.status.enabled
    assert (driver.status.actuator_c if pad else driver.status.junction_c) == 25.0   # 0 A
    assert driver.peer_version == 2 and driver.version_error is None
    assert driver.state == 128                           # the heartbeat says fault
    assert c["sent"] == 30 and c["statuses"] == 31       # each command answered + the trip
    assert c["heartbeats"] == 7 and c["undecodable"] == c["error_frames"] == c["reboots"] == 0
    assert applied[1] == ((10, 1, -500) if pad else (10, 1, 1250))
    assert applied[-1] == (trip_ms, 0, 0)
    if pad:
        assert water[1] == (10, 1, 125) and water[-1] == (trip_ms, 0, 0)
        assert not driver.status.pump_on and not driver.status.heater_on


def test_the_active_pad_variant_drives_pump_and_heater_and_its_watchdog_stops_them(tt_host):
    """The slave's active pad (node 2, PAD_* frames): the same rules as the
    display's driver, and pump and heater off whenever the pad is disabled."""
    script = "t 0\n" + cmd(1, 4.0) + "t 5\n"              # the display's frame: not ours
    for i, ms in enumerate(range(10, 201, 10)):
        script += pad_cmd(i, -0.5, pump=1, heater_duty=0.748) + f"t {ms}\n"
    script += "".join(f"t {ms}\n" for ms in range(201, 450))
    events = peltier_trace(tt_host, script, "--pad")
    assert not [e for e in events if e[0] == 5 and e[1] != "tx"]
    water = [e for e in events if e[1] == "water"]
    assert water[0] == (0, "water", 0, 0)
    assert water[1] == (10, "water", 1, 187)              # 0.748 / 0.004
    trip_ms = 200 + WATCHDOG_MS + 1
    assert [e for e in water if e[2] == 0 and e[0] > 0] == [(trip_ms, "water", 0, 0)]
    assert [e for e in events if e[1] == "set" and e[2] == 0 and e[0] > 0] == \
        [(trip_ms, "set", 0, 0)]
    names = {e[2] for e in events if e[1] == "tx"}
    assert names == {"PAD_STATUS", "PAD_HEARTBEAT"}
    statuses = [e for e in events if e[2] == "PAD_STATUS"]
    assert len(statuses) == 21                            # 20 commands + the trip
    assert statuses[0][3]["pump_on"] == statuses[0][3]["heater_on"] == 1
    # -0.5 A: the ideal element's junction 1 K above the sink; drive -0.5 / 8.5.
    assert statuses[0][3]["actuator_c"] == 26.0 and statuses[0][3]["drive"] == -0.058
    assert statuses[-1][0] == trip_ms and statuses[-1][3]["watchdog"] == 1
    assert statuses[-1][3]["pump_on"] == statuses[-1][3]["heater_on"] == 0
    beats = [e[3]["state"] for e in events if e[2] == "PAD_HEARTBEAT"]
    assert beats == [0, 5, 5, 5, 128]              # boot; 100, 200, 300 ms; 400 ms: fault


@pytest.mark.parametrize("measure, flag", [("3500 2500 -9351 1", "over_current"),
                                           ("3500 2500 -4000 0", "sensor_fault")])
def test_over_current_and_a_failed_sensor_disable_the_element(tt_host, measure, flag):
    script = "t 0\n" + cmd(1, 3.5) + "t 1\n" + f"meas {measure}\n" + "t 2\n" + \
        cmd(2, 3.5) + "t 3\n"
    events = peltier_trace(tt_host, script)
    assert [e for e in events if e[1] == "set"][1:] == [(1, "set", 1, 3500),
                                                         (2, "set", 0, 0)]
    status = {e[0]: e[3] for e in events if e[2] == "PELTIER_STATUS"}
    assert status[2][flag] == 1 and status[2]["enabled"] == 0
    assert status[3][flag] == 1 and status[3]["enabled"] == 0          # still refused
    assert sum(status[2][f] for f in ("over_temp", "over_current", "sensor_fault")) == 1


def test_the_firmware_refuses_a_version_1_command_and_says_version_2(tt_host):
    """A version-1 master's frame (bytes 1-2 a set point of 40.00 C) is
    counted and not answered; the heartbeat says version 2 (the master's
    driver refuses a board whose heartbeat says otherwise)."""
    old = "rx 101 11a00f01\n"               # enable, counter 1, 4000, version 1
    events = peltier_trace(tt_host, "t 0\n" + old + "t 1\n" + "t 100\n")
    assert not [e for e in events if e[2] == "PELTIER_STATUS"]
    assert [e for e in events if e[1] == "set"] == [(0, "set", 0, 0)]   # never driven
    assert {e[3]["version"] for e in events if e[2] == "PELTIER_HEARTBEAT"} == {2}


def test_the_sink_saturated_warning_keeps_the_element_driven(tt_host):
    script = "t 0\n" + cmd(1, 8.5) + "t 1\n" + "meas 1800 6150 8500 1\n" + cmd(2, 8.5) + \
        "t 2\n"
    events = peltier_trace(tt_host, script)
    status = {e[0]: e[3] for e in events if e[2] == "PELTIER_STATUS"}
    assert status[1]["sink_saturated"] == 0
    assert status[2]["sink_saturated"] == 1 and status[2]["enabled"] == 1
    assert not any(status[2][f] for f in ("over_temp", "over_current", "sensor_fault"))


def test_a_heater_duty_past_full_scale_is_applied_clamped_and_counted(tt_host):
    """Golden vector ``pad_cmd_heater_over_range``: raw 255 (1.02) is past
    CAN.md's 0..1; the active pad applies raw 250 (full duty) and counts the
    command as clamped; raw 250 itself is applied as sent, not counted."""
    data, fields = vectors("can")["pad_cmd_heater_over_range"]
    assert fields["raw"]["heater_duty"] == 255
    full = bytearray(data)
    full[3] = 250
    script = f"t 0\nrx 102 {data.hex()}\nt 1\nrx 102 {bytes(full).hex()}\nt 2\n"
    done = subprocess.run([str(tt_host), "peltier", "--pad"], input=script,
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    water = [line.split() for line in done.stdout.splitlines() if line.startswith("water")]
    assert water == [["water", "0", "0", "0"], ["water", "1", "1", "250"],
                     ["water", "2", "1", "250"]]
    assert "1 clamped" in done.stderr

"""The reference firmware's STM32F405 images on an emulated core:
``qemu-system-arm -M netduinoplus2`` (the STM32F405 of QEMU 7.2), with
deterministic instruction timing (``-icount``), its two UARTs bridged to
pseudo-terminals so that the project's drivers open them by path as they
would open ``/dev/ttyUSB0``.

* USART1, the link to the PC: the sensor board's frames, the Peltier
  driver's SLCAN (python-can's ``slcan`` interface opens
  ``slcan:<link_path>``), the codec image's text;
* USART2, the plant link (``firmware/stm32f4/plant.c``): the analog
  readings in, the H-bridge's command out.

QEMU serves each UART on a loopback TCP socket and waits for both to be
connected before the core starts, so nothing the firmware sends at reset is
lost; a thread copies bytes between each socket and the master side of a
pty (``os.openpty``), which keeps what the core sends until a driver opens
the pty. Bytes sent to the core before its firmware has set up the UART
are lost, as on silicon: wait for its first output (the boot frame, the
boot heartbeat, the codec's ``ready``). :func:`missing` names what is not installed, with the Debian
package that provides it.
"""

from __future__ import annotations

import fcntl
import logging
import os
import re
import selectors
import shutil
import socket
import subprocess
import tempfile
import termios
import threading
import time
import tty
from pathlib import Path

from telethermal.devices.board import DeviceError
from telethermal.ports import kernel_ports

log = logging.getLogger(__name__)

QEMU = "qemu-system-arm"
#: QEMU 7.2's STM32F405 machine (the Olimex STM32-H405, the board the port
#: names, is a QEMU 8.0 machine; the SoC and its peripherals are the same).
MACHINE = "netduinoplus2"
#: Virtual nanoseconds per instruction, as 2**shift: 2**3 = 8 ns, 125 M
#: instructions per emulated second (the part runs 168 MHz; QEMU models no
#: pipeline, one instruction is one step of its clock).
ICOUNT_SHIFT = 3
FIRMWARE = Path(__file__).resolve().parents[3] / "firmware"
#: The images: the display's sensor board (frame version 1), the slave's
#: (version 2), the Peltier driver, the active pad's driver, the codecs.
IMAGES = ("tt_board", "tt_board2", "tt_peltier", "tt_pad", "tt_codec")
#: How many times the cores stretch their millisecond at most (a rig's
#: time scale; firmware's board_time_scale: SysTick's 24 bits at 168 MHz).
MAX_TIME_SCALE = 99.0
HEARTBEAT_S = 0.1      #: the drivers' heartbeat period, s of the core's time (proto/CAN.md)


def missing() -> list[tuple[str, str]]:
    """What the processor-in-the-loop needs and is not installed, as
    (what, the apt package that provides it)."""
    out = []
    if shutil.which(QEMU) is None:
        out.append((QEMU, "qemu-system-arm"))
    gcc = shutil.which("arm-none-eabi-gcc")
    if gcc is None:
        out.append(("arm-none-eabi-gcc", "gcc-arm-none-eabi"))
    else:
        found = subprocess.run([gcc, "-print-file-name=picolibc.specs"], capture_output=True,
                               text=True).stdout.strip()
        if not os.path.isabs(found):
            out.append(("picolibc for arm-none-eabi", "picolibc-arm-none-eabi"))
    if shutil.which("make") is None:
        out.append(("make", "make"))
    return out


def require(purpose: str) -> None:
    """DeviceError naming what ``purpose`` lacks and its apt package, if
    anything is missing."""
    gone = missing()
    if gone:
        raise DeviceError(f"{purpose} needs " + ", ".join(
            f"{what} (apt-get install {package})" for what, package in gone))


def _dying_with_parent(argv: list[str]) -> list[str]:
    """``argv`` run so that it is killed when the thread that started it
    ends (Linux ``PR_SET_PDEATHSIG``, set by util-linux's ``setpriv`` before
    it execs QEMU), so no core outlives a service killed before its clean-up
    could run. Not by ``preexec_fn``: Python's documentation warns it may
    deadlock in a process with threads, as the services are. Without
    ``setpriv`` the core is stopped by :meth:`QemuCore.close` only, said in
    the log."""
    setpriv = shutil.which("setpriv")
    if setpriv is None:
        log.warning("setpriv not found (apt-get install util-linux): a QEMU core may "
                    "outlive a service that is killed")
        return argv
    return [setpriv, "--pdeathsig", "KILL", "--", *argv]


#: What a make passes its sub-makes: its command line's variables among them
#: (``make bench OUT=dir`` had the firmware's images written into ``dir``).
MAKE_ENV = ("MAKEFLAGS", "MFLAGS", "MAKELEVEL", "MAKEOVERRIDES")


def own_make_env() -> dict[str, str]:
    """This process's environment without what an outer make passes down:
    the firmware's build is its own, not a sub-make of whatever ran us."""
    return {k: v for k, v in os.environ.items() if k not in MAKE_ENV}


def build_images(build_dir: str | Path, firmware: Path = FIRMWARE) -> dict[str, Path]:
    """``make -C firmware TARGET=stm32f405 BUILD=build_dir``: image name ->
    its ELF file. ``DeviceError`` with the compiler's output if it fails.
    Builds in one folder wait for each other (a lock file in it), so two
    services sharing a build folder never link a half-written object."""
    out = Path(build_dir).resolve()
    try:
        out.mkdir(parents=True, exist_ok=True)
        with open(out / ".build.lock", "w") as lock:
            fcntl.flock(lock, fcntl.LOCK_EX)
            done = subprocess.run(["make", "-C", str(firmware), "TARGET=stm32f405",
                                   f"BUILD={out}"],
                                  capture_output=True, text=True, timeout=300,
                                  env=own_make_env())
    except (OSError, subprocess.TimeoutExpired) as exc:
        raise DeviceError(f"the STM32F405 build did not run to its end: {exc}") from exc
    if done.returncode != 0:
        raise DeviceError(f"the STM32F405 build failed:\n{done.stdout}\n{done.stderr}")
    return {name: out / "stm32f405" / f"{name}.elf" for name in IMAGES}


class _PtyBridge:
    """Bytes both ways between a connected socket and a pty's master side;
    the slave side's path is what a driver opens."""

    def __init__(self, sock: socket.socket):
        self.sock = sock
        self.master, self.slave = os.openpty()
        tty.setraw(self.slave)
        os.set_blocking(self.master, False)
        self.path = os.ttyname(self.slave)

    def pump(self, sel: selectors.BaseSelector) -> None:
        sel.register(self.sock, selectors.EVENT_READ, (self, self.sock, self.master))
        sel.register(self.master, selectors.EVENT_READ, (None, self.master, self.sock))

    def close(self) -> None:
        self.sock.close()
        os.close(self.master)
        os.close(self.slave)


class QemuCore:
    """One emulated STM32F405 running ``image`` (an ELF file).

    ``link_path`` and ``plant_path``: the ptys of USART1 and USART2. The
    core starts when both are connected (in the constructor; with
    ``paused``, at :meth:`resume`) and stops in :meth:`close`. :meth:`reset` restarts the firmware (QEMU's
    ``system_reset``), as a watchdog or a power cycle would."""

    def __init__(self, image: str | Path, icount_shift: int = ICOUNT_SHIFT,
                 start_timeout_s: float = 20.0, paused: bool = False):
        qemu = shutil.which(QEMU)
        if qemu is None:
            raise DeviceError(f"{QEMU} not found: apt-get install qemu-system-arm")
        self.image = Path(image)
        if not self.image.is_file():
            raise DeviceError(f"firmware image {self.image} not found: build it with "
                              "make -C firmware TARGET=stm32f405")
        # Ports of the kernel's choice, from its ephemeral range, which
        # free_ports (the services' ports) never draws from. TCP, not a Unix
        # socket: a Unix socket's buffer counts each small write whole, and a
        # core that lags under load filled it in a fraction of a second (the
        # bridge's send timed out and dropped a command, once in a CI
        # rehearsal); TCP's holds far more.
        ports = kernel_ports(3)
        serials = []
        for name, port in zip(("link", "plant", "mon"), ports):
            serials += ["-chardev", f"socket,id={name},host=127.0.0.1,port={port},"
                        f"server=on,nodelay=on,wait={'on' if name != 'mon' else 'off'}"]
        # QEMU's messages to a file, not a pipe nobody reads while it runs (a
        # full pipe would stop the core in its next write).
        self._stderr = tempfile.TemporaryFile()
        self.proc = subprocess.Popen(_dying_with_parent(
            [qemu, "-M", MACHINE, "-nodefaults", "-display", "none",
             "-icount", f"shift={icount_shift},align=off,sleep=on", "-kernel", str(self.image),
             *serials, "-serial", "chardev:link", "-serial", "chardev:plant",
             "-mon", "chardev=mon,mode=readline", *(["-S"] if paused else [])]),
            stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=self._stderr)
        self._bridges: list[_PtyBridge] = []
        self._monitor: socket.socket | None = None
        self._stop = threading.Event()
        self.dropped_bytes = 0
        self.bytes = {"to_core": 0, "from_core": 0, "cut": 0}   # through the bridges
        #: UARTs whose line is cut (0 the link, 1 the plant): bytes lost both
        #: ways, as with a cable pulled, until removed from the set.
        self.cut: set[int] = set()
        #: Line noise, for tests: ``fault(uart, data) -> data`` is applied to
        #: what the core sends (uart 0 the link, 1 the plant) before the pty.
        self.line_fault = None
        #: A probe on the core's TX pins, for tests: ``tap(uart, data)`` sees
        #: every byte the core sends, as sent (before a cut or a fault), once
        #: whatever of it reaches the pty is there (so a clock read from the
        #: core's stamps never runs ahead of what a driver can read).
        self.tap = None
        try:
            for port in ports[:2]:
                self._bridges.append(_PtyBridge(self._connect(port, start_timeout_s)))
            self._monitor = self._connect(ports[2], start_timeout_s)
        except BaseException:
            self.close()
            raise
        self.link_path, self.plant_path = (b.path for b in self._bridges)
        self._thread = threading.Thread(target=self._pump, name="qemu-uarts", daemon=True)
        self._thread.start()

    def _connect(self, port: int, timeout_s: float) -> socket.socket:
        deadline = time.monotonic() + timeout_s
        while True:
            if self.proc.poll() is not None:
                raise DeviceError(f"{QEMU} exited with {self.proc.returncode}: "
                                  f"{self.messages()}")
            try:
                sock = socket.create_connection(("127.0.0.1", port), timeout=1.0)
                sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
                return sock
            except OSError:
                if time.monotonic() > deadline:
                    raise DeviceError(f"{QEMU} did not open its UART socket on "
                                      f"127.0.0.1:{port} within {timeout_s} s") from None
                time.sleep(0.02)

    def messages(self) -> str:
        """What QEMU has written to its stderr so far (read at offset 0
        without moving the file's position, which QEMU shares)."""
        fd = self._stderr.fileno()
        return os.pread(fd, os.fstat(fd).st_size, 0).decode(errors="replace")

    def _probe(self, name: str, hook, *args):
        """A hook on the bridge (``tap``: a test's, or a pad driver's probe
        of the core's TX pin; ``line_fault``: a test's) that raises is
        logged and removed, never the end of the bridge: a bridge that
        stopped would leave the ptys unread, and every writer to them
        waiting. A hook replaced meanwhile is left in place."""
        try:
            return hook(*args)
        except Exception:                  # noqa: BLE001 - a hook's bug, said once
            log.exception("QEMU bridge: the %s hook failed; it is removed", name)
            if getattr(self, name) is hook:
                setattr(self, name, None)
            return None

    def _pump(self) -> None:
        with selectors.DefaultSelector() as sel:
            for bridge in self._bridges:
                bridge.pump(sel)
            while not self._stop.is_set():
                for key, _ in sel.select(0.05):
                    from_core, src, dst = key.data
                    try:
                        data = src.recv(4096) if isinstance(src, socket.socket) \
                            else os.read(src, 4096)
                    except (BlockingIOError, InterruptedError, TimeoutError):
                        continue                # nothing after all: still open
                    except OSError:
                        data = b""
                    if not data:                # QEMU gone, or a pty closed
                        sel.unregister(key.fileobj)
                        continue
                    bridge = from_core if from_core is not None else \
                        next(b for b in self._bridges if b.master == src)
                    sent, tap = data, self.tap
                    if self._bridges.index(bridge) in self.cut:
                        self.bytes["cut"] += len(data)      # the line is cut: lost
                    else:
                        fault = self.line_fault
                        if from_core is not None and fault is not None:
                            faulted = self._probe("line_fault", fault,
                                                  self._bridges.index(from_core), data)
                            data = data if faulted is None else faulted
                        way = "from_core" if from_core is not None else "to_core"
                        self.bytes[way] += len(data)
                        self._send_all(dst, data)
                    if from_core is not None and tap is not None:
                        self._probe("tap", tap, self._bridges.index(from_core), sent)

    def _send_all(self, dst, data: bytes) -> None:
        try:
            if isinstance(dst, socket.socket):
                dst.sendall(data)
            else:
                while data:
                    data = data[os.write(dst, data):]
        except BlockingIOError:
            self._dropped(len(data), "nobody reads the pty: a UART overrun")
        except OSError as exc:                  # the core not reading for 1 s, or gone
            self._dropped(len(data), f"{type(exc).__name__}: {exc}")

    def _dropped(self, n: int, why: str) -> None:
        """Bytes the bridge could not pass on: counted, and said the first time."""
        if not self.dropped_bytes:
            log.warning("QEMU bridge (%s): %d bytes dropped (%s); further drops only counted "
                        "(dropped_bytes)", self.image.name, n, why)
        self.dropped_bytes += n

    def read_u32(self, address: int, guard_s: float = 10.0) -> int:
        """A word of the core's memory (QEMU's monitor, ``xp``): a variable
        the firmware keeps, found by :func:`symbols`."""
        self._monitor.sendall(f"xp /1wx {address:#x}\n".encode())
        pattern = re.compile(rf"^0*{address:x}: 0x([0-9a-f]{{8}})", re.M)
        text, deadline = "", time.monotonic() + guard_s
        while (m := pattern.search(text)) is None:
            if time.monotonic() > deadline:
                raise DeviceError(f"QEMU's monitor did not answer xp {address:#x}")
            self._monitor.settimeout(guard_s)
            text += self._monitor.recv(65536).decode(errors="replace")
        return int(m.group(1), 16)

    def reset(self) -> None:
        """The firmware restarts from its reset vector (RAM is not cleared
        by QEMU's reset; the startup code sets up .data and .bss)."""
        self._monitor.sendall(b"system_reset\n")

    def resume(self) -> None:
        """Start a core made with ``paused=True``: its drivers opened first
        (pyserial's open flushes a port's input, so a boot frame sent before
        it would be lost)."""
        self._monitor.sendall(b"cont\n")

    def restart(self, drain_s: float = 0.02) -> None:
        """The firmware from its reset vector with nothing of its last run
        left on the ptys: the core paused, what it had sent drained (a guard
        of ``drain_s`` of the host's time) and discarded, then reset and
        resumed; wait for its first output as after start."""
        self._monitor.sendall(b"stop\n")
        self.read_u32(0x08000000)           # the monitor has paused the core
        time.sleep(drain_s)
        for bridge in self._bridges:
            termios.tcflush(bridge.slave, termios.TCIFLUSH)
        self._monitor.sendall(b"system_reset\ncont\n")

    def close(self) -> None:
        self._stop.set()
        if getattr(self, "_thread", None) is not None:
            self._thread.join(timeout=5)
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(timeout=5)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        self._stderr.close()
        for bridge in self._bridges:
            bridge.close()
        if self._monitor is not None:
            self._monitor.close()

    def __enter__(self) -> QemuCore:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class PtyLine:
    """One end of a core's UART pty, opened by path: bytes in; what came
    back kept in ``buf`` (consumed by :meth:`until`) and ``log`` (all)."""

    def __init__(self, path: str):
        self.fd: int | None = os.open(path, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
        self.buf = self.log = b""

    def write(self, data: bytes, guard_s: float = 30.0) -> None:
        """All of ``data``; while the core does not take more, what it sends
        is read meanwhile (a core that answers as it reads would otherwise
        fill the other direction and both sides wait for ever). ``guard_s``
        guards against a core that takes nothing (DeviceError); it times
        nothing."""
        deadline = time.monotonic() + guard_s
        while data:
            try:
                data = data[os.write(self.fd, data):]
                deadline = time.monotonic() + guard_s        # it took some: not stalled
            except BlockingIOError:
                if time.monotonic() > deadline:
                    raise DeviceError(f"the core took no input for {guard_s} s: "
                                      f"{len(data)} bytes left to write") from None
                self.read(0.001)

    def read(self, wait_s: float = 0.0) -> bytes:
        """What has arrived, after ``wait_s`` more seconds of listening."""
        deadline = time.monotonic() + wait_s
        while True:
            try:
                got = os.read(self.fd, 65536)
                self.buf += got
                self.log += got
            except BlockingIOError:
                pass
            if time.monotonic() >= deadline:
                return self.buf
            time.sleep(0.002)

    def until(self, pattern: bytes, guard_s: float = 30.0) -> re.Match:
        """Read until ``pattern`` matches; the bytes up to the match's end
        are consumed. ``guard_s`` guards against a hang (DeviceError); it
        times nothing."""
        deadline = time.monotonic() + guard_s
        while (m := re.search(pattern, self.buf, re.S)) is None:
            if time.monotonic() > deadline:
                raise DeviceError(f"no {pattern!r} from the core within {guard_s} s: "
                                  f"{self.buf[-200:]!r}")
            self.read(0.005)
        self.buf = self.buf[m.end():]
        return m

    def close(self) -> None:
        if self.fd is not None:
            os.close(self.fd)
            self.fd = None


class QemuBoards:
    """Some of the images on their cores, for as long as a service runs:
    built once (in ``build_dir``, make's own incremental build, or a
    temporary folder), each core started and its plant link open.
    ``cores[name]``, ``plants[name]``; :meth:`restart` gives a new touch
    boards fresh from reset; :meth:`close` stops every core.

    ``time_scale``: the rig's (a service's ``time_scale``): each core, once
    ready, told to stretch its millisecond as much (the plant link's ``k``
    line, answered), so that its timeouts, heartbeats and watchdog run on
    the services' time; QEMU's own clock keeps the machine's."""

    def __init__(self, names: tuple[str, ...], build_dir: str | Path = "",
                 purpose: str = "devices = 'qemu'", time_scale: float = 1.0):
        require(purpose)
        self.scale_milli = round(1000 * time_scale)
        if not 1000 <= self.scale_milli <= 1000 * MAX_TIME_SCALE:
            raise DeviceError(f"time_scale {time_scale!r}: the cores stretch their "
                              f"millisecond from 1 to {MAX_TIME_SCALE:g} times")
        self._tmp = None if build_dir else tempfile.TemporaryDirectory(prefix="telethermal-qemu-")
        self.cores: dict[str, QemuCore] = {}
        self.plants: dict[str, PtyLine] = {}
        try:
            images = build_images(build_dir or self._tmp.name)
            for name in names:
                self.cores[name] = QemuCore(images[name])
                self.plants[name] = PtyLine(self.cores[name].plant_path)
            self.wait_ready()
            if self.scale_milli != 1000:
                log.info("%s: each core's millisecond stretched to %g of the machine's "
                         "milliseconds (time scale)", ", ".join(names), self.scale_milli / 1000)
        except BaseException:
            self.close()
            raise

    def wait_ready(self) -> None:
        """Until every core's plant link says ``ready`` (its UARTs are up),
        then its time scale set and answered (none to set at 1)."""
        for plant in self.plants.values():
            plant.until(rb"ready\n")
        if self.scale_milli == 1000:
            return
        for name, plant in self.plants.items():
            plant.write(b"k %d\n" % self.scale_milli)
        for name, plant in self.plants.items():
            try:
                plant.until(rb"k %d\n" % self.scale_milli, guard_s=10.0)
            except DeviceError as exc:
                raise DeviceError(f"{name}: its core did not take the time scale (an image "
                                  f"built before the plant link's k line? rebuild it): "
                                  f"{exc}") from None

    def restart(self) -> None:
        """Every core from its reset vector, nothing of its last run left on
        its lines (:meth:`QemuCore.restart`), then ready."""
        for name, core in self.cores.items():
            self.plants[name].buf = b""         # what it read of the last run
            core.restart()
        self.wait_ready()

    def close(self) -> None:
        try:
            for plant in self.plants.values():
                plant.close()
            for core in self.cores.values():
                core.close()
        finally:
            if self._tmp is not None:
                self._tmp.cleanup()

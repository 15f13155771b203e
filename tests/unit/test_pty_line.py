"""The processor-in-the-loop tests' line to a core (devices.qemu.PtyLine)
against a peer on ``os.openpty()``: a peer that answers before it reads must
not deadlock a write, and a peer that takes nothing is an error, not a hang."""

import os
import threading
import time
import tty

import pytest

from telethermal.devices import qemu
from telethermal.devices.board import DeviceError


@pytest.fixture
def pty_pair():
    master, slave = os.openpty()
    tty.setraw(slave)                       # bytes as they are, no echo (QEMU's ptys are raw)
    line = qemu.PtyLine(os.ttyname(slave))
    yield master, line
    line.close()
    os.close(slave)
    os.close(master)


def test_a_write_reads_what_the_peer_sends_meanwhile(pty_pair):
    """The peer sends 256 kB before it reads anything, far over the pty's
    buffers both ways: the write must drain it to get its own 256 kB
    through. Conservation: every byte arrives, in order, both ways."""
    master, line = pty_pair
    ours, theirs = bytes(range(256)) * 1024, bytes(reversed(range(256))) * 1024
    got = bytearray()

    def peer():
        view = memoryview(theirs)
        while view:
            view = view[os.write(master, view):]
        while len(got) < len(ours):
            got.extend(os.read(master, 65536))

    thread = threading.Thread(target=peer, daemon=True)
    thread.start()
    line.write(ours, guard_s=60)
    thread.join(60)
    assert not thread.is_alive()
    assert bytes(got) == ours
    guard = time.monotonic() + 30               # a hang guard: what is left, however slowly
    while len(line.buf) < len(theirs) and time.monotonic() < guard:
        line.read(0.01)
    assert line.buf == theirs


def test_a_peer_that_takes_nothing_is_an_error_naming_what_was_left(pty_pair):
    _, line = pty_pair
    with pytest.raises(DeviceError, match=r"took no input for 0\.2 s: \d+ bytes left"):
        line.write(b"x" * (1 << 20), guard_s=0.2)

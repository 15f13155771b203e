"""A real ``telethermal slave`` process on loopback with CURVE, and masters
written from the document (doc_peer.py) to drive it.

telethermal is imported here only to train the slave's models once (they
are the slave's configuration, not its protocol); everything on the wire
goes through pyzmq and msgpack alone.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import msgpack
import pytest
import zmq
import zmq.auth

from doc_peer import DocMaster

# A loopback port finder is not protocol code: the project's own is used.
from telethermal.ports import free_ports  # noqa: E402,F401 (re-exported to tests)

HEARTBEAT_S = 0.05
DEAD_AFTER_S = 0.5
#: How long a test waits for what it pumps for: a hang guard (a pump ends as
#: soon as its condition holds; how soon is the machine's load's, never asserted).
GUARD_S = 60.0
SCENE = "fingertip-7"


def pytest_collection_modifyitems(items):
    """Tests that stop the suite's slave (SIGTERM) run after all others."""
    items.sort(key=lambda item: item.get_closest_marker("stops_slave") is not None)


def pytest_configure(config):
    config.addinivalue_line("markers", "stops_slave: the test ends the shared slave process")




@pytest.fixture(scope="session")
def slave_models(tmp_path_factory, trained_models):
    """The slave's identifier decides within 0.3 s of contact (its longest
    window), so each touch the suite makes is short."""
    import numpy as np

    from telethermal.data.generate import pad_database
    from telethermal.ident.prepare import from_trials
    from telethermal.ident.registry import make
    from telethermal.physics.scene import load_scene
    from telethermal.render.generator import save_generator
    from telethermal.physics.scene import with_finger

    scene = with_finger(load_scene(SCENE))
    folder = tmp_path_factory.mktemp("conformance-models")
    trials = pad_database(scene, np.random.default_rng(0))
    identifier = make("effusivity-lda", max_window_s=0.3).fit(from_trials(trials)[0])
    return (identifier.save(folder / "identifier.npz"),
            save_generator(trained_models.generator(scene, 0), folder / "generator.npz"))


@pytest.fixture(scope="session")
def curve_keys(tmp_path_factory):
    """The slave's pair; masters a and b allowed; a stranger not."""
    root = tmp_path_factory.mktemp("conformance-keys")
    pairs = {}
    for name in ("slave", "a", "b", "stranger"):
        (root / name).mkdir()
        public, secret = zmq.auth.create_certificates(str(root / name), name)
        os.chmod(secret, 0o600)         # a slave refuses a secret others can read
        pairs[name] = zmq.auth.load_certificate(secret)
    (root / "allowed").mkdir()
    for name in ("a", "b"):
        (root / "allowed" / f"{name}.key").write_bytes((root / name / f"{name}.key").read_bytes())
    server = pairs["slave"][0]
    return {"root": root, **{n: {"public": pub, "secret": sec, "server": server}
                              for n, (pub, sec) in pairs.items()}}


class SlaveProcess:
    """``telethermal slave`` with a config written here; admin over REQ."""

    def __init__(self, folder: Path, models, keys):
        self.folder = folder
        self.control_port, self.stream_port, self.admin_port = free_ports(3)
        identifier, generator = models
        config = folder / "slave.toml"
        config.write_text(
            f'[slave]\nscene = "{SCENE}"\nidentifier = "{identifier}"\n'
            f'generator = "{generator}"\nseed = 0\nplace = "steel"\n'
            f'admin_port = {self.admin_port}\n\n[transport]\nbind_host = "127.0.0.1"\n'
            f'control_port = {self.control_port}\nstream_port = {self.stream_port}\n'
            f'security = "curve"\nkeys_dir = "{keys["root"] / "slave"}"\n'
            f'allowed_dir = "{keys["root"] / "allowed"}"\n'
            f'heartbeat_s = {HEARTBEAT_S}\ndead_after_s = {DEAD_AFTER_S}\n')
        self.log = folder / "slave.log"
        self._log = open(self.log, "ab")
        self.proc = subprocess.Popen([sys.executable, "-m", "telethermal", "slave", "--config",
                                      str(config)], stdout=self._log, stderr=subprocess.STDOUT,
                                     env={**os.environ, "PYTHONUNBUFFERED": "1"})
        self.ctx = zmq.Context()
        end = time.monotonic() + 60
        while True:
            assert self.proc.poll() is None, f"the slave exited:\n{self.log.read_text()[-2000:]}"
            try:
                if self.admin("status", timeout_s=0.5).get("ok"):
                    break
            except TimeoutError:
                assert time.monotonic() < end, "the slave's admin socket never answered"

    @property
    def control(self) -> str:
        return f"tcp://127.0.0.1:{self.control_port}"

    @property
    def stream(self) -> str:
        return f"tcp://127.0.0.1:{self.stream_port}"

    def admin(self, cmd: str, timeout_s: float = 5.0, **args) -> dict:
        sock = self.ctx.socket(zmq.REQ)
        sock.linger = 0
        sock.connect(f"tcp://127.0.0.1:{self.admin_port}")
        try:
            sock.send(msgpack.packb({"cmd": cmd, **args}))
            if not sock.poll(timeout_s * 1000):
                raise TimeoutError(f"admin {cmd}: no reply in {timeout_s} s")
            return msgpack.unpackb(sock.recv(), raw=False)
        finally:
            sock.close(linger=0)

    def counters(self) -> dict:
        return self.admin("status")["counters"]

    @property
    def alive(self) -> bool:
        return self.proc.poll() is None

    def log_bytes(self) -> int:
        return self.log.stat().st_size

    def terminate(self, timeout_s: float = 15.0) -> int:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
        try:
            return self.proc.wait(timeout_s)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            return self.proc.wait()
        finally:
            self._log.close()
            if not self.ctx.closed:
                self.ctx.destroy(linger=0)


@pytest.fixture(scope="session")
def slave(tmp_path_factory, slave_models, curve_keys):
    """One slave process for the suite; it must exit 0 at the end."""
    proc = SlaveProcess(tmp_path_factory.mktemp("slave"), slave_models, curve_keys)
    yield proc
    assert proc.terminate() == 0, proc.log.read_text()[-3000:]


@pytest.fixture
def masters(slave, curve_keys):
    """``masters(key="a")`` opens a document master on ``slave``; all are
    closed after the test. (The next test's master is refused as "busy"
    until the slave declares these dead; its hello is repeated until then.)"""
    ctx = zmq.Context()
    opened = []

    def open_master(key: str = "a", connect: bool = True, **kw) -> DocMaster:
        m = DocMaster(ctx, slave.control, slave.stream, curve_keys[key],
                      heartbeat_s=HEARTBEAT_S, **kw)
        opened.append(m)
        if connect:
            m.connect()
        return m

    yield open_master
    for m in opened:
        m.close()
    ctx.destroy(linger=0)

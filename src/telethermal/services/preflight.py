"""``telethermal check --config FILE``: a service's set-up checked before a
session, one line per finding, each problem with its fix.

Slave: the config, the scene, its key pair, the allowed-keys folder (and the
fingerprint of every master in it), the model files (loadable, matching
``SHA256SUMS`` when one lies beside them, renderable together), and that
``bind_host`` and the ports can be bound here. Master: the config, the scene,
its key pair and the slave's public key, the admin port, and the slave:
TCP reachability of both ports and a CURVE handshake (no message is sent,
so a running session is not disturbed).
"""

from __future__ import annotations

import errno
import hashlib
import socket
import time
from dataclasses import dataclass
from pathlib import Path

import zmq
import zmq.auth

from telethermal.errors import TelethermalError, TransportError
from telethermal.tomltables import read_toml
from telethermal.wire.handshake import HandshakeWatch, diagnose, key_file_fingerprint
from telethermal.wire.keys import check_allowed_folder, check_secret_private


@dataclass(frozen=True)
class Finding:
    ok: bool
    what: str
    fix: str = ""

    def text(self) -> str:
        return f"ok       {self.what}" if self.ok else f"PROBLEM  {self.what}\n         fix: {self.fix}"


def run_checks(path: str | Path, timeout_s: float = 3.0) -> list[Finding]:
    from telethermal.services.config import ConfigError, load_config

    path = Path(path)
    try:
        sections = set(read_toml(path, "config file", ConfigError))
    except ConfigError as exc:
        return [Finding(False, str(exc), "give the path of a slave or master config file")]
    roles = sections & {"slave", "master"}
    if len(roles) != 1:
        return [Finding(False, f"{path}: has {sorted(roles) or 'no'} [slave]/[master] section",
                        "a service config has exactly one of [slave] or [master]")]
    role = roles.pop()
    try:
        config = load_config(path, role)
    except TelethermalError as exc:
        return [Finding(False, str(exc), "correct that key (templates: deploy/two-host/)")]
    out = [Finding(True, f"{path}: a {role} config")]
    out += _scene(config)
    checks = _slave_checks if role == "slave" else _master_checks
    return out + checks(config, timeout_s)


def _scene(config) -> list[Finding]:
    from telethermal.physics.scene import load_scene

    try:
        scene = load_scene(config.scene)
    except TelethermalError as exc:
        return [Finding(False, f"scene {config.scene!r}: {exc}",
                        "name a shipped scene (`telethermal scenes`) or a scene file")]
    return [Finding(True, f"scene {scene.name} ({len(scene.materials)} materials)")]


def _key_pair(t, name: str) -> list[Finding]:
    secret = Path(t.keys_dir) / f"{name}.key_secret"
    public = Path(t.keys_dir) / f"{name}.key"
    make = f"telethermal keys --out {t.keys_dir} --name {name}" + (
        " --force (a new pair: give its public key to the peer again)"
        if secret.exists() or public.exists() else "")
    if not secret.is_file():
        return [Finding(False, f"{secret}: no such file", make)]
    try:
        if zmq.auth.load_certificate(str(secret))[1] is None:
            return [Finding(False, f"{secret}: holds no secret key", make)]
    except (OSError, ValueError) as exc:
        return [Finding(False, f"{secret}: unreadable ({exc})", make)]
    out = []
    try:
        check_secret_private(secret)
    except TransportError as exc:
        out.append(Finding(False, str(exc).split("; fix: ")[0], f"chmod 600 {secret}"))
    if public.is_file():
        out.append(Finding(True, f"key pair {name} in {t.keys_dir}, public key "
                                 f"{key_file_fingerprint(public)}"))
    else:
        out.append(Finding(False, f"{public}: no public key beside the secret one", make))
    return out


def _public_key(path: Path, fix: str) -> list[Finding]:
    if not path.is_file():
        return [Finding(False, f"{path}: no such public key file", fix)]
    try:
        return [Finding(True, f"{path.name}: {key_file_fingerprint(path)}")]
    except (OSError, ValueError) as exc:
        return [Finding(False, f"{path}: not a public key file ({exc})", fix)]


def _allowed(t) -> list[Finding]:
    folder = Path(t.allowed_dir)
    if not folder.is_dir():
        return [Finding(False, f"allowed_dir {folder}: no such folder",
                        f"mkdir -p {folder}, then copy each master's master.key into it")]
    try:
        keys = check_allowed_folder(folder)
    except TransportError as exc:
        what, _, fix = str(exc).partition("; fix: ")
        return [Finding(False, what, fix)]
    if not keys:
        return [Finding(False, f"allowed_dir {folder}: holds no public key, so every master "
                               "is refused", f"copy each master's keys/master.key into {folder}")]
    out = []
    for key in keys:
        out += _public_key(key, f"replace {key} with the master's keys/master.key")
    return [Finding(f.ok, f"allowed master {f.what}" if f.ok else f.what, f.fix) for f in out]


def _checksum(path: Path) -> list[Finding]:
    from telethermal.teleop.models import read_sums
    sums, digest = path.parent / "SHA256SUMS", read_sums(path.parent).get(path.name)
    if digest is None:
        return []
    if hashlib.sha256(path.read_bytes()).hexdigest() != digest:
        return [Finding(False, f"{path}: does not match {sums} (a partial or other copy)",
                        f"copy {path.name} again, then `sha256sum -c SHA256SUMS` in "
                        f"{path.parent}")]
    return [Finding(True, f"{path.name} matches {sums.name}")]


def _models(config) -> list[Finding]:
    from telethermal.ident.registry import load_model
    from telethermal.render.generator import load_generator

    make = "telethermal models --out models (here, or on another host and copy with " \
           "SHA256SUMS), or leave the key empty to train at start"
    loaded, out = {}, []
    for key, loader in (("identifier", load_model), ("generator", load_generator)):
        value = getattr(config, key)
        if not value:
            out.append(Finding(True, f"{key}: none named, trained at start from the scene"))
            continue
        path = Path(value)
        if not path.is_file():
            out.append(Finding(False, f"{key} {path}: no such model file", make))
            continue
        try:
            loaded[key] = loader(path)
        except TelethermalError as exc:
            out.append(Finding(False, f"{key} {path}: {exc}", make))
            continue
        out += _checksum(path) or [Finding(True, f"{key} {path.name} loads")]
    if len(loaded) == 2:
        renderable = [c for c in loaded["identifier"].classes_
                      if c in loaded["generator"].materials]
        if not renderable:
            out.append(Finding(False, "no class of the identifier has a generator curve",
                               "train both on the same scene or dataset (telethermal models)"))
    return out


def _bind(host: str, port: int, what: str) -> list[Finding]:
    with socket.socket(socket.AF_INET6 if ":" in host else socket.AF_INET) as s:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            s.bind((host, port))
        except OSError as exc:
            if exc.errno == errno.EADDRNOTAVAIL:
                return [Finding(False, f"{what} {host}: not an address of this host",
                                "set it to this host's address on the link to the master "
                                "(`ip -br addr`)")]
            if exc.errno == errno.EADDRINUSE:
                return [Finding(False, f"{what} {host}:{port}: already in use",
                                "stop what holds it (`ss -ltnp`: a service already running?) "
                                "or choose another port")]
            return [Finding(False, f"{what} {host}:{port}: {exc}", "check the address")]
    return [Finding(True, f"{what} {host}:{port} free")]


def _slave_checks(config, timeout_s: float) -> list[Finding]:
    t = config.transport
    out = []
    if t.security == "curve":
        out += _key_pair(t, t.server_key) + _allowed(t)
    out += _models(config)
    out += _bind(t.bind_host, t.control_port, "bind_host, control_port")
    out += _bind(t.bind_host, t.stream_port, "bind_host, stream_port")
    if not config.admin_ipc:
        out += _bind("127.0.0.1", config.admin_port, "admin")
    return out


def _master_checks(config, timeout_s: float) -> list[Finding]:
    t = config.transport
    out = []
    if t.security == "curve":
        out += _key_pair(t, t.client_key)
        out += _public_key(Path(t.keys_dir) / f"{t.server_key}.key",
                           f"copy the slave's keys/{t.server_key}.key into {t.keys_dir}")
    if not config.admin_ipc:
        out += _bind("127.0.0.1", config.admin_port, "admin")
    reach = [_tcp(t.host, port, timeout_s) for port in (t.control_port, t.stream_port)]
    out += reach
    if all(f.ok for f in reach) and all(f.ok for f in out) and t.security == "curve":
        out.append(_handshake(t, timeout_s))
    return out


def _tcp(host: str, port: int, timeout_s: float) -> Finding:
    try:
        with socket.create_connection((host, port), timeout=timeout_s):
            return Finding(True, f"slave {host}:{port} accepts TCP")
    except ConnectionRefusedError:
        return Finding(False, f"slave {host}:{port}: connection refused (nothing listens, or "
                              "a firewall rejects)",
                       "start `telethermal slave` there; check host and the ports against the "
                       "slave's bind_host and ports, and its firewall (deploy/two-host/slave.nft)")
    except socket.timeout:
        return Finding(False, f"slave {host}:{port}: no answer in {timeout_s:.0f} s (packets "
                              "dropped)", "open the port to this master on the slave's firewall "
                                          "(deploy/two-host/slave.nft), and check host")
    except OSError as exc:
        return Finding(False, f"slave {host}:{port}: {exc.strerror or exc}",
                       "check host (the slave's address) and this host's route to it")


def _handshake(t, timeout_s: float) -> Finding:
    """A CURVE handshake on the control port, no message sent."""
    from telethermal.wire.keys import load_public, load_secret

    ctx = zmq.Context.instance()
    sock = ctx.socket(zmq.DEALER)
    sock.linger = 0
    public, secret = load_secret(t.keys_dir, t.client_key)
    sock.curve_publickey, sock.curve_secretkey = public, secret
    sock.curve_serverkey = load_public(t.keys_dir, t.server_key)
    where = f"tcp://{t.host}:{t.control_port}"
    watch = HandshakeWatch.on(sock, where)
    sock.connect(where)
    start = time.monotonic()
    try:
        while time.monotonic() - start < timeout_s:
            watch.read(time.monotonic())
            if watch.succeeded or watch.auth_failed or watch.handshake_failed:
                break
            time.sleep(0.02)
    finally:
        watch.close(sock)
        sock.close(linger=0)
    if watch.succeeded:
        return Finding(True, f"CURVE handshake with the slave at {where}: this master's key "
                             "is allowed")
    d = diagnose(watch, time.monotonic() - start,
                 key_file_fingerprint(Path(t.keys_dir) / f"{t.client_key}.key"), t.keys_dir)
    return Finding(False, d["problem"], d["fix"])


def qemu_findings() -> list[Finding]:
    """``telethermal check --devices qemu``: what the processor in the loop
    (``session --devices qemu``) needs, each missing part with the Debian
    package that provides it, then the firmware's STM32F405 images built
    (into a temporary folder) and their flash and RAM sizes."""
    import tempfile

    from telethermal.devices import qemu, qemu_elf
    from telethermal.devices.board import DeviceError

    gone = qemu.missing()
    out = [Finding(False, f"{what}: not installed", f"apt-get install {package}")
           for what, package in gone]
    if gone:
        return out
    out.append(Finding(True, f"{qemu.QEMU}, arm-none-eabi-gcc and picolibc installed"))
    if not (qemu.FIRMWARE / "Makefile").is_file():
        return out + [Finding(False, f"{qemu.FIRMWARE}: no firmware sources (the package is "
                                     "installed without them)",
                              "run from a source checkout of telethermal (pip install -e .)")]
    with tempfile.TemporaryDirectory(prefix="telethermal-check-") as build:
        try:
            images = qemu.build_images(build)
            sizes = {name: qemu_elf.image_size(elf) for name, elf in images.items()}
        except (DeviceError, OSError, ValueError) as exc:
            return out + [Finding(False, f"make -C firmware TARGET=stm32f405: {exc}",
                                  "see firmware/README.md ('Build')")]
    return out + [Finding(True, f"firmware image {name}: flash {s['flash']:,} B, RAM "
                                f"{s['ram']:,} B") for name, s in sizes.items()]

"""CURVE key files of a master-slave link: made by ``telethermal keys``,
read by the endpoints (``proto/PROTOCOL.md`` section 2).

``<name>.key`` holds a public key, ``<name>.key_secret`` the pair; ZeroMQ's
own certificate format (:mod:`zmq.auth`).
"""

from __future__ import annotations

import os
from pathlib import Path

import zmq.auth

from telethermal.errors import TransportError


def generate_keys(folder: str | Path, name: str) -> tuple[Path, Path]:
    """``name.key`` (public) and ``name.key_secret`` in ``folder``."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    public, secret = zmq.auth.create_certificates(str(folder), name)
    os.chmod(secret, 0o600)
    return Path(public), Path(secret)


def generate_link_keys(folder: str | Path) -> Path:
    """Keys for one master-slave link, laid out as the configs expect:
    ``slave/`` (the slave's pair), ``master/`` (the master's pair and the
    slave's public key), ``allowed/`` (the master's public key)."""
    folder = Path(folder)
    generate_keys(folder / "slave", "slave")
    generate_keys(folder / "master", "master")
    (folder / "allowed").mkdir(exist_ok=True)
    (folder / "allowed" / "master.key").write_bytes((folder / "master" / "master.key").read_bytes())
    (folder / "master" / "slave.key").write_bytes((folder / "slave" / "slave.key").read_bytes())
    return folder


def load_secret(folder, name) -> tuple[bytes, bytes]:
    """(public, secret) from ``folder/name.key_secret``; TransportError if
    the file is missing or holds no secret key."""
    path = Path(folder) / f"{name}.key_secret"
    if not path.is_file():
        raise TransportError(f"{path}: no such key file (create it with `telethermal keys`)")
    public, secret = zmq.auth.load_certificate(str(path))
    if secret is None:
        raise TransportError(f"{path}: holds no secret key")
    return public, secret


def load_public(folder, name) -> bytes:
    """The public key in ``folder/name.key``; TransportError if missing."""
    path = Path(folder) / f"{name}.key"
    if not path.is_file():
        raise TransportError(f"{path}: no such public key file")
    return zmq.auth.load_certificate(str(path))[0]

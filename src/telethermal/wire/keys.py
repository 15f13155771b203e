"""CURVE key files of a master-slave link: made by ``telethermal keys``,
read by the endpoints (``proto/PROTOCOL.md`` section 2).

``<name>.key`` holds a public key, ``<name>.key_secret`` the pair; ZeroMQ's
own certificate format (:mod:`zmq.auth`).

No other user can touch them at any instant (``docs/limits.md``, "Keys"):
a secret is created with mode 600 (``os.open`` with the mode, then written,
then renamed into place: never a moment at 644), a key folder this code
makes is 700 whatever the umask, and a slave refuses to start with a secret
others can read or an ``allowed/`` folder (or key in it) others can write.
"""

from __future__ import annotations

import datetime
import logging
import os
import stat
from pathlib import Path

import zmq
import zmq.auth

from telethermal.errors import TransportError

log = logging.getLogger(__name__)

SECRET_MODE = 0o600
PUBLIC_MODE = 0o644
FOLDER_MODE = 0o700


def _make_folder(folder: Path) -> None:
    """``folder`` and its missing parents, each made 700 (``os.mkdir``'s mode
    is masked by the umask, so the mode is set again, exactly)."""
    missing = []
    while not folder.exists():
        missing.append(folder)
        folder = folder.parent
    for part in reversed(missing):
        os.mkdir(part, FOLDER_MODE)
        os.chmod(part, FOLDER_MODE)


def write_private(path: Path, data: bytes, mode: int) -> Path:
    """``data`` into ``path`` with ``mode`` from the first instant: a new
    file next to it, created with the mode (``O_EXCL``, no symlink
    followed), written and synced, then renamed over ``path``."""
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW, mode)
    try:
        os.fchmod(fd, mode)                  # the umask may only have taken bits away
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return path


def _certificate(banner: str, public: bytes, secret: bytes | None = None) -> bytes:
    """ZeroMQ's certificate text (as ``zmq.auth.create_certificates`` writes it)."""
    lines = [f"#   ****  Generated on {datetime.datetime.now()} by telethermal  ****",
             f"#   ZeroMQ CURVE {banner}", "", "metadata", "curve",
             f'    public-key = "{public.decode("ascii")}"']
    if secret is not None:
        lines[1:1] = ["#   DO NOT PROVIDE THIS FILE TO OTHER USERS nor change its permissions."]
        lines.append(f'    secret-key = "{secret.decode("ascii")}"')
    return ("\n".join(lines) + "\n").encode("ascii")


def generate_keys(folder: str | Path, name: str, replace: bool = False) -> tuple[Path, Path]:
    """``name.key`` (public, 644) and ``name.key_secret`` (600) in ``folder``
    (made 700 if missing; an existing one others can write is refused).
    ``name``: a plain file name (letters, digits, ``_``, ``-``, ``.``; no
    folder). A pair already there is refused unless ``replace``: every peer
    given its public key would be locked out."""
    import re

    if not re.fullmatch(r"[A-Za-z0-9_-][A-Za-z0-9_.-]*", name or ""):
        raise TransportError(f"key name {name!r}: letters, digits, '_', '-' and '.' only "
                             "(a file name in --out, not a path), e.g. slave or master")
    folder = Path(folder)
    if folder.exists() and not folder.is_dir():
        raise TransportError(f"{folder}: a file, not a folder for the keys")
    pair = (folder / f"{name}.key", folder / f"{name}.key_secret")
    taken = [p for p in pair if p.exists()]
    if taken and not replace:
        if len(taken) < 2:             # half a pair: nothing to keep, the peer must be told
            raise TransportError(f"{taken[0]} exists but {({*pair} - {*taken}).pop().name} "
                                 "does not: the pair is broken; make a new one with --force "
                                 "and give its public key to the peer again")
        raise TransportError(f"{taken[0]} exists: a new pair would lock out every peer given "
                             f"the old public key; keep it, or replace both with --force")
    if folder.exists():
        check_not_writable_by_others(folder)
    else:
        _make_folder(folder)
    public, secret = zmq.curve_keypair()
    secret_path = write_private(folder / f"{name}.key_secret",
                                _certificate("**Secret** Certificate", public, secret),
                                SECRET_MODE)
    public_path = write_private(folder / f"{name}.key",
                                _certificate("Public Certificate", public), PUBLIC_MODE)
    return public_path, secret_path


def make_allowed_folder(folder: str | Path) -> Path:
    """A slave's ``allowed/`` (the masters' public keys): 700."""
    folder = Path(folder)
    if folder.exists():
        check_not_writable_by_others(folder)
    else:
        _make_folder(folder)
    return folder


def generate_link_keys(folder: str | Path) -> Path:
    """Keys for one master-slave link, laid out as the configs expect:
    ``slave/`` (the slave's pair), ``master/`` (the master's pair and the
    slave's public key), ``allowed/`` (the master's public key)."""
    folder = Path(folder)
    generate_keys(folder / "slave", "slave", replace=True)       # the link's own, made anew
    generate_keys(folder / "master", "master", replace=True)
    make_allowed_folder(folder / "allowed")
    write_private(folder / "allowed" / "master.key",
                  (folder / "master" / "master.key").read_bytes(), PUBLIC_MODE)
    write_private(folder / "master" / "slave.key",
                  (folder / "slave" / "slave.key").read_bytes(), PUBLIC_MODE)
    return folder


# ---------------------------------------------------------------- checks
def _mode(path: Path) -> int:
    return stat.S_IMODE(os.stat(path).st_mode)


def check_not_writable_by_others(path: str | Path) -> None:
    """TransportError if group or others may write ``path`` (a key folder,
    ``allowed/`` or a key in it: they could add or replace a key)."""
    path = Path(path)
    mode = _mode(path)
    if mode & 0o022:
        who = {0o020: "its group", 0o002: "every user"}.get(mode & 0o022, "group and others")
        raise TransportError(f"{path}: writable by {who} (mode {mode:03o}): another user could "
                             f"add or replace a key; fix: chmod go-w {path}")


def check_secret_private(path: str | Path) -> None:
    """TransportError if anyone but the owner may read or write the secret."""
    path = Path(path)
    mode = _mode(path)
    if mode & 0o077:
        raise TransportError(f"{path}: readable or writable by others (mode {mode:03o}): the "
                             f"secret key is not secret; fix: chmod 600 {path}")


def check_allowed_folder(folder: str | Path) -> list[Path]:
    """The slave's ``allowed/``: neither it nor a key in it writable by
    others (TransportError naming the fix); returns its key files."""
    folder = Path(folder)
    if not folder.is_dir():
        raise TransportError(f"{folder}: allowed-keys folder does not exist")
    check_not_writable_by_others(folder)
    keys = sorted(folder.glob("*.key"))
    for key in keys:
        check_not_writable_by_others(key)
    return keys


def load_secret(folder, name, private: bool = False) -> tuple[bytes, bytes]:
    """(public, secret) from ``folder/name.key_secret``; TransportError if
    the file is missing or holds no secret key. A secret others can read is
    refused with ``private`` (the slave), logged as a warning otherwise."""
    path = Path(folder) / f"{name}.key_secret"
    if not path.is_file():
        raise TransportError(f"{path}: no such key file (create it with `telethermal keys`)")
    try:
        check_secret_private(path)
    except TransportError as exc:
        if private:
            raise
        log.warning("%s", exc)
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

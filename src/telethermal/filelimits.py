"""Every file the product reads is held to a size stated in docs/limits.md,
checked before it is read: one check, one wording, for scenes, TOML files,
model files, recordings and a lab's CSV files. Only regular files are read
(a FIFO or a device reports size 0 and would be read without end), and
never more than the limit, even if the file grows after its size was read."""

from __future__ import annotations

import stat
from pathlib import Path

from telethermal.errors import TelethermalError

#: What a file that grew after its size was read is read on in.
CHUNK_B = 1 << 20


def check_size(path: str | Path, limit_b: int, what: str, error=TelethermalError) -> int:
    """The size of the regular file at ``path`` (a ``what``: "scene file",
    ...); ``error`` naming the file if it cannot be read, is not a regular
    file or is over ``limit_b``."""
    try:
        st = Path(path).stat()
    except OSError as exc:
        raise error(f"{path}: cannot read: {exc}") from exc
    if not stat.S_ISREG(st.st_mode):
        raise error(f"{path}: not a regular file (a {what} is read from a file)")
    if st.st_size > limit_b:
        raise error(f"{path}: {st.st_size} bytes, over the {limit_b}-byte limit of a {what} "
                    "(docs/limits.md)")
    return st.st_size


def read_bytes(path: str | Path, limit_b: int, what: str, error=TelethermalError) -> bytes:
    """The file's bytes, checked as :func:`check_size` says, read at most
    ``limit_b`` + 1 of them (a file grown past the limit since is refused)."""
    size = check_size(path, limit_b, what, error)
    try:
        with open(path, "rb") as fh:
            # The size read, then what the file has more, up to the limit
            # (one read of limit + 1 would allocate the limit at once).
            data = fh.read(size + 1)
            while size < len(data) <= limit_b and \
                    (more := fh.read(min(CHUNK_B, limit_b + 1 - len(data)))):
                data += more                  # it grew since: read on, to the limit
    except OSError as exc:
        raise error(f"{path}: cannot read: {exc}") from exc
    if len(data) > limit_b:
        raise error(f"{path}: over the {limit_b}-byte limit of a {what} (docs/limits.md; it "
                    "grew while being read)")
    return data


def read_text(path: str | Path, limit_b: int, what: str, error=TelethermalError) -> str:
    """The file's text: :func:`read_bytes`, decoded as UTF-8, else ``error``
    naming the file and the first bad byte."""
    data = read_bytes(path, limit_b, what, error)
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise error(f"{path}: not UTF-8 text (byte {exc.start}: "
                    f"{data[exc.start:exc.start + 1]!r})") from None

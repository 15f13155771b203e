"""Every file the product reads is held to a size stated in docs/limits.md,
checked before it is read: one check, one wording, for scenes, TOML files,
model files, recordings and a lab's CSV files."""

from __future__ import annotations

from pathlib import Path

from telethermal.errors import TelethermalError


def check_size(path: str | Path, limit_b: int, what: str, error=TelethermalError) -> int:
    """The size of the file at ``path`` (a ``what``: "scene file", ...);
    ``error`` naming the file if it cannot be read or is over ``limit_b``."""
    try:
        size = Path(path).stat().st_size
    except OSError as exc:
        raise error(f"{path}: cannot read: {exc}") from exc
    if size > limit_b:
        raise error(f"{path}: {size} bytes, over the {limit_b}-byte limit of a {what} "
                    "(docs/limits.md)")
    return size


def read_text(path: str | Path, limit_b: int, what: str, error=TelethermalError) -> str:
    """The file's text: at most ``limit_b`` bytes (:func:`check_size`),
    UTF-8, else ``error`` naming the file and the first bad byte."""
    check_size(path, limit_b, what, error)
    try:
        data = Path(path).read_bytes()
    except OSError as exc:
        raise error(f"{path}: cannot read: {exc}") from exc
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise error(f"{path}: not UTF-8 text (byte {exc.start}: "
                    f"{data[exc.start:exc.start + 1]!r})") from None

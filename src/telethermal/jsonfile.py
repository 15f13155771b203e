"""JSON reports (benchmarks, evaluations, sessions): NaN and infinities
written as null, written through a temporary file (a failure leaves the old
file or none, never half of one); figures written the same way."""

from __future__ import annotations

import json
import math
import os
from pathlib import Path


def json_safe(value):
    """NaN and infinities become null (JSON has neither): "not measured"."""
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {k: json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_safe(v) for v in value]
    return value


def write_json(path: str | Path, payload: dict) -> Path:
    """Write ``payload`` (indented, one trailing newline) to ``path``."""
    return write_text(path, json.dumps(json_safe(payload), indent=2, allow_nan=False) + "\n")


def write_text(path: str | Path, text: str) -> Path:
    """Write ``text`` (UTF-8) to ``path`` atomically: all of it or, on any
    failure, nothing (the old file kept). A path that is a folder is
    refused, naming it."""
    return _atomic(path, lambda tmp: tmp.write_text(text, encoding="utf-8"), "a file's path")


def write_figure(fig, path: str | Path, dpi: int = 110, fmt: str | None = None) -> Path:
    """Save a matplotlib figure to ``path`` atomically, as :func:`write_text`
    (``fmt``: its format; default the path's suffix, else PNG). A path that
    is a folder is refused before anything is drawn, naming it."""
    fmt = fmt or Path(path).suffix.lstrip(".") or "png"
    return _atomic(path, lambda tmp: fig.savefig(tmp, dpi=dpi, format=fmt),
                   "an image file's path")


def _atomic(path: str | Path, write, what: str) -> Path:
    """``write(tmp)`` into a temporary sibling of ``path``, then renamed
    over it; on any failure the temporary removed and the old file kept."""
    path = Path(path)
    if path.is_dir():
        raise IsADirectoryError(21, f"a folder, not {what}", str(path))
    path.parent.mkdir(parents=True, exist_ok=True)
    # One temporary file per process: two processes writing the same file
    # (an idle policy in the cache, two test workers) do not write into
    # each other's, and a failure leaves no temporary file behind.
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        write(tmp)
        tmp.replace(path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return path

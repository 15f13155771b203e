"""Model files: one ``.npz`` holding a JSON header and named arrays, read
with ``allow_pickle=False`` and written through a temporary file (a crash
leaves the old file or none, never half of one). Identifiers and flux
generators both use it."""

from __future__ import annotations

import json
import os
import zipfile
from pathlib import Path

import numpy as np

from telethermal import __version__
from telethermal.errors import ModelFileError


def write_npz(path: str | Path, fmt: str, version: int, header: dict, arrays: dict) -> Path:
    path = Path(path)
    full = {"format": fmt, "format_version": version, "telethermal_version": __version__,
            **header}
    payload = {"header": np.frombuffer(json.dumps(full).encode(), dtype=np.uint8),
               **{k: np.asarray(v) for k, v in arrays.items()}}
    path.parent.mkdir(parents=True, exist_ok=True)
    # One temporary file per process: two processes writing the same file
    # (a cache) do not write into each other's.
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        with open(tmp, "wb") as fh:
            np.savez(fh, **payload)
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return path


def read_npz(path: str | Path, fmt: str, version: int, what: str) -> tuple[dict, dict]:
    """(header, arrays) of a ``fmt`` file; ModelFileError naming the file and
    what is wrong with it otherwise (``what``: "model", "generator")."""
    path = Path(path)
    if not path.is_file():
        raise ModelFileError(f"{path}: no such {what} file")
    if not zipfile.is_zipfile(path):
        # (numpy would try it as a pickle, and its error advises
        # allow_pickle=True: advice this program must never take.)
        raise ModelFileError(f"{path}: not a telethermal {what} file (not an .npz archive: "
                             f"truncated, overwritten, or another kind of file)")
    try:
        with open(path, "rb") as fh, np.load(fh, allow_pickle=False) as data:
            arrays = {k: data[k] for k in data.files}
    except ValueError as exc:
        # An array of Python objects: numpy refuses it without unpickling.
        why = "it holds pickled objects, which telethermal never loads" \
            if "pickle" in str(exc) else str(exc)
        raise ModelFileError(f"{path}: not a readable {what} file: {why}") from exc
    except (zipfile.BadZipFile, EOFError, OSError, KeyError) as exc:
        raise ModelFileError(f"{path}: not a readable {what} file (truncated or not "
                             f"a telethermal {what}): {exc}") from exc
    try:
        header = json.loads(arrays.pop("header").tobytes().decode())
    except (KeyError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ModelFileError(f"{path}: no valid header; not a telethermal {what}") from exc
    if header.get("format") != fmt:
        raise ModelFileError(f"{path}: not a {fmt.replace('-', ' ')} file")
    if header.get("format_version") != version:
        raise ModelFileError(f"{path}: {what} format version {header.get('format_version')} "
                             f"(written by telethermal {header.get('telethermal_version')}); "
                             f"this telethermal reads version {version}")
    return header, arrays

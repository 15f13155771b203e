"""Model files: one ``.npz`` holding a JSON header and named arrays, read
with ``allow_pickle=False`` and written through a temporary file (a crash
leaves the old file or none, never half of one). Identifiers and flux
generators both use it.

Reading checks the file against the limits of ``docs/limits.md`` before
any array is read into memory: the file's size, then every member's
``.npy`` header (dtype: bool, integer or float, never objects; the bytes its
shape declares equal to what the member holds), the header's size; then,
once read, every float array finite. A file that declares a 3 GB array in
3 MB is refused from its headers, without allocating the array."""

from __future__ import annotations

import json
import os
import zipfile
from pathlib import Path

import numpy as np

from telethermal import __version__
from telethermal.errors import ModelFileError
from telethermal.filelimits import check_size

#: The largest model file read (the project's models: 10-50 KB; the
#: effusivity curves' cache: 2-3 MB).
MAX_FILE_BYTES = 64 * 1024 * 1024
#: The uncompressed arrays of one file, together (``np.savez`` stores them
#: uncompressed; a compressed member may not inflate past this).
MAX_ARRAYS_BYTES = 256 * 1024 * 1024
#: The JSON header (the project's: under 4 KB).
MAX_HEADER_BYTES = 1024 * 1024
#: Array dtypes a model file may hold: bool, integers, floats.
DTYPE_KINDS = "biuf"
#: In the header: nesting depth, a string's length (UTF-8 bytes; a name
#: that goes on the wire, a class or material, is held to the wire's 256).
MAX_HEADER_DEPTH = 16
MAX_STRING_BYTES = 4096
MAX_NAME_BYTES = 256


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
    check_size(path, MAX_FILE_BYTES, f"{what} file", ModelFileError)
    check_members(path, what)
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
        header = json.loads(arrays.pop("header").tobytes().decode(),
                            parse_constant=_not_finite)
    except (KeyError, UnicodeDecodeError, json.JSONDecodeError, RecursionError) as exc:
        raise ModelFileError(f"{path}: no valid header; not a telethermal {what}") from exc
    if not isinstance(header, dict):
        raise ModelFileError(f"{path}: the header is not a JSON object; not a telethermal {what}")
    check_header_values(path, header)
    for name, value in arrays.items():
        if value.dtype.kind == "f" and not np.isfinite(value).all():
            index = tuple(int(i) for i in np.argwhere(~np.isfinite(value))[0])
            raise ModelFileError(f"{path}: array {name!r} holds {value[index]} at {index}: "
                                 f"every number of a {what} must be finite")
    if header.get("format") != fmt:
        raise ModelFileError(f"{path}: not a {fmt.replace('-', ' ')} file")
    if header.get("format_version") != version:
        raise ModelFileError(f"{path}: {what} format version {header.get('format_version')} "
                             f"(written by telethermal {header.get('telethermal_version')}); "
                             f"this telethermal reads version {version}")
    return header, arrays


def _npy_header(member, where: str) -> tuple[np.dtype, tuple, int]:
    """(dtype, shape, header length) of one ``.npy`` member, from its header only."""
    fmt = np.lib.format
    try:
        version = fmt.read_magic(member)
        reader = {(1, 0): fmt.read_array_header_1_0, (2, 0): fmt.read_array_header_2_0}.get(
            version)
        if reader is None:
            raise ValueError(f"npy format version {version}")
        shape, _, dtype = reader(member, max_header_size=10_000)
    except (ValueError, SyntaxError, TypeError, EOFError) as exc:
        raise ModelFileError(f"{where}: not a readable array header ({exc})") from exc
    return dtype, shape, member.tell()


def check_members(path: Path, what: str) -> None:
    """Every member of the archive an ``.npy`` array of an allowed dtype
    whose declared bytes are those the member holds, together under
    ``MAX_ARRAYS_BYTES``: checked from the zip directory and each array's
    header, before any array is read."""
    try:
        with zipfile.ZipFile(path) as archive:
            members = archive.infolist()
            total = sum(m.file_size for m in members)
            if total > MAX_ARRAYS_BYTES:
                raise ModelFileError(f"{path}: its arrays take {total} bytes, over the "
                                     f"{MAX_ARRAYS_BYTES}-byte limit of a {what} file")
            for m in members:
                where = f"{path}: array {m.filename!r}"
                if not m.filename.endswith(".npy"):
                    raise ModelFileError(f"{where}: not an .npy array; not a telethermal {what}")
                if m.filename == "header.npy" and m.file_size > MAX_HEADER_BYTES:
                    raise ModelFileError(f"{where}: {m.file_size} bytes, over the "
                                         f"{MAX_HEADER_BYTES}-byte limit of a header")
                with archive.open(m) as member:
                    dtype, shape, offset = _npy_header(member, where)
                if dtype.hasobject:
                    raise ModelFileError(f"{where}: not a readable {what} file: it holds "
                                         "pickled objects, which telethermal never loads")
                if dtype.kind not in DTYPE_KINDS:
                    raise ModelFileError(f"{where}: dtype {dtype}; a {what} holds only bool, "
                                         "integer and float arrays")
                declared = int(np.prod(shape, dtype=object)) * dtype.itemsize
                if declared != m.file_size - offset:
                    raise ModelFileError(f"{where}: its header declares shape {shape} of "
                                         f"{dtype} ({declared} bytes) but it holds "
                                         f"{m.file_size - offset}")
    except (zipfile.BadZipFile, OSError, EOFError) as exc:
        raise ModelFileError(f"{path}: not a readable {what} file (truncated or not a "
                             f"telethermal {what}): {exc}") from exc


class _NotFinite(float):
    """A header's NaN or Infinity, kept as such to be named by the check."""


def _not_finite(text: str) -> float:
    return _NotFinite(text.replace("Infinity", "inf"))


def check_header_values(path: Path, header, where: str = "header", depth: int = 0) -> None:
    """Every number of the header finite, every string at most
    ``MAX_STRING_BYTES``, nesting at most ``MAX_HEADER_DEPTH``; ModelFileError
    naming the field otherwise."""
    if depth > MAX_HEADER_DEPTH:
        raise ModelFileError(f"{path}: {where}: nested deeper than {MAX_HEADER_DEPTH}")
    if isinstance(header, dict):
        items = header.items()
    elif isinstance(header, list):
        items = ((f"[{i}]", v) for i, v in enumerate(header))
    else:
        if isinstance(header, float) and not np.isfinite(header):
            raise ModelFileError(f"{path}: {where} is {header}: every number must be finite")
        if isinstance(header, str) and len(header.encode()) > MAX_STRING_BYTES:
            raise ModelFileError(f"{path}: {where}: a string of {len(header.encode())} bytes, "
                                 f"over the {MAX_STRING_BYTES}-byte limit")
        return
    for key, value in items:
        if len(str(key).encode()) > MAX_NAME_BYTES:
            raise ModelFileError(f"{path}: {where}: a key of {len(str(key).encode())} bytes, "
                                 f"over {MAX_NAME_BYTES}")
        name = f"{where}{key}" if str(key).startswith("[") else f"{where}.{key}"
        check_header_values(path, value, name, depth + 1)


def check_names(path: Path, names, field: str, what: str) -> list:
    """A non-empty list of distinct strings of 1-256 UTF-8 bytes (classes,
    materials: they go on the wire)."""
    if not isinstance(names, list) or not names:
        raise ModelFileError(f"{path}: {field} must be a non-empty list of names, got "
                             f"{str(names)[:64]}; a {what} without them identifies nothing")
    for name in names:
        if not isinstance(name, str) or not 0 < len(name.encode()) <= MAX_NAME_BYTES:
            raise ModelFileError(f"{path}: {field}: {str(name)[:64]!r} is not a name of 1 to "
                                 f"{MAX_NAME_BYTES} bytes (the wire's cap)")
    if len(set(names)) != len(names):
        raise ModelFileError(f"{path}: {field} names a class twice")
    return names

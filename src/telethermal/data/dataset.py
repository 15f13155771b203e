"""The dataset format: a manifest of trials and one CSV per trial.

``DIR/manifest.csv`` has one row per trial and at least the columns of
:data:`MANIFEST_COLUMNS`; extra columns are kept as they are. Each trial file
``DIR/<file>`` is a CSV with a header row, a ``t_s`` column (0 at first
contact, negative before, strictly increasing, spaced 1 / ``sample_rate_hz``
within 1 %) and any numeric channels (``heat_flux_W_m2``, ``temperature_C``,
``force_N``, ...). Heat flux is positive from the pad (or finger) into the
object. Every error names the file, the row and the column at fault.

Writing is all or nothing: a dataset is written into a hidden sibling folder
and renamed into place only once complete.
"""

from __future__ import annotations

import contextlib
import csv
import io
import math
import os
import shutil
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterable

import numpy as np

from telethermal.errors import DatasetError

MANIFEST = "manifest.csv"
MANIFEST_COLUMNS = ("trial_id", "material", "file", "sample_rate_hz", "T_object_C",
                    "T_pad_C", "T_room_C", "group")
NUMERIC_COLUMNS = ("sample_rate_hz", "T_object_C", "T_pad_C", "T_room_C")
TIME = "t_s"
#: Allowed mismatch between the median t_s step and 1 / sample_rate_hz.
RATE_TOLERANCE = 0.01


@dataclass
class Trial:
    """One manifest row plus, once loaded, its channels."""

    trial_id: str
    material: str
    file: str
    sample_rate_hz: float
    T_object_C: float
    T_pad_C: float
    T_room_C: float
    group: str
    extra: dict[str, str] = field(default_factory=dict)
    channels: dict[str, np.ndarray] | None = field(default=None, repr=False)

    @property
    def gap_k(self) -> float:
        """Pad (or finger) minus object temperature before contact, K."""
        return self.T_pad_C - self.T_object_C

    def manifest_row(self) -> dict[str, str]:
        row = {c: _fmt(getattr(self, c)) for c in MANIFEST_COLUMNS}
        row.update(self.extra)
        return row


def _fmt(value) -> str:
    return repr(float(value)) if isinstance(value, float) else str(value)


# ------------------------------------------------------------------ reading
def read_manifest(root: str | Path) -> list[Trial]:
    """Read and check ``root/manifest.csv`` (not the trial files)."""
    root = Path(root)
    path = root / MANIFEST
    if not path.is_file():
        parts = [p for p in ("pad", "finger") if (root / p / MANIFEST).is_file()]
        raise DatasetError(f"{path}: no manifest (is {root} a dataset folder?)" + (
            f"; {root} holds the databases {' and '.join(p + '/' for p in parts)}: give "
            + " or ".join(f"{root / p}" for p in parts) + " (pad/: the pad's touches, "
            "for identification; finger/: the finger's, for the generator)" if parts else ""))
    try:
        trials = _manifest_trials(path, root)
    except UnicodeDecodeError as exc:
        raise DatasetError(f"{path}: not UTF-8 text (byte {exc.start}): not a manifest") \
            from None
    except csv.Error as exc:
        raise DatasetError(f"{path}: not CSV: {exc}") from None
    if not trials:
        raise DatasetError(f"{path}: no trials")
    return trials


def _manifest_trial(row: dict, path: Path, line: int, root: Path) -> Trial:
    values = {}
    for col in MANIFEST_COLUMNS:
        cell = row.get(col)
        if cell is None or cell.strip() == "":
            raise DatasetError(f"{path} row {line}: empty '{col}'")
        if col in NUMERIC_COLUMNS:
            try:
                values[col] = float(cell)
            except ValueError as exc:
                raise DatasetError(f"{path} row {line}, column '{col}': "
                                   f"{cell!r} is not a number") from exc
            if not math.isfinite(values[col]):
                raise DatasetError(f"{path} row {line}, column '{col}': {cell!r} is not finite")
        else:
            values[col] = cell.strip()
    if values["sample_rate_hz"] <= 0:
        raise DatasetError(f"{path} row {line}: sample_rate_hz must be > 0")
    file = root / values["file"]
    if not file.is_file():
        raise DatasetError(f"{path} row {line}: trial file {values['file']!r} does not exist")
    extra = {k: v for k, v in row.items() if k not in MANIFEST_COLUMNS and k is not None}
    return Trial(**values, extra=extra)


def read_trial_file(path: str | Path, sample_rate_hz: float | None = None) -> dict[str, np.ndarray]:
    """Read one trial CSV into ``{channel: array}``; check t_s and the rate."""
    path = Path(path)
    text = path.read_text()
    lines = text.splitlines()
    if not lines:
        raise DatasetError(f"{path}: empty file")
    header = [h.strip() for h in lines[0].split(",")]
    if TIME not in header:
        raise DatasetError(f"{path}: no '{TIME}' column (header: {', '.join(header)})")
    if len(set(header)) != len(header):
        raise DatasetError(f"{path}: repeated column names in the header")
    try:
        table = np.loadtxt(io.StringIO(text), delimiter=",", skiprows=1, ndmin=2)
    except ValueError as exc:
        _locate_bad_cell(path, lines, header)
        raise DatasetError(f"{path}: cannot read the numbers ({exc})") from exc
    if table.shape[0] == 0:
        raise DatasetError(f"{path}: no data rows")
    if table.shape[1] != len(header):
        raise DatasetError(f"{path}: {table.shape[1]} columns in the data, "
                           f"{len(header)} in the header")
    bad = ~np.isfinite(table)
    if bad.any():
        row, col = np.argwhere(bad)[0]
        raise DatasetError(f"{path} line {row + 2}, column '{header[col]}': not finite")
    channels = {name: table[:, i] for i, name in enumerate(header)}
    _check_time(path, channels[TIME], sample_rate_hz)
    return channels


def _locate_bad_cell(path: Path, lines: list[str], header: list[str]):
    for number, line in enumerate(lines[1:], start=2):
        cells = line.split(",")
        if len(cells) != len(header):
            raise DatasetError(f"{path} line {number}: {len(cells)} cells, "
                               f"{len(header)} columns in the header")
        for name, cell in zip(header, cells):
            try:
                float(cell)
            except ValueError as exc:
                raise DatasetError(f"{path} line {number}, column '{name}': "
                                   f"{cell.strip()!r} is not a number") from exc


def _check_time(path: Path, t_s: np.ndarray, sample_rate_hz: float | None):
    if len(t_s) < 2:
        return
    steps = np.diff(t_s)
    if np.any(steps <= 0):
        line = int(np.argmax(steps <= 0)) + 3
        raise DatasetError(f"{path} line {line}: '{TIME}' does not increase")
    if sample_rate_hz is not None:
        step = float(np.median(steps))
        if abs(step * sample_rate_hz - 1.0) > RATE_TOLERANCE:
            raise DatasetError(f"{path}: '{TIME}' is spaced {step:.6g} s ({1 / step:.6g} Hz) "
                               f"but the manifest says sample_rate_hz = {sample_rate_hz:g}")


def trial_digest(trial: Trial) -> str:
    """A short digest of a loaded trial's content (its channels, as read):
    the same contact copied, renamed or re-imported has the same digest."""
    import hashlib

    h = hashlib.sha256()
    for name in sorted(trial.channels or {}):
        h.update(name.encode())
        h.update(np.round(np.asarray(trial.channels[name], dtype=np.float64), 6).tobytes())
    return h.hexdigest()[:16]


#: The channels the identifiers read (``ident/prepare.py``): heat flux always,
#: the pad's temperature and the pressing force when a model is given them.
FLUX_CHANNEL = "heat_flux_W_m2"
IDENTIFIER_CHANNELS = (FLUX_CHANNEL, "temperature_C", "force_N")


def check_identifier_channels(trials: list[Trial], root: str | Path = "") -> None:
    """Refuse trials an identifier could not read: every trial needs the
    heat-flux column, and a column named like one the identifiers read but
    not the same (``heatflux_W_m2``) is taken for a typo, with the name
    meant. Other channels are kept as they are."""
    import difflib

    for trial in trials:
        where = Path(root) / trial.file
        names = [c for c in trial.channels if c != TIME]
        for name in names:
            if name in IDENTIFIER_CHANNELS:
                continue
            meant = difflib.get_close_matches(name, IDENTIFIER_CHANNELS, n=1, cutoff=0.8)
            if meant and meant[0] not in names:
                raise DatasetError(f"{where}: column '{name}' is not one the identifiers "
                                   f"read (did you mean '{meant[0]}'?)")
        if FLUX_CHANNEL not in names:
            raise DatasetError(f"{where}: no '{FLUX_CHANNEL}' column, which every "
                               f"identifier reads (columns: {', '.join(names) or 'none'})")


def manifest_header(path) -> set[str]:
    """The column names of a manifest's first line (empty if there is no
    such file); DatasetError if it is not UTF-8 text."""
    path = Path(path)
    if not path.is_file():
        return set()
    try:
        with path.open(newline="", encoding="utf-8-sig") as fh:
            return {h.strip() for h in fh.readline().split(",")}
    except UnicodeDecodeError as exc:
        raise DatasetError(f"{path}: not UTF-8 text (byte {exc.start}): not a manifest") \
            from None


def is_dataset_manifest(path) -> bool:
    """Whether ``path`` is a dataset's own manifest (as ``dataset generate``
    or ``import`` write it: its header has ``trial_id`` and
    ``sample_rate_hz``), not a lab's list of files; False if there is none."""
    return {"trial_id", "sample_rate_hz"} <= manifest_header(path)


def _manifest_trials(path: Path, root: Path) -> list[Trial]:
    with path.open(newline="", encoding="utf-8") as fh:
        reader = csv.DictReader(fh)
        header = reader.fieldnames or []
        missing = [c for c in MANIFEST_COLUMNS if c not in header]
        if missing:
            raise DatasetError(f"{path}: missing column(s) {', '.join(missing)}")
        trials, seen = [], set()
        for line, row in enumerate(reader, start=2):
            trials.append(_manifest_trial(row, path, line, root))
            if trials[-1].trial_id in seen:
                raise DatasetError(f"{path} row {line}: trial_id {trials[-1].trial_id!r} repeats")
            seen.add(trials[-1].trial_id)
    return trials


def load_dataset(root: str | Path) -> list[Trial]:
    """Read the manifest and every trial file, fully checked."""
    root = Path(root)
    trials = read_manifest(root)
    for trial in trials:
        trial.channels = read_trial_file(root / trial.file, trial.sample_rate_hz)
    return trials


# ------------------------------------------------------------------ writing
#: Decimals written per channel (t_s keeps 9, enough for any rate up to 1 GHz).
DECIMALS = {"t_s": 9, "heat_flux_W_m2": 3, "temperature_C": 4, "force_N": 4}
_DEFAULT_DECIMALS = 6


def _trial_csv(channels: dict[str, np.ndarray]) -> str:
    """CSV text of one trial; one %-format over the whole table (C speed)."""
    names = list(channels)
    if names[0] != TIME:
        raise DatasetError(f"the first channel must be '{TIME}', got {names[0]!r}")
    table = np.column_stack([np.asarray(channels[n], dtype=np.float64) for n in names])
    if not np.all(np.isfinite(table)):
        row, col = np.argwhere(~np.isfinite(table))[0]
        raise DatasetError(f"channel '{names[col]}' row {row}: not finite, not written")
    row_fmt = ",".join(f"%.{DECIMALS.get(n, _DEFAULT_DECIMALS)}f" for n in names) + "\n"
    body = (row_fmt * len(table)) % tuple(table.ravel().tolist())
    return ",".join(names) + "\n" + body


@contextlib.contextmanager
def staged_dir(root: str | Path, overwrite: bool = False):
    """Yield a hidden sibling folder to fill; on success it replaces ``root``
    (an old ``root`` is removed only after the rename), on any error it is
    removed and ``root`` is left as it was."""
    root = Path(root)
    if root.exists() and (not root.is_dir() or any(root.iterdir())):
        if not overwrite:
            raise DatasetError(f"{root} exists and is not empty: give --force to replace it")
        # --force replaces a dataset or a generated database, nothing else (a
        # mistyped --out had deleted a file, or would a whole folder).
        if not root.is_dir():
            raise DatasetError(f"{root}: a file, not a dataset folder; --force replaces a "
                               "dataset, not other files: give a new folder")
        if not (is_dataset_manifest(root / MANIFEST) or (root / "generation.json").is_file()):
            raise DatasetError(f"{root}: not a dataset (no dataset's {MANIFEST} or "
                               "generation.json in it: a lab's own manifest.csv is not one); "
                               "--force replaces only a dataset: give a new folder")
    root.parent.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix=f".{root.name}.", dir=root.parent))
    try:
        yield staging
        old = None
        if root.exists():
            old = root.with_name(f".{root.name}.old-{os.getpid()}")
            root.rename(old)
        staging.rename(root)
        if old is not None:
            shutil.rmtree(old, ignore_errors=True) if old.is_dir() else old.unlink()
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise


def write_trials(root: Path, trials: Iterable[Trial]) -> None:
    """Write trials (each with ``channels``) and the manifest into ``root``
    (not atomic by itself: use inside :func:`staged_dir`)."""
    rows, ids = [], set()
    root.mkdir(parents=True, exist_ok=True)
    for trial in trials:
        if trial.trial_id in ids:
            raise DatasetError(f"trial {trial.trial_id!r} twice: not written")
        ids.add(trial.trial_id)
        if trial.channels is None:
            raise DatasetError(f"trial {trial.trial_id}: no channels to write")
        dest = root / trial.file
        dest.parent.mkdir(parents=True, exist_ok=True)
        dest.write_text(_trial_csv(trial.channels), encoding="utf-8")
        rows.append(trial.manifest_row())
    if not rows:
        raise DatasetError("no trials to write")
    # Every trial's extra columns (trials from different sources carry
    # different ones: blank where a trial has none).
    columns = list(dict.fromkeys(list(MANIFEST_COLUMNS) + [c for r in rows for c in r]))
    with (root / MANIFEST).open("w", newline="", encoding="utf-8") as fh:
        writer = csv.DictWriter(fh, fieldnames=columns, restval="")
        writer.writeheader()
        writer.writerows(rows)


def write_dataset(root: str | Path, trials: Iterable[Trial], overwrite: bool = False) -> Path:
    """Write a dataset at ``root``, all or nothing.

    Raises
    ------
    DatasetError
        If ``root`` exists and is not empty and ``overwrite`` is false, or a
        trial is malformed. ``root`` is then left as it was.
    """
    with staged_dir(root, overwrite) as staging:
        write_trials(staging, trials)
    return Path(root)

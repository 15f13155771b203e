"""A lab's own recorded contacts, from CSV files, into the dataset format
(``telethermal dataset import FILE.csv ... --into DIR``).

A lab's file is one contact: a header row and one row per sample. What its
columns are called and in which units, where the contact begins, which
material was touched and what the temperatures were before contact are
given by the call (or a manifest of many files); every value is checked and
an error names the file, the line and the column. What each dataset column
means (docs/concepts/databases.md, "Dataset format"):

* ``t_s``: time, s; 0 at the first contact sample, negative before.
  Pre-contact samples are optional (the identifiers read from contact on).
* ``heat_flux_W_m2``: the heat flux through the *pad's* face, W/m², positive
  from the pad into the object (a measurement, not a set point). Required:
  every identifier reads it.
* ``temperature_C``: the pad's measured surface temperature, °C (optional).
* ``force_N``: the pressing force, N (optional; when present the identifier
  learns the range of forces and a live touch outside it ends "unknown").
* Per trial (manifest): ``T_object_C`` the object's temperature measured
  before contact, ``T_pad_C`` the pad's *measured* temperature before contact
  (not its set point: their difference, the gap, is what drives the heat;
  under 2 K nothing is identified), ``T_room_C``, ``material`` and ``group``
  (what is held out together in cross-validation: a person, a session, an
  object; a calibration needs at least two).

Files are told apart by content: an MCAP recording starts with its magic
bytes, anything else is read as CSV. A CSV may start with a byte-order mark,
use ``;`` or a tab between cells and then ``,`` as the decimal mark.
"""

from __future__ import annotations

import csv
import math
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from telethermal.data.dataset import MANIFEST_COLUMNS, TIME, Trial, trial_digest
from telethermal.errors import DatasetError
from telethermal.filelimits import check_size

#: Dataset channels a lab file may map to, and the units each may be given in
#: (factor and offset to the dataset's unit: value * factor + offset).
UNITS = {
    "t_s": {"s": (1.0, 0.0), "ms": (1e-3, 0.0)},
    "heat_flux_W_m2": {"W/m2": (1.0, 0.0), "kW/m2": (1e3, 0.0), "W/cm2": (1e4, 0.0)},
    "temperature_C": {"C": (1.0, 0.0), "K": (1.0, -273.15)},
    "force_N": {"N": (1.0, 0.0), "kN": (1e3, 0.0), "gf": (9.80665e-3, 0.0)},
}
REQUIRED = (TIME, "heat_flux_W_m2")
#: Limits of a lab file (docs/limits.md): its size, a cell's length (the
#: csv module's own limit, 128 KiB, raised a bare _csv.Error), each
#: channel's physical range in the dataset's unit (far beyond a pad's:
#: 1e308 W/m^2 was accepted), and a material's name (a folder of the dataset).
MAX_CSV_BYTES = 256 * 1024 * 1024
RANGES = {"t_s": (-1e6, 1e6), "heat_flux_W_m2": (-1e6, 1e6), "temperature_C": (-273.15, 1000.0),
          "force_N": (-1e5, 1e5)}
MAX_MATERIAL_CHARS = 64
MCAP_MAGIC = b"\x89MCAP"
#: The per-trial values a manifest of lab files may give, by the names the
#: project's own manifest uses.
PER_TRIAL = ("material", "group", "T_object_C", "T_pad_C", "T_room_C", "onset_s")


def is_recording(path: str | Path) -> bool:
    """An MCAP recording (its magic bytes), not a CSV."""
    with open(path, "rb") as fh:
        return fh.read(len(MCAP_MAGIC)) == MCAP_MAGIC


def parse_mapping(text: str | None, what: str, allowed=None) -> dict[str, str]:
    """``a=b,c=d`` into {a: b, c: d}; ``allowed``: the keys it may name."""
    out: dict[str, str] = {}
    for item in (text or "").split(","):
        if not item.strip():
            continue
        key, sep, value = item.partition("=")
        key, value = key.strip(), value.strip()
        if not sep or not key or not value:
            raise DatasetError(f"{what} {item!r}: expected NAME=VALUE")
        if allowed is not None and key not in allowed:
            raise DatasetError(f"{what} {key!r}: not a dataset column; columns: "
                               f"{', '.join(allowed)}")
        out[key] = value
    return out


@dataclass(frozen=True)
class CsvSpec:
    """How to read a lab's files: ``columns`` dataset name -> the file's
    header name; ``units`` dataset name -> unit (``UNITS``)."""

    columns: dict
    units: dict

    @classmethod
    def from_options(cls, columns: str | None, units: str | None) -> "CsvSpec":
        spec = cls(parse_mapping(columns, "--columns", tuple(UNITS)),
                   parse_mapping(units, "--units", tuple(UNITS)))
        for name, unit in spec.units.items():
            if unit not in UNITS[name]:
                raise DatasetError(f"--units {name}={unit}: {name} takes "
                                   f"{', '.join(UNITS[name])}")
        return spec


def read_lab_csv(path: str | Path, spec: CsvSpec) -> dict[str, np.ndarray]:
    """The file's mapped channels in the dataset's names and units, in file
    order (time not yet shifted to the contact)."""
    path = Path(path)
    _check_size(path)
    try:
        text = path.read_bytes().decode("utf-8-sig")           # a BOM is dropped
    except UnicodeDecodeError as exc:
        raise DatasetError(f"{path}: not UTF-8 text (byte {exc.start}): not a CSV file") \
            from exc
    numbered = [(i, ln) for i, ln in enumerate(text.splitlines(), start=1) if ln.strip()]
    file_line = [i for i, _ in numbered]            # a row's line in the file (blanks skipped)
    lines = [ln for _, ln in numbered]
    if len(lines) < 3:
        raise DatasetError(f"{path}: a header and at least two samples are needed")
    delimiter = ";" if lines[0].count(";") > lines[0].count(",") else \
        "\t" if "\t" in lines[0] else ","
    decimal_comma = delimiter != ","
    rows = []
    try:
        for row in csv.reader(lines, delimiter=delimiter):
            rows.append(row)
    except csv.Error as exc:                     # a cell over csv's 128 KiB, a stray quote
        raise DatasetError(f"{path} line {file_line[len(rows)]}: not CSV: {exc}") from None
    header = [h.strip() for h in rows[0]]
    wanted = {name: spec.columns.get(name, name) for name in UNITS}
    missing = [f"{n} (column {c!r})" for n, c in wanted.items() if n in REQUIRED and
               c not in header]
    if missing:
        raise DatasetError(f"{path}: no {', '.join(missing)}; its header: {', '.join(header)}"
                           f" (map them with --columns {REQUIRED[1]}=NAME,...)")
    for name, column in spec.columns.items():
        if column not in header:
            raise DatasetError(f"{path}: --columns {name}={column}: no column {column!r}; its "
                               f"header: {', '.join(header)}")
    index = {n: header.index(c) for n, c in wanted.items() if c in header}
    out = {n: np.empty(len(rows) - 1) for n in index}
    for k, row in enumerate(rows[1:], start=1):
        line = file_line[k]
        if len(row) != len(header):
            raise DatasetError(f"{path} line {line}: {len(row)} cells, {len(header)} columns in "
                               f"the header")
        for n, i in index.items():
            cell = row[i].strip()
            try:
                value = float(cell.replace(",", ".") if decimal_comma else cell)
            except ValueError:
                raise DatasetError(f"{path} line {line}, column {header[i]!r}: {cell!r} is not "
                                   f"a number") from None
            if not math.isfinite(value):
                raise DatasetError(f"{path} line {line}, column {header[i]!r}: {cell!r} is not "
                                   f"finite")
            out[n][k - 1] = value
    for n in out:
        factor, offset = UNITS[n][spec.units.get(n, next(iter(UNITS[n])))]
        with np.errstate(over="ignore"):           # an overflow is inf, refused below
            out[n] = out[n] * factor + offset
        lo, hi = RANGES[n]
        bad = np.flatnonzero((out[n] < lo) | (out[n] > hi))
        if bad.size:
            raise DatasetError(f"{path} line {file_line[bad[0] + 1]}, column "
                               f"{header[index[n]]!r}: {n} = {out[n][bad[0]]:g} is outside "
                               f"[{lo:g}, {hi:g}] (docs/limits.md)")
    steps = np.diff(out[TIME])
    if np.any(steps <= 0):
        k = int(np.argmax(steps <= 0))
        what = "restarts" if steps[k] < 0 else "repeats"
        raise DatasetError(f"{path} line {file_line[k + 2]}, column {header[index[TIME]]!r}: "
                           f"the time {what} ({out[TIME][k]:g} then {out[TIME][k + 1]:g}): one "
                           f"contact per file, time increasing")
    rel = np.abs(steps / np.median(steps) - 1.0)
    if np.any(rel > 0.5):
        k = int(np.argmax(rel > 0.5))
        raise DatasetError(f"{path} line {file_line[k + 2]}: a gap in the time ({steps[k]:g} s "
                           f"after {out[TIME][k]:g} s, the usual step {np.median(steps):g} s): "
                           f"samples missing")
    return out


def contact_onset_s(channels: dict, force_on_n: float = 1.0) -> float | None:
    """Where the contact begins on the file's clock: the first sample whose
    force reaches ``force_on_n``; None without a force column."""
    force = channels.get("force_N")
    if force is None:
        return None
    on = np.flatnonzero(force >= force_on_n)
    return None if not len(on) else float(channels[TIME][on[0]])


def lab_trial(path: str | Path, spec: CsvSpec, values: dict, index: int) -> Trial:
    """One dataset trial from one lab file. ``values``: the per-trial
    values (``PER_TRIAL``), from the call or the manifest row."""
    path = Path(path)
    channels = read_lab_csv(path, spec)
    for key in ("material", "group", "T_object_C", "T_pad_C", "T_room_C"):
        if values.get(key) in (None, ""):
            raise DatasetError(f"{path}: no {key} given (--{_option(key)} or a manifest column "
                               f"{key!r})")
    onset = values.get("onset_s")
    if onset not in (None, ""):
        onset = _number(values, "onset_s", path)
    else:
        if np.any(channels[TIME] < 0):
            onset = 0.0                              # the file's own t = 0 is the contact
        else:
            onset = contact_onset_s(channels)
            if onset is None:
                raise DatasetError(f"{path}: where does the contact begin? Its time does not "
                                   f"go below 0 and it has no force column: give --onset-s "
                                   f"(or an onset_s manifest column)")
    t = channels[TIME] - float(onset)
    if t[-1] <= 0:
        raise DatasetError(f"{path}: the contact begins at {onset} s, after the last sample")
    channels = {TIME: t, **{n: v for n, v in channels.items() if n != TIME}}
    rate = 1.0 / float(np.median(np.diff(t)))
    stem = re.sub(r"[^A-Za-z0-9_.-]+", "-", path.stem).strip(".") or f"trial-{index}"
    material = check_material(str(values["material"]).strip(), path)
    trial = Trial("", material, "", round(rate, 6), _number(values, "T_object_C", path),
                  _number(values, "T_pad_C", path), _number(values, "T_room_C", path),
                  str(values["group"]).strip(), extra={"source": path.name}, channels=channels)
    # Named by content: the same contact imported again has the same id (and
    # is refused as such), two different ones never share one.
    trial.trial_id = f"{stem}-{trial_digest(trial)[:8]}"
    trial.file = f"{material}/{trial.trial_id}.csv"
    return trial


def check_material(material: str, path) -> str:
    """A material's name as a folder of the dataset: at most
    ``MAX_MATERIAL_CHARS`` of letters, digits and ``_ . - + |``."""
    if len(material) > MAX_MATERIAL_CHARS:
        raise DatasetError(f"{path}: material {material[:32]!r}...: {len(material)} characters, "
                           f"over {MAX_MATERIAL_CHARS} (it names a folder of the dataset)")
    if not re.fullmatch(r"[A-Za-z0-9_][A-Za-z0-9_ .|+-]*", material) or ".." in material:
        raise DatasetError(f"{path}: material {material!r}: letters, digits and _ . - + | only "
                           f"(it names a folder of the dataset)")
    return material


def _option(key: str) -> str:
    return {"T_object_C": "object-c", "T_pad_C": "pad-c", "T_room_C": "room-c"}.get(key, key)


def _number(values: dict, key: str, path: Path) -> float:
    try:
        x = float(str(values[key]).replace(",", "."))
    except ValueError:
        raise DatasetError(f"{path}: {key} {values[key]!r} is not a number") from None
    if not math.isfinite(x):
        raise DatasetError(f"{path}: {key} {values[key]!r} is not finite")
    return x


def read_lab_manifest(path: str | Path) -> dict[str, dict]:
    """A lab's manifest: ``file`` and any of ``PER_TRIAL`` per row; the
    files relative to the manifest. Returns {resolved file path: values}."""
    path = Path(path)
    _check_size(path)
    try:
        return _manifest_rows(path)
    except csv.Error as exc:
        raise DatasetError(f"{path}: not CSV: {exc}") from None
    except UnicodeDecodeError as exc:
        raise DatasetError(f"{path}: not UTF-8 text (byte {exc.start})") from None


def _check_size(path: Path) -> None:
    check_size(path, MAX_CSV_BYTES, "lab file", DatasetError)


def _manifest_rows(path: Path) -> dict[str, dict]:
    with path.open(newline="", encoding="utf-8-sig") as fh:
        reader = csv.DictReader(fh)
        header = [h.strip() for h in reader.fieldnames or []]
        if "file" not in header:
            raise DatasetError(f"{path}: no 'file' column (columns: file, "
                               f"{', '.join(PER_TRIAL)})")
        unknown = [h for h in header if h != "file" and h not in PER_TRIAL]
        if unknown:
            raise DatasetError(f"{path}: unknown column(s) {', '.join(unknown)}; a lab manifest "
                               f"holds file, {', '.join(PER_TRIAL)}")
        out = {}
        for row in reader:
            line = reader.line_num                  # the file's line (blank lines counted)
            # Cells past the row's end are blank (filled "where known"); cells
            # past the header's end are refused unless empty (a trailing comma).
            extra = [c for c in row.get(None) or [] if c.strip()]
            if extra:
                raise DatasetError(f"{path} line {line}: {len(extra)} more cell(s) than the "
                                   f"header has columns ({extra[0][:32]!r}...)")
            row = {k.strip(): (v or "").strip() for k, v in row.items() if k}
            if not row.get("file"):
                raise DatasetError(f"{path} line {line}: no file named (its 'file' cell is "
                                   "empty)")
            file = path.parent / row["file"]
            if not file.is_file():
                raise DatasetError(f"{path} line {line}: file {row['file']!r} does not exist")
            if str(file.resolve()) in out:
                raise DatasetError(f"{path} line {line}: file {row['file']!r} listed twice")
            out[str(file.resolve())] = {k: v for k, v in row.items() if k != "file" and v != ""}
    if not out:
        raise DatasetError(f"{path}: no rows")
    return out


# A manifest of the dataset has these columns; the lab's per-trial names are
# the same so one file can feed the other.
assert set(PER_TRIAL) - {"onset_s"} <= set(MANIFEST_COLUMNS)

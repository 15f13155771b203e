"""What proto/PROTOCOL.md says a message is, read from the document itself.

The conformance suite must not import telethermal's wire code: its idea of
the protocol comes from the document (section 7's tables, section 3's
limits, section 4's counters), so a deviation between the document and the
services shows up as a failing test, whichever of the two is wrong.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path

DOC = Path(__file__).resolve().parents[2] / "proto" / "PROTOCOL.md"
GOLDEN = DOC.parent / "golden"


@dataclass(frozen=True)
class DocField:
    name: str
    type: str
    nullable: bool
    lo: float
    hi: float
    required: bool


@dataclass(frozen=True)
class DocKind:
    name: str
    stream: str               # "control" or "stream"
    lossless: bool
    direction: str            # "both", "slave->master", "master->slave"
    fields: dict


def _text() -> str:
    return DOC.read_text(encoding="utf-8")


def _rows(block: str) -> dict[str, DocField]:
    fields = {}
    for line in block.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) < 6 or not cells[0].startswith("`"):
            continue
        name = cells[0].strip("`")
        type_, nullable = cells[1].removesuffix(" or nil"), cells[1].endswith(" or nil")
        lo, hi = -math.inf, math.inf
        m = re.fullmatch(r"\[([^,]*), ([^\]]*)\]", cells[3])
        if m:
            lo = float(m.group(1)) if m.group(1) else -math.inf
            hi = float(m.group(2)) if m.group(2) else math.inf
        fields[name] = DocField(name, type_, nullable, lo, hi, cells[4] == "yes")
    return fields


def kinds() -> tuple[dict[str, DocField], dict[str, DocKind]]:
    """The envelope's fields and every kind of section 7."""
    text = _text()
    section = text[text.index("## 7. Kinds and fields"):text.index("## 8.")]
    parts = re.split(r"^### ", section, flags=re.M)[1:]
    envelope, out = {}, {}
    for part in parts:
        title, body = part.split("\n", 1)
        if title.startswith("Envelope"):
            envelope = _rows(body)
            continue
        name = title.strip().strip("`")
        m = re.search(r"Stream: \*\*(\w+)\*\* \(([^)]*)\); direction: ([\w\->]+)\.", body)
        assert m, f"PROTOCOL.md section 7: no stream/direction line for {name}"
        out[name] = DocKind(name, m.group(1), m.group(2).startswith("lossless"), m.group(3),
                            _rows(body))
    return envelope, out


def golden_vectors() -> list[str]:
    """Section 8: ``<kind>`` or ``<kind>.<variant>``, one pair of files each."""
    return sorted(p.name[:-len(".msgpack")] for p in GOLDEN.glob("*.msgpack"))


def limits() -> dict[str, int]:
    """Section 3's size limits, as the document words them."""
    text = _text()
    def find(pattern: str) -> int:
        return int(re.search(pattern.replace(" ", r"\s+"), text).group(1))

    kib = find(r"\*\*Size limit\*\*: (\d+) KiB per encoded message")
    string = find(r"`str` UTF-8 string \(at most (\d+) bytes\)")
    array = find(r"an array of at most (\d+) items")
    return {"message_bytes": kib * 1024, "string_bytes": string, "array_items": array}


def counters() -> list[str]:
    """Section 4's table of counters."""
    text = _text()
    table = text[text.index("| counter | counts |"):]
    table = table[:table.index("\n\n")]
    return re.findall(r"^\s*\| `(\w+)` \|", table, flags=re.M)


ENVELOPE, KINDS = kinds()
LIMITS = limits()


def _check(t: str, value, where: str, f: DocField | None) -> list[str]:
    lim = LIMITS
    if t == "str":
        if not isinstance(value, str):
            return [f"{where}: not a string: {value!r}"]
        if len(value.encode("utf-8")) > lim["string_bytes"]:
            return [f"{where}: over {lim['string_bytes']} bytes"]
        return []
    if t == "bool":
        return [] if isinstance(value, bool) else [f"{where}: not a bool: {value!r}"]
    if t == "uint":
        ok = isinstance(value, int) and not isinstance(value, bool) and 0 <= value < 2 ** 64
        if ok and f is not None and not f.lo <= value <= f.hi:
            return [f"{where}: {value} outside [{f.lo}, {f.hi}]"]
        return [] if ok else [f"{where}: not a uint: {value!r}"]
    if t == "float":
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            return [f"{where}: not a number: {value!r}"]
        if not math.isfinite(value):
            return [f"{where}: not finite"]
        if f is not None and not f.lo <= value <= f.hi:
            return [f"{where}: {value} outside [{f.lo}, {f.hi}]"]
        return []
    if t.startswith("list["):
        if not isinstance(value, list):
            return [f"{where}: not an array"]
        if len(value) > lim["array_items"]:
            return [f"{where}: {len(value)} items"]
        inner = t[5:-1]
        return [e for i, v in enumerate(value) for e in _check(inner, v, f"{where}[{i}]", f)]
    if t == "counters":
        if not isinstance(value, dict):
            return [f"{where}: not a map"]
        return [e for k, v in value.items() for e in
                _check("str", k, f"{where} key", None) + _check("uint", v, f"{where}[{k}]", None)]
    if t == "curves":
        if not isinstance(value, dict):
            return [f"{where}: not a map"]
        errors = []
        for name, curve in value.items():
            w = f"{where}[{name}]"
            errors += _check("str", name, f"{where} key", None)
            if not isinstance(curve, dict) or set(curve) != {"t_s", "g_w_m2k"}:
                errors.append(f"{w}: not {{t_s, g_w_m2k}}")
                continue
            errors += _check("list[float]", curve["t_s"], f"{w}.t_s", None)
            errors += _check("list[float]", curve["g_w_m2k"], f"{w}.g_w_m2k", None)
            t_s = curve["t_s"]
            if len(t_s) != len(curve["g_w_m2k"]) or len(t_s) < 2:
                errors.append(f"{w}: lengths")
            elif any(b <= a for a, b in zip(t_s, t_s[1:])):
                errors.append(f"{w}: t_s not strictly ascending")
        return errors
    return [f"{where}: the document's type {t!r} is unknown to this suite"]


#: Rules section 7 states across fields, in its "meaning" column; each is
#: tied to the document's words (a test fails if the wording goes).
ACROSS = {
    "material_estimate": "same order and length as classes",
    "posterior_estimate": "same order and length as classes",
    "flux_trajectory": "strictly ascending; as many as g_w_m2k, at least 2",
    "measurement_batch": "the three channels hold one value per sample (equal lengths)",
}


def _across_fields(kind: str, m: dict) -> list[str]:
    if kind in ("material_estimate", "posterior_estimate") and \
            len(m["classes"]) != len(m["posteriors"]):
        return [f"{kind}: {ACROSS[kind]}"]
    if kind == "flux_trajectory":
        t, g = m["t_s"], m["g_w_m2k"]
        if len(t) != len(g) or len(t) < 2 or any(b <= a for a, b in zip(t, t[1:])):
            return [f"{kind}.t_s: {ACROSS[kind]}"]
    if kind == "measurement_batch" and \
            len({len(m[c]) for c in ("flux_w_m2", "temp_c", "force_n")}) != 1:
        return [f"{kind}: {ACROSS[kind]}"]
    return []


def deviations(message, sender: str | None = None, stream: str | None = None,
               version: int | None = 1) -> list[str]:
    """Everything in ``message`` (decoded msgpack) that the document does not
    allow; ``sender`` ("slave" or "master") and ``stream`` ("control" or
    "stream") also check the kind's direction and stream; ``version``: the
    session's, which every kind but hello must carry in ``v``."""
    if not isinstance(message, dict):
        return ["not a map"]
    if not all(isinstance(key, str) for key in message):
        return ["a map with keys that are not strings"]
    kind = message.get("kind")
    if not isinstance(kind, str) or kind not in KINDS:
        return [f"unknown kind {kind!r}"]
    k = KINDS[kind]
    errors = []
    for f in list(ENVELOPE.values()) + list(k.fields.values()):
        if f.name not in message:
            if f.required:
                errors.append(f"{kind}.{f.name}: missing")
            continue
        value = message[f.name]
        if value is None:
            if not f.nullable:
                errors.append(f"{kind}.{f.name}: nil")
            continue
        errors += _check(f.type, value, f"{kind}.{f.name}", f)
    if not errors:
        errors += _across_fields(kind, message)
    if version is not None and kind != "hello" and "v" in message and \
            message["v"] != version and not errors:
        errors.append(f"{kind}.v: {message['v']}, the session speaks {version}")
    extra = set(message) - set(ENVELOPE) - set(k.fields)
    if extra:
        errors.append(f"{kind}: fields not in the document: {sorted(extra)}")
    if sender is not None and k.direction not in ("both", f"{sender}->"
                                                  f"{'master' if sender == 'slave' else 'slave'}"):
        errors.append(f"{kind}: sent by the {sender}, direction is {k.direction}")
    if stream is not None and k.stream != stream:
        errors.append(f"{kind}: on the {stream} stream, the document says {k.stream}")
    return errors

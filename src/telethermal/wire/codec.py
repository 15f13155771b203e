"""Encode and decode protocol messages: msgpack maps, validated field by
field against :mod:`telethermal.wire.schema`. No pickle, no extension types.

Encoding is canonical (the envelope keys, then the kind's fields in schema
order; floats as float64, integers in their smallest msgpack form), so the
golden vectors in ``proto/golden/`` are byte-exact both ways.

Rules for readers (``PROTOCOL.md`` section 3): an unknown kind is an error
the receiver counts and drops; an unknown field is ignored (a newer minor
revision may add optional fields); a missing required field, a wrong type,
a non-finite float or a value out of range is an error naming the kind and
the field.
"""

from __future__ import annotations

import math

import msgpack

from telethermal.errors import ProtocolError, UnknownKindError
from telethermal.wire.schema import (ENVELOPE, KINDS, MAX_ARRAY, MAX_MESSAGE_BYTES, MAX_STRING,
                                     PROTOCOL_VERSION, Field)

_UINT_MAX = 2 ** 64 - 1
_NAMES = {k: {f.name for f in ENVELOPE + v.fields} for k, v in KINDS.items()}


def _float(value, where: str, f: Field | None = None) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ProtocolError(f"{where}: expected a number, got {type(value).__name__}")
    x = float(value)
    if not math.isfinite(x):
        raise ProtocolError(f"{where}: {x} is not a finite number")
    if f is not None and not (f.lo <= x <= f.hi):
        raise ProtocolError(f"{where}: {x} outside [{f.lo}, {f.hi}] {f.unit}")
    return x


def _uint(value, where: str, f: Field | None = None) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= _UINT_MAX:
        raise ProtocolError(f"{where}: expected an unsigned integer, got {value!r}")
    if f is not None and not (f.lo <= value <= f.hi):
        raise ProtocolError(f"{where}: {value} outside [{f.lo:g}, {f.hi:g}]")
    return value


def _short(value: str) -> bool:
    """At most MAX_STRING bytes of UTF-8 (not characters: "é" is two bytes)."""
    return len(value) <= MAX_STRING and (value.isascii() or
                                         len(value.encode("utf-8", "surrogatepass")) <= MAX_STRING)


def _str(value, where: str) -> str:
    if not isinstance(value, str):
        raise ProtocolError(f"{where}: expected a string, got {type(value).__name__}")
    if not _short(value):
        raise ProtocolError(f"{where}: string longer than {MAX_STRING} bytes of UTF-8")
    return value


def _list(value, where: str) -> list:
    if not isinstance(value, (list, tuple)):
        raise ProtocolError(f"{where}: expected an array, got {type(value).__name__}")
    if len(value) > MAX_ARRAY:
        raise ProtocolError(f"{where}: array of {len(value)} > {MAX_ARRAY} items")
    return list(value)


def _fast_floats(items, f: Field) -> bool:
    lo, hi = f.lo, f.hi
    return all(type(v) is float and math.isfinite(v) and lo <= v <= hi for v in items)


def _value(f: Field, value, kind: str):
    """Check one field; the error text (kind.field[index]) is built only on failure."""
    t = f.type
    # Fast paths for the common, valid case: no string building at all.
    if t == "float" and type(value) is float and math.isfinite(value) and f.lo <= value <= f.hi:
        return value
    if t == "uint" and type(value) is int and 0 <= value <= _UINT_MAX and \
            f.lo <= value <= f.hi:
        return value
    if t == "str" and type(value) is str and _short(value):
        return value
    if t == "bool" and type(value) is bool:
        return value
    if t == "list[float]" and type(value) is list and len(value) <= MAX_ARRAY and \
            _fast_floats(value, f):
        return value
    if t == "list[str]" and type(value) is list and len(value) <= MAX_ARRAY and \
            all(type(v) is str and _short(v) for v in value):
        return value
    return _value_slow(f, value, f"{kind}.{f.name}")


def _value_slow(f: Field, value, where: str):
    if value is None:
        if f.nullable:
            return None
        raise ProtocolError(f"{where}: may not be nil")
    t = f.type
    if t == "str":
        return _str(value, where)
    if t == "bool":
        if not isinstance(value, bool):
            raise ProtocolError(f"{where}: expected true or false, got {value!r}")
        return value
    if t == "uint":
        return _uint(value, where, f)
    if t == "float":
        return _float(value, where, f)
    if t == "list[str]":
        return [_str(v, f"{where}[{i}]") for i, v in enumerate(_list(value, where))]
    if t == "list[uint]":
        return [_uint(v, f"{where}[{i}]") for i, v in enumerate(_list(value, where))]
    if t == "list[float]":
        return [_float(v, f"{where}[{i}]", f) for i, v in enumerate(_list(value, where))]
    if t == "counters":
        if not isinstance(value, dict):
            raise ProtocolError(f"{where}: expected a map")
        return {_str(k, f"{where} key"): _uint(v, f"{where}[{k!r}]") for k, v in value.items()}
    if t == "curves":
        if not isinstance(value, dict):
            raise ProtocolError(f"{where}: expected a map of material -> curve")
        out = {}
        for name, curve in value.items():
            w = f"{where}[{name!r}]"
            _str(name, f"{where} key")
            if not isinstance(curve, dict) or set(curve) != {"t_s", "g_w_m2k"}:
                raise ProtocolError(f"{w}: expected {{t_s: [...], g_w_m2k: [...]}}")
            t_s = [_float(v, f"{w}.t_s[{i}]") for i, v in enumerate(_list(curve["t_s"], w))]
            g = [_float(v, f"{w}.g_w_m2k[{i}]") for i, v in
                 enumerate(_list(curve["g_w_m2k"], w))]
            if len(t_s) != len(g) or len(t_s) < 2:
                raise ProtocolError(f"{w}: t_s and g_w_m2k need the same length >= 2")
            if any(b <= a for a, b in zip(t_s, t_s[1:])):
                raise ProtocolError(f"{w}: t_s must be strictly ascending")
            out[name] = {"t_s": t_s, "g_w_m2k": g}
        return out
    raise AssertionError(f"schema type {t}")           # a bug in the schema, not in input


def validate(message: dict) -> tuple[dict, list[str]]:
    """The message in canonical order and the names of fields ignored."""
    if not isinstance(message, dict):
        raise ProtocolError(f"a message is a map, got {type(message).__name__}")
    kind_name = message.get("kind")
    if not isinstance(kind_name, str):
        # No kind, or not a string (bytes, a number): a malformed message, not
        # an unknown kind of a newer revision.
        raise ProtocolError(f"kind: expected a string, got "
                            f"{'nothing' if kind_name is None else type(kind_name).__name__}")
    if kind_name not in KINDS:
        raise UnknownKindError(f"unknown message kind {kind_name[:64]!r}")
    kind = KINDS[kind_name]
    out = {}
    for f in ENVELOPE + kind.fields:
        if f.name not in message:
            if f.required:
                raise ProtocolError(f"{kind_name}.{f.name}: missing")
            continue
        out[f.name] = _value(f, message[f.name], kind_name)
    # hello is the negotiation itself: its layout is the same in every version
    # and it is read whatever its v (the receiver answers a version it does
    # not speak with fault "version").
    if out["v"] != PROTOCOL_VERSION and kind_name != "hello":
        raise ProtocolError(f"{kind_name}: protocol version {out['v']}, this side speaks "
                            f"{PROTOCOL_VERSION}")
    if kind_name in ("material_estimate", "posterior_estimate") and \
            len(out["classes"]) != len(out["posteriors"]):
        raise ProtocolError(f"{kind_name}: classes and posteriors differ in length")
    if kind_name == "flux_trajectory":
        if len(out["t_s"]) != len(out["g_w_m2k"]) or len(out["t_s"]) < 2:
            raise ProtocolError("flux_trajectory: t_s and g_w_m2k need the same length >= 2")
        if any(b <= a for a, b in zip(out["t_s"], out["t_s"][1:])):
            raise ProtocolError("flux_trajectory.t_s: must be strictly ascending")
    if kind_name == "measurement_batch":
        n = {len(out[c]) for c in ("flux_w_m2", "temp_c", "force_n")}
        if len(n) != 1:
            raise ProtocolError("measurement_batch: channels differ in length")
    ignored = [k for k in message if k not in out and k not in _NAMES[kind_name]] \
        if len(message) != len(out) else []
    return out, ignored


def encode(message: dict) -> bytes:
    """Validate and pack one message; ProtocolError names what is wrong."""
    canonical, ignored = validate(message)
    if ignored:
        raise ProtocolError(f"{message['kind']}: fields not in protocol version "
                            f"{PROTOCOL_VERSION}: {', '.join(map(str, ignored))}")
    data = msgpack.packb(canonical, use_bin_type=True)
    if len(data) > MAX_MESSAGE_BYTES:
        raise ProtocolError(f"{message['kind']}: {len(data)} bytes > {MAX_MESSAGE_BYTES}")
    return data


def decode(data: bytes) -> dict:
    return decode_verbose(data)[0]


def decode_verbose(data: bytes) -> tuple[dict, list[str]]:
    """Unpack and validate; returns (message, names of ignored unknown fields)."""
    if len(data) > MAX_MESSAGE_BYTES:
        raise ProtocolError(f"message of {len(data)} bytes > {MAX_MESSAGE_BYTES}")
    try:
        raw = msgpack.unpackb(data, raw=False, strict_map_key=True, use_list=True)
    except (msgpack.exceptions.ExtraData, msgpack.exceptions.FormatError,
            msgpack.exceptions.StackError, ValueError, TypeError) as exc:
        raise ProtocolError(f"not a msgpack message: {exc}") from exc
    return validate(raw)

"""The admin requests' fields: one table per service, checked before a
handler runs (``docs/limits.md``, "Admin requests").

A request is ``{"cmd": NAME, FIELD: value, ...}``. Every field a request
may carry is named here with its type and range; a field not named, a value
of the wrong type (a bool is not a number), a non-finite number or one out of
range is refused with an error that names the request, the field, what it
must be and what came. A handler then reads only checked values.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from telethermal.errors import TelethermalError

#: The wire's cap on a string (``proto/PROTOCOL.md``): names sent on the
#: admin socket are held to it as well.
MAX_NAME_BYTES = 256
#: Seeds of the simulated trials and operators (numpy's generators take any
#: non-negative integer; the services add 1 for the next trial).
MAX_SEED = 2 ** 32 - 1


class RequestError(TelethermalError, ValueError):
    """An admin request whose fields break the request's schema."""


@dataclass(frozen=True)
class Number:
    """A finite real in ``[lo, hi]`` (``lo`` excluded when ``open_lo``)."""
    lo: float
    hi: float
    open_lo: bool = False

    def check(self, value):
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise TypeError("a number")
        try:
            value = float(value)
        except OverflowError:
            value = math.inf
        low_ok = value > self.lo if self.open_lo else value >= self.lo
        if not (math.isfinite(value) and low_ok and value <= self.hi):
            raise ValueError(f"a number in {'(' if self.open_lo else '['}{self.lo:g}, "
                             f"{self.hi:g}]")
        return value


@dataclass(frozen=True)
class Integer:
    lo: int
    hi: int

    def check(self, value):
        if isinstance(value, bool) or not isinstance(value, int) or \
                not self.lo <= value <= self.hi:
            raise ValueError(f"an integer in [{self.lo}, {self.hi}]")
        return int(value)


@dataclass(frozen=True)
class Text:
    """A non-empty string of at most ``MAX_NAME_BYTES`` UTF-8 bytes, one of
    ``choices`` if given."""
    choices: tuple = ()

    def check(self, value):
        if not isinstance(value, str) or not value or \
                len(value.encode("utf-8", "replace")) > MAX_NAME_BYTES:
            raise ValueError(f"a non-empty string of at most {MAX_NAME_BYTES} bytes")
        if self.choices and value not in self.choices:
            raise ValueError(f"one of {list(self.choices)}")
        return value


@dataclass(frozen=True)
class Flag:
    def check(self, value):
        if not isinstance(value, bool):
            raise ValueError("true or false")
        return value


@dataclass(frozen=True)
class Table:
    """A map whose keys are ``fields`` (each optional; ``check_fields``
    checks them, naming the field inside the map)."""
    fields: tuple

    def check(self, value):
        if not isinstance(value, dict):
            raise ValueError(f"a map with the keys {[k for k, _ in self.fields]}")
        return value


def check_fields(schema: dict, values: dict, where: str) -> dict:
    """``values`` checked against ``schema`` (name -> kind; None values are
    absent); raises :class:`RequestError` naming the first bad field."""
    unknown = [k for k in values if k not in schema]
    if unknown:
        raise RequestError(f"unknown field {str(unknown[0])[:64]!r}{where}; fields: "
                           f"{', '.join(schema) or 'none'}")
    out = {}
    for name, kind in schema.items():
        value = values.get(name)
        if value is None:
            continue
        try:
            out[name] = kind.check(value)
            if isinstance(kind, Table):
                out[name] = check_fields(dict(kind.fields), value, f" of {name}{where}")
        except RequestError:
            raise
        except (TypeError, ValueError) as exc:
            shown = repr(value)
            shown = shown if len(shown) <= 64 else shown[:61] + "..."
            raise RequestError(f"{name}{where} must be {exc}, got {shown}") from None
    return out


#: The placed object, given with a touch for the figures against direct
#: contact (simulation): its temperature within a scene object's bounds.
TRUTH = Table((("material", Text()), ("object_true_c", Number(-20.0, 100.0))))

MASTER = {
    "touch": {"contact_s": Number(0.0, 60.0, open_lo=True), "seed": Integer(0, MAX_SEED),
              "source": Text(("trajectory", "setpoints")), "wait": Flag(), "truth": TRUTH},
    "lift": {},
    "report": {"trace": Flag()},
}

SLAVE = {
    "place": {"material": Text(), "seed": Integer(0, MAX_SEED), "object_id": Text()},
    "calibrate_thermometer": {"drift_k_per_reading": Number(-1.0, 1.0)},
    "forget": {"object_id": Text()},
    "report": {},
}

#: Served by every service (``AdminServer.handle``).
COMMON = {"status": {}, "stop": {}}


def check_request(request: dict, schema: dict) -> dict:
    """The request's fields (``cmd`` left out), checked against its entry in
    ``schema`` (``MASTER`` or ``SLAVE``; ``COMMON`` added)."""
    cmd = request["cmd"]
    fields = {**COMMON, **schema}.get(cmd)
    if fields is None:
        raise RequestError(f"unknown command {cmd[:64]!r}; commands: "
                           f"{', '.join([*COMMON, *schema])}")
    return check_fields(fields, {k: v for k, v in request.items() if k != "cmd"}, "")

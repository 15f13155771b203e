"""The display pad's sensor board over a serial line (pyserial).

:class:`SensorBoard` opens any pyserial URL (a tty path, ``loop://``,
``spy://``, ``socket://``...), reads the framed stream of
:mod:`telethermal.devices.frames` and converts it: heat flux from the
sensor's microvolts (1.26 uV per W/m^2 unless a calibration file says
otherwise), the pad temperature from the type-T thermocouple's microvolts
and its cold-junction temperature (NIST polynomials), the force.

It never raises on what the line brings: bad frames are counted and
skipped, a port that disappears is reopened every ``reopen_s`` while the
readings are missing (NaN, so the safety supervisor holds the pad in its
safe state), and a reading older than ``stale_s`` is missing too.
"""

from __future__ import annotations

import logging
import math
import select
import time
from dataclasses import dataclass, field
from pathlib import Path

import serial

from telethermal.devices.frames import (STATUS_FLUX, STATUS_FORCE, STATUS_HEATER, STATUS_IR,
                                        STATUS_PUMP, STATUS_TC, VERSIONS, FrameReader)
from telethermal.errors import ModelError, TelethermalError
from telethermal.physics.sensors import type_t_emf_mv, type_t_temp_c
from telethermal.tomltables import read_toml

log = logging.getLogger(__name__)

#: What an MLX90614-class infrared thermometer can report (datasheet: object
#: -70..382.2 C, sensor die -40..125 C); a reading outside is a fault, never a
#: temperature (``ir_out_of_range``).
IR_OBJECT_RANGE_C = (-70.0, 382.2)
IR_AMBIENT_RANGE_C = (-40.0, 125.0)


class DeviceError(TelethermalError, OSError):
    """A device that cannot be opened or used; names the device and the cause."""


@dataclass(frozen=True)
class Calibration:
    """Conversions of the board's raw readings (a TOML file, see
    ``deploy/hardware/calibration.toml``)."""

    flux_sensitivity_uv_per_w_m2: float = 1.26
    flux_offset_uv: float = 0.0
    thermocouple_type: str = "T"
    thermocouple_offset_uv: float = 0.0
    force_scale: float = 1.0
    force_offset_n: float = 0.0

    def __post_init__(self):
        if not (self.flux_sensitivity_uv_per_w_m2 > 0 and
                math.isfinite(self.flux_sensitivity_uv_per_w_m2)):
            raise DeviceError(f"calibration: flux sensitivity must be > 0 uV per W/m^2, got "
                              f"{self.flux_sensitivity_uv_per_w_m2}")
        if self.thermocouple_type != "T":
            raise DeviceError(f"calibration: only type-T thermocouples are supported, got "
                              f"{self.thermocouple_type!r}")

    @classmethod
    def load(cls, path: str | Path) -> "Calibration":
        path = Path(path)
        data = read_toml(path, "calibration file", DeviceError)
        keys = {("heat_flux", "sensitivity_uv_per_w_m2"): "flux_sensitivity_uv_per_w_m2",
                ("heat_flux", "offset_uv"): "flux_offset_uv",
                ("thermocouple", "type"): "thermocouple_type",
                ("thermocouple", "offset_uv"): "thermocouple_offset_uv",
                ("force", "scale"): "force_scale", ("force", "offset_n"): "force_offset_n"}
        values = {}
        for section, table in data.items():
            if not isinstance(table, dict):
                raise DeviceError(f"calibration {path}: [{section}] must be a table")
            for key, value in table.items():
                name = keys.get((section, key))
                if name is None:
                    raise DeviceError(f"calibration {path}: unknown key {section}.{key}; "
                                      f"known: {', '.join('.'.join(k) for k in keys)}")
                if name != "thermocouple_type" and (isinstance(value, bool) or
                                                    not isinstance(value, (int, float))):
                    raise DeviceError(f"calibration {path}: {section}.{key} must be a number, "
                                      f"got {value!r}")
                values[name] = value
        return cls(**values)

    def flux_w_m2(self, flux_uv: float) -> float:
        return (flux_uv - self.flux_offset_uv) / self.flux_sensitivity_uv_per_w_m2

    def flux_uv(self, flux_w_m2: float) -> float:
        return flux_w_m2 * self.flux_sensitivity_uv_per_w_m2 + self.flux_offset_uv

    def temp_c(self, tc_uv: float, cold_junction_c: float) -> float:
        """Cold-junction compensation: E(T) = E_measured + E(T_cj)."""
        emf_mv = (tc_uv - self.thermocouple_offset_uv) / 1000.0 + \
            type_t_emf_mv(float(cold_junction_c))
        return type_t_temp_c(float(emf_mv))

    def tc_uv(self, temp_c: float, cold_junction_c: float) -> float:
        return 1000.0 * (type_t_emf_mv(float(temp_c)) - type_t_emf_mv(float(cold_junction_c))) \
            + self.thermocouple_offset_uv

    def force_n(self, raw_n: float) -> float:
        return raw_n * self.force_scale + self.force_offset_n


@dataclass(frozen=True, slots=True)
class BoardReading:
    seq: int
    t_us: int
    received_s: float
    flux_w_m2: float          # nan where the board flagged the channel or it did not convert
    pad_temp_c: float
    force_n: float
    # Version-2 frames (the slave's board); NaN, False in version 1.
    ir_object_c: float = math.nan     # nan where flagged or out of range
    ir_ambient_c: float = math.nan
    pad_drive: float = math.nan
    heater_on: bool = False
    pump_on: bool = False
    version: int = 1


@dataclass
class SensorBoard:
    url: str
    calibration: Calibration = field(default_factory=Calibration)
    baudrate: int = 921_600
    reopen_s: float = 0.2
    stale_s: float = 0.05
    clock: object = time.monotonic
    #: Frame versions read (others skipped, counted in ``version``).
    versions: tuple = VERSIONS
    #: Keep every reading for :meth:`take_readings` (the slave reads every
    #: sample; the display only the newest).
    keep: bool = False

    def __post_init__(self):
        self.reader = FrameReader(self.versions)
        self.counters = {"port_lost": 0, "reopened": 0, "open_failed": 0, "conversion": 0,
                         "ir_flagged": 0, "ir_out_of_range": 0}
        self.latest: BoardReading | None = None
        self._kept: list[BoardReading] = []
        self._ser = None
        self._next_open = 0.0
        self._closed = False
        self._open(first=True)

    # ------------------------------------------------------------ the port
    def _open(self, first: bool = False) -> bool:
        try:
            self._ser = serial.serial_for_url(self.url, baudrate=self.baudrate, timeout=0)
        except (serial.SerialException, OSError, ValueError) as exc:
            if first:
                raise DeviceError(f"sensor board: cannot open {self.url!r}: {exc}") from exc
            self.counters["open_failed"] += 1
            self._next_open = self.clock() + self.reopen_s
            return False
        if not first:
            # Opening flushes the input: no gap is counted across the reopening.
            self.reader.restart_sequence()
            self.counters["reopened"] += 1
            log.warning("sensor board: %s is back", self.url)
        return True

    def _lost(self, exc: Exception) -> None:
        self.counters["port_lost"] += 1
        log.warning("sensor board: %s lost (%s); reopening every %.2f s", self.url, exc,
                    self.reopen_s)
        try:
            self._ser.close()
        except Exception:           # noqa: BLE001 - the port is gone already
            pass
        self._ser = None
        self.latest = None                 # nothing read before the loss is current
        self._next_open = self.clock() + self.reopen_s

    def close(self) -> None:
        self._closed = True
        if self._ser is not None:
            self._ser.close()
            self._ser = None

    # ------------------------------------------------------------ reading
    def _read_available(self) -> bytes:
        ser = self._ser
        n = ser.in_waiting
        return ser.read(n) if n else b""

    def _wait(self, timeout_s: float) -> None:
        try:
            fd = self._ser.fileno()
        except (AttributeError, OSError, serial.SerialException, NotImplementedError):
            time.sleep(min(timeout_s, 2e-4))
            return
        select.select([fd], [], [], timeout_s)

    def poll(self, wait_s: float = 0.0) -> BoardReading | None:
        """Read what has arrived (waiting up to ``wait_s`` for a new frame)
        and return the newest reading, or None if nothing new came."""
        if self._closed:
            raise DeviceError(f"sensor board {self.url!r} is closed")
        if self._ser is None:
            if self.clock() < self._next_open or not self._open():
                return None
        end = time.monotonic() + wait_s
        newest = None
        while True:
            try:
                frames = self.reader.feed(self._read_available())
            except (serial.SerialException, OSError) as exc:
                self._lost(exc)
                return newest
            for f in frames:
                newest = self._convert(f)
                if self.keep:
                    self._kept.append(newest)
            remaining = end - time.monotonic()
            if newest is not None or remaining <= 0:
                break
            self._wait(remaining)
        if newest is not None:
            self.latest = newest
        return newest

    def _convert(self, f) -> BoardReading:
        cal = self.calibration
        nan = math.nan
        flux = cal.flux_w_m2(f.flux_uv) if f.status & STATUS_FLUX else nan
        force = cal.force_n(f.force_n) if f.status & STATUS_FORCE else nan
        temp = nan
        if f.status & STATUS_TC:
            try:
                temp = cal.temp_c(f.tc_uv, f.cj_c)
            except ModelError as exc:
                self.counters["conversion"] += 1
                log.debug("sensor board: thermocouple reading out of range: %s", exc)
        values = [v if math.isfinite(v) else nan for v in (flux, temp, force)]
        if f.version == 1:
            return BoardReading(f.seq, f.t_us, self.clock(), *values)
        ir_obj, ir_amb = self._ir(f)
        return BoardReading(f.seq, f.t_us, self.clock(), *values, ir_obj, ir_amb,
                            f.pad_drive if math.isfinite(f.pad_drive) else nan,
                            bool(f.status & STATUS_HEATER), bool(f.status & STATUS_PUMP),
                            f.version)

    def _ir(self, f) -> tuple[float, float]:
        """The IR thermometer's object and ambient temperatures, or NaN where
        the board flagged the channel or a value is outside what the sensor
        can report (counted; the slave then refuses to identify)."""
        if f.type != 1:
            return math.nan, math.nan
        if not f.status & STATUS_IR:
            self.counters["ir_flagged"] += 1
            return math.nan, math.nan
        lo, hi = IR_OBJECT_RANGE_C
        alo, ahi = IR_AMBIENT_RANGE_C
        if not (lo <= f.ir_object_c <= hi and alo <= f.ir_ambient_c <= ahi):
            self.counters["ir_out_of_range"] += 1
            if self.counters["ir_out_of_range"] == 1:
                log.warning("sensor board: IR thermometer reading out of range (object %r C, "
                            "ambient %r C; the sensor reports object %g..%g, ambient %g..%g): "
                            "no object temperature (counted in 'ir_out_of_range')",
                            f.ir_object_c, f.ir_ambient_c, lo, hi, alo, ahi)
            return math.nan, math.nan
        return float(f.ir_object_c), float(f.ir_ambient_c)

    def take_readings(self) -> list[BoardReading]:
        """Every reading since the last call (``keep=True``), oldest first."""
        out, self._kept = self._kept, []
        return out

    def reading(self, wait_s: float = 0.0) -> tuple[float, float, float]:
        """(flux W/m^2, pad degC, force N) now: NaN where missing or stale."""
        self.poll(wait_s)
        r = self.latest
        if r is None or self.clock() - r.received_s > self.stale_s:
            return math.nan, math.nan, math.nan
        return r.flux_w_m2, r.pad_temp_c, r.force_n

    @property
    def all_counters(self) -> dict[str, int]:
        return {**self.reader.counters, **self.counters}

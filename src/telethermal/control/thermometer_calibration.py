"""Calibrate the object thermometer against the pad's own thermocouple.

A real lab does this before a session: it aims the infrared thermometer at
its own pad (or lays the contact probe on it), whose temperature it knows
from the pad's thermocouple, at two or more pad temperatures, and fits the
thermometer's reading as ``offset + gain * pad``. Inverting the fit removes
the thermometer's session bias and gain error; what remains is tied to the
pad's thermocouple, and since the pad is set and its gap measured by that
same thermocouple, the thermocouple's own bias cancels from the gap.

Each point waits for the pad to settle and then takes ``readings`` readings
of both instruments; a target that drifts during them (the pad's reading, or
the thermometer's difference from it, moving by more than ``max_drift_k``
and by more than four standard errors of the readings' own scatter: about
0.25 K for an MLX90614's 0.1 K averaged noise over 30 readings) is refused with a :class:`~telethermal.errors.CalibrationError` naming the
point: a drifting target would fold its drift into the bias, silently.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from telethermal.errors import CalibrationError
from telethermal.physics.sensors import Instruments, Thermocouple

#: Pad temperatures for calibration, relative to the room (K): they span
#: the objects' and fingers' range of the shipped scenes.
DEFAULT_OFFSETS_K = (-5.0, 5.0, 15.0)
#: The pad's own temperature loop holds its set point to about this, K
#: (see ``data.generate.PELTIER_SETPOINT_SD_K``).
PAD_HOLD_SD_K = 0.05


class CalibrationTarget(Protocol):
    """What calibration drives: the pad's set point, the pad's thermocouple
    and the object thermometer aimed at the pad."""

    def set_pad_c(self, temp_c: float) -> None: ...
    def read_pad_c(self) -> float: ...
    def read_thermometer_c(self) -> float: ...


@dataclass(frozen=True)
class ThermometerCalibration:
    """``thermometer = offset_k + gain * pad``, and its quality.

    ``residual_k``: RMS difference of the corrected thermometer from the pad
    at the calibration points (0 with two points: nothing left to check);
    ``offset_sd_k``: standard error of the correction at the points' mean
    temperature, from the scatter of the readings.
    """

    offset_k: float = 0.0
    gain: float = 1.0
    residual_k: float = math.nan
    offset_sd_k: float = math.nan
    points: tuple[tuple[float, float], ...] = field(default_factory=tuple)

    @property
    def calibrated(self) -> bool:
        return bool(self.points)

    def correct_c(self, reading_c):
        """The thermometer's reading with its bias and gain error removed, degC."""
        return (np.asarray(reading_c, dtype=np.float64) - self.offset_k) / self.gain

    def to_dict(self) -> dict:
        return {"calibrated": self.calibrated, "offset_k": self.offset_k, "gain": self.gain,
                "residual_k": None if math.isnan(self.residual_k) else self.residual_k,
                "offset_sd_k": None if math.isnan(self.offset_sd_k) else self.offset_sd_k,
                "points": [list(p) for p in self.points]}

    @classmethod
    def from_dict(cls, d: dict, where: str = "calibration") -> "ThermometerCalibration":
        """The calibration :meth:`to_dict` wrote (a slave's ``status`` gives
        it): ValueError naming ``where`` and the field for one that is
        missing or not a number."""
        if not isinstance(d, dict):
            raise ValueError(f"{where}: not a thermometer calibration (a "
                             f"{type(d).__name__}, not a table)")
        try:
            points = tuple((float(a), float(b)) for a, b in d.get("points") or ())
            nan = math.nan
            cal = cls(float(d["offset_k"]), float(d["gain"]),
                      nan if d.get("residual_k") is None else float(d["residual_k"]),
                      nan if d.get("offset_sd_k") is None else float(d["offset_sd_k"]), points)
        except (KeyError, TypeError, ValueError) as exc:
            raise ValueError(f"{where}: not a thermometer calibration "
                             f"({type(exc).__name__}: {exc})") from None
        if not (math.isfinite(cal.offset_k) and math.isfinite(cal.gain) and cal.gain > 0):
            raise ValueError(f"{where}: offset_k {cal.offset_k} and gain {cal.gain} must be "
                             "finite and the gain > 0")
        return cal


UNCALIBRATED = ThermometerCalibration()


def _drift_k(values: np.ndarray) -> tuple[float, float]:
    """Change over the dwell of a least-squares line through ``values``, and
    its standard error (from the scatter about the line)."""
    n = len(values)
    if n < 3:
        return 0.0, math.inf
    i = np.arange(n)
    slope, intercept = np.polyfit(i, values, 1)
    resid = values - (slope * i + intercept)
    se = np.sqrt(np.sum(resid ** 2) / (n - 2) / np.sum((i - i.mean()) ** 2))
    return float(slope * (n - 1)), float(se * (n - 1))


def calibrate_thermometer(target: CalibrationTarget, setpoints_c, readings: int = 30,
                          max_drift_k: float = 0.1, max_residual_k: float = 0.3,
                          gain_range=(0.8, 1.25)) -> ThermometerCalibration:
    """Fit the thermometer against the pad at each of ``setpoints_c``.

    Raises
    ------
    CalibrationError
        Fewer than two distinct set points, a point whose target drifted, a
        gain outside ``gain_range`` (the thermometer does not see the pad),
        or a residual above ``max_residual_k``.
    """
    setpoints = [float(s) for s in setpoints_c]
    if len(set(setpoints)) < 2:
        raise CalibrationError(f"calibration needs two or more distinct pad temperatures, "
                               f"got {setpoints}")
    pad_means, thermo_means, scatter = [], [], []
    for i, sp in enumerate(setpoints):
        target.set_pad_c(sp)
        pairs = [(target.read_pad_c(), target.read_thermometer_c()) for _ in range(readings)]
        pad, thermo = (np.array(v) for v in zip(*pairs))
        if not (np.all(np.isfinite(pad)) and np.all(np.isfinite(thermo))):
            raise CalibrationError(f"calibration point {i + 1} (pad set to {sp:.2f} C): a "
                                   "reading was not a number; nothing was changed")
        for what, values in (("pad's thermocouple", pad),
                             ("thermometer's difference from the pad", thermo - pad)):
            drift, se = _drift_k(values)
            # A drift counts when it is both larger than the limit and more
            # than four standard errors (not the readings' own noise).
            if abs(drift) > max_drift_k and abs(drift) > 4 * se:
                raise CalibrationError(
                    f"calibration point {i + 1} (pad set to {sp:.2f} C): the {what} moved "
                    f"{drift:+.3f} K over {readings} readings (limit {max_drift_k} K): the "
                    "target was not steady; nothing was changed")
        pad_means.append(pad.mean())
        thermo_means.append(thermo.mean())
        scatter.append(np.var(thermo - pad, ddof=1) / readings if readings > 1 else 0.0)
    x, y = np.array(pad_means), np.array(thermo_means)
    if np.ptp(x) < 1.0:
        raise CalibrationError(f"the pad reached only {np.ptp(x):.2f} K of span over set "
                               f"points {setpoints}; at least 1 K is needed")
    gain, offset = np.polyfit(x, y, 1)
    if not gain_range[0] <= gain <= gain_range[1]:
        raise CalibrationError(f"fitted gain {gain:.3f} is outside {gain_range}: the "
                               "thermometer does not see the pad (aim, emissivity, wiring)")
    corrected = (y - offset) / gain
    residual = float(np.sqrt(np.mean((corrected - x) ** 2))) if len(x) > 2 else 0.0
    if residual > max_residual_k:
        raise CalibrationError(f"calibration residual {residual:.3f} K exceeds "
                               f"{max_residual_k} K: the thermometer is not linear over "
                               f"{x.min():.1f}..{x.max():.1f} C, or the target moved")
    sd = float(np.sqrt(np.mean(scatter) / len(x)) / gain)
    return ThermometerCalibration(float(offset), float(gain), residual, sd,
                                  tuple((round(float(a), 4), round(float(b), 4))
                                        for a, b in zip(x, y)))


class SimulatedPadTarget:
    """The simulator's pad with its thermocouple and the session's object
    thermometer aimed at it. The pad's loop holds the thermocouple's
    *reading* at the set point (so the pad itself is off by minus the
    thermocouple's bias); ``drift_k_per_reading`` makes the pad wander
    during a dwell, ``thermometer_drift_k_per_reading`` the thermometer's
    own reading (warming up): hard cases calibration must refuse."""

    def __init__(self, instruments: Instruments, room_c: float, rng: np.random.Generator,
                 thermocouple_noise_uv: float = 1.0, drift_k_per_reading: float = 0.0,
                 thermometer_drift_k_per_reading: float = 0.0):
        self.instruments, self.rng = instruments, rng
        self.tc = Thermocouple(noise_uv_rms=thermocouple_noise_uv, cold_junction_c=room_c,
                               bias_k=instruments.pad_tc_bias_k)
        self.drift_k_per_reading = drift_k_per_reading
        self.thermometer_drift_k_per_reading = thermometer_drift_k_per_reading
        self._thermometer_offset_k = 0.0
        self.pad_true_c = room_c

    def set_pad_c(self, temp_c: float) -> None:
        hold = float(self.rng.normal(0.0, PAD_HOLD_SD_K))
        self.pad_true_c = temp_c - self.instruments.pad_tc_bias_k + hold

    def read_pad_c(self) -> float:
        self.pad_true_c += self.drift_k_per_reading
        return float(self.tc.read_c(np.array([self.pad_true_c]), self.rng)[0])

    def read_thermometer_c(self) -> float:
        self._thermometer_offset_k += self.thermometer_drift_k_per_reading
        return float(self.instruments.thermometer.read_c(np.array([self.pad_true_c]),
                                                         self.rng)[0]) + self._thermometer_offset_k


def calibrate_simulated(instruments: Instruments, room_c: float, rng: np.random.Generator,
                        thermocouple_noise_uv: float = 1.0, **kw) -> ThermometerCalibration:
    """Run :func:`calibrate_thermometer` on the simulated pad at the default
    set points (room -5, +5, +15 K)."""
    target = SimulatedPadTarget(instruments, room_c, rng, thermocouple_noise_uv,
                                kw.pop("drift_k_per_reading", 0.0))
    return calibrate_thermometer(target, [room_c + d for d in DEFAULT_OFFSETS_K], **kw)

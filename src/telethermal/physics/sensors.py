"""Sensor models: heat-flux film, type-T thermocouple, force sensor, object thermometer
(infrared or contact), and the per-session errors of a set of instruments.

Each model turns a true physical signal into what a data-acquisition system
would record: through the transducer's units (microvolts), noise and ADC
quantisation, and back to SI units the way a driver would convert it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from telethermal.errors import ModelError

# NIST ITS-90 type-T reference functions (Monograph 175): E in mV, T in degC.
_TYPE_T_EMF_NEG = (0.0, 3.8748106364e-2, 4.4194434347e-5, 1.1844323105e-7,
                   2.0032973554e-8, 9.0138019559e-10, 2.2651156593e-11,
                   3.6071154205e-13, 3.8493939883e-15, 2.8213521925e-17,
                   1.4251594779e-19, 4.8768662286e-22, 1.0795539270e-24,
                   1.3945027062e-27, 7.9795153927e-31)          # -270 .. 0 degC
_TYPE_T_EMF_POS = (0.0, 3.8748106364e-2, 3.3292227880e-5, 2.0618243404e-7,
                   -2.1882256846e-9, 1.0996880928e-11, -3.0815758772e-14,
                   4.5479135290e-17, -2.7512901673e-20)          # 0 .. 400 degC
_TYPE_T_INV_NEG = (0.0, 2.5949192e1, -2.1316967e-1, 7.9018692e-1, 4.2527777e-1,
                   1.3304473e-1, 2.0241446e-2, 1.2668171e-3)      # -5.603 .. 0 mV
_TYPE_T_INV_POS = (0.0, 2.592800e1, -7.602961e-1, 4.637791e-2, -2.165394e-3,
                   6.048144e-5, -7.293422e-7)                     # 0 .. 20.872 mV


def _two_piece(x, lo, hi, negative, positive, what):
    """Evaluate one of two NIST polynomials (split at 0) after a range check.
    A Python float in, a float out by Horner's rule (a device driver converts
    one reading per period: numpy's per-call overhead would be 30x the work);
    arrays through numpy."""
    if isinstance(x, float):
        if not lo <= x <= hi:
            raise ModelError(f"type-T {what} range is {lo}..{hi}, got {x}")
        acc = 0.0
        for c in reversed(negative if x < 0 else positive):
            acc = acc * x + c
        return acc
    x = np.asarray(x, dtype=np.float64)
    if np.any((x < lo) | (x > hi)):
        raise ModelError(f"type-T {what} range is {lo}..{hi}, got {x.min()}..{x.max()}")
    poly = np.polynomial.polynomial.polyval
    return np.where(x < 0, poly(x, negative), poly(x, positive))


def type_t_emf_mv(temp_c):
    """Type-T thermocouple EMF (reference junction at 0 degC), mV, -270..400 degC."""
    return _two_piece(temp_c, -270.0, 400.0, _TYPE_T_EMF_NEG, _TYPE_T_EMF_POS, "degC")


def type_t_temp_c(emf_mv):
    """Inverse of :func:`type_t_emf_mv` (NIST inverse polynomials, +-0.04 degC)."""
    return _two_piece(emf_mv, -5.603, 20.872, _TYPE_T_INV_NEG, _TYPE_T_INV_POS, "EMF (mV)")


def quantise(values, lsb):
    """Round to the nearest multiple of ``lsb`` (an ideal mid-tread ADC)."""
    return np.round(np.asarray(values) / lsb) * lsb


@dataclass(frozen=True, slots=True)
class HeatFluxSensor:
    """A thin-film heat-flux sensor read through an amplifier and an ADC.

    The first-order lag (``lag_s``) is applied by the physics solver itself,
    exactly (see ``LayeredContact.solve(sensor_lag_s=...)``); this class adds
    what follows the film: microvolts, noise, quantisation, conversion back.
    """

    sensitivity_uv_per_w_m2: float = 1.26
    lag_s: float = 0.15
    noise_uv_rms: float = 0.5
    adc_lsb_uv: float = 0.3
    gain: float = 1.0            # true over nominal sensitivity (this instrument)

    def read_w_m2(self, flux_w_m2, rng: np.random.Generator):
        """Flux as recorded, W/m^2, from the (already lagged) film flux,
        converted with the nominal sensitivity."""
        volts_uv = np.asarray(flux_w_m2) * self.sensitivity_uv_per_w_m2 * self.gain
        volts_uv = volts_uv + rng.normal(0.0, self.noise_uv_rms, volts_uv.shape)
        return quantise(volts_uv, self.adc_lsb_uv) / self.sensitivity_uv_per_w_m2


@dataclass(frozen=True, slots=True)
class Thermocouple:
    """A type-T thermocouple with cold-junction compensation."""

    noise_uv_rms: float = 1.0
    adc_lsb_uv: float = 0.5
    cold_junction_c: float = 25.0
    bias_k: float = 0.0          # this thermocouple's deviation from ITS-90

    def read_c(self, temp_c, rng: np.random.Generator):
        """Temperature as recorded, degC."""
        temp_c = np.asarray(temp_c, dtype=np.float64) + self.bias_k
        emf_uv = 1e3 * (type_t_emf_mv(temp_c) - type_t_emf_mv(self.cold_junction_c))
        emf_uv = quantise(emf_uv + rng.normal(0.0, self.noise_uv_rms, emf_uv.shape),
                          self.adc_lsb_uv)
        return type_t_temp_c(emf_uv / 1e3 + type_t_emf_mv(self.cold_junction_c))


@dataclass(frozen=True, slots=True)
class ForceSensor:
    """A force or pressure sensor: zero before contact, then a first-order
    rise to the pressing force."""

    rise_s: float = 0.03
    noise_n_rms: float = 0.05

    def read_n(self, t_s, force_n: float, rng: np.random.Generator):
        t = np.asarray(t_s, dtype=np.float64)
        true = np.where(t > 0, force_n * -np.expm1(-np.clip(t, 0, None) / self.rise_s), 0.0)
        return true + rng.normal(0.0, self.noise_n_rms, t.shape)


@dataclass(frozen=True, slots=True)
class ObjectThermometer:
    """The instrument that measures an object's (or a finger's) temperature
    before contact: an infrared thermometer (``kind="ir"``) or a contact
    probe (``kind="contact"``, a thermocouple laid on the object).

    A reading is ``T + bias_k + gain_error (T - reference_c) + noise``,
    averaged over ``readings`` readings and rounded to ``resolution_k``.
    ``bias_k`` and ``gain_error`` belong to this instrument in this session
    (drawn once by :func:`draw_instruments`); the noise is per reading.

    Parameters
    ----------
    bias_k : float
        Offset of this instrument in this session, K.
    gain_error : float
        Relative slope error about ``reference_c`` (emissivity setting,
        calibration), dimensionless.
    noise_k : float
        Standard deviation of one reading, K.
    resolution_k : float
        Output resolution, K (0 for none).
    readings : int
        Readings averaged into one measurement (the target is static).
    """

    kind: str = "ir"
    bias_k: float = 0.0
    gain_error: float = 0.0
    noise_k: float = 0.2
    resolution_k: float = 0.02
    readings: int = 4
    reference_c: float = 25.0

    def read_c(self, temp_c, rng: np.random.Generator):
        """One (averaged) measurement of each element of ``temp_c``, degC."""
        temp_c = np.asarray(temp_c, dtype=np.float64)
        shape = temp_c.shape + (max(1, self.readings),)
        true = temp_c + self.bias_k + self.gain_error * (temp_c - self.reference_c)
        each = true[..., None] + rng.normal(0.0, self.noise_k, shape)
        if self.resolution_k > 0:
            each = quantise(each, self.resolution_k)
        return each.mean(axis=-1)


@dataclass(frozen=True, slots=True)
class Instruments:
    """The errors of one set of instruments in one session.

    ``pad_tc_bias_k``: the pad's thermocouple (fixed for the instrument);
    the pad's own temperature loop holds the *reading* at its set point, so
    the pad's true temperature is off by minus this bias.
    ``flux_gain``: the heat-flux sensor's true sensitivity over the nominal
    one used to convert it (fixed for the instrument; its calibration
    certificate's uncertainty). ``thermometer``: the object thermometer with
    this session's bias and gain error.
    """

    thermometer: ObjectThermometer
    pad_tc_bias_k: float = 0.0
    flux_gain: float = 1.0

    def describe(self) -> dict:
        return {"thermometer": self.thermometer.kind,
                "thermometer_bias_k": round(self.thermometer.bias_k, 4),
                "thermometer_gain_error": round(self.thermometer.gain_error, 5),
                "pad_tc_bias_k": round(self.pad_tc_bias_k, 4),
                "flux_gain": round(self.flux_gain, 5)}


#: The display thermocouple's calibration: 30 readings of 1 uV (0.025 K) of
#: noise each, averaged.
DISPLAY_TC_CALIBRATION_SD_K = 0.025 / 30 ** 0.5


def draw_instruments(sensors, session_rng: np.random.Generator,
                     role: str = "slave") -> Instruments:
    """The instruments of a scene (a :class:`~telethermal.physics.scene.SensorSpec`)
    in one session.

    Figures given as limits (a datasheet's accuracy) are drawn uniformly
    within them (JCGM 100:2008, 4.3.7: a rectangular distribution for a
    bound with nothing more known). What is fixed for an instrument (the
    thermocouple's and flux sensor's errors) comes from the scene's
    ``instrument_seed``, so every session of a scene has the same
    instruments; the object thermometer's bias and gain error depend on the
    session (ambient, warm-up, aim) and come from ``session_rng``. ``role``:
    the slave's and the master's pads are different instruments.
    """
    fixed = np.random.default_rng((int(sensors.instrument_seed), 0x5E550,
                                   0 if role == "slave" else 1))   # its own stream
    tc_bias = fixed.uniform(-1, 1) * sensors.pad_tc_bias_limit_k
    flux_gain = 1.0 + fixed.uniform(-1, 1) * sensors.flux_sensitivity_limit_rel
    if role != "slave":
        # The display's thermocouple, calibrated against the reference probe
        # (held with the pad at a settled idle, 30 readings of 0.025 K noise):
        # what is left is the probe's own error and the readings' mean.
        probe = np.random.default_rng((int(sensors.instrument_seed), 0x9B0BE))
        tc_bias = probe.uniform(-1, 1) * sensors.display_tc_reference_limit_k + \
            fixed.normal(0.0, DISPLAY_TC_CALIBRATION_SD_K)
    bias = session_rng.uniform(-1, 1) * sensors.object_bias_limit_k
    gain = session_rng.uniform(-1, 1) * sensors.object_gain_limit
    thermometer = ObjectThermometer(sensors.object_thermometer, bias, gain,
                                    sensors.object_noise_k, sensors.object_resolution_k,
                                    int(sensors.object_readings))
    return Instruments(thermometer, tc_bias, flux_gain)

"""A scene's ``[sensors]`` table: every sensor's error, as configured
(``physics/scene.py`` reads it; docs/scenes.md lists its keys)."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

from telethermal.physics.thermoelectric import DEFAULT_JUNCTION_SENSOR


@dataclass(frozen=True)
class SensorSpec:
    """Every sensor's error, each figure from a datasheet or paper (the table
    in docs/concepts/databases.md, "Sensor errors"). ``*_limit_*`` figures are bounds drawn
    uniformly per instrument or session (:func:`~telethermal.physics.sensors.draw_instruments`)."""

    flux_lag_s: float = 0.15
    flux_noise_uv: float = 0.5
    #: The flux thermopile's nominal sensitivity (its calibration
    #: certificate's; the first paper's Captec sensor, sec. 2) and the ADC
    #: step its microvolts are read at: with ``flux_noise_uv``, the flux
    #: noise the product's fits expect (:meth:`flux_noise_w_m2`).
    flux_sensitivity_uv_per_w_m2: float = 1.26
    flux_adc_lsb_uv: float = 0.3
    flux_sensitivity_limit_rel: float = 0.03
    onset_jitter_s: float = 0.005
    thermocouple_noise_uv: float = 1.0
    pad_tc_bias_limit_k: float = 0.5
    #: The display's (master's) pad thermocouple is calibrated before a
    #: session against a reference probe of this accuracy (IEC 60751 class
    #: AA Pt100: +-(0.1 + 0.0017 |t|) K, 0.14 K at 25 C); its bias is then
    #: the probe's error (one probe, fixed per instrument) plus the
    #: calibration's averaging noise, instead of ``pad_tc_bias_limit_k``.
    display_tc_reference_limit_k: float = 0.1425
    object_thermometer: str = "ir"
    object_bias_limit_k: float = 0.5
    object_gain_limit: float = 0.0
    object_noise_k: float = 0.2
    object_resolution_k: float = 0.02
    object_readings: float = 4
    instrument_seed: float = 1
    #: The display's junction sensor (a part of physics/modules.toml's
    #: ``[junction_sensors]``) and its lag as mounted, s (None: the part's
    #: stated one): what the junction loop is designed for, and what the
    #: simulated pad's sensor lags (times ``[as_built.display] junction_lag_s``).
    junction_sensor: str = DEFAULT_JUNCTION_SENSOR
    junction_lag_s: float | None = None

    def flux_noise_w_m2(self) -> float:
        """The flux reading's noise as configured, W/m^2 rms: the
        thermopile's noise and the ADC's quantisation (``lsb / sqrt 12``)
        over the nominal sensitivity."""
        return math.hypot(self.flux_noise_uv, self.flux_adc_lsb_uv / math.sqrt(12.0)) \
            / self.flux_sensitivity_uv_per_w_m2

    def flux_sensor(self, lag_s: float | None = None, gain: float = 1.0):
        """The flux sensor these figures describe
        (:class:`~telethermal.physics.sensors.HeatFluxSensor`): what the
        simulator reads its pads' flux through (its lag ``lag_s``, None: the
        configured one; ``gain``: this instrument's true over nominal)."""
        from telethermal.physics.sensors import HeatFluxSensor
        return HeatFluxSensor(sensitivity_uv_per_w_m2=self.flux_sensitivity_uv_per_w_m2,
                              lag_s=self.flux_lag_s if lag_s is None else lag_s,
                              noise_uv_rms=self.flux_noise_uv, adc_lsb_uv=self.flux_adc_lsb_uv,
                              gain=gain)

    def junction_sensor_spec(self):
        """The display's junction sensor as configured
        (:class:`~telethermal.physics.thermoelectric.JunctionSensorSpec`)."""
        from telethermal.physics.thermoelectric import get_junction_sensor
        spec = get_junction_sensor(self.junction_sensor)
        return spec if self.junction_lag_s is None else dataclasses.replace(
            spec, tau_s=self.junction_lag_s)

import numpy as np
import pytest

from telethermal.errors import ModelError
from telethermal.physics.scene import load_scene
from telethermal.physics.sensors import (DISPLAY_TC_CALIBRATION_SD_K, ForceSensor, HeatFluxSensor,
                                         ObjectThermometer, draw_instruments,
                                         Thermocouple, quantise, type_t_emf_mv, type_t_temp_c)


@pytest.mark.parametrize("temp_c,emf_mv", [(100.0, 4.279), (-100.0, -3.379), (300.0, 14.862),
                                           (25.0, 0.992)])
def test_type_t_matches_nist_table(temp_c, emf_mv):
    # NIST Monograph 175 type-T table values, given to 1 uV.
    assert type_t_emf_mv(temp_c) == pytest.approx(emf_mv, abs=1e-3)


def test_type_t_inverse_round_trips_within_nist_accuracy():
    temps = np.linspace(-200.0, 400.0, 601)
    # NIST quotes the inverse polynomials to +-0.04 degC (negative range) and +-0.03 degC.
    np.testing.assert_allclose(type_t_temp_c(type_t_emf_mv(temps)), temps, atol=0.04)


def test_type_t_refuses_out_of_range():
    with pytest.raises(ModelError):
        type_t_emf_mv(500.0)
    with pytest.raises(ModelError):
        type_t_temp_c(30.0)


def test_thermocouple_reads_true_temperature_on_average(rng):
    reading = Thermocouple(noise_uv_rms=1.0).read_c(np.full(20000, 31.0), rng)
    # 1 uV is ~0.025 K of type T near 30 degC: the mean of 20000 is within 1e-3 K
    # (plus the 0.03 K inverse-polynomial accuracy).
    assert reading.mean() == pytest.approx(31.0, abs=0.035)


def test_heat_flux_sensor_converts_through_microvolts(rng):
    sensor = HeatFluxSensor(noise_uv_rms=0.0, adc_lsb_uv=0.3)
    out = sensor.read_w_m2(np.array([0.0, 1000.0]), rng)
    lsb = 0.3 / 1.26
    assert out[0] == 0.0
    assert abs(out[1] - 1000.0) <= lsb / 2 + 1e-9


def test_quantise_is_a_mid_tread_adc():
    np.testing.assert_allclose(quantise(np.array([0.49, 0.51, -0.51]), 1.0), [0.0, 1.0, -1.0])


def test_force_sensor_is_zero_before_contact_and_rises_to_the_force(rng):
    t = np.array([-0.1, 0.0, 1.0])
    f = ForceSensor(noise_n_rms=0.0).read_n(t, 10.0, rng)
    assert f[0] == 0.0 and f[1] == 0.0 and f[2] == pytest.approx(10.0, rel=1e-9)


def test_thermometer_error_is_its_bias_plus_averaged_noise(rng):
    # Mean error = the session bias; spread = per-reading noise / sqrt(readings);
    # 20000 measurements: the mean to 4 standard errors, the spread to 5 %.
    thermo = ObjectThermometer(bias_k=0.5, noise_k=0.2, resolution_k=0.0, readings=4)
    err = thermo.read_c(np.full(20000, 30.0), rng) - 30.0
    assert err.mean() == pytest.approx(0.5, abs=4 * 0.1 / np.sqrt(20000))
    assert err.std() == pytest.approx(0.1, rel=0.05)


def test_thermometer_gain_error_grows_with_distance_from_reference(rng):
    thermo = ObjectThermometer(gain_error=0.02, noise_k=0.0, resolution_k=0.0, reference_c=25.0)
    np.testing.assert_allclose(thermo.read_c(np.array([25.0, 35.0, 15.0]), rng),
                               [25.0, 35.2, 14.8], atol=1e-12)


def test_thermometer_resolution_rounds_each_reading(rng):
    thermo = ObjectThermometer(noise_k=0.0, resolution_k=0.02, readings=1)
    assert thermo.read_c(np.array([30.013]), rng)[0] == pytest.approx(30.02, abs=1e-12)


def test_the_scalar_nist_path_equals_the_array_path():
    temps = np.linspace(-200.0, 390.0, 97)
    emf = type_t_emf_mv(temps)
    np.testing.assert_allclose([type_t_emf_mv(float(t)) for t in temps], emf, rtol=1e-12,
                               atol=1e-12)
    np.testing.assert_allclose([type_t_temp_c(float(e)) for e in emf], type_t_temp_c(emf),
                               rtol=1e-12, atol=1e-12)
    with pytest.raises(ModelError, match="range"):
        type_t_temp_c(25.0)


def test_display_thermocouple_is_calibrated_against_the_probe():
    """Master: the probe's error (within its class AA bound) plus the
    calibration's noise; the slave's thermocouple keeps its own bound."""
    for seed in range(40):
        spec = load_scene("fingertip-7").sensors
        spec = spec.__class__(**{**vars(spec), "instrument_seed": seed})
        master = draw_instruments(spec, np.random.default_rng(seed), "master")
        slave = draw_instruments(spec, np.random.default_rng(seed), "slave")
        assert abs(master.pad_tc_bias_k) <= (spec.display_tc_reference_limit_k
                                             + 5 * DISPLAY_TC_CALIBRATION_SD_K)
        assert abs(slave.pad_tc_bias_k) <= spec.pad_tc_bias_limit_k

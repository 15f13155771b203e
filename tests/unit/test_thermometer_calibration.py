"""Calibrating the object thermometer against the pad's thermocouple: it
removes the session's bias and gain error, refuses a drifting target, and
makes the measured gap independent of both instruments' biases."""

import dataclasses

import numpy as np
import pytest

from telethermal.control.thermometer_calibration import (UNCALIBRATED, SimulatedPadTarget,
                                                         ThermometerCalibration,
                                                         calibrate_simulated,
                                                         calibrate_thermometer)
from telethermal.data.generate import SensorSession, pad_database, sensor_session
from telethermal.errors import CalibrationError
from telethermal.physics.scene import load_scene
from telethermal.physics.sensors import Instruments, ObjectThermometer

ROOM_C = 24.0


def _instruments(bias_k, gain_error=0.0, tc_bias_k=0.0, noise_k=0.2):
    return Instruments(ObjectThermometer("ir", bias_k, gain_error, noise_k, 0.02, 4), tc_bias_k)


@pytest.mark.parametrize("bias_k", [0.5, -0.5])        # the MLX90614 datasheet's limit, both ways
def test_calibration_removes_a_bias_at_the_datasheet_limit(bias_k):
    rng = np.random.default_rng(3)
    inst = _instruments(bias_k, gain_error=0.01)
    cal = calibrate_simulated(inst, ROOM_C, rng)
    truth = np.linspace(14.0, 44.0, 7)
    corrected = cal.correct_c(ObjectThermometer("ir", bias_k, 0.01, 0.0, 0.0, 1).read_c(truth, rng))
    # What remains is the standard error of the fit: 3 points x 30 readings of
    # 0.1 K noise each (averaged readings) plus the pad's 0.05 K hold: < 0.05 K.
    np.testing.assert_allclose(corrected, truth, atol=0.05)
    assert cal.calibrated and cal.residual_k < 0.1 and cal.offset_sd_k < 0.05


def test_calibration_ties_the_thermometer_to_the_pad_thermocouple():
    # The thermocouple's own bias reappears in the corrected reading, so the gap
    # (thermocouple pad minus corrected object) carries neither bias.
    rng = np.random.default_rng(4)
    inst = _instruments(0.4, tc_bias_k=-0.3, noise_k=0.0)
    cal = calibrate_simulated(inst, ROOM_C, rng)
    corrected = cal.correct_c(inst.thermometer.read_c(np.array([30.0]), rng))[0]
    assert corrected == pytest.approx(30.0 - 0.3, abs=0.06)


def test_a_drifting_target_is_refused_naming_the_point():
    rng = np.random.default_rng(5)
    target = SimulatedPadTarget(_instruments(0.3), ROOM_C, rng, drift_k_per_reading=0.02)
    with pytest.raises(CalibrationError, match=r"point 1 .*moved .*not steady"):
        calibrate_thermometer(target, [19.0, 29.0, 39.0])


def test_a_thermometer_warming_through_a_point_is_refused():
    # Only the thermometer moves (0.5 K over the 30 readings of a point), so
    # the pad's thermocouple cannot see it; left in, it would shift the offset
    # by ~0.25 K. Four standard errors of the 0.1 K noise are ~0.25 K: refused.
    rng = np.random.default_rng(8)
    target = SimulatedPadTarget(_instruments(0.3), ROOM_C, rng,
                                thermometer_drift_k_per_reading=0.5 / 29)
    with pytest.raises(CalibrationError, match=r"thermometer's difference .*not steady"):
        calibrate_thermometer(target, [19.0, 29.0, 39.0])


def test_a_drift_within_the_noise_is_not_refused():
    rng = np.random.default_rng(6)
    cal = calibrate_thermometer(SimulatedPadTarget(_instruments(0.3), ROOM_C, rng,
                                                   drift_k_per_reading=1e-4),
                                [19.0, 29.0, 39.0])
    assert cal.calibrated


@pytest.mark.parametrize("setpoints,match", [([30.0], "two or more"),
                                             ([30.0, 30.0], "two or more"),
                                             ([30.0, 30.5], "span")])
def test_too_few_or_too_close_points_are_refused(setpoints, match):
    target = SimulatedPadTarget(_instruments(0.0), ROOM_C, np.random.default_rng(0))
    with pytest.raises(CalibrationError, match=match):
        calibrate_thermometer(target, setpoints)


def test_a_thermometer_that_does_not_see_the_pad_is_refused():
    class Blind(SimulatedPadTarget):
        def read_thermometer_c(self):
            return ROOM_C + float(self.rng.normal(0, 0.05))     # reads the wall behind
    with pytest.raises(CalibrationError, match="does not see the pad"):
        calibrate_thermometer(Blind(_instruments(0.0), ROOM_C, np.random.default_rng(0)),
                              [19.0, 29.0, 39.0])


def test_uncalibrated_is_the_identity():
    np.testing.assert_array_equal(UNCALIBRATED.correct_c(np.array([21.5, 30.0])), [21.5, 30.0])
    assert not UNCALIBRATED.calibrated


def test_a_calibration_reads_back_from_its_dict_exactly():
    # A slave's status carries its calibration as to_dict wrote it (through
    # msgpack or JSON: floats exact); the simulator reads it back to read
    # the pad through the same correction (sim.inprocess.service_sensors).
    import json
    cal = calibrate_simulated(_instruments(0.43, 0.012), ROOM_C, np.random.default_rng(3))
    back = ThermometerCalibration.from_dict(json.loads(json.dumps(cal.to_dict())))
    assert back == cal
    assert ThermometerCalibration.from_dict(UNCALIBRATED.to_dict()).correct_c(21.5) == 21.5


@pytest.mark.parametrize("d, match", [
    ({"gain": 1.0}, "offset_k"),
    ({"offset_k": "x", "gain": 1.0}, "could not convert"),
    ({"offset_k": 0.1, "gain": 0.0}, "gain > 0"),
    ({"offset_k": float("nan"), "gain": 1.0}, "finite"),
    ({"offset_k": 0.1, "gain": 1.0, "points": [[1.0]]}, "not a thermometer calibration"),
    (None, "not a table"),
])
def test_a_calibration_dict_that_is_not_one_is_refused_naming_where(d, match):
    with pytest.raises(ValueError, match=match) as err:
        ThermometerCalibration.from_dict(d, "the slave's status")
    assert "the slave's status" in str(err.value)


@pytest.mark.parametrize("bias_k", [0.5, -0.5])
def test_measured_gap_error_with_and_without_calibration(bias_k):
    # Uncalibrated, the measured gap (thermocouple pad minus thermometer object)
    # is off by the thermocouple's bias minus the thermometer's (0.2 K -+ 0.5 K);
    # calibrated, by the thermometer's noise (0.1 K per averaged measurement)
    # and a systematic part under 0.1 K: the fit's standard error (~0.02 K)
    # and NIST's inverse type-T polynomial (+-0.04 K, tested above).
    scene = load_scene("fingertip-7")
    inst = _instruments(bias_k, tc_bias_k=0.2)
    for calibrate, limit in ((False, None), (True, 0.1)):
        rng = np.random.default_rng(7)
        session = sensor_session(scene, rng, calibrate, inst)
        trials = pad_database(scene, rng, session)
        err = np.array([t.gap_k - (float(t.extra["T_pad_true_C"]) -
                                   float(t.extra["T_object_true_C"])) for t in trials])
        if limit is None:
            assert err.mean() == pytest.approx(0.2 - bias_k, abs=0.05)
        else:
            assert abs(err.mean()) < 0.1 and err.std() < 1.5 * limit


def test_contact_probe_scenes_carry_no_infrared_model():
    for name in ("gripper-case-I-pro", "gripper-case-II", "gripper-case-V"):
        assert load_scene(name).sensors.object_thermometer == "contact"
    assert load_scene("fingertip-7").sensors.object_thermometer == "ir"


def test_session_records_true_errors_and_calibration():
    scene = load_scene("fingertip-7")
    session = sensor_session(scene, np.random.default_rng(1))
    d = session.describe()
    assert abs(d["instruments"]["thermometer_bias_k"]) <= scene.sensors.object_bias_limit_k
    assert d["calibration"]["calibrated"] and len(d["calibration"]["points"]) == 3
    assert isinstance(session, SensorSession)


def test_instrument_errors_are_fixed_across_sessions_of_a_scene():
    scene = load_scene("fingertip-7")
    a = sensor_session(scene, np.random.default_rng(1)).instruments
    b = sensor_session(scene, np.random.default_rng(2)).instruments
    assert a.pad_tc_bias_k == b.pad_tc_bias_k and a.flux_gain == b.flux_gain
    assert a.thermometer.bias_k != b.thermometer.bias_k          # the session's own
    other = dataclasses.replace(scene, sensors=dataclasses.replace(scene.sensors,
                                                                   instrument_seed=9))
    assert sensor_session(other, np.random.default_rng(1)).instruments.flux_gain != a.flux_gain

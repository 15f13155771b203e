"""``telethermal calibrate display --devices hardware`` (issue 44's display
half on a lab's master): the routine opens the sensor board and the Peltier
driver by URL and bus, as the master service does, asks the lab to press
the reference block and then to lift it, and fits the display's figures.

The lab's display here is the emulated board (on a pty) and Peltier driver
(on a virtual CAN bus) around the simulated bench (sim/display_rig.py)
built off its datasheet, advanced to each deadline the routine's clock
sleeps until: the routine's own pacing, in lockstep, so nothing here
depends on this machine's speed."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from telethermal.control import display_calibration as routine
from telethermal.devices.emulators import PeltierEmulator, SensorBoardEmulator
from telethermal.errors import CalibrationError
from telethermal.sim.display_rig import simulated_bench
from telethermal.teleop.display_hardware import LIFT_BLOCK, calibrate_hardware

from test_display_calibration import BUILT, _scene

_buses = itertools.count()


class LockstepRig:
    """The lab's display on its bench, emulated, and the clock the routine
    paces itself by: each deadline slept until, the plant is driven up to
    it at the current the board drives, and the board sends its frame."""

    def __init__(self, tmp_path, scene, block="plexiglass", seed=0, touch=None):
        self.touch = touch or simulated_bench(scene, block, seed, routine.RATE_HZ)
        self.touch.contact_s = math.inf         # on the face until the lab lifts it
        self.t = 0.0
        self._last: float | None = None
        self.force_n = 0.0
        self.board = SensorBoardEmulator(tmp_path / "board", seed=seed)
        self.bus = f"virtual:calibrate-hardware-{next(_buses)}"
        self.peltier = PeltierEmulator(self.bus, lambda a: None, clock=self.now,
                                       state=self.touch.module_state)
        self.frames_missed = 0          # a test may drop the board's frames: the next n,
        self.silent = (math.inf, math.inf)  # or those in a window of its time (s)
        self.interrupt_at = math.inf    # Ctrl-C pressed at this time
        self.lifted_at: float | None = None

    def now(self) -> float:
        return self.t

    def sleep_until(self, deadline_s: float) -> None:
        if deadline_s >= self.interrupt_at:
            raise KeyboardInterrupt
        if self._last is not None and deadline_s > self._last:
            self.peltier.poll()                 # the period's command reaches the board
            step = routine.RoutineStep(self._last, self.peltier.current_a)
            self.touch.actuate(self._last, step, deadline_s - self._last, self.force_n)
        self.t = max(self.t, deadline_s)
        self._last = self.t
        s = self.touch.sense(self.t)
        self.force_n = s.force_n
        if self.frames_missed:
            self.frames_missed -= 1
        elif not self.silent[0] <= self.t < self.silent[1]:
            self.board.send(self.t, s.flux_w_m2, s.pad_temp_c, s.force_n)
        self.peltier.poll()

    def prompt(self, text: str) -> None:
        """The lab: the block is on the face from the start; lifted when asked."""
        if text == LIFT_BLOCK:
            self.touch.contact_s = self.t
            self.lifted_at = self.t

    def close(self) -> None:
        self.peltier.close()
        self.board.close()


@pytest.fixture
def rig(tmp_path):
    r = LockstepRig(tmp_path, _scene(as_built=BUILT))
    yield r
    r.close()


def run(rig, wait_s=0.05, **kw):
    """The routine on the rig; ``wait_s`` for each frame (in lockstep the
    rig's frame is on the line before the routine reads: the wait is its
    delivery's, and spent whole on a frame the rig dropped)."""
    return calibrate_hardware(_scene(as_built=BUILT), rig.board.path, rig.bus,
                              prompt=rig.prompt, clock=rig, wait_s=wait_s, **kw)


def test_a_labs_display_off_its_datasheet_is_found_through_its_drivers(rig):
    """The display as built (flux lag x1.3, junction lag x1.5, gain x1.05)
    read through the board and the driver: each true figure in its 95 %
    interval, the residuals at the sensors' noise, the file marked as a
    hardware bench; the driver disabled at the end. The junction reading
    comes in the driver's status, answered to the period's command and
    read the period after: its lag is the sensor's plus that period (the
    sensor's alone lies outside the interval: 0.150 against [0.1516,
    0.1522] s)."""
    cal = run(rig)
    scene = _scene(as_built=BUILT)
    truth = {"flux_lag_s": 1.3 * scene.sensors.flux_lag_s,
             "junction_lag_s": 1.5 * scene.sensors.junction_sensor_spec().tau_s
             + 1 / routine.RATE_HZ,
             "flux_gain": 1.05}
    for name, true in truth.items():
        lo, hi = getattr(cal, name + "_lo"), getattr(cal, name + "_hi")
        assert lo <= true <= hi, (name, lo, getattr(cal, name), hi, true)
    assert cal.bench == "hardware" and rig.lifted_at is not None
    assert cal.chi2_per_dof_air < routine.CHI2_MAX and cal.chi2_per_dof_block < routine.CHI2_MAX
    rig.peltier.poll()
    assert not rig.peltier.enabled and rig.peltier.current_a == 0.0


def test_a_block_never_lifted_is_refused_by_its_force(rig):
    rig.prompt = lambda text: None          # the lab did not lift it
    with pytest.raises(CalibrationError, match="face free.*was the block lifted"):
        run(rig)


def test_an_interrupt_during_the_steps_leaves_the_driver_disabled(rig):
    """Ctrl-C 3 s into the block part, the driver at +-1 A: disabled, 0 A."""
    rig.interrupt_at = 3.0
    with pytest.raises(KeyboardInterrupt):
        run(rig)
    assert rig.t == pytest.approx(3.0 - 1 / routine.RATE_HZ) and rig.peltier.current_a != 0.0
    rig.peltier.poll()
    assert not rig.peltier.enabled and rig.peltier.current_a == 0.0


def test_a_board_silent_mid_part_stops_the_steps_and_the_driver(rig):
    """The board's frames stop 2 s into the block part (the driver still
    stepping): after BLIND_MAX periods without a new frame the routine
    stops, the driver disabled. The board's own reading would have held
    its last frame for 50 ms (25 periods) as if new."""
    from telethermal.teleop.display_hardware import BLIND_MAX
    rig.silent = (2.0, 10.0)
    with pytest.raises(CalibrationError, match=f"no trusted reading for {BLIND_MAX} periods"):
        run(rig)
    assert rig.t < 2.0 + (BLIND_MAX + 1) / routine.RATE_HZ
    rig.peltier.poll()
    assert not rig.peltier.enabled and rig.peltier.current_a == 0.0


def test_a_short_silence_is_filled_and_the_display_still_found(rig):
    rig.silent = (2.0, 2.0 + 4 / routine.RATE_HZ)          # 4 frames lost mid-part
    cal = run(rig)
    assert cal.flux_lag_s_lo <= 1.3 * _scene(as_built=BUILT).sensors.flux_lag_s <= \
        cal.flux_lag_s_hi


def test_a_period_whose_deadline_passed_is_skipped_and_the_steps_stay_on_time():
    """A period that overran by 2.5 periods: the one whose whole period
    passed meanwhile is a row of NaN (missed), the next is read late (its
    stamp says when), every later row at its deadline; each row with its
    own current, as the steps are timed."""
    dt = 1 / routine.RATE_HZ

    class Clock:
        t = 100.0

        def now(self):
            return self.t

        def sleep_until(self, d):
            self.t = max(self.t, d)

    clock = Clock()

    class Display:
        def read(self, t):
            if abs(t - 10 * dt) < dt / 2:
                clock.t += 2.5 * dt                    # this period overran
            return __import__("telethermal.devices.readings", fromlist=["x"]).PadSensors(
                1.0, 2.0, 0.0, 3.0)

        def apply(self, t, step, dt_s, force_n):
            pass

    rec = routine.run_part(Display(), 0.0, routine.RATE_HZ, clock)
    nan_rows = np.flatnonzero(np.isnan(rec.flux_w_m2))
    assert list(nan_rows) == [11]
    k = np.arange(rec.t_s.size)
    assert rec.t_s[12] == pytest.approx(12.5 * dt)
    np.testing.assert_allclose(rec.t_s[13:], k[13:] * dt, atol=1e-9)
    np.testing.assert_array_equal(rec.current_a, [routine.current_at(i * dt) for i in k])


def test_on_grid_refuses_a_gap_longer_than_it_fills():
    n = 1000
    t = np.arange(n) / routine.RATE_HZ
    flux = np.ones(n)
    flux[500:500 + routine.GAP_MAX + 1] = math.nan
    rec = routine.Record(t, np.zeros(n), np.ones(n), np.ones(n), flux, np.ones(n))
    with pytest.raises(CalibrationError, match=f"{routine.GAP_MAX + 1} in a row"):
        routine.on_grid(rec, routine.RATE_HZ, "test")
    flux[500 + routine.GAP_MAX] = 1.0
    routine.on_grid(rec, routine.RATE_HZ, "test")


def test_an_interrupt_while_the_lab_is_asked_leaves_the_driver_disabled(rig):
    def interrupted(text):
        if text == LIFT_BLOCK:
            raise KeyboardInterrupt
    rig.prompt = interrupted
    with pytest.raises(KeyboardInterrupt):
        run(rig)
    rig.peltier.poll()
    assert not rig.peltier.enabled and rig.peltier.current_a == 0.0


def test_missed_readings_past_their_share_refuse_the_part(rig):
    """Frames lost one period in four (never BLIND_MAX in a row, nor
    GAP_MAX): more than MISSING_MAX of the part's periods miss a reading,
    and the part is refused, named."""
    sleep_until = rig.sleep_until
    count = itertools.count()

    def every_fourth_lost(deadline_s):
        rig.frames_missed = int(next(count) % 4 == 0)
        sleep_until(deadline_s)

    rig.sleep_until = every_fourth_lost
    with pytest.raises(CalibrationError, match="part on the block missed a reading in"):
        run(rig, wait_s=0.002)          # a dropped frame's wait: not 50 ms x 750


def test_on_grid_fills_a_missing_reading_and_keeps_the_grid():
    t = np.arange(100) / routine.RATE_HZ + 1e-4 * (np.arange(100) % 3)   # read late, by turns
    ramp = t * routine.RATE_HZ
    flux = ramp.copy()
    flux[40] = math.nan                                  # 1 % missing: filled
    rec = routine.Record(t, np.zeros(100), ramp, ramp, flux, np.full(100, 5.0))
    got = routine.on_grid(rec, routine.RATE_HZ, "test")
    np.testing.assert_allclose(np.diff(got.t_s), 1 / routine.RATE_HZ, rtol=1e-12)
    # A linear reading stays linear (interpolation is exact on it, to 1e-9).
    np.testing.assert_allclose(got.flux_w_m2, got.t_s * routine.RATE_HZ, atol=1e-9)
    np.testing.assert_allclose(got.junction_c, got.t_s * routine.RATE_HZ, atol=1e-9)


def test_the_command_takes_a_labs_display_and_writes_its_table(rig, tmp_path, monkeypatch,
                                                                capsys):
    """``calibrate display --devices hardware --board URL --can BUS``: the
    lab's display by the names its master's config gives them; the routine
    asks at the terminal (here answered by the rig) and writes [display]."""
    import telethermal.teleop.display_hardware as hw
    from telethermal.cli import main
    from telethermal.teleop.display_calibration import read_display_calibration

    real = hw.calibrate_hardware
    asked = []

    def at_the_terminal(*a, prompt, **kw):
        def both(text):             # the command asks (Enter typed), the rig's lab does it
            prompt(text)
            asked.append(text)
            rig.prompt(text)
        return real(*a, prompt=both, clock=rig, wait_s=0.05, **kw)

    monkeypatch.setattr(hw, "calibrate_hardware", at_the_terminal)
    monkeypatch.setattr("sys.stdin", __import__("io").StringIO("\n\n"))
    out = tmp_path / "cal.toml"
    assert main(["calibrate", "display", "--scene", "fingertip-7", "--out", str(out),
                 "--devices", "hardware", "--board", rig.board.path, "--can", rig.bus]) == 0
    cal = read_display_calibration(out)
    assert cal.bench == "hardware" and cal.scene == "fingertip-7"
    assert "on a hardware bench" in capsys.readouterr().out
    assert asked == [hw.PRESS_BLOCK.format(block="plexiglass"), hw.LIFT_BLOCK]


@pytest.mark.parametrize("args, words", [
    (["--devices", "hardware"], "needs the master's config (--master-config FILE"),
    (["--devices", "hardware", "--board", "/dev/ttyUSB0"], "or --board URL"),
    (["--board", "/dev/ttyUSB0", "--can", "socketcan:can0"], "--board, --can name a lab's"),
    (["--board-calibration", "board.toml"], "--board-calibration name a lab's display"),
    (["--devices", "hardware", "--seed", "3", "--board", "x", "--can", "y"],
     "--seed draws the simulated bench's noise"),
    (["--devices", "hardware", "--master-config", "m.toml", "--board", "x"],
     "give it alone, or --board and --can"),
])
def test_the_command_says_what_a_labs_display_needs(tmp_path, capsys, args, words):
    from telethermal.cli import main
    code = main(["calibrate", "display", "--scene", "fingertip-7", "--out",
                 str(tmp_path / "cal.toml"), *args])
    assert code != 0 and words in capsys.readouterr().err
    assert not (tmp_path / "cal.toml").exists()



def test_the_masters_config_names_the_display_and_a_closed_terminal_is_said(
        rig, tmp_path, monkeypatch, capsys):
    """``--master-config``: the board, the bus and the board's calibration
    as the master will use them; run where nothing answers its questions
    (stdin closed), it stops saying why, the driver left disabled and no
    file written."""
    from telethermal.cli import main
    config = tmp_path / "master.toml"
    config.write_text(f'[master]\ndevices = "hardware"\nboard_url = "{rig.board.path}"\n'
                      f'can_bus = "{rig.bus}"\n[transport]\nsecurity = "plain"\n')
    monkeypatch.setattr("sys.stdin", __import__("io").StringIO(""))
    out = tmp_path / "cal.toml"
    assert main(["calibrate", "display", "--scene", "fingertip-7", "--out", str(out),
                 "--devices", "hardware", "--master-config", str(config)]) != 0
    assert "its input was closed: run it at a terminal" in capsys.readouterr().err
    assert not out.exists()
    rig.peltier.poll()
    assert not rig.peltier.enabled and rig.peltier.current_a == 0.0


def test_a_block_not_at_the_pads_temperature_is_refused_before_its_fit(tmp_path):
    """The block 1.5 K warmer than the pad when the steps begin: the face
    drifts through the first rest, and the routine says so rather than fit
    a transient its model leaves out (on the simulated bench a pad 1 K off
    read a flux lag 8 % long, its chi2 passing)."""
    from telethermal.sim.display_rig import GREASED_CONTACT_W_M2K, BenchTouch
    from telethermal.sim.touch import Operator

    scene = _scene(as_built=BUILT)
    room = scene.room_temp_c
    block = Operator(room + 1.5, room + 1.5, 1.0, 1.0, routine.BLOCK_FORCE_N,
                     GREASED_CONTACT_W_M2K, 0.0)
    touch = BenchTouch(scene, block, routine.RATE_HZ, 2 * routine.steps_duration_s(), room,
                       np.random.default_rng([0, 44]), "plexiglass")
    warm = LockstepRig(tmp_path, scene, touch=touch)
    try:
        with pytest.raises(CalibrationError, match="sensed flux drifted .*before the steps"):
            run(warm)
    finally:
        warm.close()


def test_the_drift_check_passes_a_steady_face_and_refuses_a_slow_ramp():
    """On noise alone (sd 25 mK, the thermocouple's; 20 W/m^2 on the flux)
    the slopes stay inside their bound; a face ramping 0.2 K/s over the rest,
    or a flux decaying 400 W/m^2 over it, does not."""
    n = int(round(routine.steps_duration_s() * routine.RATE_HZ))
    t = np.arange(n) / routine.RATE_HZ
    noise = np.random.default_rng(3).normal(0.0, 0.025, n)
    steady = routine.Record(t, np.zeros(n), np.zeros(n), 24.0 + noise, np.zeros(n), np.ones(n))
    routine.check_settled(steady, "on the block")
    ramp = routine.Record(t, np.zeros(n), np.zeros(n), 24.0 + 0.2 * t + noise, np.zeros(n),
                          np.ones(n))
    with pytest.raises(CalibrationError, match="face drifted"):
        routine.check_settled(ramp, "on the block")
    flux_noise = np.random.default_rng(4).normal(0.0, 20.0, n)
    decaying = routine.Record(t, np.zeros(n), np.zeros(n), 24.0 + noise,
                              500.0 * np.exp(-t / 0.5) + flux_noise, np.ones(n))
    with pytest.raises(CalibrationError, match="sensed flux drifted"):
        routine.check_settled(decaying, "on the block")
    steady_flux = routine.Record(t, np.zeros(n), np.zeros(n), 24.0 + noise, 30.0 + flux_noise,
                                 np.ones(n))
    routine.check_settled(steady_flux, "on the block")      # an offset is not a drift

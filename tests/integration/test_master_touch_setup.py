"""A simulated touch is set up inside one period of the master service's
loop (its operator and display pad built, its devices opened: several
periods long). Nothing is controlled meanwhile: a simulated display exists
only in a touch. Its clock and the loop's deadlines start when it is set up,
and the deadlines that passed are set aside, not missed
(``FixedRateLoop.restart_deadlines``; docs/concepts/loop.md).

The loop runs on the simulated clock, and the service reads the same clock,
so the set-up "takes" a chosen time and every figure here is exact."""

from types import SimpleNamespace

import pytest

from telethermal.control.loop import FixedRateLoop, SimClock
from telethermal.ports import free_ports
from telethermal.record.recording import read_recording
from telethermal.services import master as master_service
from telethermal.services.config import MasterConfig
from telethermal.services.master import MasterService
from telethermal.teleop.session import PRE_CONTACT_S
from telethermal.wire.codec import decode
from telethermal.wire.messages import parse
from telethermal.wire.transport import TransportConfig

from test_master_drivers import (DT, SCENE, SEED, Loopback, Recorder, _models,
                                 operator_and_forces, slave_recording)

class QuietLoopback(Loopback):
    """The stand-in transport with nothing arriving (the service's loop
    polls it every period)."""

    def poll(self, wait_s: float = 0.0) -> list:
        return []


#: The touch's contact (s).
CONTACT_S = 0.3
#: The touch's set-up, as the simulated clock has it: 3.5 periods.
SETUP_S = 3.5 * DT
#: The period (of the loop's run) whose admin request asks for the touch.
ASKED_AT = 3


@pytest.fixture(scope="module")
def models(trained_models):
    return _models(trained_models.pair(SCENE, 0))


def test_a_touch_set_up_inside_a_period_starts_its_clock_and_deadlines_when_ready(
        models, monkeypatch, tmp_path):
    operator, forces = operator_and_forces(CONTACT_S)
    before, _, _, _ = slave_recording(models, "aluminium", forces, operator.finger_ir_c, False)
    clock = SimClock(100.0)
    made = []

    class SlowTouch(master_service.Touch):
        def __init__(self, *args, **kw):
            super().__init__(*args, **kw)
            clock.advance(SETUP_S)               # the set-up's time
            self.devices = Recorder(self.devices)
            made.append(self)

    monkeypatch.setattr(master_service, "Touch", SlowTouch)
    control, stream, admin = free_ports(3)
    service = MasterService(MasterConfig(
        seed=SEED, admin_port=admin, record_dir=str(tmp_path),
        transport=TransportConfig(security="plain", control_port=control, stream_port=stream)))
    endpoint, service.endpoint = service.endpoint, QuietLoopback()
    service.wire.endpoint = service.endpoint
    replies, steps = [], [0]
    service.admin.reply = lambda **r: replies.append(r)
    request = {"cmd": "touch", "contact_s": CONTACT_S, "seed": SEED, "wait": False}
    service.admin.receive = lambda: request if steps[0] == ASKED_AT else None
    service.loop = FixedRateLoop(DT, clock)
    service.clock = SimpleNamespace(monotonic=clock.now, scale=1.0)     # its messages' too

    def step(t_loop, dt_s):
        keep = service.step(t_loop, dt_s)
        steps[0] += 1
        return keep and not (made and service.touch is None)    # the touch is over

    try:
        for data in before:
            service._on_message(parse(decode(data)), clock.now())
        stats = service.loop.run(step, 10_000)
    finally:
        service.endpoint = service.wire.endpoint = endpoint
        service.shutdown()

    assert replies and replies[0]["ok"], replies
    (touch,) = made
    ready_s = 100.0 + ASKED_AT * DT + SETUP_S
    assert stats.set_aside == 3 and stats.missed_deadlines == 0
    assert touch.setup_s == pytest.approx(SETUP_S, abs=1e-12)
    assert touch.origin_s == pytest.approx(ready_s + PRE_CONTACT_S, abs=1e-12)
    # Its first period is its first: at -PRE_CONTACT_S on its own clock, in
    # the loop's next step (none in the step that set it up), a period apart.
    times = [t for t, _ in touch.devices.readings]
    assert times == pytest.approx([-PRE_CONTACT_S + k * DT for k in range(len(times))],
                                  abs=1e-9)
    # Its report: its own periods, none of the set-up's (each step but the
    # set-up "takes" no time on this clock, so no busy time, no overrun).
    loop = service.last_touch["loop"]
    assert loop["steps"] == len(times)
    assert loop["deadline_misses"] == 0 and loop["deadlines_set_aside"] == 3
    assert loop["setup_s"] == pytest.approx(SETUP_S, abs=1e-12)
    assert loop["overruns"] == 0 and loop["busy_mean_us"] == 0.0
    assert loop["period_max_us"] == pytest.approx(DT * 1e6)
    # A recording starts the touch when its clock starts.
    (path,) = tmp_path.glob("master-*.mcap")
    starts = read_recording(path).topics["/master/touch_start"]
    assert [t for t, _ in starts] == [pytest.approx(ready_s, abs=1e-12)]

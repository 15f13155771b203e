"""bench devices' latency paths measure what they say: a command that
reaches the emulated board, not the bench's own wait running out."""

from telethermal.bench import devices


def test_every_can_command_reaches_the_board_within_the_wait(monkeypatch):
    # Before this test the master's path commanded 34 A (a temperature, from
    # when the Peltier took one) and waited for an attribute that no longer
    # existed: every sample was the bench's whole wait, and it reported that
    # as the latency. The wait is made 10x the bench's so that only a broken
    # path, not a loaded machine, can run it out.
    monkeypatch.setattr(devices, "CAN_WAIT_S", 0.5)
    can = devices._paths(20)["emulated"]["can_controller_to_actuator"]
    assert can["n"] == 220 and can["timed_out"] == 0

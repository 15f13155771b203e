"""The hand-over's offset (teleop/rendering.py ``Handover.close_offset``):
from what is applied to what the controller asks for, at a bounded slope,
and never past what separates the two."""

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from telethermal.teleop.rendering import Handover

temps = st.floats(min_value=-20.0, max_value=60.0, allow_nan=False)


def test_a_still_command_is_reached_at_the_slope():
    # Applied 19 C, the command 27 C and still, 0.1 K per period: the offset
    # is -8 + 0.1 k (closed form) and zero from period 80 on; the command
    # plus the offset is what the pad is asked, each period 0.1 K closer.
    h = Handover(offset_k=19.0 - 27.0)
    applied = 19.0
    for k in range(1, 100):
        out = 27.0 + h.close_offset(applied, 27.0, 0.1)
        assert h.offset_k == pytest.approx(min(-8.0 + 0.1 * k, 0.0), abs=1e-9)
        assert out - applied == pytest.approx(min(0.1, 27.0 - applied), abs=1e-9)
        applied = out


def test_a_command_that_falls_past_what_is_applied_takes_no_stale_offset():
    # The case that sent the pad the wrong way: the hand-over opened at
    # -6.8 K (applied 20.8 C, the command 27.6 C), then the command fell to
    # 21.4 C (a posterior collapsing onto a better conductor). Kept whole,
    # the offset would ask for 14.6 C, 6.2 K below what is applied and the
    # command; the pad is asked to stay where it is and go up from there.
    h = Handover(offset_k=-6.8)
    offset = h.close_offset(20.8, 21.4, 0.1)
    assert offset == pytest.approx(-0.6)
    assert 21.4 + offset == pytest.approx(20.8)
    # A command falling below what is applied: the offset is gone at once.
    h = Handover(offset_k=-6.8)
    assert h.close_offset(20.8, 18.0, 0.1) == 0.0


@settings(max_examples=300, deadline=None)
@given(start=temps, steps=st.lists(st.tuples(temps, temps), min_size=1, max_size=40),
       step_k=st.floats(min_value=0.0, max_value=2.0))
def test_the_offset_never_asks_past_what_is_applied(start, steps, step_k):
    # Whatever the command and what is applied do period to period, the
    # command plus the offset lies between the command and what is applied
    # (never further from the command than the pad already is), and the
    # offset's size never grows.
    h = Handover(offset_k=start)
    for applied, command in steps:
        before = abs(h.offset_k)
        offset = h.close_offset(applied, command, step_k)
        lo, hi = min(applied, command), max(applied, command)
        assert lo - 1e-9 <= command + offset <= hi + 1e-9
        # Closer to zero by the step each period, or by more where the
        # command came towards what is applied.
        assert abs(offset) <= min(max(before - step_k, 0.0), abs(applied - command)) + 1e-9


@pytest.mark.parametrize("command", [math.nan, math.inf])
def test_a_command_that_is_not_a_number_leaves_no_offset(command):
    # A reading lost in the hand-over's first period makes the command (and
    # so the offset opened on it) not a number: no offset is carried on, in
    # that period or the next (an offset of NaN would poison every command
    # after it in the contact).
    h = Handover(offset_k=20.0 - command)
    assert h.close_offset(20.0, command, 0.1) == 0.0
    assert h.close_offset(20.0, 25.0, 0.1) == 0.0

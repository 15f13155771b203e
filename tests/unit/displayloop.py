"""The master display driven on the simulated plant, period by period, as
the master unit tests drive it (tests/unit/test_master.py,
test_master_estimate.py): idle before contact (t < 0), the finger on the
plant from t = 0."""

import math

from telethermal.devices.readings import PadSensors
from telethermal.sim.plant import DisplayPlant
from telethermal.sim.touch import display_model


def display_periods(master, news_at, layers, seconds, rate_hz, pre_s, start_c, finger_c,
                    conductance_w_m2k, lag_s, fault_at=None):
    """Yield ``(t, reading or None, step)`` for each period from ``-pre_s``
    to ``seconds``: ``master.step`` on the plant's reading (none before
    contact), ``news_at(t)`` the slave's news; the plant (built at contact
    from the junction applied so far, ``start_c`` before) then steps on the
    junction the master applied. ``fault_at = (t0, t1)``: the flux reads NaN
    there."""
    dt = 1.0 / rate_hz
    plant, junction = None, start_c
    for k in range(int(round((pre_s + seconds) * rate_hz))):
        t = k * dt - pre_s
        touching = t >= 0
        if touching and plant is None:
            plant = DisplayPlant(display_model(layers, seconds + 1, dt), junction, finger_c,
                                 conductance_w_m2k, dt, lag_s)
        r = plant.read() if touching else None
        flux = r.flux_w_m2 if r else 0.0
        if fault_at and fault_at[0] <= t < fault_at[1]:
            flux = math.nan
        step = master.step(t, dt, PadSensors(flux, r.pad_surface_c if r else junction,
                                             10.0 if touching else 0.0), news_at(t))
        junction = step.junction_applied_c
        if touching:
            plant.step(junction)
        yield t, r, step

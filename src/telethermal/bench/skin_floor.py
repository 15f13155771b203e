"""The skin-temperature floor of the display: the best any controller could
do on a touch, to put the controllers' figures beside.

For one session touch (its operator, object and direct-contact skin curve),
the junction temperature is chosen on a 5 ms grid, knowing everything (the
material from t = 0, the operator's skin, contact and temperature, the exact
plant), to minimise the squared skin-temperature error over the contact.
The display plant is linear in the junction temperature, so this is a
bounded linear least-squares problem (``scipy.optimize.lsq_linear``) over the
plant's exact response to a junction pulse. The bounds are the supervisor's
skin band (the junction never leaves it); there is no slew limit (which
only makes the floor lower). The pad starts at ``idle_c`` at contact: the
object's temperature, as the display idles today, or another idle to show
what the pad's state at contact is worth.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import toeplitz
from scipy.optimize import lsq_linear

from telethermal.devices.sim_plant import DisplayPlant
from telethermal.teleop.run import display_model

GRID_S = 0.005


def skin_floor(scene, session_result, band_c: tuple[float, float], idle_c: float | None = None,
               grid_s: float = GRID_S) -> dict:
    """Skin RMS (K) and flux RMS (fraction of the direct peak) of the best
    bounded junction trajectory for the touch of ``session_result`` (a
    :class:`~telethermal.teleop.run.SessionResult`)."""
    tr, s = session_result.trace, session_result.summary
    op, contact_s = s["operator"], s["contact_s"]
    t = tr["t_s"]
    during = (t >= 0) & (t < contact_s)
    n = int(round(contact_s / grid_s))
    tg = (np.arange(n) + 1) * grid_s
    skin_direct = np.interp(tg, t[during], tr["direct_skin_c"][during])
    flux_direct = np.interp(tg, t[during], tr["direct_flux_w_m2"][during])
    pad0 = float(tr["junction_c"][during][0]) if idle_c is None else float(idle_c)
    model = display_model(tuple(scene.pad.layers), round(contact_s + 1.0, 3), grid_s)

    def simulate(junction):
        plant = DisplayPlant(model, pad0, op["finger_c"], op["conductance_w_m2k"], grid_s,
                             None, op["skin_k_scale"], op["skin_heat_scale"])
        out = np.array([(r.skin_surface_c, r.contact_flux_w_m2)
                        for r in (plant.step(u) for u in junction)])
        return out[:, 0], out[:, 1]

    free_skin, _ = simulate(np.full(n, pad0))
    step_skin, _ = simulate(np.full(n, pad0 + 1.0))
    pulse = np.diff(np.r_[0.0, step_skin - free_skin])
    response = toeplitz(pulse, np.zeros(n))
    fit = lsq_linear(response, skin_direct - free_skin,
                     bounds=(np.full(n, band_c[0] - pad0), np.full(n, band_c[1] - pad0)),
                     lsmr_tol="auto", max_iter=2000)
    skin, flux = simulate(pad0 + fit.x)
    return {"idle_c": pad0, "band_c": list(band_c),
            "temp_rms_error_c": float(np.sqrt(np.mean((skin - skin_direct) ** 2))),
            "flux_rms_error_rel": float(np.sqrt(np.mean((flux - flux_direct) ** 2))
                                        / np.max(np.abs(flux_direct)))}

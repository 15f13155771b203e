"""``bench render``'s bookkeeping of the module's limits and the dew: which
sessions ``limits`` pools (the shipped display's alone), each row's own,
and the dew section (no dew point in dry air)."""

from __future__ import annotations

from telethermal.control.dew import DEW_MARGIN_K, dew_point_c
from telethermal.teleop.display_config import DisplayConfig
from telethermal.teleop.display_setup import add_limits, limits_report, new_limit_totals


def limits_of(rows) -> dict:
    """The module limits pooled over ``rows`` (each with its session's
    ``module_limits``): one bench row's, or the shipped configuration's."""
    totals = new_limit_totals()
    for r in rows:
        add_limits(totals, r["module_limits"])
    return limits_report(totals)


def dew_report(scene, pooled: dict) -> dict:
    """The bench's ``dew``: the scene's humidity, its dew point (None for
    dry air, 0 %: no dew point, as sim/inprocess.py reports it) and margin, and
    ``pooled``'s sessions and least idle above the dew point."""
    dew_c = dew_point_c(scene.room_temp_c, scene.room_humidity_pct) \
        if scene.room_humidity_pct > 0 else None
    return {"humidity": scene.room_humidity_pct, "room_c": scene.room_temp_c,
            "dew_point_c": dew_c, "margin_k": DEW_MARGIN_K, **pooled}


def shipped_limits(report: dict) -> dict:
    """Issue 43's ``limits``: the shipped display's alone, the default
    controller at the default rate (its first touches: the controller
    section's row of the default model, run at the default rate); the other
    controllers, rates and gains have theirs in their rows' ``limits``."""
    shipped = DisplayConfig()
    row = next(c for c in report["controller"]
               if c["feedforward_model"] == shipped.feedforward_model)
    return {"configuration": f"{shipped.feedforward_model} controller at "
                             f"{shipped.rate_hz:g} Hz (shipped)", **limits_of(row["rows"])}

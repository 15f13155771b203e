"""Fig. 3 of learning-based-thermal-rendering for one session: the flux and
the temperature at the master's fingertip against direct contact.

Flux is drawn in the project's one convention: positive from the pad into
the object, and here the finger is the pad (as in the finger database) and
the object is what it touches, the real one or the display standing in for
it: a finger cooled by aluminium draws a positive flux. The session's trace
holds the display's flux into the finger, so it is drawn negated."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402


def plot_session(result, path: str | Path, title: str | None = None) -> Path:
    """Draw :func:`session_figure` into ``path`` (written whole or not at all)."""
    from telethermal.jsonfile import write_figure

    fig = session_figure(result, title)
    try:
        return write_figure(fig, path, dpi=110)
    finally:
        plt.close(fig)


def session_figure(result, title: str | None = None):
    """The session's flux (left) and temperatures (right) against direct
    contact; the title's second line gives the errors on ``demo.json``'s
    windows."""
    s, tr = result.summary, result.trace
    t = tr["t_s"]
    fig, (ax_q, ax_t) = plt.subplots(1, 2, figsize=(12, 4.5))
    out_of_finger = {k: -np.asarray(tr[k], dtype=float) / 1e3 for k in FLUX_KEYS}
    ax_q.plot(t, out_of_finger["direct_flux_w_m2"], "k-", lw=2, label="direct contact (true)")
    ax_q.plot(t, out_of_finger["flux_w_m2"], "C3-", lw=1.2, label="rendered (true)")
    ax_q.plot(t, out_of_finger["direct_flux_sensed_w_m2"], "k:", lw=1.2,
              label="direct, as sensed")
    ax_q.plot(t, out_of_finger["flux_sensed_w_m2"], "C0:", lw=1.2, label="rendered, as sensed")
    ax_q.plot(t, out_of_finger["desired_flux_w_m2"], "C2--", lw=1, label="setpoint (generator)")
    ax_t.plot(t, tr["direct_skin_c"], "k-", lw=2, label="skin surface, direct contact")
    ax_t.plot(t, tr["skin_surface_c"], "C3-", lw=1.2, label="skin surface, rendered")
    ax_t.plot(t, tr["pad_surface_c"], "C0-", lw=1, label="display pad surface")
    ax_t.plot(t, tr["junction_c"], "C7--", lw=1, label="Peltier junction (applied)")
    for ax in (ax_q, ax_t):
        _mark_decision(ax, s)
        ax.axvline(0, color="0.6", lw=0.8)
        ax.set_xlabel("time since contact (s)")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    ax_q.set_ylabel(OUT_OF_FINGER_KW)
    ax_t.set_ylabel("temperature (°C)")
    # Every flux plotted inside the axes (the true direct curve peaks
    # beyond the sensed ones: aluminium's left the axis below -12.8 kW/m2).
    ax_q.set_ylim(*_limits(np.concatenate(list(out_of_finger.values()))))
    heading = title or f"{s['scene']}: {s['material']} rendered at {s['rate_hz']:g} Hz"
    fig.suptitle(f"{heading}\n{error_windows(s)}", fontsize=10)
    fig.tight_layout()
    return fig


#: The axis of a flux drawn out of the finger (the display's flux into it, negated).
OUT_OF_FINGER_KW = "heat flux finger -> object or display (kW/m$^2$),\npositive out of the finger"
#: The trace's flux series, each the display's (or the object's) flux into the finger.
FLUX_KEYS = ("direct_flux_w_m2", "flux_w_m2", "direct_flux_sensed_w_m2", "flux_sensed_w_m2",
             "desired_flux_w_m2")


def error_windows(s: dict) -> str:
    """The session's errors over the windows ``demo.json`` reports them on,
    in its words: from the decision on, over the first second, over the
    whole contact; and the skin's."""
    def pct(key):
        value = s.get(key)
        return "n/a" if value is None or not np.isfinite(value) else f"{100 * value:.2f} %"
    return (f"flux error, % of peak: {pct('flux_rms_error_rel')} from the decision on, "
            f"{pct('flux_rms_error_rel_first_s')} over the first second, "
            f"{pct('flux_rms_error_rel_whole')} over the whole contact; "
            f"skin {s['temp_rms_error_c']:.2f} K RMS")


def _mark_decision(ax, s: dict) -> None:
    """The slave's decision at ``decision_time_s`` (solid), and where the
    display started rendering the decided material (dotted: the trajectory's
    arrival, or the object memory's announcement before any decision)."""
    if s.get("decision_time_s") is not None:
        ax.axvline(s["decision_time_s"], color="C2", lw=1.0)
        ax.annotate(f"decided: {s['identified']} ({s['decision_time_s']:.2f} s)",
                    (s["decision_time_s"], 0.02), xycoords=("data", "axes fraction"),
                    fontsize=8, color="C2")
    if s.get("render_start_s") is not None:
        ax.axvline(s["render_start_s"], color="C2", lw=0.8, ls=":")
        ax.annotate(f"rendered from {s['render_start_s']:.2f} s", (s["render_start_s"], 0.08),
                    xycoords=("data", "axes fraction"), fontsize=7, color="C2")


def _limits(values):
    v = values[np.isfinite(values)]
    if not len(v):
        return -1, 1
    lo, hi = float(v.min()), float(v.max())
    pad = 0.15 * (hi - lo or 1.0)
    return lo - pad, hi + pad

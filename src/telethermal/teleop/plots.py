"""Fig. 3 of learning-based-thermal-rendering for one session: the flux and
the temperature at the master's fingertip against direct contact."""

from __future__ import annotations

import os
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402


def plot_session(result, path: str | Path, title: str | None = None) -> Path:
    s, tr = result.summary, result.trace
    t = tr["t_s"]
    fig, (ax_q, ax_t) = plt.subplots(1, 2, figsize=(12, 4.5))
    ax_q.plot(t, tr["direct_flux_w_m2"] / 1e3, "k-", lw=2, label="direct contact (true)")
    ax_q.plot(t, tr["flux_w_m2"] / 1e3, "C3-", lw=1.2, label="rendered (true, into the finger)")
    ax_q.plot(t, tr["direct_flux_sensed_w_m2"] / 1e3, "k:", lw=1.2, label="direct, as sensed")
    ax_q.plot(t, tr["flux_sensed_w_m2"] / 1e3, "C0:", lw=1.2, label="rendered, as sensed")
    ax_q.plot(t, tr["desired_flux_w_m2"] / 1e3, "C2--", lw=1, label="setpoint (generator)")
    ax_t.plot(t, tr["direct_skin_c"], "k-", lw=2, label="skin surface, direct contact")
    ax_t.plot(t, tr["skin_surface_c"], "C3-", lw=1.2, label="skin surface, rendered")
    ax_t.plot(t, tr["pad_surface_c"], "C0-", lw=1, label="display pad surface")
    ax_t.plot(t, tr["junction_c"], "C7--", lw=1, label="Peltier junction (applied)")
    for ax in (ax_q, ax_t):
        if s.get("render_start_s") is not None:
            ax.axvline(s["render_start_s"], color="C2", lw=0.8)
            ax.annotate(f"identified: {s['identified']}", (s["render_start_s"], 0.02),
                        xycoords=("data", "axes fraction"), fontsize=8, color="C2")
        ax.axvline(0, color="0.6", lw=0.8)
        ax.set_xlabel("time since contact (s)")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    ax_q.set_ylabel("heat flux pad -> finger (kW/m$^2$)")
    ax_t.set_ylabel("temperature (°C)")
    # Every flux plotted inside the axes (the true direct curve peaks
    # beyond the sensed ones: aluminium's left the axis below -12.8 kW/m2).
    ax_q.set_ylim(*_limits(np.concatenate([tr[k] for k in (
        "direct_flux_w_m2", "flux_w_m2", "direct_flux_sensed_w_m2", "flux_sensed_w_m2",
        "desired_flux_w_m2")]) / 1e3))
    fig.suptitle(title or f"{s['scene']}: {s['material']} rendered at {s['rate_hz']:g} Hz; "
                 f"flux error {100 * s['flux_rms_error_rel']:.1f} % of peak after identification, "
                 f"skin {s['temp_rms_error_c']:.2f} K RMS", fontsize=10)
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp")
    fig.savefig(tmp, dpi=110, format=path.suffix.lstrip(".") or "png")
    plt.close(fig)
    os.replace(tmp, path)
    return path


def _limits(values):
    v = values[np.isfinite(values)]
    if not len(v):
        return -1, 1
    lo, hi = float(v.min()), float(v.max())
    pad = 0.15 * (hi - lo or 1.0)
    return lo - pad, hi + pad

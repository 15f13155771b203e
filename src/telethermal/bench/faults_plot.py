"""``telethermal bench faults``' figures: the simulated part against
one-way delay, and the processes' traces beside it."""

from __future__ import annotations

from pathlib import Path

import numpy as np


def plot(report: dict, traces: dict, path: str | Path) -> Path:
    """The simulated part against one-way delay (``path``) and, beside it
    (``<stem>-traces`` with its suffix), the processes' traces, each in the
    format its suffix names; returns ``path``."""
    path = Path(path)
    _plot_delay(report["simulated"], path)
    if report["rows"]:
        plot_traces(report, traces, path.with_name(f"{path.stem}-traces{path.suffix}"))
    return path


def _plot_delay(sim: dict, path: Path) -> None:
    """Error against one-way delay, one line per mode, +- 1 sd shaded, the
    oracle floor; one panel per window."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from telethermal.bench.faults_sim import WINDOWS

    rows = [(r["profile"].get("delay_s", 0.0), r) for n, r in sim["rows"].items()
            if n.startswith("delay") and "," not in n]
    rows.sort(key=lambda x: x[0])
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.2), sharex=True)
    xs = np.array([1e3 * d for d, _ in rows])
    oracle = sim["oracle"]["whole"]
    for ax, window in zip(axes, WINDOWS):
        for mode, color in (("compensated", "C3"), ("naive", "C0"), ("repeat", "C2")):
            st = [r["modes"][mode][window] for _, r in rows]
            m = np.array([np.nan if s["mean"] is None else 100 * s["mean"] for s in st])
            sd = np.array([np.nan if s["sd"] is None else 100 * s["sd"] for s in st])
            label = {"repeat": "repeated touch (object memory)"}.get(mode, mode + ", first touch"
                                                                     if mode != "naive" else mode)
            ax.plot(xs, m, "o-", color=color, label=label)
            ax.fill_between(xs, m - sd, m + sd, color=color, alpha=0.12, lw=0)
        if window == "whole" and oracle["mean"] is not None:
            ax.axhline(100 * oracle["mean"], color="k", ls="--", lw=1,
                       label="oracle floor (material known at t = 0)")
        ax.set_title({"blind": "blind window (contact -> first news)",
                      "after_news": "after the first news", "whole": "whole contact"}[window],
                     fontsize=9)
        ax.set_xlabel("one-way delay (ms)")
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("flux RMS error (% of the direct contact's peak)")
    axes[2].legend(fontsize=7)
    fig.suptitle(f"telethermal bench faults, simulated clock: {len(sim['materials'])} "
                 f"materials x {len(sim['seeds'])} seeds per point, mean +- 1 sd over touches, "
                 f"{sim['contact_s']:g} s contacts at {sim['rate_hz']:g} Hz", fontsize=9)
    fig.tight_layout()
    from telethermal.jsonfile import write_figure
    write_figure(fig, path, dpi=100)
    plt.close(fig)


def plot_traces(report: dict, traces: dict, path: str | Path) -> Path:
    """Jepsen-style: for each fault setting, the first material's flux at the
    finger against time, compensated and naive beside direct contact, the
    fault's window shaded (red: partition or crash until the service is back;
    grey: the delay's blind interval, 2 x one-way delay, before which no news
    of the remote contact can reach the master)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from telethermal.teleop.plots import OUT_OF_FINGER_KW

    rows = [r for r in report["rows"] if r["fault"] in traces]
    n = len(rows)
    cols = 3
    fig, axes = plt.subplots((n + cols - 1) // cols, cols, figsize=(15, 3.2 * ((n + 2) // 3)),
                             squeeze=False, sharex=True)
    for ax, row in zip(axes.flat, rows):
        tr = traces[row["fault"]]
        for source, style, label in (("trajectory", "C3-", "compensated"),
                                     ("setpoints", "C0-", "naive")):
            if source in tr:
                t = tr[source]["t_s"]
                # Into the finger, drawn out of it (the project's one convention).
                ax.plot(t, -tr[source]["flux_w_m2"] / 1e3, style, lw=1, label=label)
        ref = tr.get("trajectory") or tr.get("setpoints")
        if ref is not None:
            ax.plot(ref["t_s"], -ref["direct_flux_w_m2"] / 1e3, "k-", lw=1.6, label="direct")
        delay = row["profile"].get("delay_s", 0.0)
        if delay:
            ax.axvspan(0, 2 * delay, color="0.85", lw=0)
        window = row.get("fault_window_s")
        if window and None not in window:
            ax.axvspan(window[0], window[1], color="C3", alpha=0.15, lw=0)
        c, nv = row["compensated_flux_rms_error_rel"], row["naive_flux_rms_error_rel"]
        ax.set_title(f"{row['fault']}\ncompensated {100 * c:.1f} %, naive {100 * nv:.1f} % "
                     f"of peak; safety events {row['safety_events']}", fontsize=8)
        ax.axhline(0, color="0.6", lw=0.5)
        ax.grid(alpha=0.3)
        ax.set_xlim(-0.2, report["contact_s"] + 0.3)
    for ax in axes.flat[n:]:
        ax.set_visible(False)
    axes.flat[0].legend(fontsize=7)
    for ax in axes[-1]:
        ax.set_xlabel("time since the master's contact onset (s)")
    for ax in axes[:, 0]:
        ax.set_ylabel(OUT_OF_FINGER_KW)
    fig.suptitle(f"telethermal bench faults: {report['materials'][0]}, first touch of each "
                 f"setting; {report['machine']}, {report['date']}", fontsize=9)
    fig.tight_layout()
    from telethermal.jsonfile import write_figure
    write_figure(fig, path, dpi=100)
    plt.close(fig)
    return path

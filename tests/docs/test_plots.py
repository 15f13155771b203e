"""The demo's plots: one flux sign convention (positive from the pad, or the
finger, into the object) stated on every flux axis and drawn that way; the
decision marked at ``decision_time_s``; the title's errors on the windows
``demo.json`` reports."""

from __future__ import annotations

from types import SimpleNamespace

import matplotlib.pyplot as plt
import numpy as np

from telethermal.teleop.plots import FLUX_KEYS, error_windows, session_figure


def _session():
    t = np.linspace(-0.2, 1.0, 121)
    into_finger = np.where(t >= 0, -5e3 / np.sqrt(np.clip(t, 1e-2, None)), 0.0)  # a cold object
    trace = {k: into_finger.copy() for k in FLUX_KEYS}
    trace.update(t_s=t, direct_skin_c=33 - t, skin_surface_c=33 - t, pad_surface_c=30 + 0 * t,
                 junction_c=28 + 0 * t)
    summary = dict(scene="fingertip-7", material="aluminium", identified="aluminium",
                   rate_hz=500.0, decision_time_s=0.06, render_start_s=0.098,
                   flux_rms_error_rel=0.009, flux_rms_error_rel_first_s=0.0675,
                   flux_rms_error_rel_whole=0.052, temp_rms_error_c=0.79)
    return SimpleNamespace(summary=summary, trace=trace)


def test_touch_plot_draws_flux_out_of_the_finger_positive_and_says_so():
    fig = session_figure(_session())
    try:
        ax_q = fig.axes[0]
        assert "finger -> object" in ax_q.get_ylabel() and "positive" in ax_q.get_ylabel()
        direct = next(line for line in ax_q.get_lines() if line.get_label().startswith("direct contact"))
        t, q = direct.get_data()
        # A finger touching a colder object loses heat: positive out of it.
        assert np.all(q[t >= 0] > 0) and np.all(q[t < 0] == 0)
    finally:
        plt.close(fig)


def test_touch_plot_marks_the_decision_at_decision_time_and_the_windows_in_its_title():
    s = _session()
    fig = session_figure(s, "fingertip-7: aluminium over the network")
    try:
        for ax in fig.axes:
            vertical = {line.get_xdata()[0]: line.get_linestyle() for line in ax.get_lines()
                        if len(set(np.atleast_1d(line.get_xdata()))) == 1}
            assert vertical.get(0.06) == "-", vertical           # the decision, solid
            assert vertical.get(0.098) == ":", vertical          # rendering from, dotted
        title = fig._suptitle.get_text()
        assert "0.90 % from the decision on" in title
        assert "6.75 % over the first second" in title and "5.20 % over the whole contact" in title
        assert title == f"fingertip-7: aluminium over the network\n{error_windows(s.summary)}"
    finally:
        plt.close(fig)


def test_database_plot_states_the_convention_on_each_flux_axis(tmp_path):
    from telethermal.cli import main
    from telethermal.data.plots import datasets_figure

    for name, pad in (("pad", "alumina"), ("finger", "skin")):
        assert main(["simulate", "--pad", pad, "--object", "aluminium", "--pad-temp-c", "33",
                     "--object-temp-c", "23", "--seconds", "0.3", "--rate-hz", "100",
                     "--out", str(tmp_path / name)]) == 0
    fig = datasets_figure(tmp_path)
    try:
        labels = [ax.get_ylabel() for ax in fig.axes]
        assert [lab.split("\n")[0] for lab in labels[::2]] == [
            "heat flux finger -> object (W/m$^2$),", "heat flux pad -> object (W/m$^2$),"]
        flux = fig.axes[0].get_lines()[0].get_ydata()
        assert np.nanmax(flux) > 0 and np.nanmin(flux) >= -1.0   # warmer finger: positive
    finally:
        plt.close(fig)


def test_replay_plot_draws_flux_out_of_the_finger_positive_as_the_touch_plot_does():
    """`telethermal replay`'s plot (issue 46's review: it drew the display's
    flux into the finger, pad -> finger, negative for a cold object, beside
    the touch plots' positive): every master-side flux, recorded, replayed
    and the simulator's truth, drawn out of the finger, under the touch
    plot's own axis label."""
    from telethermal.teleop.plots import OUT_OF_FINGER_KW
    from telethermal.teleop.replay import replay_figure

    t = np.linspace(-0.2, 1.0, 121)
    into_finger = np.where(t >= 0, -5e3 / np.sqrt(np.clip(t, 1e-2, None)), 0.0)  # a cold object
    recorded = {"t_s": t, "flux_w_m2": into_finger, "desired_flux_w_m2": into_finger,
                "pad_temp_c": 30 + 0 * t, "junction_applied_c": 28 + 0 * t,
                "phase": np.array(["track"] * len(t), dtype=object)}
    result = {"recorded": recorded,
              "replayed": {"t_s": t, "desired_flux_w_m2": into_finger,
                           "junction_applied_c": 28 + 0 * t},
              "trace": {"t_s": t, "direct_flux_w_m2": into_finger, "flux_w_m2": into_finger,
                        "direct_skin_c": 33 - t, "skin_surface_c": 33 - t},
              "summary": {"identical": True, "periods": len(t), "file": "touch.mcap",
                          "slave": {"onset_s": 0.0, "decision_time_s": 0.06,
                                    "identified": "aluminium"}}}
    fig = replay_figure(result)
    try:
        ax_q = fig.axes[0]
        assert ax_q.get_ylabel() == OUT_OF_FINGER_KW
        lines = [line for line in ax_q.get_lines() if len(line.get_xdata()) == len(t)]
        assert len(lines) == 5                  # truth x2, sensor, setpoint recorded/replayed
        for line in lines:
            x, q = (np.asarray(v, dtype=float) for v in line.get_data())
            assert np.all(q[x >= 0] > 0) and np.all(q[x < 0] == 0), line.get_label()
    finally:
        plt.close(fig)


def test_fault_bench_plot_draws_flux_out_of_the_finger_positive(tmp_path, monkeypatch):
    """`bench faults`' traces, the display's flux into the finger, drawn
    out of it under the touch plot's axis label (they were pad -> finger)."""
    from telethermal.bench.faults_plot import plot_traces
    from telethermal.teleop.plots import OUT_OF_FINGER_KW

    t = np.linspace(-0.2, 1.0, 61)
    into_finger = np.where(t >= 0, -5e3 / np.sqrt(np.clip(t, 1e-2, None)), 0.0)
    trace = {"t_s": t, "flux_w_m2": into_finger, "direct_flux_w_m2": into_finger}
    row = {"fault": "none", "profile": {}, "fault_window_s": None, "safety_events": 0,
           "compensated_flux_rms_error_rel": 0.01, "naive_flux_rms_error_rel": 0.02}
    report = {"rows": [row], "contact_s": 1.0, "materials": ["aluminium"], "machine": "m",
              "date": "d"}
    figures = []
    monkeypatch.setattr(plt, "close", figures.append)
    plot_traces(report, {"none": {"trajectory": trace}}, tmp_path / "faults.png")
    ax = figures[0].axes[0]
    try:
        assert ax.get_ylabel() == OUT_OF_FINGER_KW
        for line in ax.get_lines():
            x, q = (np.asarray(v, dtype=float) for v in line.get_data())
            if len(x) == len(t):
                assert np.all(q[x >= 0] > 0), line.get_label()
    finally:
        monkeypatch.undo()
        plt.close(figures[0])

"""``bench identify``'s figure: Table 1 on the fingertip pad, the active pad
and the cross-temperature rows, each method beside the paper."""

from __future__ import annotations


def plot(report: dict, out_png) -> None:
    """The figure of ``report`` (the paper's 5-class accuracy: its Table 1
    rows' ``paper_accuracy_5``)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(12, 4.5))
    for method, rep in report["methods"].items():
        t1 = rep["table1"]
        for key, style in (("accuracy_7", "o-"), ("accuracy_5", "s--")):
            axes[0].plot([float(k) for k in t1[key]], [100 * v for v in t1[key].values()],
                         style, label=f"{method}, {key[-1]} classes")
        act = rep.get("active_passive", {}).get("active_accuracy_by_window_s", {})
        if act:
            axes[1].plot([float(k) for k in act], [100 * v for v in act.values()], "o-",
                         label=f"{method}, active I-pro")
        for name, row in rep.get("cross_temperature", {}).items():
            acc = row["accuracy_by_window_s"]
            axes[1].plot([float(k) for k in acc], [100 * v for v in acc.values()], ":",
                         label=f"{method}, {name}")
    paper = next((rep["table1"]["paper_accuracy_5"] for rep in report["methods"].values()
                  if "paper_accuracy_5" in rep.get("table1", {})), {})
    axes[0].plot([float(k) for k in paper], [100 * v for v in paper.values()], "k*", ms=10,
                 label="paper, 5 classes")
    for ax, title in zip(axes, ("fingertip-7 pad database (leave-trials-out)",
                                "gripper: active pad and cross-temperature")):
        ax.set_xlabel("time after contact (s)")
        ax.set_ylabel("accuracy (%)")
        ax.set_ylim(0, 102)
        ax.grid(alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=7)
        ax.set_title(title, fontsize=9)
    fig.suptitle(f"telethermal bench identify - {report['date']} - {report['machine']}",
                 fontsize=9)
    fig.tight_layout()
    from telethermal.jsonfile import write_figure
    write_figure(fig, out_png, dpi=110)
    plt.close(fig)

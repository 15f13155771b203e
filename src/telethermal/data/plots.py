"""Plots of datasets, in the manner of Fig. 2 of learning-based-thermal-rendering:
heat flux (left) and temperature (right) against time after contact, one
colour per material, the mean of its trials with a band of +-1 standard
deviation."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from telethermal.data.dataset import MANIFEST, Trial, load_dataset  # noqa: E402
from telethermal.errors import DatasetError  # noqa: E402

#: (channel, axis label); ``{who}`` is the dataset's pad, or the finger for a
#: finger database: flux is positive from it into the object, as in the files.
PANELS = (("heat_flux_W_m2", "heat flux {who} -> object (W/m$^2$),\npositive into the object"),
          ("temperature_C", "{who} temperature (°C)"))


def _dataset_dirs(root: Path) -> list[Path]:
    if (root / MANIFEST).is_file():
        return [root]
    subs = [p for p in sorted(root.iterdir()) if (p / MANIFEST).is_file()] if root.is_dir() else []
    if not subs:
        raise DatasetError(f"{root}: neither a dataset (no {MANIFEST}) nor a folder of datasets")
    return subs


def _mean_band(trials: list[Trial], channel: str):
    """Common time axis (the shortest trial's) and mean/std of a channel."""
    usable = [t for t in trials if channel in t.channels]
    if not usable:
        return None
    shortest = min(usable, key=lambda t: len(t.channels["t_s"]))
    axis = shortest.channels["t_s"]
    stack = np.stack([np.interp(axis, t.channels["t_s"], t.channels[channel]) for t in usable])
    return axis, stack.mean(axis=0), stack.std(axis=0)


def plot_datasets(root: str | Path, out_png: str | Path) -> Path:
    """Plot one dataset, or every dataset in a folder (one row each)."""
    from telethermal.jsonfile import write_figure

    out_png = Path(out_png)
    if out_png.is_dir():             # said before the datasets are read and drawn
        raise IsADirectoryError(21, "a folder, not an image file's path", str(out_png))
    fig = datasets_figure(root)
    try:
        return write_figure(fig, out_png, dpi=110, fmt="png")
    finally:
        plt.close(fig)


def datasets_figure(root: str | Path):
    """The figure :func:`plot_datasets` writes."""
    dirs = _dataset_dirs(Path(root))
    fig, axes = plt.subplots(len(dirs), 2, figsize=(12, 4.2 * len(dirs)), squeeze=False)
    for row, folder in zip(axes, dirs):
        trials = load_dataset(folder)
        materials = sorted({t.material for t in trials})
        colours = plt.cm.tab10(np.linspace(0, 1, max(len(materials), 10)))
        for ax, (channel, label) in zip(row, PANELS):
            for colour, material in zip(colours, materials):
                group = [t for t in trials if t.material == material]
                band = _mean_band(group, channel)
                if band is None:
                    continue
                axis, mean, std = band
                ax.plot(axis, mean, color=colour, label=f"{material} (n = {len(group)})", lw=1.4)
                ax.fill_between(axis, mean - std, mean + std, color=colour, alpha=0.2, lw=0)
            ax.axvline(0.0, color="0.5", lw=0.8, ls=":")
            ax.set_xlabel("time after contact (s)")
            ax.set_ylabel(label.format(who="finger" if folder.name == "finger" else "pad"))
            ax.set_title(f"{folder.name}: {len(trials)} trials; line: mean, band: +- 1 sd "
                         f"across the trials of a material", fontsize=9)
            ax.grid(alpha=0.3)
        row[0].legend(fontsize=8, ncol=2)
    fig.tight_layout()
    return fig

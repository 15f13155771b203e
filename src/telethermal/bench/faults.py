"""``telethermal bench faults``: rendering under network faults, the
compensated path beside the naive one, measured in the same run, in two
parts.

**Simulated clock** (:mod:`telethermal.bench.faults_sim`): every delay,
jitter and loss row, every material of fingertip-7, several seeds, every
mode (compensated first touch, naive, repeated touch with object memory,
the oracle floor) on the very same touches, errors over the blind window,
after the first news and the whole contact. This is where the modes are
compared: the real clock's noise is gone.

**Processes** (:mod:`telethermal.bench.faults_procs`): the fault matrix
(delay, loss, a partition, a crash of either service) on the real services;
it says whether the simulated figures hold on real processes (same seeds:
the same physics) and whether every fault is survived safely and recovered
from.

The figures are drawn by :mod:`telethermal.bench.faults_plot`, the section
the command prints and the report holds written by
:mod:`telethermal.bench.faults_text`; this module runs both parts and
exports what the command line uses (``run``, ``plot``, ``SETTINGS``).
"""

from __future__ import annotations

from pathlib import Path

from telethermal.bench.faults_plot import plot, plot_traces
from telethermal.bench.models import bench_models
from telethermal.bench.faults_procs import (CONTACT_S, MATERIALS, SETTINGS, confirm,
                                            processes_report, run_processes)
from telethermal.errors import BenchError
from telethermal.physics.scene import load_scene, with_finger
from telethermal.render.generator import save_generator

__all__ = ["CONTACT_S", "MATERIALS", "SETTINGS", "SIM_SEEDS", "parse_delays", "plot", "plot_traces",
           "run"]

#: Seeds per material of the simulated part (the issue asks for >= 5).
SIM_SEEDS = 5


def _select(settings, only: str | None):
    if not only:
        return settings
    parts = [p.strip() for p in only.split(",") if p.strip()]
    return [s for s in settings if s[0] == "delay 0 ms" or any(p in s[0] for p in parts)]


def parse_delays(text: str) -> list[float]:
    """``--delays``: comma-separated one-way delays in ms, each in
    [0, ``MAX_DELAY_MS``]; 0 is added (every ratio needs it)."""
    out = set()
    for part in text.split(","):
        try:
            ms = float(part.strip())
        except ValueError:
            raise BenchError(f"--delays: {part.strip()!r} is not a delay in ms "
                             f"(give e.g. --delays 0,50,200)") from None
        if not 0.0 <= ms <= MAX_DELAY_MS:
            raise BenchError(f"--delays: {ms:g} ms is outside [0, {MAX_DELAY_MS:g}] ms")
        out.add(ms)
    return sorted(out | {0.0})


def with_delays(rows, delays_ms: list[float] | None) -> list:
    """``rows`` with their pure-delay rows (no jitter, loss or fault)
    replaced by one row per delay of ``delays_ms`` (None: unchanged)."""
    if delays_ms is None:
        return list(rows)
    pure = [(f"delay {d:g} ms", {"delay_s": d / 1e3} if d else {}) for d in delays_ms]
    return pure + [r for r in rows if set(r[1]) - {"delay_s"}]


#: The longest one-way delay ``--delays`` takes (ms): longer than the
#: bench's contacts, so nothing after it would be measured.
MAX_DELAY_MS = 2000.0


def run(progress=None, quick: bool = False, only: str | None = None,
        seeds: int | None = None, processes: bool = True, jobs: int = 2,
        scene_name: str = "fingertip-7", delays_ms: list[float] | None = None,
        executor=None, models=None) -> dict:
    """Both parts; ``quick``: the zero-delay and WAN rows on a third of the
    materials, 2 seeds, the processes on one material; ``only``: parts of row names (the zero-delay
    row is always run, every ratio needs it); ``scene_name``: a shipped
    scene or a scene file (its processes touch wood and steel where it has
    them, else its first two materials); ``delays_ms``: the pure-delay rows
    of both parts (``parse_delays``; default: the committed rows); ``executor``:
    where the simulated rows run (:mod:`telethermal.bench.executor`; None: a
    pool of ``jobs`` worker processes); ``models``: a folder of ``telethermal
    models`` for the scene (:func:`telethermal.bench.models.bench_models`;
    None: trained here)."""
    from telethermal.bench import faults_sim
    from telethermal.teleop.display_config import DisplayConfig

    step = progress or (lambda _m: None)
    scene = with_finger(load_scene(scene_name))
    sim_rows = [r for r in faults_sim.ROWS if not quick or r[0] in faults_sim.ABLATION_ROWS]
    sim_rows = _select(with_delays(sim_rows, delays_ms), only)
    settings = _select(with_delays([SETTINGS[0], SETTINGS[2]] if quick else SETTINGS,
                                   delays_ms), only)
    names = list(dict.fromkeys([n for n, _ in with_delays(faults_sim.ROWS, delays_ms)] +
                               [n for n, _ in with_delays(SETTINGS, delays_ms)]))
    parts = [q.strip() for q in (only or "").split(",") if q.strip()]
    if only and not any(q in n for q in parts for n in names):
        raise BenchError(f"--only {only!r} matches no setting; settings: " + "; ".join(names))
    n_seeds = seeds if seeds is not None else (2 if quick else SIM_SEEDS)
    if n_seeds < 1:
        raise BenchError(f"--seeds must be >= 1, got {n_seeds}")
    materials = MATERIALS if set(MATERIALS) <= set(scene.materials) else \
        tuple(scene.materials[:2])
    materials = materials[:1] if quick else materials
    from telethermal.bench.executor import work_folder

    with work_folder(executor) as tmp:
        out = Path(tmp)
        step("training" if models is None else "loading the models")
        identifier, generator, provenance = bench_models(scene, models)
        ident = identifier.save(out / "identifier.npz")
        gen = save_generator(generator, out / "generator.npz")
        # --quick: a third of the materials, and those the processes touch
        # (their errors are checked against the simulated spread of theirs).
        sim_materials = [m for m in scene.materials
                         if not quick or m in scene.materials[::3] or m in materials]
        simulated = faults_sim.run(scene, ident, gen, DisplayConfig(), sim_materials,
                                   list(range(1, n_seeds + 1)), CONTACT_S, sim_rows, jobs=jobs,
                                   progress=step, executor=executor)
        rows, traces, codes = run_processes(scene, out, ident, gen,
                                            settings if processes else [], materials, step)
    report = processes_report(rows, codes, materials)
    report["simulated"] = simulated
    report["models"] = provenance
    report["summary"] = {**simulated["summary"], **report["summary"],
                         **confirm(rows, simulated)}
    report["_traces"] = traces
    return report

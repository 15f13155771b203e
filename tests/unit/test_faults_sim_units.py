"""``bench faults``' simulated part as units of work (row, part, material),
swept on an executor: every unit once, and the results gathered in the
order one process would make them, whichever order they finished in."""

from telethermal.bench import faults_sim
from telethermal.bench.faults_sim import assemble, run_unit, units
from telethermal.teleop.display_config import DisplayConfig

MATERIALS = ["aluminium", "steel", "wood"]


def test_every_unit_once():
    names = [n for n, _ in faults_sim.ROWS]
    work = units(names, MATERIALS)
    # Oracle, modes of every row, "before" on both ablation rows, "lossless"
    # on the WAN row only (the zero-delay row loses nothing): per material.
    assert len(work) == len(MATERIALS) * (1 + len(names) + 2 + 1)
    assert len(set(work)) == len(work)


def _fake_touch(material, seed, spec, mode="compensated", config=None, memory=None,
                object_id=None, network_seed=None):
    """A touch summary whose error names the material and seed."""
    code = {"aluminium": 1, "steel": 2, "wood": 3}[material] * 1000 + seed
    return {"material": material, "seed": seed, "mode": mode, "identified": material,
            "first_news_s": 0.0, "blind_s": 0.01, "render_start_s": 0.0,
            "flux_rms_error_rel_blind": code, "flux_rms_error_rel_after_news": code,
            "flux_rms_error_rel_whole": code, "temp_rms_error_c": 0.1, "safety_events": 0}


def test_results_are_gathered_material_by_material_seed_by_seed():
    rows = [r for r in faults_sim.ROWS if r[0] in (faults_sim.ZERO, faults_sim.WAN)]
    seeds = [1, 2]
    config = DisplayConfig()
    work = units([n for n, _ in rows], MATERIALS)
    links = dict(rows)
    # Units made in a scrambled order, as two processes would.
    results = {u: run_unit(_fake_touch, u, links.get(u[1]), config, seeds)
               for u in reversed(work)}
    out = assemble(results, rows, MATERIALS, seeds)
    zero = out["rows"][faults_sim.ZERO]
    assert [(t["material"], t["seed"]) for t in zero["touches"]["compensated"]] == [
        (m, s) for m in MATERIALS for s in seeds]
    assert set(zero["ablations"]) == {"before hold"}
    assert set(out["rows"][faults_sim.WAN]["ablations"]) == {"before hold",
                                                             "estimates lossless"}
    assert zero["repeat_with_memory"] == 0.0              # the fake slave learns nothing
    assert out["oracle"]["whole"]["n"] == len(MATERIALS) * len(seeds)
    assert list(out["rows"]) == [faults_sim.ZERO, faults_sim.WAN]

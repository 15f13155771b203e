"""``bench render``'s floor at the slave's decision times: the best any
display that learns each material only when this bench's slave decided it
can do on the nominal touch (control/decision_floor.py), beside the first
touches. The floors (nested SLSQP) are a job of the bench's sweep."""

from __future__ import annotations

import numpy as np

from telethermal.bench.render_sessions import mean_of as _mean
from telethermal.physics.scene import load_scene, with_finger


def decision_times(first: list[dict], materials) -> dict[str, float]:
    """Per material the mean over seeds of its first touches'
    ``decision_from_s`` (materials never decided left out)."""
    times = {}
    for m in materials:
        vals = [r["decision_from_s"] for r in first
                if r["material"] == m and r["decision_from_s"] is not None]
        if vals:
            times[m] = float(np.mean(vals))
    return times


def decision_floors(scene_ref: str, times: dict[str, float]) -> dict:
    """The floors of :func:`decision_floor_at_the_slaves_times` (its
    expensive part, nested SLSQP: a job of the bench's sweep, run beside
    the sessions): the scene ``scene_ref`` with its finger, the materials
    learnt at ``times`` (s after contact)."""
    from telethermal.control import preconditioning as pc
    from telethermal.control import display_floor
    from telethermal.control.decision_floor import decision_floor

    scene = with_finger(load_scene(scene_ref))
    search = pc.FloorSearch(scene, display_floor.hardware(scene),
                            display_floor.nominal_touch(scene))
    idle_c = pc.idle_for(scene, None, search.touch.object_c, search.touch.finger_c)
    targets = {m: search.targets[m] for m in times}
    f = decision_floor(search.hw, search.plant, targets, idle_c, times)
    # Against each material's floor knowing it at contact (the same model):
    # the least worst ratio any display learning at these times can reach.
    known = {m: search.floor_k(m, idle_c) for m in times}
    rel = decision_floor(search.hw, search.plant, targets, idle_c, times, relative_to=known)
    return {"idle_c": idle_c, "grid_s": search.plant.grid_s, "worst_k": f.worst_k,
            "per_material_k": f.per_material_k, "converged": f.converged, "known": known,
            "worst_ratio": rel.worst_ratio, "ratio_converged": rel.converged}


def decision_floor_at_the_slaves_times(first: list[dict], materials, times: dict[str, float],
                                       floors: dict) -> dict:
    """The floor of a display that learns each material when this bench's
    slave decided it (control/decision_floor.py, nested information), from
    the idle policy's pad for an unknown object, beside the first touches;
    ``times``: :func:`decision_times` of ``first``; ``floors``:
    :func:`decision_floors` at those times.

    The decision time per material is the mean over seeds of the first
    touches' ``decision_from_s`` (from contact); the floor is on the
    scene's nominal touch (as ``bench skin-floor``'s), on 10 ms slots. Its
    worst material is a bound no causal display that learns nothing before
    its decision beats on its worst material, on this model and up to the
    solver's slack; its per-material values are not bounds (a minimax
    trades materials). Caveats, each stated in the report: the sessions'
    touches each have their own operator and object (the floor is the
    nominal touch's), so a session can fall below it; the times include
    decisions that named a pair, "unknown" or a wrong material (each
    earlier than naming the material: the floor is then lower, the
    comparison harsher); the product's display mixes the posteriors before
    the decision, which this floor does not give it."""
    decided = [m for m in materials if m in times]
    if not decided:
        return {"note": "no first touch was decided"}
    known = floors["known"]
    skin = {m: _mean([r for r in first if r["material"] == m], "temp_rms_error_c")
            for m in decided}
    first_worst = max(decided, key=lambda m: skin[m])
    return {"decision_s": times, "idle_c": floors["idle_c"], "grid_s": floors["grid_s"],
            "floor_worst_k": floors["worst_k"], "per_material_k": floors["per_material_k"],
            "converged": floors["converged"], "first_touch_worst_material": first_worst,
            "first_touch_worst_k": skin[first_worst],
            "ratio": skin[first_worst] / floors["worst_k"],
            "floor_k_known_at_contact": known,
            "least_worst_ratio_to_floor_k": floors["worst_ratio"],
            "ratio_converged": floors["ratio_converged"],
            "first_touch_ratio_to_floor_k": {m: skin[m] / known[m] for m in decided},
            "undecided": [m for m in materials if m not in times],
            "caveats": "the floor is on the scene's nominal touch, each session on its own "
                       "operator and object; decision times include pairs, unknown and wrong "
                       "decisions (harsher); the display's posterior mixture before the "
                       "decision is information this floor does not give it; on 10 ms slots, "
                       "up to the solver's slack (control/decision_floor.py)",
            "criterion": "nested: the pad's heat common to the materials not yet decided; "
                         "minimax over the decided materials; per_material_k: each "
                         "material on that trajectory, not a bound per material; "
                         "least_worst_ratio_to_floor_k: the least, over every display "
                         "learning at these times, of the worst first touch's ratio to its "
                         "floor knowing the material at contact (floor_k_known_at_contact, "
                         "the same model)"}

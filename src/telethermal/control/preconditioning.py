"""The display pad's idle temperature before a touch (preconditioning).

Before contact the module holds the pad uniform at an idle temperature;
what the display can then do on the touch (its floor,
:mod:`telethermal.control.display_floor`) depends strongly on it. For a
known material the best idle is searched; for an unknown object one idle
offset from the object's measured temperature is chosen over the scene's
materials, minimising the worst floor (minimax). :func:`idle_for` is what
the product calls: the per-scene table is computed once (lru_cache) and
applied as a rule, ``idle = object + fraction * (finger - object)``.
"""

from __future__ import annotations

import functools
import math

import numpy as np

from telethermal.control.display_floor import (  # noqa: F401  (re-exported)
    BOUND_MARGIN, CONTACT_S, GRID_S, Floor, Hardware, JunctionPlant, Touch, Verified,
    best_touch, bounded_fit, direct_skin_c, hardware, idle_hold, nominal_touch,
    pump_bounds_w_m2, verify)
from telethermal.control.safety import SafetyLimits
from telethermal.errors import ControlError, UnknownMaterialError
from telethermal.physics.scene import Scene, load_scene


# ---------------------------------------------------------------- idle search and policy
#: The searches run on 10 ms slots with at most 3 bound rounds (the floor
#: settles to ~1e-3 K by then) and the fast solver; the floors reported are
#: then recomputed on 5 ms slots, exactly, to convergence, on the nonlinear
#: module, at the idles found.
SEARCH_GRID_S = 0.01
SEARCH_ROUNDS = 3


class FloorSearch:
    """The cheap floor of every material of ``scene`` as a function of the
    idle temperature, for one hardware and touch (cached per idle)."""

    def __init__(self, scene: Scene, hw: Hardware, touch: Touch,
                 grid_s: float = SEARCH_GRID_S, contact_s: float = CONTACT_S):
        self.scene, self.hw, self.touch = scene, hw, touch
        self.plant = JunctionPlant(hw, touch, contact_s, grid_s)
        self.targets = {m: direct_skin_c(scene, m, touch, self.plant.n, grid_s)
                        for m in scene.materials}
        limits = SafetyLimits()
        self.band_c = (limits.skin_min_c, limits.skin_max_c)
        self._cache: dict = {}

    def floor_k(self, material: str, idle_c: float) -> float:
        key = (material, round(float(idle_c), 6))
        if key not in self._cache:
            self._cache[key] = best_touch(self.hw, self.plant, self.targets[material], idle_c,
                                          nonlinear=False, max_rounds=SEARCH_ROUNDS,
                                          exact=False).skin_rms_k
        return self._cache[key]

    def refine(self, cost, grid: np.ndarray) -> float:
        """The minimum of ``cost(idle)``: the best point of ``grid`` (C),
        then a bounded 1-D search between its neighbours (xatol 0.1 K)."""
        from scipy.optimize import minimize_scalar

        values = [cost(x) for x in grid]
        i = int(np.argmin(values))
        lo, hi = grid[max(i - 1, 0)], grid[min(i + 1, len(grid) - 1)]
        best = minimize_scalar(cost, bounds=(lo, hi), method="bounded",
                               options={"xatol": 0.1})
        return float(best.x) if best.fun <= values[i] else float(grid[i])

    def idle_grid(self, step_k: float) -> np.ndarray:
        lo, hi = self.band_c
        return np.unique(np.r_[np.arange(lo, hi, step_k), hi, self.touch.object_c])


def search_idles(search: FloorSearch, step_k: float = 4.0) -> dict:
    """Per material the best uniform idle in the skin band (the state
    searched: pad and junction uniform at one temperature before contact,
    as the module holds it in air); and for an unknown object the idle
    minimising the worst floor over the scene's materials (minimax) and the
    one minimising the mean floor (the scene's materials equally likely).
    Idles are offsets from the object's temperature and, as a rule,
    fractions of the finger-object difference (exact for the linear plant
    where the pumping bounds do not bind)."""
    grid = search.idle_grid(step_k)
    materials = search.scene.materials
    best = {m: search.refine(lambda x, m=m: search.floor_k(m, x), grid) for m in materials}
    minimax = search.refine(lambda x: max(search.floor_k(m, x) for m in materials), grid)
    expected = search.refine(lambda x: float(np.mean([search.floor_k(m, x)
                                                       for m in materials])), grid)
    t = search.touch
    span = t.finger_c - t.object_c

    def rule(idle_c):
        return {"idle_c": idle_c, "offset_k": idle_c - t.object_c,
                "fraction_of_finger_minus_object": (idle_c - t.object_c) / span}

    return {"preconditioned": {m: rule(x) for m, x in best.items()},
            "minimax": rule(minimax), "expected": rule(expected),
            "table": {"idle_c": grid.tolist(),
                      "floor_k": {m: [search.floor_k(m, x) for x in grid] for m in materials}}}


def minimax_idle(search: FloorSearch, step_k: float = 7.0) -> tuple[float, list[str]]:
    """The idle minimising the worst floor over the scene's materials,
    solved on a subset and certified on all: start with the materials of
    highest and lowest effusivity; at the subset's minimax idle evaluate
    every material; if one is worse, add it and solve again. When none is,
    the answer is the minimax of all (the maximum over all materials is at
    least the subset's everywhere, and equal to it there). Returns (idle C,
    the subset that decided it)."""
    from telethermal.physics.materials import get_material

    def effusivity(m):
        mat = get_material(m)
        return mat.conductivity_w_mk * mat.volumetric_heat_j_m3k

    materials = search.scene.materials
    subset = [max(materials, key=effusivity), min(materials, key=effusivity)]
    grid = search.idle_grid(step_k)
    while True:
        idle = search.refine(lambda x: max(search.floor_k(m, x) for m in subset), grid)
        worst = max(materials, key=lambda m: search.floor_k(m, idle))
        if worst in subset or search.floor_k(worst, idle) <= \
                max(search.floor_k(m, idle) for m in subset) + 1e-9:
            return idle, subset
        subset.append(worst)


@functools.lru_cache(maxsize=8)
def _policy(scene_name: str) -> dict:
    scene = load_scene(scene_name)
    return search_idles(FloorSearch(scene, hardware(scene), nominal_touch(scene)))


def idle_for(scene: Scene | str, material: str | None, object_temp_c: float,
             finger_temp_c: float) -> float:
    """The pad's idle temperature (C) before a touch: for a known
    ``material`` its best idle, for ``None`` (unknown object) the minimax
    policy's; both as the fraction of ``finger - object`` found on the
    scene's nominal touch (computed once per scene, cached), clipped to
    the skin band."""
    scene = load_scene(scene) if isinstance(scene, str) else scene
    if material is not None and material not in scene.materials:
        raise UnknownMaterialError(f"material {material!r} is not in scene {scene.name} (its "
                                   f"materials: {', '.join(scene.materials)})")
    if not (math.isfinite(object_temp_c) and math.isfinite(finger_temp_c)):
        raise ControlError(f"temperatures must be finite, got object {object_temp_c}, "
                           f"finger {finger_temp_c}")
    policy = _policy(scene.name)
    rule = policy["minimax"] if material is None else policy["preconditioned"][material]
    limits = SafetyLimits()
    idle = object_temp_c + rule["fraction_of_finger_minus_object"] * (finger_temp_c -
                                                                       object_temp_c)
    return float(min(max(idle, limits.skin_min_c), limits.skin_max_c))

"""The display pad's idle temperature before a touch (preconditioning).

Before contact the module holds the pad uniform at an idle temperature;
what the display can then do on the touch (its floor,
:mod:`telethermal.control.display_floor`) depends strongly on it. For a
known material the best idle is searched; for an unknown object one idle
offset from the object's measured temperature is chosen over the scene's
materials, minimising the worst floor (minimax). :func:`idle_for` is what
the product calls: the per-scene table is shipped for the package's scenes
(``scenes/<name>.idle.json``), else computed once and cached
(:func:`scene_policy`), and applied as a rule,
``idle = object + fraction * (finger - object)``.

Regenerate the shipped tables after changing a shipped scene, the module,
the materials or the search (a stale table is not used, only recomputed,
and a test says which are stale)::

    telethermal scenes --write-idle-policy fingertip-7 ...
"""

from __future__ import annotations

import hashlib
import json
import logging
import math
from importlib import resources

import numpy as np

from telethermal.cachedir import cache_dir
from telethermal.control.display_floor import (CONTACT_S, Hardware, JunctionPlant, Touch,
                                              best_touch, direct_skin_c, hardware,
                                              nominal_touch)
from telethermal.control.safety import SafetyLimits
from telethermal.errors import ControlError, UnknownMaterialError
from telethermal.jsonfile import write_json
from telethermal.physics.figures import physical
from telethermal.physics.scene import Scene, load_scene

log = logging.getLogger("telethermal.preconditioning")


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


#: The floor table's idle step (K): every group's minimax idle is read off
#: it (linear interpolation between its points, then a 0.05 K search).
TABLE_STEP_K = 1.0


def floor_table(search: FloorSearch, step_k: float = TABLE_STEP_K) -> dict:
    """Every material's floor on an idle grid over the skin band."""
    lo, hi = search.band_c
    grid = np.unique(np.r_[np.arange(lo, hi, step_k), hi])
    return {"idle_c": grid.tolist(),
            "floor_k": {m: [search.floor_k(m, x) for x in grid] for m in search.scene.materials}}


def group_minimax_idle(table: dict, materials) -> tuple[float, float]:
    """(idle C, worst floor K) minimising the worst floor over ``materials``
    (a remembered group: the object is one of them, which is not known),
    from :func:`floor_table`'s table."""
    grid = np.asarray(table["idle_c"], dtype=np.float64)
    fine = np.unique(np.r_[np.arange(grid[0], grid[-1], 0.05), grid[-1]])
    worst = np.max([np.interp(fine, grid, np.asarray(table["floor_k"][m], dtype=np.float64))
                    for m in materials], axis=0)
    i = int(np.argmin(worst))
    return float(fine[i]), float(worst[i])


def minimax_idle(search: FloorSearch, step_k: float = 7.0) -> tuple[float, list[str]]:
    """The idle minimising the worst floor over the scene's materials,
    solved on a subset and certified on all: start with the materials of
    highest and lowest effusivity; at the subset's minimax idle evaluate
    every material; if one is worse, add it and solve again. When none is,
    the answer is the minimax of all (the maximum over all materials is at
    least the subset's everywhere, and equal to it there). Returns (idle C,
    the subset that decided it)."""

    def effusivity(m):
        mat = search.scene.object_named(m).layers()[0].material   # a layered one's surface
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


#: How a pair's label joins its materials: the identifier's group label
#: (``ident.label.GROUP_SEPARATOR``, a layer above; a test checks they agree).
PAIR_SEPARATOR = "|"

#: Bumped when the search or the floor it minimises changes: every stored
#: policy (shipped or cached) is then recomputed.
POLICY_VERSION = 2          # 2: minimax idles for every pair (a remembered group)


def policy_key(scene: Scene) -> str:
    """What the policy depends on, hashed: the display's hardware (module,
    heat sink, pad layers, room), the nominal touch, the finger, the objects
    and their materials' properties, the variability, the contact models'
    sampling and tolerance, the skin band, the search's grid and contact
    length and its version. Not the slave's gap or sensors, nor the names,
    nor a part's descriptive text (its ``source``): a scene differing only
    there shares the policy. A policy stored under another key is stale."""
    inputs = (POLICY_VERSION, SEARCH_GRID_S, SEARCH_ROUNDS, CONTACT_S,
              physical(hardware(scene)), physical(nominal_touch(scene)),
              physical(scene.finger), physical(scene.objects), physical(scene.variability),
              scene.room_temp_c, scene.sample_rate_hz, scene.tolerance_rel,
              [physical(la.material) for o in scene.objects for la in o.layers()],
              physical(SafetyLimits()))
    if scene.pad.size_mm is not None:           # a face other than the module's
        inputs += (scene.pad.size_mm,)
    return hashlib.sha256(repr(inputs).encode()).hexdigest()[:32]


def compute_policy(scene: Scene) -> dict:
    """The idle table of ``scene`` (:func:`search_idles` on its nominal
    touch), with the key it was computed for. A few minutes on fingertip-7
    (most of it the floor table the pairs' idles are read off)."""
    from itertools import combinations

    search = FloorSearch(scene, hardware(scene), nominal_touch(scene))
    policy = search_idles(search)
    # A remembered pair (the slave's memory holds a group: the object is one
    # of two materials) idles at the pair's minimax, read off a floor table.
    table = floor_table(search)
    span = search.touch.finger_c - search.touch.object_c
    groups = {}
    for pair in combinations(scene.materials, 2):
        idle_c, worst_k = group_minimax_idle(table, pair)
        groups[PAIR_SEPARATOR.join(sorted(pair))] = {
            "idle_c": idle_c, "offset_k": idle_c - search.touch.object_c,
            "fraction_of_finger_minus_object": (idle_c - search.touch.object_c) / span,
            "worst_floor_k": worst_k}
    return {"scene": scene.name, "key": policy_key(scene), "version": POLICY_VERSION,
            "minimax": policy["minimax"], "expected": policy["expected"],
            "preconditioned": policy["preconditioned"], "groups": groups, "table": table}


def shipped_policy_path(scene_name: str):
    """Where the package keeps a shipped scene's policy."""
    return resources.files("telethermal").joinpath("scenes", f"{scene_name}.idle.json")


def _read_policy(path, key: str) -> dict | None:
    """The policy stored at ``path`` if it is one for ``key``; None if the
    file is missing or stale. A file that is not a policy is an error that
    names it (it is never silently recomputed over)."""
    try:
        text = path.read_text()
    except (FileNotFoundError, NotADirectoryError):
        return None
    try:
        data = json.loads(text)
        ok = isinstance(data, dict) and all(k in data for k in ("key", "minimax",
                                                                   "preconditioned", "groups"))
    except ValueError:
        ok = False
    if not ok:
        raise ControlError(f"{path}: not an idle policy (delete it to recompute)")
    return data if data["key"] == key else None


_POLICIES: dict[str, dict] = {}


def policy_known(scene: Scene) -> bool:
    """Whether :func:`scene_policy` has the scene's policy without computing
    it (shipped for it, cached, or read before in this process)."""
    key = policy_key(scene)
    return key in _POLICIES or \
        _read_policy(shipped_policy_path(scene.name), key) is not None or \
        _read_policy(cache_dir() / f"idle-policy-{key}.json", key) is not None


def prepare_policy(scene: Scene, echo=log.warning) -> None:
    """The scene's idle policy made ready before a service's first touch (a
    scene with none shipped or cached computes it now: minutes, once, then
    cached), so that no touch waits on it: the master, its admin socket
    unanswered, would look dead. ``echo`` says so when it computes."""
    import time

    known = policy_known(scene)
    if not known:
        echo(f"display idle policy for scene {scene.name}: computing (minutes, once)...")
    start = time.monotonic()
    scene_policy(scene)
    if not known:
        echo(f"display idle policy ready in {time.monotonic() - start:.0f} s (cached in "
             f"{cache_dir()})")


def scene_policy(scene: Scene) -> dict:
    """The idle policy of ``scene``: the package's for a shipped scene it
    was computed for, else the user's cache (:func:`cache_dir`), else
    computed now (a few minutes; logged) and cached (written atomically)."""
    key = policy_key(scene)
    if key in _POLICIES:
        return _POLICIES[key]
    policy = _read_policy(shipped_policy_path(scene.name), key)
    cached = cache_dir() / f"idle-policy-{key}.json"
    if policy is None:
        policy = _read_policy(cached, key)
    if policy is None:
        log.warning("scene %s: computing the display's idle policy (a few minutes, once; "
                    "cached in %s)", scene.name, cached.parent)
        policy = compute_policy(scene)
        try:
            write_json(cached, policy)
        except OSError as exc:
            log.warning("could not cache the idle policy in %s: %s", cached, exc)
    _POLICIES[key] = policy
    return policy


UNKNOWN_KEY = "unknown"


def policy_fractions(scene: Scene) -> dict[str, float]:
    """The policy as the product applies it: per material, per pair of
    materials (a remembered group, its label ``a|b``), and for an unknown
    object (:data:`UNKNOWN_KEY`), the idle's fraction of ``finger - object``
    (what a recording keeps to replay a touch)."""
    policy = scene_policy(scene)
    out = {UNKNOWN_KEY: float(policy["minimax"]["fraction_of_finger_minus_object"])}
    for section in ("preconditioned", "groups"):
        out.update({m: float(r["fraction_of_finger_minus_object"])
                    for m, r in policy[section].items()})
    return out


def idle_from_fractions(fractions: dict[str, float], material: str | None,
                        object_temp_c: float, finger_temp_c: float) -> float:
    """``object + fraction * (finger - object)`` for ``material`` (a
    material, a group's label, or None: an unknown object), clipped to the
    skin band."""
    if not (math.isfinite(object_temp_c) and math.isfinite(finger_temp_c)):
        raise ControlError(f"temperatures must be finite, got object {object_temp_c}, "
                           f"finger {finger_temp_c}")
    key = UNKNOWN_KEY if material is None else material
    if key not in fractions:
        raise UnknownMaterialError(f"material {material!r} has no idle in the policy (its "
                                   f"materials: {', '.join(k for k in fractions if k != UNKNOWN_KEY)})")
    limits = SafetyLimits()
    idle = object_temp_c + fractions[key] * (finger_temp_c - object_temp_c)
    return float(min(max(idle, limits.skin_min_c), limits.skin_max_c))


def idle_for(scene: Scene | str, material: str | None, object_temp_c: float,
             finger_temp_c: float) -> float:
    """The pad's idle temperature (C) before a touch: for a known
    ``material`` its best idle (a pair's label: the pair's), for ``None``
    (unknown object) the minimax policy's; each as the fraction of
    ``finger - object`` found on the scene's nominal touch
    (:func:`scene_policy`: shipped, cached or computed), clipped to the
    skin band."""
    scene = load_scene(scene) if isinstance(scene, str) else scene
    if material is not None and not all(m in scene.materials
                                        for m in material.split(PAIR_SEPARATOR)):
        raise UnknownMaterialError(f"material {material!r} is not in scene {scene.name} (its "
                                   f"materials: {', '.join(scene.materials)})")
    return idle_from_fractions(policy_fractions(scene), material, object_temp_c,
                               finger_temp_c)


def precondition_from(fractions: dict[str, float], finger_temp_c: float):
    """The display's pre-conditioning (``MasterDisplay(precondition=...)``):
    ``f(material or None, object_temp_c) -> idle offset from the object, K``;
    its ``fractions`` attribute is the policy it applies (a recording keeps it)."""
    said = set()

    def offset(material, object_temp_c):
        if material is not None and material not in fractions:
            # A label the policy has no idle for (a group of three, a class
            # the scene's table lacks): idle as for an unknown object, never
            # fail a display period over it; said once per label.
            if material not in said:
                said.add(material)
                log.info("no idle for %r in the policy: idling as for an unknown object",
                         material)
            material = None
        return idle_from_fractions(fractions, material, object_temp_c,
                                   finger_temp_c) - object_temp_c
    offset.fractions = dict(fractions)
    return offset


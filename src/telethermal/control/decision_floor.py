"""The floor of a display that learns the material only when the slave
decides: what no controller can beat on a first touch of an unknown object.

The floor of :mod:`telethermal.control.display_floor` knows the material
from t = 0. A live display does not: until the slave's first decision
reaches it (``decision_s`` after contact), whatever it pumps is the same for
every material the object could be. So here the heat the module delivers to
its junction, ``q_j`` per slot, is one common trajectory over the slots
before ``decision_s`` and one trajectory per material after (a
non-anticipative, or causal, controller), all within the module's pumping
limits, from the same idle.

Criterion: the worst skin RMS error over the scene's materials (minimax,
as the idle policy). Given the common slots ``c``, each material's own
slots are an independent bounded least-squares problem (its error
``e_m(c)``, convex in ``c``: a partial minimum of a convex function, its
gradient ``-2/n A_c^T (r_m - A q_m)`` by the envelope theorem); the common
slots (a few: the decision comes in under 0.1 s) then minimise
``max_m e_m(c)`` in epigraph form (``s >= e_m(c)``) with SLSQP. The
pumping bounds are recomputed once on the first solution's junction (two
rounds, not iterated to convergence as
:func:`~telethermal.control.display_floor.best_touch` does: on fingertip-7
at 0.08 s a third round moved the worst material by under 1e-4 K).

How exact: the tails are solved by bounded least squares (bvls, warm-
started from the last active set while its KKT conditions hold to a
tolerance: within about 1e-6 of bvls's squared error, tested), the bounds
in two rounds, SLSQP to its tolerance; each can only leave the
computed minimax higher than the model's true one, so "no controller does
better" holds up to that slack (2e-3 K against the exact per-material
floor at t_d = 0, tested).

What it is a floor of: this model (the slots' input held, the error on
slot ends, a linear junction with the hot side at the idle's steady
temperature, the bounds ``BOUND_MARGIN`` inside the module's, one nominal
operator), for a display that knows nothing of the material before its
decision. The product's display renders the slave's posterior mixture
before the decision (``DisplayConfig.before = "prior"``): information this
model does not give it, so a display using it could in principle go
below. The per-material values are each material's error on the minimax
trajectory, not bounds for that material.

Decisions at different times per material (``decision_s`` a mapping, the
slave's measured decision time for each material): the information is then
nested. At any instant the display knows only whether the slave has decided;
an object not yet decided is one of the materials whose decision comes
later, so slot ``j`` is common to exactly the materials decided after it
and each material has its own slots from its decision on. The common
vector is then the longest prefix (to the latest decision), material ``m``
sees its first ``k_m`` slots; the rest is as above. With equal times it is
the single-time floor (the same arithmetic: tested against the scalar form).

Checks (tests/unit/test_decision_floor.py): with ``decision_s = 0`` it is the
worst of the per-material floors of ``display_floor.best_touch``; it never
falls when the decision comes later; with one material it is that
material's floor whenever the decision comes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize

from telethermal.control.display_floor import (BOUND_MARGIN, Hardware, JunctionPlant,
                                               bounded_fit, idle_hold, pump_bounds_w_m2)
from telethermal.errors import ControlError

#: Rounds re-computing the pumping bounds on the solution's junction.
BOUND_ROUNDS = 2
#: q in the solver's units (W/m^2 / SCALE) for conditioning.
SCALE = 1e4
#: An active slot's gradient, over its column's norm times the residual's,
#: that still counts as optimal (:class:`_Box`).
KKT_COSINE = 1e-4


@dataclass
class DecisionFloor:
    decision_s: float | dict    # one time for all, or each material's
    idle_c: float
    worst_k: float              # the minimax value: no causal controller's worst is lower
    per_material_k: dict        # each material's RMS on the minimax trajectory
    common_q_w_m2: np.ndarray   # what is pumped before the decision
    converged: bool
    #: With ``relative_to``: the least worst ratio of a material's RMS to its
    #: reference (no causal controller has every material under it); then
    #: ``worst_k`` is only the largest RMS on that trajectory.
    worst_ratio: float | None = None

    def summary(self) -> dict:
        decision = dict(self.decision_s) if isinstance(self.decision_s, dict) \
            else self.decision_s
        return {"decision_s": decision, "idle_c": self.idle_c,
                "floor_worst_k": self.worst_k, "per_material_k": dict(self.per_material_k),
                "common_q_w_m2": self.common_q_w_m2.tolist(), "converged": self.converged,
                "worst_ratio": self.worst_ratio}


class _Box:
    """``argmin ||a q - r||`` over ``lo <= q <= hi`` for one fixed ``a`` and
    bounds and a changing ``r``, warm-started: the last solution's active
    set (the slots at a bound) is tried first, its free slots by least
    squares (the factor kept while the set stays), and kept when the
    Karush-Kuhn-Tucker conditions hold (free slots inside their bounds, no
    active slot whose gradient would take it inside): for this convex
    problem, then the optimum (to the tolerances). Otherwise ``bounded_fit``
    (``bvls``, the exact active-set method) finds the new set. Each SLSQP step
    moves ``r`` a little, so the set seldom changes: a matrix-vector
    product instead of a bounded solve."""

    def __init__(self, a: np.ndarray, lo: np.ndarray, hi: np.ndarray):
        self.a, self.lo, self.hi = a, lo, hi
        self.scale = np.maximum(hi - lo, 1e-9)
        self._col = np.linalg.norm(a, axis=0)
        self._active = None            # -1 at lo, +1 at hi, 0 free
        self._solve = None             # r -> the free slots, for ``_active``
        #: Solves that kept the last active set, and those that ran bvls.
        self.calls = {"warm": 0, "cold": 0}

    def _factor(self, active: np.ndarray) -> None:
        free = active == 0
        fixed = np.where(active < 0, self.lo, self.hi) * (active != 0)
        pinv = np.linalg.pinv(self.a[:, free]) if free.any() else None
        pushed = self.a @ fixed

        def solve(r):
            q = fixed.copy()
            if pinv is not None:
                q[free] = pinv @ (r - pushed)
            return q
        self._active, self._solve = active, solve

    def _kkt(self, q: np.ndarray, r: np.ndarray) -> bool:
        tol = 1e-9 * self.scale
        free = self._active == 0
        if np.any(q[free] < self.lo[free] - tol[free]) or \
                np.any(q[free] > self.hi[free] + tol[free]):
            return False
        err = self.a @ q - r
        g = self.a.T @ err                       # half the objective's gradient
        # A slot's gradient against its column's reach (on render's plant
        # the columns span 12 orders of magnitude: the last slots barely
        # reach the skin): an active slot freed alone lowers the squared
        # error by at most (g_i / |a_i|)^2, under 1e-8 of it within this
        # tolerance (bvls itself leaves some at about 1e-5); many such
        # slots at once, more (1.35e-6 of it seen on a hard path).
        gtol = KKT_COSINE * self._col * (np.linalg.norm(err) + 1e-12)
        return not (np.any(g[self._active < 0] < -gtol[self._active < 0]) or
                    np.any(g[self._active > 0] > gtol[self._active > 0]))

    def __call__(self, r: np.ndarray) -> np.ndarray:
        if self._solve is not None:
            q = self._solve(r)
            if self._kkt(q, r):
                self.calls["warm"] += 1
                return q
        self.calls["cold"] += 1
        q = bounded_fit(self.a, r, self.lo, self.hi, exact=True)
        near = 1e-9 * self.scale
        self._factor(np.where(q <= self.lo + near, -1, np.where(q >= self.hi - near, 1, 0)))
        return q


class _Tails:
    """Each material's best own slots for given common slots (cached):
    material ``m`` shares the first ``k[m]`` slots of ``c``."""

    def __init__(self, plant: JunctionPlant, residuals, k, lo, hi):
        self.a, self.k = plant.skin_matrix, [int(x) for x in k]
        self.residuals, self.lo, self.hi = residuals, lo, hi
        self._key, self._out = None, None
        n = residuals.shape[1]
        self._boxes = [_Box(self.a[:, k_m:], lo[m, k_m:], hi[m, k_m:]) if k_m < n else None
                       for m, k_m in enumerate(self.k)]

    def __call__(self, c: np.ndarray):
        key = c.tobytes()
        if key != self._key:
            n = self.residuals.shape[1]
            q, mse, grad = [], [], []
            for m, r in enumerate(self.residuals):
                k_m = self.k[m]
                a_c, a_t = self.a[:, :k_m], self.a[:, k_m:]
                rest = r - a_c @ c[:k_m]
                tail = self._boxes[m](rest) if k_m < n else np.zeros(0)
                err = rest - a_t @ tail
                q.append(np.r_[c[:k_m], tail])
                mse.append(float(err @ err) / n)
                grad.append(np.r_[-2.0 / n * (a_c.T @ err), np.zeros(len(c) - k_m)])
            self._key, self._out = key, (np.array(q), np.array(mse), np.array(grad))
        return self._out


def _common(tails: _Tails, lo_c, hi_c, start, weight):
    """argmin over c in [lo_c, hi_c] of max_m weight_m e_m(c) (SLSQP,
    epigraph form, c scaled by SCALE)."""
    k_d = len(lo_c)
    if k_d == 0:
        return np.zeros(0), True

    def cons(x):
        return x[-1] - weight * tails(x[:-1] * SCALE)[1]

    def cons_jac(x):
        grad = weight[:, None] * tails(x[:-1] * SCALE)[2] * SCALE
        return np.hstack([-grad, np.ones((len(grad), 1))])

    x0 = np.r_[np.clip(start, lo_c, hi_c) / SCALE,
               (weight * tails(np.clip(start, lo_c, hi_c))[1]).max()]
    res = minimize(lambda x: x[-1], x0, jac=lambda x: np.r_[np.zeros(k_d), 1.0],
                   method="SLSQP", constraints=[{"type": "ineq", "fun": cons, "jac": cons_jac}],
                   bounds=[*zip(lo_c / SCALE, hi_c / SCALE), (0.0, None)],
                   options={"maxiter": 200, "ftol": 1e-9})
    return res.x[:-1] * SCALE, bool(res.success)


def _slots(plant: JunctionPlant, decision_s: float, name: str) -> int:
    """The slots wholly before a decision at ``decision_s`` (the common
    ones). A slot the decision falls inside is the material's own: the
    display is credited with the material from that slot's start, up to one
    slot early, so the floor never gives it less than it has."""
    if not (isinstance(decision_s, (int, float)) and math.isfinite(decision_s)
            and decision_s >= 0):
        raise ControlError(f"decision_s{name} must be finite and >= 0, got {decision_s}")
    return min(int(math.floor(decision_s / plant.grid_s + 1e-9)), plant.n)


def decision_floor(hw: Hardware, plant: JunctionPlant, targets: dict, idle_c: float,
                   decision_s: float | dict, relative_to: dict | None = None) -> DecisionFloor:
    """The minimax floor over ``targets`` (material -> direct-contact skin
    at slot ends, C, shape (plant.n,)) of a controller that learns the
    material ``decision_s`` after contact (one time, or a mapping material
    -> its own time: nested information), from the pad idle at ``idle_c``.
    ``relative_to`` (material -> a reference RMS, K, e.g. its floor knowing
    the material at contact): minimise the worst ratio to it instead; its
    value is ``worst_ratio``: no causal controller has every material's
    RMS under that multiple of its reference."""
    if not targets:
        raise ControlError("no material to take the floor over")
    names = list(targets)
    if relative_to is None:
        weight = np.ones(len(names))
    else:
        refs = [relative_to.get(m) for m in names]
        if not all(isinstance(r, (int, float)) and math.isfinite(r) and r > 0 for r in refs):
            raise ControlError(f"relative_to: need a positive reference RMS for each of "
                               f"{', '.join(names)}, got {relative_to}")
        weight = 1.0 / np.square(np.asarray(refs, dtype=np.float64))
    if isinstance(decision_s, dict):
        missing = [m for m in names if m not in decision_s]
        if missing:
            raise ControlError(f"decision_s: no decision time for {', '.join(missing)}")
        k = np.array([_slots(plant, decision_s[m], f"[{m!r}]") for m in names])
    else:
        k = np.full(len(names), _slots(plant, decision_s, ""))
    k_d = int(k.max())
    free_j, free_s = plant.free(idle_c)
    residuals = np.stack([np.asarray(targets[m], float) - free_s for m in names])
    n_mat, n = residuals.shape
    hot = np.full((n_mat, n), idle_hold(hw, idle_c)[1])
    cold = np.broadcast_to(np.r_[idle_c, free_j[:-1]], (n_mat, n)).copy()
    c, converged = np.zeros(k_d), True
    for round_ in range(BOUND_ROUNDS):
        lo, hi = pump_bounds_w_m2(hw, cold, hot)
        margin = BOUND_MARGIN * (hi - lo)
        lo, hi = lo + margin, hi - margin
        tails = _Tails(plant, residuals, k, lo, hi)
        # Slot j is common to the materials decided after it: the bounds of
        # those (every material shares slot 0 .. min(k) - 1).
        shares = np.arange(k_d)[None, :] < k[:, None]
        lo_c = np.where(shares, lo[:, :k_d], -np.inf).max(axis=0)
        hi_c = np.where(shares, hi[:, :k_d], np.inf).min(axis=0)
        c, converged = _common(tails, lo_c, hi_c, c, weight)
        q, mse, _ = tails(c)
        if round_ + 1 < BOUND_ROUNDS:
            junction = free_j[None, :] + q @ plant.junction_matrix.T
            cold = np.hstack([np.full((n_mat, 1), idle_c), junction[:, :-1]])
    rms = np.sqrt(mse)
    ratio = None if relative_to is None else float(np.sqrt((weight * mse).max()))
    return DecisionFloor(dict(decision_s) if isinstance(decision_s, dict) else decision_s,
                         float(idle_c), float(rms.max()),
                         {m: float(v) for m, v in zip(names, rms)}, c, converged, ratio)

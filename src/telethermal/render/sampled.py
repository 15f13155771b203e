"""A generator carried over the wire: each material's normalised flux
sampled at log-spaced times (``session_config.curves``, ``flux_trajectory``)
and interpolated in log t on the receiving side.

256 knots from the generator's first fitted time to its last reproduce the
network to 1e-4 of its peak (tested); below the first knot the curve ramps
linearly from 0 at contact, as the network does; past the last it holds.
"""

from __future__ import annotations

from bisect import bisect_left

import numpy as np

from telethermal.errors import IdentificationError

N_KNOTS = 256


def sample_curves(generator, materials=None, n_knots: int = N_KNOTS,
                  t_last_s: float = 60.0) -> dict[str, dict[str, list[float]]]:
    """``{material: {"t_s": [...], "g_w_m2k": [...]}}`` for the wire."""
    fitted = getattr(generator, "t_range_s_", None)     # a network's; the others have none
    t_first = fitted[0] if fitted else 1e-3
    t_last = max(fitted[1] if fitted else t_last_s, t_first * 10)
    t = np.geomspace(t_first, t_last, n_knots)
    names = list(materials) if materials is not None else generator.materials
    return {m: {"t_s": t.tolist(), "g_w_m2k": generator.normalised(m, t).tolist()}
            for m in names}


class SampledGenerator:
    """``normalised``/``normalised_many``/``materials`` like the fitted ones."""

    def __init__(self, curves: dict):
        self._curves = {}
        self._shared = {}
        self._given = dict(curves)
        for name, curve in curves.items():
            t = np.asarray(curve["t_s"], dtype=np.float64)
            g = np.asarray(curve["g_w_m2k"], dtype=np.float64)
            if len(t) < 2 or len(t) != len(g) or np.any(np.diff(t) <= 0) or t[0] <= 0:
                raise IdentificationError(f"curve for {name!r}: need >= 2 ascending positive "
                                          "times and as many values")
            self._curves[name] = (np.log(t), g, t[0])
        self._shared: dict = {}
        self._shared_lists: dict = {}

    @property
    def materials(self) -> list[str]:
        return sorted(self._curves)

    def set_curve(self, name: str, t_s, g_w_m2k) -> None:
        """Replace (or add) one curve; the others keep their exact knots
        (rebuilt from what was given, not from exp(log t), which rounds). A
        curve equal to the one held changes nothing, caches included."""
        held = self._given.get(name)
        if held is not None and np.array_equal(np.asarray(held["t_s"], dtype=np.float64),
                                               np.asarray(t_s, dtype=np.float64)) and \
                np.array_equal(np.asarray(held["g_w_m2k"], dtype=np.float64),
                               np.asarray(g_w_m2k, dtype=np.float64)):
            return
        self.__init__({**self._given, name: {"t_s": t_s, "g_w_m2k": g_w_m2k}})

    def normalised(self, material: str, t_s) -> np.ndarray:
        if material not in self._curves:
            raise IdentificationError(f"no curve for {material!r}; have {', '.join(self.materials)}")
        log_t, g, t_first = self._curves[material]
        t = np.atleast_1d(np.asarray(t_s, dtype=np.float64))
        q = np.interp(np.log(np.maximum(t, t_first)), log_t, g)
        return np.where(t >= t_first, q, np.clip(t, 0, None) / t_first * g[0])

    def _shared_knots(self, key: tuple):
        """(log t, stacked values, first time) when every material of ``key``
        has the same knots, else False; cached per tuple."""
        shared = self._shared.get(key)
        if shared is None:
            curves = [self._curves[m] for m in key] if all(m in self._curves for m in key) \
                else None
            if curves and all(np.array_equal(c[0], curves[0][0]) for c in curves):
                shared = (curves[0][0], np.stack([c[1] for c in curves]), curves[0][2])
            else:
                shared = False
            self._shared[key] = shared
        return shared

    def normalised_many(self, materials, t_s) -> np.ndarray:
        """Every material at once; one interpolation when they share knots
        (they do when they come from one ``sample_curves``)."""
        shared = self._shared_knots(tuple(materials))
        if shared is False:
            return np.stack([self.normalised(m, t_s) for m in materials])
        log_t, g, t_first = shared
        t = np.atleast_1d(np.asarray(t_s, dtype=np.float64))
        x = np.log(np.maximum(t, t_first))
        i = np.clip(np.searchsorted(log_t, x), 1, len(log_t) - 1)
        w = np.clip((x - log_t[i - 1]) / (log_t[i] - log_t[i - 1]), 0.0, 1.0)
        q = g[:, i - 1] * (1 - w) + g[:, i] * w
        return np.where(t >= t_first, q, np.clip(t, 0, None) / t_first * g[:, :1])

    def weighted_sum(self, materials, weights, t_s) -> list[float] | None:
        """``sum_m w_m g_m(t)`` at a few times, as floats: the same
        arithmetic as ``np.sum(w[:, None] * normalised_many(...), axis=0)``,
        operation for operation, so the same bits (tested), without numpy's
        per-call cost on arrays of three (the display's period calls it
        once). None when the materials do not share knots."""
        key = tuple(materials)
        lists = self._shared_lists.get(key)
        if lists is None:
            shared = self._shared_knots(key)
            lists = (shared[0].tolist(), [row.tolist() for row in shared[1]], float(shared[2])) \
                if shared is not False else False
            self._shared_lists[key] = lists
        if lists is False:
            return None
        log_t, rows, t_first = lists
        times = [float(t) for t in t_s]
        # numpy's log, not math's: the two may differ in the last bit.
        xs = np.log(np.maximum(np.array(times), t_first)).tolist()
        last = len(log_t) - 1
        out = []
        for t, x in zip(times, xs):
            i = min(max(bisect_left(log_t, x), 1), last)
            a = (x - log_t[i - 1]) / (log_t[i] - log_t[i - 1])
            a = min(max(a, 0.0), 1.0)
            inside = t >= t_first
            ramp = max(t, 0.0) / t_first
            total = 0.0                 # numpy's sum starts from its identity (so -0.0 -> 0.0)
            for w, g in zip(weights, rows):
                q = g[i - 1] * (1 - a) + g[i] * a if inside else ramp * g[0]
                total = total + w * q
            out.append(total)
        return out

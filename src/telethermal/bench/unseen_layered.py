"""``telethermal bench unseen``'s layered objects (issue 30's hard case, "a
thin object on a metal base: the estimate drifts with time").

A layered object has no single true effusivity: the pad feels its surface
layer first and its base once heat has crossed the layer (``L^2 / alpha``
sets when). So instead of an error and a coverage against one value, per
window the median estimate beside the effusivities of its surface and of
the layer beneath it, and the **drift** from the first window to the last:
the median ratio of the two estimates, how many touches moved toward the
base, and how many moved beyond their intervals (the first and the last
window's 95 % intervals do not overlap). Layered objects are left out of the
error and coverage targets and of the pooled coverage (their JSON says so:
``"layered": true`` and the stack).
"""

from __future__ import annotations

import numpy as np

#: What the error and coverage fields of a layered object hold.
NOT_ONE_VALUE = ("not_applicable: a layered object has no single true effusivity (the "
                 "estimate moves from its surface's toward its base's); see 'drift'")
#: Why a layered object's oracle column is not rendered.
ORACLE_NOT_RUN = ("not_run: the oracle renders one true effusivity (a semi-infinite "
                  "object) through the display's closed form; it cannot be given a stack")


def stack(obj) -> list[dict]:
    """The object's layers from its surface outwards, with their effusivities."""
    return [{"material": la.material.name, "thickness_m": la.thickness_m,
             "effusivity_w_s05_m2k": float(la.material.effusivity)} for la in obj.layers()]


def _overlap(a, b) -> bool:
    return a[0] <= b[1] and b[0] <= a[1]


def drift(rows: list[dict], first_s: float, last_s: float, base_e: float) -> dict:
    """The estimate's change from window ``first_s`` to ``last_s`` over the
    touches ``rows`` (each with ``windows``: window s -> estimate)."""
    pairs = [(r["windows"][first_s], r["windows"][last_s]) for r in rows]
    ratio = [b.effusivity_w_s05_m2k / a.effusivity_w_s05_m2k for a, b in pairs]
    toward = [abs(np.log(b.effusivity_w_s05_m2k / base_e))
              < abs(np.log(a.effusivity_w_s05_m2k / base_e)) for a, b in pairs]
    apart = [not _overlap(a.interval_w_s05_m2k, b.interval_w_s05_m2k) for a, b in pairs]
    beyond = [x and y for x, y in zip(toward, apart)]
    return {"from_s": first_s, "to_s": last_s, "n": len(pairs),
            "ratio_p50": float(np.median(ratio)), "ratio_min": float(min(ratio)),
            "ratio_max": float(max(ratio)), "toward_base": int(sum(toward)),
            "intervals_disjoint": int(sum(apart)),
            "toward_base_beyond_intervals": int(sum(beyond)),
            "beyond_rate": sum(beyond) / len(pairs)}


def summary(obj, rows: list[dict], windows) -> dict:
    """A layered object's figures over its touches (every seed): per window
    the median estimate, its interval's median relative width, how many
    estimates fit their model and reached the grid's bound; the drift."""
    layers = stack(obj)
    surface_e, base_e = layers[0]["effusivity_w_s05_m2k"], layers[1]["effusivity_w_s05_m2k"]
    out = {"layered": True, "stack": layers, "surface_effusivity_w_s05_m2k": surface_e,
           "base_effusivity_w_s05_m2k": base_e, "estimate_p50_w_s05_m2k": {},
           "interval_width_rel": {}, "fits_rate": {}, "at_bound": {}}
    for w in windows:
        ests = [r["windows"][w] for r in rows]
        key = f"{w:g}"
        out["estimate_p50_w_s05_m2k"][key] = float(np.median(
            [e.effusivity_w_s05_m2k for e in ests]))
        out["interval_width_rel"][key] = float(np.median(
            [(e.interval_w_s05_m2k[1] - e.interval_w_s05_m2k[0]) / e.effusivity_w_s05_m2k
             for e in ests]))
        out["fits_rate"][key] = sum(e.fits for e in ests) / len(ests)
        out["at_bound"][key] = sum(e.at_bound for e in ests)
    out["drift"] = drift(rows, windows[0], windows[-1], base_e)
    return out


def describe(r: dict) -> str:
    """The stack in words: ``glass 1 mm (e 1620) on aluminium 30 mm (e 20100)``."""
    return " on ".join(f"{la['material']} {1e3 * la['thickness_m']:g} mm "
                       f"(e {la['effusivity_w_s05_m2k']:.0f})" for la in r["stack"])


def section_line(name: str, r: dict, windows) -> str:
    """One layered object's row of ``bench report``'s table (its error and
    coverage columns hold the median estimate and the drift instead)."""
    rep = r["reported"] if isinstance(r["reported"], dict) else {}
    est = " / ".join(f"{r['estimate_p50_w_s05_m2k'][k]:,.0f}" for k in windows)
    d = r["drift"]
    first = rep.get("named_then_new", 0)
    return (f"| {name} (unseen, layered: {describe(r)}) | - | median estimate {est} | drift "
            f"{d['from_s']:g} -> {d['to_s']:g} s x{d['ratio_p50']:.2f}, "
            f"{d['toward_base_beyond_intervals']} of {d['n']} toward the base beyond the "
            f"intervals; fits {' / '.join(f'{100 * v:.0f}' for v in r['fits_rate'].values())} % "
            f"| - | {rep.get('named', '-')} | {rep.get('new', '-')}"
            f"{f' ({first})' if first else ''} | {rep.get('unknown', '-')} |")

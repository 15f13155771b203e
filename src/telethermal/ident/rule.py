"""The anytime rule, one window at a time: the one copy of it.

Three places walk a touch's posteriors window by window and must agree to
the window: the bench's and the recording's :func:`~telethermal.ident.anytime.decide`,
the slave's :class:`~telethermal.ident.anytime.StreamingIdentifier` (sample
by sample), and the calibration's check of which windows may commit
(:func:`~telethermal.ident.base.commit_from_index`). Each feeds
:class:`AnytimeRule` the window's posterior and what it knows of the window
(whether the calibration lets it commit there, the pressing force, whether
the touch lies outside every class) and reads back what the rule committed.

The rule: a class commits for good once its calibrated posterior has
passed ``threshold`` at ``confirm`` windows in a row (:class:`Runs`); a
class passing it at a touch unlike every trained class is not final (a few
samples can be); when no class passes but the two most probable together
do, for ``confirm`` windows in a row, the pair commits and keeps refining
(a member passing alone later replaces it). A window where the force lies
outside the trained range, or before the calibration's first committing
window, commits nothing and breaks the runs.
"""

from __future__ import annotations

from typing import Callable

import numpy as np


class Runs:
    """Consecutive windows a commitment's condition has held (the same
    class, or the same pair): a decision commits once it has held for
    ``need`` windows in a row (``confirm_windows``). Each window is a
    separate fit, so a posterior can spike past the threshold at one window
    and fall back at the next (seen: a rubber touch at 0.998 plexiglass at
    0.44 s, 1.000 rubber at 0.50 s); a crossing that holds is the evidence,
    a spike is not."""

    def __init__(self, need: int):
        self.need = max(1, int(need))
        self._single, self._pair = (None, 0), (None, 0)

    def single(self, k: int, holds: bool) -> bool:
        """Window's best class ``k`` passed the threshold (``holds``): commit now?"""
        key, n = self._single
        self._single = ((k, n + 1 if key == k else 1) if holds else (None, 0))
        return holds and self._single[1] >= self.need

    def pair(self, members, holds: bool) -> bool:
        """The two most probable together passed it (``holds``): commit the pair now?"""
        key = tuple(sorted(int(m) for m in members)) if holds else None
        old, n = self._pair
        self._pair = ((key, n + 1 if old == key else 1) if holds else (None, 0))
        return holds and self._pair[1] >= self.need

    def reset(self) -> None:
        """A window that may not commit (force outside, before the schedule)."""
        self._single, self._pair = (None, 0), (None, 0)


def top_pair(p: np.ndarray, threshold: float):
    """Indices of the two most probable classes (most probable first) when
    together they pass the threshold and there are more than two classes;
    else None (the caller has checked that neither passes alone)."""
    if len(p) < 3:
        return None
    top = np.argsort(p)[::-1][:2]
    return top if p[top].sum() >= threshold else None


class AnytimeRule:
    """The anytime rule's state over one touch (see the module).

    Feed :meth:`step` each window in order; it returns ``("class", k)`` when
    class ``k`` commits for good (the walk ends there), ``("pair", (a, b))``
    when a pair commits (it stands, refining, until a member commits alone),
    or None. After the last window, :attr:`pair` is the standing pair (or
    None), :attr:`unlike` whether the last confident window was unlike every
    class, and :attr:`force_outside` whether the last window's force was
    outside the trained range: what the touch ends as when nothing committed.
    """

    def __init__(self, threshold: float, confirm: int = 1):
        self.threshold = float(threshold)
        self.runs = Runs(confirm)
        self.pair = None              # the standing pair's class indices, sorted by posterior
        self.pair_window = None       # the window index it committed at
        self.unlike = False
        self.force_outside = False

    def step(self, i: int, p: np.ndarray, may_commit: bool = True, force_outside: bool = False,
             unlike: Callable[[], bool] | None = None):
        """Window ``i`` with calibrated posterior ``p``.

        ``may_commit``: the calibration supports a commitment here;
        ``force_outside``: the pressing force lies outside the trained
        range; ``unlike``: asked (only when it matters: it may cost a model
        evaluation) whether the touch lies outside every class here.
        """
        self.force_outside = bool(force_outside)
        if force_outside or not may_commit:
            self.runs.reset()
            return None
        k = int(np.argmax(p))
        if self.runs.single(k, bool(p[k] >= self.threshold)):
            # Unlike every class here: not final, the touch is watched on.
            self.unlike = bool(unlike()) if unlike is not None else False
            return None if self.unlike else ("class", k)
        pair = top_pair(p, self.threshold)
        holds = self.pair is None and pair is not None and \
            not (unlike is not None and unlike())
        if self.runs.pair(pair if holds else (), holds):
            self.pair, self.pair_window = tuple(int(j) for j in pair), i
            return ("pair", self.pair)
        return None

"""A decided touch watched to its last window (issue 29: the slave's sample
loop): effusivity-fit makes each window's fit as the window comes
(``EffusivityFit.follow``), so no sample waits for a backlog of fits at the
last window, and the decisions are the very same (each window's fit starts
from the previous one's either way). Counted in fits, not timed.

The model: effusivity-fit on fingertip-7's seed-0 touches, windows up to
0.3 s (tests/unit/fitcases.py)."""

import pytest

from telethermal.ident import fitted
from telethermal.ident.anytime import StreamingIdentifier
from telethermal.ident.effusivity import EffusivityEstimator

from fitcases import SCENE, contacts as _contacts


@pytest.fixture(scope="module")
def model(fit_model_0_3s):
    return fit_model_0_3s


def _stream(model, x, gap_k, monkeypatch):
    """Every estimate pushed out, and the fits each sample's push made."""
    fitted.clear_cache()
    count = [0]
    real = EffusivityEstimator.estimate

    def counted(self, *a, **kw):
        count[0] += 1
        return real(self, *a, **kw)

    with monkeypatch.context() as m:
        m.setattr(EffusivityEstimator, "estimate", counted)
        stream = StreamingIdentifier(model, gap_k)
        out, fits = [], []
        for row in x * gap_k:
            before = count[0]
            est = stream.push(row)
            fits.append(count[0] - before)
            if est is not None:
                out.append(est)
            if stream.finished:
                break
    return out, fits


def test_a_watched_touch_fits_one_window_at_a_time_and_decides_the_same(model, monkeypatch):
    held = _contacts(SCENE, 3)
    checked = 0
    for j in range(len(held)):
        if held.labels[j] not in ("aluminium", "wood"):
            continue
        x = held.x[j, :int(held.lengths[j])]
        followed, fits = _stream(model, x, held.gap_k[j], monkeypatch)
        with monkeypatch.context() as m:
            m.setattr(type(model), "follow", None)
            backlog, fits_then = _stream(model, x, held.gap_k[j], monkeypatch)
        assert [(e.label, e.reason, e.t_s, e.effusivity_w_s05_m2k, e.effusivity_lo_w_s05_m2k,
                 e.effusivity_hi_w_s05_m2k) for e in followed] == \
            [(e.label, e.reason, e.t_s, e.effusivity_w_s05_m2k, e.effusivity_lo_w_s05_m2k,
              e.effusivity_hi_w_s05_m2k) for e in backlog]
        decided = [e for e in followed if e.final]
        first = decided[0].t_s if decided else None
        if first is not None and first < 0.2:        # decided early, then watched
            assert max(fits) == 1
            assert max(fits_then) >= round((0.3 - first) / 0.02) - 1
            checked += 1
    assert checked >= 5, "too few touches decided early to show the watch"

"""A pad model that does not fit the pad is caught (issue 44, deliverable
4): the touch is not named by the pad model ("pad model does not fit:
recalibrate"), never a confident wrong name."""

from __future__ import annotations


import numpy as np
import pytest

from telethermal.data.generate import pad_database
from telethermal.ident.anytime import MisfitRun, StreamingIdentifier, decide, decide_all
from telethermal.ident.label import Reason
from telethermal.ident.prepare import from_trials
from telethermal.ident.registry import make
from telethermal.physics.as_built import AsBuilt, BuiltFactors, with_as_built
from telethermal.physics.scene import load_scene
from test_pad_calibration import _scene as reference_scene

MATERIALS = ("steel", "plexiglass", "wood")


def _scene(trials):
    return reference_scene(MATERIALS, trials)


@pytest.fixture(scope="module")
def model():
    scene = _scene(6)
    return make("effusivity-fit", scene=load_scene("fingertip-7")).fit(
        from_trials(pad_database(scene, np.random.default_rng(1)))[0])


@pytest.mark.slow          # over 10 s here: make test-all and CI run it
def test_a_sensor_lag_20_percent_off_is_flagged_and_never_named_wrong(model):
    """The fit's residual against the noise: a lag of 0.18 s fitted with a
    model of 0.15 s reads chi2/dof 7-45 from 0.25 s (as modelled: under
    0.05; the limit 2). Target (issue 44): flagged on >= 90 % of touches,
    none committed wrong."""
    lagged = with_as_built(_scene(6), AsBuilt(BuiltFactors((1, 1, 1), flux_lag_s=1.2),
                                              BuiltFactors((1, 1, 1))))
    contacts = from_trials(pad_database(lagged, np.random.default_rng(2)))[0]
    decisions = decide_all(model, contacts)
    flagged = [d.reason == Reason.PAD_MODEL_MISFIT for d in decisions]
    assert np.mean(flagged) >= 0.9
    wrong = [(t, str(d.label)) for d, t in zip(decisions, contacts.labels)
             if not d.label.is_unknown and not d.label.holds(t)]
    assert not wrong
    # The slave's sample-by-sample decision is the same.
    i = int(np.argmax(flagged))
    stream = StreamingIdentifier(model, contacts.gap_k[i])
    for row in contacts.x[i, :contacts.lengths[i]]:
        stream.push(row * contacts.gap_k[i])
        if stream.finished:
            break
    assert stream.estimate.reason == Reason.PAD_MODEL_MISFIT
    assert stream.estimate.label.is_unknown


def test_touches_of_the_pad_as_modelled_are_not_flagged(model):
    contacts = from_trials(pad_database(_scene(6), np.random.default_rng(3)))[0]
    decisions = decide_all(model, contacts)
    assert not [d for d in decisions if d.reason == Reason.PAD_MODEL_MISFIT]
    assert all(d.label.is_unknown or d.label.holds(t) for d, t in zip(decisions,
                                                                       contacts.labels))


def test_the_misfit_statistic_is_given_against_the_sensor_noise_alone_too(model):
    """``misfit_chi2``: the statistic the misfit tests (against the flux
    noise plus the curves' allowance) and the same residual against the
    noise alone, whose variance is smaller: larger, by the ratio of the two
    variances where the amplitude's prior moves nothing (within 5 %, the
    prior's pull on the amplitude). The misfit is the first past 2."""
    from telethermal.ident.calibration import CHI2_MAX
    contacts = from_trials(pad_database(_scene(1), np.random.default_rng(3)))[0]
    est, gap_k = model.estimator()
    last = len(model.windows_s_) - 1
    for i in range(len(contacts.labels)):
        x = contacts.x[i:i + 1, :contacts.lengths[i]]
        chi2, chi2_noise = model.misfit_chi2(x, last)
        row = model.window(x, model.windows_s_[last])[0, :, 0]
        ratio = est.noise_var(row, gap_k) / est.noise_var(row, gap_k, allowance=0.0)
        assert ratio > 1.5                       # the allowance dominates the denominator
        assert chi2_noise == pytest.approx(chi2 * ratio, rel=0.05)
        assert model.misfit(x, last) is (chi2 > CHI2_MAX)


def test_samples_the_driver_filled_in_are_not_counted_as_measured(model):
    """A frame lost on the line is held by the driver (the previous sample
    repeated, ``ContactSamples.measured`` False). Counted as measurements,
    seven held samples (one every 100 ms from 140 ms, 5 % lost frames as
    tests/integration/test_slave_devices.py's) push a pad as modelled past
    the limit by 0.5 s (measured: steel 3.1, plexiglass 3.9, wood 4.0;
    each held sample is off by the flux's change over 10 ms, against an
    allowance of 0.1 % of the rms); left out of the residual and its
    degrees of freedom, the same touch reads 0.14-0.19, as the pad as
    modelled does (0.003-0.043, docs/calibration.md). Here the held
    samples reach the fit with their held values (``misfit_chi2`` given the
    mask alone); decide() and the stream give them as missing, and the fit
    leaves them out too (the next test). The statistic with every sample
    marked measured is the statistic without a mask; a mask shorter than
    the window is an error."""
    from telethermal.errors import IdentificationError
    from telethermal.ident.calibration import CHI2_MAX
    contacts = from_trials(pad_database(_scene(1), np.random.default_rng(3)))[0]
    i = list(contacts.labels).index("wood")
    n = int(contacts.lengths[i])
    x = contacts.x[i:i + 1, :n].copy()
    measured = np.ones(n, dtype=bool)
    for k in range(14, 80, 10):     # 140, 240, ... 740 ms: the previous sample held
        x[0, k] = x[0, k - 1]
        measured[k] = False
    last = len(model.windows_s_) - 1
    w = int(np.argmin(np.abs(np.asarray(model.windows_s_) - 0.5)))
    counted = model.misfit_chi2(x, w)[0]
    kept = model.misfit_chi2(x, w, measured)[0]
    assert counted > CHI2_MAX > kept, (counted, kept)
    assert model.misfit_chi2(x, w, np.ones(n, bool)) == model.misfit_chi2(x, w)
    with pytest.raises(IdentificationError, match="measured flags"):
        model.misfit_chi2(x, last, measured[:10])
    # A window of 5 samples has 1 degree of freedom over the fit's 4; one of
    # them filled in leaves none: no statistic (nor for a window of 4).
    sizes = [len(model.window(x, ws)[0, :, 0]) for ws in model.windows_s_]
    five = sizes.index(5)
    assert model.misfit_chi2(x, five) is not None
    early = np.ones(n, bool)
    early[2] = False
    assert model.misfit_chi2(x, five, early) is None
    assert all(model.misfit_chi2(x, i) is None for i, m in enumerate(sizes) if m <= 4)
    # decide() and the slave's stream, told which samples were filled in,
    # do not end the touch on the pad model's misfit (counting them, it
    # does: 3.2 at the last window); the stream agrees.
    d = decide(model, x[0], contacts.gap_k[i], measured=measured)
    assert d.reason != Reason.PAD_MODEL_MISFIT
    assert decide(model, x[0], contacts.gap_k[i]).reason == Reason.PAD_MODEL_MISFIT
    stream = StreamingIdentifier(model, contacts.gap_k[i])
    for row, m in zip(x[0], measured):
        stream.push(row * contacts.gap_k[i], measured=bool(m))
        if stream.finished:
            break
    assert (stream.estimate.label, stream.estimate.reason) == (d.label, d.reason)


@pytest.mark.parametrize("flags, last, ends", [
    ((True,), 5, None),                      # one window past the limit: not the verdict
    ((True, False, True), 5, None),          # two, not in a row
    ((False, True, True), 5, 2),             # two in a row: ends at the second
    ((False, False, True), 2, 2),            # at the touch's last window, one is enough
])
def test_the_misfit_ends_a_touch_at_confirm_windows_in_a_row_or_at_its_last(flags, last, ends):
    """MisfitRun with confirm_windows 2: the window index the touch ends on
    the pad model's misfit, or None (then every flagged window commits
    nothing: anytime.decide and the stream pass may_commit False there)."""
    run = MisfitRun(2)
    got = next((i for i, f in enumerate(flags) if run.step(f, i == last)), None)
    assert got == ends


def test_a_sample_held_in_the_rise_is_missing_data_to_the_fit(model):
    """A sample held in the touch's rise (under 80 ms, where the flux moves
    by several per cent a sample) pulled the fit when it counted: the
    frame at 20 ms held, these touches' fits at 0.1 s move ln e by 0.26 to
    2.8 (14 to 21 of the estimate's sd) and read chi2/dof 2,400-2,900
    (limit 2). Given as missing (``measured``), the fit reads the measured
    samples at their own instants: its estimate is the complete touch's
    within one sd of its own (the data's uncertainty: leaving one sample
    of eleven out of a consistent fit moves it by much less; measured:
    under 3e-4 in ln e against sds of 0.018-0.13) and its residual stays
    under the limit (0.005-0.035, as the complete touch's).
    decide() told which sample was filled in names the touch as the
    complete touch is named."""
    from telethermal.ident.calibration import CHI2_MAX
    contacts = from_trials(pad_database(_scene(1), np.random.default_rng(3)))[0]
    est, gap_k = model.estimator()
    for i, label in enumerate(contacts.labels):
        n = int(contacts.lengths[i])
        x = contacts.x[i, :n, 0]
        held, measured = x.copy(), np.ones(n, bool)
        held[2], measured[2] = held[1], False          # the frame at 20 ms lost
        full = est.estimate(x[:11], gap_k)
        missing = est.estimate(held[:11], gap_k, measured=measured[:11])
        counted = est.estimate(held[:11], gap_k)
        assert missing.n_samples == 10 and full.n_samples == 11
        assert abs(missing.theta[0] - full.theta[0]) < full.log_sd, label
        assert abs(counted.theta[0] - full.theta[0]) > full.log_sd, label   # what it mends
        assert missing.chi2_per_dof < CHI2_MAX < counted.chi2_per_dof
        d_full = decide(model, contacts.x[i], contacts.gap_k[i])
        d_held = decide(model, held[:, None], contacts.gap_k[i], measured=measured)
        assert (d_held.label, d_held.reason) == (d_full.label, d_full.reason), label


def _lagged(trials: int):
    return with_as_built(_scene(trials), AsBuilt(BuiltFactors((1, 1, 1), flux_lag_s=1.2),
                                                 BuiltFactors((1, 1, 1))))


@pytest.fixture(scope="module")
def with_lda(model):
    """The module's model with its model-free fallback trained on the same
    touches (the pad as modelled), as ``train_identifier`` trains it; a
    copy, the module's model stays without one."""
    import copy

    from telethermal.ident.registry import with_fallback
    contacts = from_trials(pad_database(_scene(6), np.random.default_rng(1)))[0]
    return with_fallback(copy.copy(model), contacts)


@pytest.fixture(scope="module")
def lab_model():
    """A lab's: trained on touches of its own pad (flux lag 20 % over the
    design, which the pad model keeps), with the fallback trained on the
    same touches (``models --data``); and the same model without it."""
    import copy

    from telethermal.ident.registry import with_fallback
    contacts = from_trials(pad_database(_lagged(6), np.random.default_rng(1)))[0]
    alone = make("effusivity-fit", scene=load_scene("fingertip-7")).fit(contacts)
    return alone, with_fallback(copy.copy(alone), contacts)


def _stream(model, contacts, i):
    """The slave's stream of touch ``i``, with its pressing force (as decide_all reads it)."""
    stream = StreamingIdentifier(model, contacts.gap_k[i])
    n = contacts.lengths[i]
    for row, force_n in zip(contacts.x[i, :n], contacts.force_n[i, :n]):
        stream.push(row * contacts.gap_k[i], float(force_n))
        if stream.finished:
            break
    return stream.estimate


def test_touches_the_misfit_refuses_are_named_by_the_fallback_never_wrong(lab_model):
    """Issue 44, deliverable 4: a lab's pad whose flux lag is 20 % over its
    model, the identifier trained on its own touches. Without a fallback
    every touch the check flags ends unknown (``pad model does not fit:
    recalibrate``): 18 of 18 here. With ``effusivity-lda`` trained beside it
    on the same touches, every flagged touch is named by it (reason ``pad
    model does not fit: named by the fallback``), none wrong (measured: 18
    of 18 on these touches, 17 of 17 on seed 3's); a touch not flagged is
    decided as before. The slave's stream agrees with decide() on every
    touch (label, reason, time)."""
    alone, both_model = lab_model
    contacts = from_trials(pad_database(_lagged(6), np.random.default_rng(2)))[0]
    alone_d, both = decide_all(alone, contacts), decide_all(both_model, contacts)
    flagged = [i for i, d in enumerate(alone_d) if d.reason == Reason.PAD_MODEL_MISFIT]
    assert len(flagged) >= 0.9 * len(alone_d)            # the target for the check
    assert all(alone_d[i].label.is_unknown for i in flagged)
    assert [i for i in flagged if both[i].reason == Reason.PAD_MODEL_FALLBACK] == flagged
    assert all(both[i] == alone_d[i] for i in range(len(both)) if i not in flagged)
    wrong = [(contacts.labels[i], str(d.label)) for i, d in enumerate(both)
             if not d.label.is_unknown and not d.label.holds(contacts.labels[i])]
    assert not wrong
    for i, d in enumerate(both):
        est = _stream(both_model, contacts, i)
        assert (est.label, est.reason, est.t_s) == (d.label, d.reason, d.time_s), i


def test_a_fallback_that_does_not_know_the_pad_either_names_nothing_wrong(model, with_lda):
    """The fallback trained on touches of the pad as modelled (the module's
    model: a lab that trained on another pad's touches) meets the lagged
    pad's as unlike its classes: of the touches the check refuses, it names
    some (measured: 9 of 18 here, 10 of 17 on seed 3's) and says
    "outside classes" of the others, which end unknown with the misfit's
    reason; none is named wrong."""
    contacts = from_trials(pad_database(_lagged(6), np.random.default_rng(2)))[0]
    alone, both = decide_all(model, contacts), decide_all(with_lda, contacts)
    for a, b, label in zip(alone, both, contacts.labels):
        if a.reason != Reason.PAD_MODEL_MISFIT:
            assert b == a
        elif b.reason == Reason.PAD_MODEL_FALLBACK:
            assert b.label.holds(label), (label, str(b.label))
        else:
            assert (b.label.is_unknown, b.reason) == (True, Reason.PAD_MODEL_MISFIT)
    assert any(b.reason == Reason.PAD_MODEL_FALLBACK for b in both)


def test_a_fallback_is_saved_with_its_model(with_lda, tmp_path):
    from telethermal.ident.registry import load_model
    again = load_model(with_lda.save(tmp_path / "identifier.npz"))
    assert again.fallback_.method == "effusivity-lda"
    assert again.fallback_.classes_ == with_lda.classes_
    for a, b in zip(again.fallback_.params_, with_lda.fallback_.params_):
        assert a.keys() == b.keys() and all(np.array_equal(a[k], b[k]) for k in a)
    assert load_model(with_lda.fallback_.save(tmp_path / "lda.npz")).fallback_ is None

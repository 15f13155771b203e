"""Identification: PCA, Levenberg-Marquardt, the bank identifiers, anytime
decisions and model files, on the hard cases the identification issue lists."""

import math
import numpy as np
import pytest

from telethermal.errors import IdentificationError, ModelFileError
from telethermal.ident.anytime import StreamingIdentifier, decide
from telethermal.ident.base import group_folds
from telethermal.ident.lm import MLP, train_adam, train_lm
from telethermal.ident.pca import SnapshotPCA
from telethermal.ident.prepare import Contacts, from_trials, normalise
from telethermal.ident.registry import load_model, make


# ------------------------------------------------------------------ PCA
def test_pca_basis_is_orthonormal_and_matches_svd(rng):
    x = rng.normal(size=(12, 300))          # fewer trials than samples
    pca = SnapshotPCA(max_components=50).fit(x)
    assert len(pca.eigenvalues_) == 11      # centring removes one direction
    np.testing.assert_allclose(pca.components_ @ pca.components_.T, np.eye(11), atol=1e-10)
    # The snapshot eigenvalues are the covariance eigenvalues: squared singular values / N.
    s = np.linalg.svd(x - x.mean(axis=0), compute_uv=False)
    np.testing.assert_allclose(pca.eigenvalues_, s[:11] ** 2 / 12, rtol=1e-10)


def test_pca_with_repeated_and_constant_recordings_divides_by_no_zero(rng):
    base = rng.normal(size=(3, 50))
    x = np.vstack([base, base, base])       # repeated rows: rank 2 after centring
    pca = SnapshotPCA().fit(x)
    assert len(pca.eigenvalues_) == 2 and np.all(np.isfinite(pca.components_))
    flat = SnapshotPCA().fit(np.zeros((5, 40)))
    assert len(flat.eigenvalues_) == 0 and flat.transform(np.ones((2, 40))).shape == (2, 0)


def test_pca_refuses_nan(rng):
    x = rng.normal(size=(4, 10))
    x[1, 3] = np.nan
    with pytest.raises(IdentificationError):
        SnapshotPCA().fit(x)


# ------------------------------------------------------------------ LM
def test_jacobian_matches_finite_differences(rng):
    net = MLP.init(4, 5, 3, rng)
    x = rng.normal(size=(7, 4))
    _, jac = net.jacobian(x)
    theta, eps = net.vector(), 1e-6
    for p in range(0, len(theta), 7):
        up, down = theta.copy(), theta.copy()
        up[p] += eps
        down[p] -= eps
        numeric = (net.with_vector(up)(x) - net.with_vector(down)(x)).ravel() / (2 * eps)
        np.testing.assert_allclose(jac[:, p], numeric, atol=1e-8)


def test_lm_fits_a_separable_problem_and_beats_adam_per_iteration(rng):
    x = rng.normal(size=(60, 3))
    y = np.eye(2)[(x[:, 0] + 0.5 * x[:, 1] > 0).astype(int)]
    net0 = MLP.init(3, 6, 2, rng)
    net, hist = train_lm(net0, x, y, max_iter=100)
    assert np.mean(net(x).argmax(1) == y.argmax(1)) == 1.0
    _, adam = train_adam(net0, x, y, epochs=100)
    assert hist.loss[-1] < adam.loss[-1]
    assert all(b <= a for a, b in zip(hist.loss, hist.loss[1:]))   # LM never goes uphill


def test_lm_on_a_singular_normal_matrix(rng):
    # A dead input (all zeros) gives zero Jacobian columns: J^T J is singular.
    x = rng.normal(size=(30, 3))
    x[:, 1] = 0.0
    y = np.eye(2)[(x[:, 0] > 0).astype(int)]
    net, hist = train_lm(MLP.init(3, 4, 2, rng), x, y, l2=0.0, mu=0.0, max_iter=50)
    assert np.all(np.isfinite(net.vector())) and hist.loss[-1] < hist.loss[0]


# ------------------------------------------------------------------ contacts
def contacts(rng, per_class=6, n=101, rate=100.0, classes=("glass", "wood", "steel"),
             levels=(1.0, 2.0, 4.0), noise=0.05):
    """Synthetic normalised contacts: class k has flux level k / sqrt(t)."""
    t = np.arange(n) / rate
    rows, labels, groups = [], [], []
    for name, level in zip(classes, levels):
        for i in range(per_class):
            shape = level * 300 * (1 - np.exp(-t / 0.05)) / np.sqrt(t + 0.05)
            rows.append(shape * (1 + noise * rng.normal()) + rng.normal(0, 2.0, n))
            labels.append(name)
            groups.append(f"trial-{i}")
    x = np.array(rows)[:, :, None]
    return Contacts(x, np.full(len(rows), n), labels, groups, np.full(len(rows), 10.0),
                    rate, ("heat_flux_W_m2",))


@pytest.mark.parametrize("method", ["effusivity-lda", "pca-fnn"])
def test_methods_separate_distinct_effusivities(rng, method):
    data = contacts(rng)
    folds = group_folds(data.groups, 3)
    correct = 0
    for test in folds:
        train = np.setdiff1d(np.arange(len(data)), test)
        model = make(method).fit(data.subset(train))
        p = model.proba_normalised(data.x[test], len(model.windows_s_) - 1)
        correct += sum(model.classes_[k] == data.labels[i] for k, i in zip(p.argmax(1), test))
    assert correct == len(data)


def test_constant_traces_give_uniform_posteriors_not_errors():
    data = Contacts(np.zeros((6, 51, 1)), np.full(6, 51), ["a", "a", "a", "b", "b", "b"],
                    [f"trial-{i}" for i in range(6)], np.full(6, 10.0), 100.0,
                    ("heat_flux_W_m2",))
    for method in ("effusivity-lda", "pca-fnn"):
        model = make(method, calibrate=False).fit(data)
        p = model.proba_normalised(data.x, len(model.windows_s_) - 1)
        np.testing.assert_allclose(p, 0.5)


def test_one_class_with_a_single_trial(rng):
    data = contacts(rng, per_class=4)
    keep = [i for i, lab in enumerate(data.labels) if lab != "steel"] + [data.labels.index("steel")]
    model = make("effusivity-lda").fit(data.subset(keep))
    assert model.classes_ == ["glass", "steel", "wood"]


def test_short_prefix_nan_and_tiny_gap(rng):
    model = make("effusivity-lda").fit(contacts(rng))
    flat = np.full(3, 1.0 / 3)
    np.testing.assert_allclose(model.predict_proba(np.array([5.0]), 10.0), flat)  # < 1 period
    np.testing.assert_allclose(model.predict_proba(np.empty(0), 10.0), flat)
    with pytest.raises(IdentificationError, match="sample 3"):
        model.predict_proba(np.array([1.0, 2.0, 3.0, np.nan, 5.0] * 5), 10.0)
    with pytest.raises(IdentificationError, match="gap"):
        model.predict_proba(np.ones(50), 0.01)
    with pytest.raises(IdentificationError, match="gap"):
        normalise(np.ones(3), "heat_flux_W_m2", 0.01)


def test_anytime_decisions_and_unknowns(rng):
    data = contacts(rng)
    model = make("effusivity-lda", threshold=0.95).fit(data)
    d = decide(model, data.x[0, :, :], 10.0)
    assert d.label == data.labels[0] and d.reason == "confident" and d.time_s <= 1.0
    assert decide(model, data.x[0], 0.01).label == "unknown"          # zero gap
    alien = data.x[0] * 20.0                                          # far outside every class
    assert decide(model, alien, 10.0).label == "unknown"


def test_unfitted_and_channel_mismatch(rng):
    with pytest.raises(IdentificationError, match="not fitted"):
        make("pca-fnn").predict_proba(np.ones(10), 10.0)
    with pytest.raises(IdentificationError, match="channels"):
        make("effusivity-lda", channels=("temperature_C",)).fit(contacts(rng))
    with pytest.raises(IdentificationError, match="unknown method"):
        make("crystal-ball")


def test_trials_without_a_channel_are_named():
    from telethermal.data.dataset import Trial
    trial = Trial("t1", "wood", "t1.csv", 100.0, 24.0, 34.0, 24.0, "trial-0",
                  channels={"t_s": np.arange(10) / 100.0, "force_N": np.ones(10)})
    with pytest.raises(IdentificationError, match="t1 has no channel.*heat_flux_W_m2"):
        from_trials([trial])


@pytest.mark.parametrize("method", ["effusivity-lda", "pca-fnn"])
def test_model_files_round_trip_and_refuse_damage(tmp_path, rng, method):
    data = contacts(rng)
    model = make(method).fit(data)
    path = model.save(tmp_path / "m.npz")
    again = load_model(path)
    i = len(model.windows_s_) - 1
    np.testing.assert_allclose(again.proba_normalised(data.x, i), model.proba_normalised(data.x, i))
    blob = path.read_bytes()
    (tmp_path / "cut.npz").write_bytes(blob[: len(blob) // 2])
    with pytest.raises(ModelFileError, match="truncated"):
        load_model(tmp_path / "cut.npz")
    (tmp_path / "junk.npz").write_bytes(b"not a model")
    with pytest.raises(ModelFileError, match="junk.npz: not a telethermal model file") as info:
        load_model(tmp_path / "junk.npz")
    assert "allow_pickle" not in str(info.value)        # numpy's advice, never to be taken
    # An archive holding a pickled array is refused, and says so.
    np.savez(tmp_path / "pickled.npz", header=np.array([{"a": 1}], dtype=object))
    with pytest.raises(ModelFileError, match="pickled objects, which telethermal never loads"):
        load_model(tmp_path / "pickled.npz")


def test_model_file_from_another_version(tmp_path, rng, monkeypatch):
    import telethermal.ident.base as base
    model = make("effusivity-lda").fit(contacts(rng))
    monkeypatch.setattr(base, "FORMAT_VERSION", 99)
    path = model.save(tmp_path / "future.npz")
    monkeypatch.setattr(base, "FORMAT_VERSION", 1)
    with pytest.raises(ModelFileError, match="version 99"):
        load_model(path)


@pytest.mark.parametrize("method", ["lstm", "rnn"])
def test_recurrent_learns_levels_and_round_trips(tmp_path, rng, method):
    data = contacts(rng, per_class=5)
    model = make(method, epochs=60, n_hidden=16).fit(data)
    p = model.proba_normalised(data.x, len(model.windows_s_) - 1)
    assert np.mean(p.argmax(1) == [model.classes_.index(c) for c in data.labels]) >= 0.9
    # One pass gives the posterior after every step; its last row is the full window's.
    path = model.posterior_path(data.x[0])
    np.testing.assert_allclose(path[-1], p[0], atol=1e-6)
    again = load_model(model.save(tmp_path / "r.npz"))
    np.testing.assert_allclose(again.proba_normalised(data.x, 10), model.proba_normalised(data.x, 10),
                               atol=1e-6)
    d = decide(model, data.x[0], 0.0)
    assert d.label == "unknown" and d.reason == "gap too small"


def test_torch_is_imported_by_the_recurrent_methods_alone(tmp_path, rng):
    """A process that loads the registry, a session's models or a service
    imports no torch (about a second each: the services, the benches'
    workers); a recurrent model saved by another process loads there
    without it, imports it when prepared (as a slave prepares its model at
    start, not in the first touch) and answers as here."""
    import subprocess
    import sys

    data = contacts(rng, per_class=3)
    model = make("lstm", epochs=5, n_hidden=4).fit(data)
    path = model.save(tmp_path / "lstm.npz")
    np.save(tmp_path / "x.npy", data.x)
    expected = model.proba_normalised(data.x, 10)
    code = (
        "import sys, numpy as np\n"
        "import telethermal.ident.registry, telethermal.teleop.models\n"
        "import telethermal.services.slave, telethermal.services.master\n"
        "import telethermal.bench.worker, telethermal.bench.models\n"
        "assert 'torch' not in sys.modules, 'torch imported'\n"
        "from telethermal.ident.registry import load_model\n"
        f"m = load_model({str(path)!r})\n"
        "assert 'torch' not in sys.modules, 'torch imported by loading'\n"
        "m = m.prepare()      # as a slave does at start: torch and the network now\n"
        "assert 'torch' in sys.modules and m._module is not None\n"
        f"np.save({str(tmp_path / 'p.npy')!r}, m.proba_normalised(np.load({str(tmp_path / 'x.npy')!r}), 10))\n")
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    np.testing.assert_allclose(np.load(tmp_path / "p.npy"), expected, atol=1e-6)


# ------------------------------------------------------------------ streaming
def _stream(model, raw, gap):
    stream = StreamingIdentifier(model, gap)
    for row in raw:
        stream.push(row)
    return stream.estimate


@pytest.mark.parametrize("threshold", [0.95, 0.999999])
def test_streaming_gives_the_batch_decision(rng, threshold):
    # Sample by sample, the same commitment (label, time, reason) as decide()
    # on the whole contact, for every contact, confident or not.
    data = contacts(rng)
    model = make("effusivity-lda", threshold=threshold).fit(data)
    gap = 10.0
    for i in range(len(data)):
        raw = data.x[i] * gap                      # back to raw samples
        batch = decide(model, data.x[i], gap)
        est = _stream(model, raw, gap)
        assert est.decided
        assert (est.label, est.reason) == (batch.label, batch.reason)
        if batch.time_s is not None:
            assert est.t_s == batch.time_s


def test_streaming_refuses_bad_samples_and_answers_tiny_gaps_at_once(rng):
    model = make("effusivity-lda").fit(contacts(rng))
    stream = StreamingIdentifier(model, 0.5)
    assert stream.decided and stream.estimate.reason == "gap too small"
    assert stream.push(1.0) is None                     # decided: samples are ignored
    stream = StreamingIdentifier(model, 10.0)
    with pytest.raises(IdentificationError, match="finite"):
        stream.push(np.nan)
    with pytest.raises(IdentificationError, match="1 finite"):
        stream.push([1.0, 2.0])
    assert stream.estimate.posteriors == pytest.approx((1 / 3,) * 3)  # nothing learnt yet


@pytest.mark.parametrize("correct, n", [(70, 70), (65, 70), (0, 10), (1, 3)])
def test_the_accuracy_interval_is_wilsons_closed_form(correct, n):
    from telethermal.ident.evaluate import wilson_interval

    z = 1.959963984540054                        # the 97.5 % normal quantile
    p = correct / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z / (1 + z * z / n) * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n))
    lo, hi = wilson_interval(correct, n)
    assert lo == pytest.approx(centre - half, abs=1e-12)
    assert hi == pytest.approx(centre + half, abs=1e-12)
    assert 0.0 <= lo <= p <= hi <= 1.0

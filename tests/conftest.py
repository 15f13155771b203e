"""Shared fixtures."""

import numpy as np
import pytest
from hypothesis import HealthCheck, settings

# The machines are shared and slow at times: hypothesis must not fail a test
# because drawing its inputs took long (a health check, not a property), nor
# for a slow example (no wall-clock figure in a test). Each test's own
# @settings inherits these.
settings.register_profile("shared-machine", deadline=None,
                          suppress_health_check=[HealthCheck.too_slow])
settings.load_profile("shared-machine")


@pytest.fixture
def rng():
    return np.random.default_rng(12345)


class TrainedModels:
    """``train_identifier`` / ``train_generator`` of a scene and seed, each
    trained once for the whole session (they are deterministic in the scene
    and the seed, and about 15 s a pair), and their saved files, written
    once. Shared read-only: at the session's end each model is saved again
    and each file hashed, and a test that changed one fails the run."""

    def __init__(self, folder, shared=None):
        self.folder = folder
        #: Under pytest-xdist, a folder both workers see: the first worker to
        #: need a model trains it and saves it there (under a lock), the other
        #: loads it: the same model file, half the training. The file
        #: round trip is the one a service makes (tests/unit check it).
        self.shared = shared
        self._models = {}          # (repr(scene), seed, kind[, method]) -> model
        self._files = {}           # (repr(scene), seed) -> (identifier path, generator path)
        self._digests = {}         # what each model and file was when made
        # Bound now: a test may monkeypatch teleop.models' functions later.
        from telethermal.teleop.models import train_generator, train_identifier
        self._train = {"identifier": train_identifier, "generator": train_generator}

    @staticmethod
    def _npz_digest(path) -> str:
        import hashlib
        h = hashlib.sha256()
        with np.load(path, allow_pickle=False) as z:
            for name in sorted(z.files):
                h.update(name.encode())
                h.update(np.ascontiguousarray(z[name]).tobytes())
        return h.hexdigest()

    def _model_digest(self, model, kind) -> str:
        import tempfile
        from pathlib import Path

        from telethermal.render.generator import save_generator
        with tempfile.TemporaryDirectory() as tmp:
            path = Path(tmp) / f"{kind}.npz"
            model.save(path) if kind == "identifier" else save_generator(model, path)
            return self._npz_digest(path)

    def _model(self, scene, seed, kind, method=None):
        key = (repr(scene), seed, kind) + ((method,) if method else ())
        if key not in self._models:
            self._models[key] = self._trained(key, scene, seed, kind, method)
            self._digests[key] = self._model_digest(self._models[key], kind)
        return self._models[key]

    def _trained(self, key, scene, seed, kind, method):
        train = lambda: self._train[kind](scene, seed, *((method,) if method else ()))  # noqa: E731
        if self.shared is None:
            return train()
        import fcntl
        import hashlib

        from telethermal.ident.registry import load_model
        from telethermal.render.generator import load_generator, save_generator
        name = hashlib.sha256(repr(key).encode()).hexdigest()[:24]
        path = self.shared / f"{kind}-{name}.npz"
        with open(self.shared / f"{name}.lock", "w") as lock:
            fcntl.flock(lock, fcntl.LOCK_EX)          # released when the file closes
            if path.is_file():
                return load_model(path) if kind == "identifier" else load_generator(path)
            model = train()
            model.save(path) if kind == "identifier" else save_generator(model, path)
            return model

    def identifier(self, scene, seed: int = 0, method: str | None = None):
        """``train_identifier(scene, seed[, method])``: not to be changed by
        the test (``method``: a test about that method's behaviour)."""
        return self._model(scene, seed, "identifier", method)

    def generator(self, scene, seed: int = 0):
        """``train_generator(scene, seed)``: not to be changed by the test."""
        return self._model(scene, seed, "generator")

    def pair(self, scene, seed: int = 0):
        return self.identifier(scene, seed), self.generator(scene, seed)

    def files(self, scene, seed: int = 0):
        """(identifier.npz, generator.npz) of ``pair(scene, seed)``, saved
        once into a session folder: read them, copy them, never write them."""
        from telethermal.render.generator import save_generator
        key = (repr(scene), seed)
        if key not in self._files:
            folder = self.folder / f"models-{len(self._files)}"
            folder.mkdir()
            identifier, generator = self.pair(scene, seed)
            paths = (identifier.save(folder / "identifier.npz"),
                     save_generator(generator, folder / "generator.npz"))
            self._files[key] = paths
            for p in paths:
                self._digests[p] = p.read_bytes()
        return self._files[key]

    def changed(self) -> list[str]:
        bad = []
        for key, model in self._models.items():
            if self._model_digest(model, key[2]) != self._digests[key]:
                bad.append(f"{key[2]} of seed {key[1]} for {key[0][:60]}...")
        for paths in self._files.values():
            for p in paths:
                if not p.is_file() or p.read_bytes() != self._digests[p]:
                    bad.append(str(p))
        return bad


@pytest.fixture(scope="session")
def trained_models(tmp_path_factory):
    """The session's shared trained identifiers and generators (TrainedModels)."""
    import os
    shared = None
    run = os.environ.get("PYTEST_XDIST_TESTRUNUID")
    if os.environ.get("PYTEST_XDIST_WORKER") and run:
        # The workers' base folders share this run's parent folder; the
        # run's id (xdist's, the same in every worker) names the folder, so
        # no other run's models are ever read.
        shared = tmp_path_factory.getbasetemp().parent / f"trained-models-{run}"
        shared.mkdir(exist_ok=True)
    trained = TrainedModels(tmp_path_factory.mktemp("trained-models"), shared)
    yield trained
    changed = trained.changed()
    assert not changed, f"a test changed a shared trained model or its file: {changed}"


def pytest_configure(config):
    """The suite's own cache folder (idle policies, the effusivity
    estimator's curves), in the system's temporary folder, never the
    user's home: every process the suite starts (services, the CLI)
    inherits the variable and reads what the first one built. Kept from one
    run to the next (an idle policy takes minutes to compute; every entry
    is keyed by what it depends on), one per user."""
    import os
    import tempfile
    from pathlib import Path

    from telethermal.cachedir import CACHE_ENV
    folder = Path(tempfile.gettempdir()) / f"telethermal-test-cache-{os.getuid()}"
    folder.mkdir(mode=0o700, exist_ok=True)
    config._telethermal_cache_before = os.environ.get(CACHE_ENV)
    os.environ[CACHE_ENV] = str(folder)


def pytest_unconfigure(config):
    import os

    from telethermal.cachedir import CACHE_ENV
    before = getattr(config, "_telethermal_cache_before", None)
    if before is None:
        os.environ.pop(CACHE_ENV, None)
    else:
        os.environ[CACHE_ENV] = before


#: The longest test files (a few minutes, a minute or more; measured with
#: ``--durations``), handed out first so that no worker starts one near the
#: end while the other has finished. The compose test's stack needs more
#: than a core of its own (two services, a healthcheck process every 2 s
#: each): beside it the conformance suite, mostly waiting on its slave,
#: rather than the CPU-bound test_decisions (with it, once, the slave's
#: loop stalled over its 1 s liveness and logged the warning the test
#: forbids). Order only: a file missing or renamed here is merely
#: scheduled with the rest.
LONGEST_FIRST = ("tests/integration/test_compose_up.py", "tests/docs/test_tutorials.py",
                 "tests/conformance",
                 "tests/unit/test_decisions.py",
                 "tests/integration/test_services.py",
                 "tests/integration/test_unseen_render_sessions.py",
                 "tests/integration/test_two_host_guide.py", "tests/integration/test_operate.py",
                 "tests/faults/test_session_faults.py", "tests/integration/test_lab_walk.py",
                 "tests/integration/test_decision_cases.py")


@pytest.hookimpl(optionalhook=True, tryfirst=True)
def pytest_xdist_make_scheduler(config, log):
    """Under pytest-xdist (``make test`` runs ``-n 2``): one test file is
    one unit of work, run whole by one worker, so a module's fixtures (the
    compose test's dockerd and image, a module's services or models) are
    made once; and tests/conformance/ is one unit, on one slave process.
    (``--dist loadgroup`` cannot say this: with pytest 9.2 its groups are
    silently ignored, pytest-xdist issue 1386.) The files of
    :data:`LONGEST_FIRST` go first. ``--dist each`` and ``worksteal`` are
    left to xdist."""
    if config.getvalue("dist") in ("each", "worksteal"):
        return None
    from xdist.scheduler import LoadScopeScheduling

    class FileScheduling(LoadScopeScheduling):
        def _split_scope(self, nodeid: str) -> str:
            path = nodeid.split("::", 1)[0]
            return "tests/conformance" if path.startswith("tests/conformance/") else path

        def _assign_work_unit(self, node) -> None:
            # The rest in collection order, not xdist's most-tests-first: the
            # many short unit test files then come last, the integration
            # files with one or two long tests before them.
            first = {scope: i for i, scope in enumerate(LONGEST_FIRST)}
            place = {}
            for nodeid in self.collection:
                place.setdefault(self._split_scope(nodeid), len(place))
            for scope in sorted(self.workqueue, key=lambda s: (first.get(s, len(first)),
                                                               place.get(s, 0))):
                self.workqueue.move_to_end(scope)
            super()._assign_work_unit(node)

    return FileScheduling(config, log)

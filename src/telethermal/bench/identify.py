"""``telethermal bench identify``: the papers' identification tables on the
simulated databases, with our figures beside theirs.

- First paper, Table 1: 7 classes and the 5 merged classes at 0.25 / 0.5 /
  0.75 / 1 s on ``fingertip-7``'s pad database, leave-trials-out (5 folds by
  trial index, so a trial index is never in both training and test).
- Second paper, active against passive pad: ``gripper-case-I-pro`` against
  ``gripper-case-I-cnv`` (the passive pad at zero gap must come out "unknown").
- Second paper, cross-temperature: train I-pro, test II and III; train IV,
  test V.

Every method of ``identify methods`` is run (``--methods`` picks some). The
second paper's Table 3 rows on the temperature channel use 5 s contacts of
the same gripper scenes and are run for the window-bank methods; the
recurrent ones on 5 s sequences are listed under ``not_run`` (cost).
"""

from __future__ import annotations

import datetime
import functools
import hashlib
import platform
import time
from typing import Callable

import numpy as np

from telethermal.data.generate import pad_database
from telethermal.bench.identify_live import (gaps_to_limit, limit, live_counts,
                                             sessions_table1)
from telethermal.ident.anytime import decide_all
from telethermal.ident.base import group_folds
from telethermal.ident.evaluate import (ECE_MAX_S, FIRST_PAPER_MERGE, decision_summary,
                                       default_windows, evaluate, expected_calibration_error,
                                       inference_cost_ms)
from telethermal.ident.prepare import from_trials
from telethermal.ident.registry import METHODS, make
from telethermal.physics.scene import load_scene

#: learning-based-thermal-rendering Table 1, counted from its marks (35 trials).
PAPER1_5_CLASSES = {"0.25": 29 / 35, "0.5": 34 / 35, "0.75": 1.0}
#: active-heat-flow-sensing: 100 % within 0.4 s (I-pro, 4 materials); cross-temperature
#: 100 % within 0.5 s (II, III) and 0.7 s (V).
PAPER2 = {"active_100pct_within_s": 0.4, "cross": {"II": 0.5, "III": 0.5, "V": 0.7}}
WINDOWS_T1 = (0.25, 0.5, 0.75, 1.0)
#: Methods the bench runs by default: those whose calibration error is
#: within issue 29's 0.05. The recurrent ones are not (bench identify's own
#: runs, Table 1's held-out touches and the active pad's); they stay
#: available by name.
DROPPED = {"lstm": "was 0.080-0.084 on fingertip-7 (target 0.05)",
           "rnn": "was 0.046-0.099 on fingertip-7 and 0.105 on the active pad (target 0.05)"}
DEFAULT_METHODS = tuple(m for m in sorted(METHODS) if m not in DROPPED)


def _trials(scene_name: str, seed: int):
    """The pad database of ``scene_name`` drawn with ``seed``: simulated once
    per run (every method, and several sections, use the same trials); a
    fresh list each call, the trials read-only."""
    return list(_database(scene_name, seed))


@functools.lru_cache(maxsize=None)
def _database(scene_name: str, seed: int, contact_s: float | None = None) -> tuple:
    """``pad_database`` of the scene (its contacts ``contact_s`` long when
    given), kept for the run; :func:`run` empties the cache when done."""
    scene = load_scene(scene_name)
    if contact_s is not None:
        import dataclasses
        scene = dataclasses.replace(scene, pad=dataclasses.replace(
            scene.pad, contact_duration_s=contact_s))
    return tuple(pad_database(scene, np.random.default_rng(seed)))


#: Models fitted in this process, by method, hyper-parameters and a digest
#: of the training contacts: a fit that two sections of one job share
#: (cross-temperature I-pro for case II and for case III, the same
#: materials) is made once; jobs on other workers fit their own. Training
#: is seeded by the model, so a fit does not depend on what ran before it.
_FITS: dict = {}


def _digest(contacts) -> str:
    """A digest of everything a fit reads from ``contacts``."""
    h = hashlib.sha256()
    for array in (contacts.x, contacts.lengths, contacts.gap_k, contacts.force_n):
        h.update(b"-" if array is None else np.ascontiguousarray(array).tobytes())
    h.update(repr((contacts.labels, contacts.groups, contacts.sample_rate_hz,
                   contacts.channels)).encode())
    return h.hexdigest()


def _fit(method: str, contacts, **kw):
    """``make(method, **kw).fit(contacts)``, once per run for the same
    training contacts and hyper-parameters; :func:`run` empties the store."""
    model = make(method, **kw)
    key = (method, repr(sorted(model.hyper().items())), _digest(contacts))
    if key not in _FITS:
        _FITS[key] = model.fit(contacts)
    return _FITS[key]


def _accuracy(model, contacts, w, merge=None):
    merge = merge or {}
    index = model.window_index(int(round(w * model.sample_rate_hz_)) + 1)
    p = model.proba_normalised(contacts.x, index)
    guess = [model.classes_[k] for k in p.argmax(axis=1)]
    return [merge.get(a, a) == merge.get(b, b) for a, b in zip(guess, contacts.labels)]


def _held_out_proba(model, contacts, max_s: float = ECE_MAX_S):
    """Posteriors of held-out contacts at every window of the model up to
    ``max_s`` (those an anytime decision consults), pooled, and the truth."""
    probas, truth = [], []
    y = np.array([model.classes_.index(c) for c in contacts.labels])
    for index, w in enumerate(model.windows_s_):
        if w <= max_s + 1e-9:
            probas.append(model.proba_normalised(contacts.x, index))
            truth.append(y)
    return np.vstack(probas), np.concatenate(truth)


def table1(method: str, seed: int) -> dict:
    """Leave-trials-out accuracy on the first paper's pad database, the
    calibration error of the held-out posteriors and the anytime decisions."""
    contacts, _ = from_trials(_trials("fingertip-7", seed), max_s=1.0)
    hits7 = {w: [] for w in WINDOWS_T1}
    hits5 = {w: [] for w in WINDOWS_T1}
    fit_s, probas, truth, decisions, labels = [], [], [], [], []
    for test in group_folds(contacts.groups, 5):
        train = np.setdiff1d(np.arange(len(contacts)), test)
        start = time.perf_counter()
        model = make(method, scene="fingertip-7").fit(contacts.subset(train))
        fit_s.append(time.perf_counter() - start)
        held = contacts.subset(test)
        for w in WINDOWS_T1:
            hits7[w] += _accuracy(model, held, w)
            hits5[w] += _accuracy(model, held, w, FIRST_PAPER_MERGE)
        p, t = _held_out_proba(model, held)
        probas.append(p)
        truth.append(t)
        decisions += decide_all(model, held)
        labels += held.labels
    from telethermal.ident.fitted import clear_cache
    clear_cache()               # the full training's time, its estimates included
    start = time.perf_counter()
    full = make(method, scene="fingertip-7").fit(contacts)
    train_all_s = time.perf_counter() - start
    return {"accuracy_7": {f"{w:g}": float(np.mean(v)) for w, v in hits7.items()},
            "accuracy_5": {f"{w:g}": float(np.mean(v)) for w, v in hits5.items()},
            "calibration_ece": expected_calibration_error(np.vstack(probas),
                                                          np.concatenate(truth)),
            "calibration_ece_up_to_s": ECE_MAX_S,
            "decision": {**decision_summary(decisions, labels), "threshold": full.threshold},
            "live_counts": live_counts(decisions, labels), "n_touches": len(contacts),
            "paper_accuracy_5": {k: round(v, 3) for k, v in PAPER1_5_CLASSES.items()},
            "paper_accuracy_7": "not reported (confusions Al/steel and graphite/rubber at 1 s)",
            "train_s_full_database": train_all_s, "train_s_per_fold_mean": float(np.mean(fit_s)),
            **inference_cost_ms(full, contacts.x)}


def active_passive(method: str, seed: int) -> dict:
    """Train on the active pad (I-pro), test held-out active trials and the passive pad."""
    active, _ = from_trials(_trials("gripper-case-I-pro", seed), max_s=1.0)
    passive_trials = _trials("gripper-case-I-cnv", seed + 1)
    accuracy = {}
    decisions = []
    probas, truth = [], []
    for fold, test in enumerate(group_folds(active.groups, 5)):
        train = np.setdiff1d(np.arange(len(active)), test)
        model = _fit(method, active.subset(train))
        held = active.subset(test)
        for w in [round(0.1 * k, 1) for k in range(1, 11)]:
            accuracy.setdefault(f"{w:.1f}", []).extend(_accuracy(model, held, w))
        decisions += list(zip(decide_all(model, held), held.labels))
        p, t = _held_out_proba(model, held)
        probas.append(p)
        truth.append(t)
    model = make(method).fit(active)
    passive = evaluate(model, passive_trials, windows_s=default_windows(model.channels))
    committed = [(d, lab) for d, lab in decisions if d.time_s is not None]
    return {"active_accuracy_by_window_s": {k: float(np.mean(v)) for k, v in accuracy.items()},
            "active_decision_time_s_p50": (float(np.median([d.time_s for d, _ in committed]))
                                           if committed else None),
            "active_decision_accuracy": (float(np.mean([d.label == lab for d, lab in committed]))
                                         if committed else None),
            "active_committed": f"{len(committed)}/{len(decisions)}",
            "decision": decision_summary([d for d, _ in decisions], [lab for _, lab in decisions]),
            "calibration_ece": expected_calibration_error(np.vstack(probas),
                                                          np.concatenate(truth)),
            "passive_unknown_rate": passive["decision_unknown_rate"],
            "passive_unknown_reasons": passive["unknown_reasons"],
            "paper": f"100 % within {PAPER2['active_100pct_within_s']} s (active, LSTM)"}


def cross_temperature(method: str, seed: int) -> dict:
    rows = {}
    for train_case, test_case in (("I-pro", "II"), ("I-pro", "III"), ("IV", "V")):
        test = _trials(f"gripper-case-{test_case}", seed + 7)
        # As in the paper's Fig. 11, train on the test's materials only (I-pro
        # also holds acrylic, which cases II-V do not).
        materials = {t.material for t in test}
        train = [t for t in _trials(f"gripper-case-{train_case}", seed) if t.material in materials]
        model = _fit(method, from_trials(train, max_s=1.0)[0])
        # (the tenths the committed figures use: first_window_at_99pct_s)
        report = evaluate(model, test, windows_s=default_windows(model.channels))
        rows[f"train {train_case}, test {test_case}"] = {
            "accuracy_by_window_s": report["accuracy_by_window_s"],
            "first_window_at_99pct_s": next((float(k) for k, v in
                                             report["accuracy_by_window_s"].items() if v >= 0.99),
                                            None),
            "paper_100pct_within_s": PAPER2["cross"][test_case]}
    return rows


def lm_vs_adam(seed: int) -> dict:
    """The first paper's network on its 1 s PCA features (fingertip-7 pad
    database): Levenberg-Marquardt against Adam, same start, same loss."""
    from telethermal.ident.lm import MLP, train_adam, train_lm
    from telethermal.ident.methods import PcaFnn

    contacts, _ = from_trials(_trials("fingertip-7", seed), max_s=1.0)
    model = PcaFnn(max_window_s=1.0, window_step_s=1.0)
    model.classes_ = sorted(set(contacts.labels))
    model.sample_rate_hz_ = contacts.sample_rate_hz
    x = model.window(contacts.x, 1.0)
    from telethermal.ident.pca import SnapshotPCA
    pca = SnapshotPCA(model.n_components).fit(x.reshape(len(x), -1))
    u = model.features({"mean": pca.mean_, "components": pca.components_,
                         "eigenvalues": pca.eigenvalues_}, x)
    y = np.eye(len(model.classes_))[[model.classes_.index(c) for c in contacts.labels]]
    start_net = MLP.init(u.shape[1], model.n_hidden, y.shape[1], np.random.default_rng(seed))
    out = {}
    for name, train, kw in (("levenberg-marquardt", train_lm, {"max_iter": 100}),
                            ("adam", train_adam, {"epochs": 2000})):
        start = time.perf_counter()
        _, hist = train(start_net, u, y, **kw)
        out[name] = {"iterations": len(hist.loss) - (1 if name != "adam" else 0),
                     "final_loss": hist.loss[-1], "runtime_s": time.perf_counter() - start,
                     "loss_at_iteration_10": hist.loss[min(10, len(hist.loss) - 1)],
                     "stopped": hist.stopped}
    return out


def lstm_hidden_sweep(seed: int, sizes=(16, 32, 64)) -> dict:
    """The second paper's Table 4 on the active pad (I-pro): accuracy at 0.4 s
    and 1 s against the encoder/LSTM width, 5-fold leave-trials-out."""
    contacts, _ = from_trials(_trials("gripper-case-I-pro", seed), max_s=1.0)
    rows = {}
    for size in sizes:
        hits = {0.4: [], 1.0: []}
        for fold, test in enumerate(group_folds(contacts.groups, 5)):
            train = np.setdiff1d(np.arange(len(contacts)), test)
            model = _fit("lstm", contacts.subset(train), n_hidden=size)
            for w in hits:
                hits[w] += _accuracy(model, contacts.subset(test), w)
        rows[str(size)] = {f"{w:g}": float(np.mean(v)) for w, v in hits.items()}
    return {"accuracy": rows, "paper": "100 % for every width except 16"}


def temperature_rows(method: str, seed: int) -> dict:
    """The second paper's Table 3 on the temperature channel: 5 s contacts of
    the active (I-pro) and passive (I-cnv) pads, windows 1..5 s, 5-fold
    leave-trials-out on the active pad; the passive pad is scored by the
    model trained on the active one."""
    channels = ("temperature_C",)
    active, _ = from_trials(list(_database("gripper-case-I-pro", seed, 5.0)),
                            channels=channels, max_s=5.0)
    hits = {w: [] for w in (1.0, 2.0, 3.0, 4.0, 5.0)}
    for test in group_folds(active.groups, 5):
        train = np.setdiff1d(np.arange(len(active)), test)
        model = make(method, channels=channels, max_window_s=5.0).fit(active.subset(train))
        for w in hits:
            hits[w] += _accuracy(model, active.subset(test), w)
    model = make(method, channels=channels, max_window_s=5.0).fit(active)
    passive = evaluate(model, list(_database("gripper-case-I-cnv", seed + 1, 5.0)),
                       windows_s=default_windows(model.channels))
    return {"active_accuracy_by_window_s": {f"{w:.1f}": float(np.mean(v)) for w, v in hits.items()},
            "passive_unknown_rate": passive["decision_unknown_rate"],
            "paper": "temperature sensing needed 4 s and reached 75 % (glass and acrylic alike)"}


def _session_trials(scene, seed: int, bias_k: float | None, calibrate: bool):
    """A database of ``scene`` in a session whose object thermometer has
    ``bias_k`` (drawn if None), calibrated against the pad or not."""
    import dataclasses

    from telethermal.data.generate import sensor_session
    from telethermal.physics.sensors import draw_instruments

    rng = np.random.default_rng(seed)
    inst = draw_instruments(scene.sensors, rng)
    if bias_k is not None:
        inst = dataclasses.replace(inst, thermometer=dataclasses.replace(inst.thermometer,
                                                                         bias_k=bias_k))
    session = sensor_session(scene, rng, calibrate, inst)
    return pad_database(scene, rng, session), session


@functools.lru_cache(maxsize=None)
def _shift_session(seed: int, bias_k: float, calibrate: bool):
    """A fingertip-7 session of the session-shift case, its trials as a
    tuple: drawn once per run, whichever method uses it."""
    trials, session = _session_trials(load_scene("fingertip-7"), seed, bias_k, calibrate)
    return tuple(trials), session


#: The session-shift case: the training session's thermometer reads this much
#: high, the test session's this much low (the datasheet limit both ways: a
#: 1 K shift between sessions).
SHIFT_BIAS_K = (0.5, -0.5)


def session_shift(method: str, seed: int) -> dict:
    """Train on one session of fingertip-7, test on another whose object
    thermometer's bias differs by 1 K; both sessions self-calibrated, and
    both not. Accuracy keyed like table 1."""
    out = {}
    for mode, calibrate in (("calibrated", True), ("uncalibrated", False)):
        train, s_a = _shift_session(seed, SHIFT_BIAS_K[0], calibrate)
        test, s_b = _shift_session(seed + 100, SHIFT_BIAS_K[1], calibrate)
        model = make(method, scene="fingertip-7").fit(from_trials(train, max_s=1.0)[0])
        held, _ = from_trials(test, max_s=1.0)
        decisions = decide_all(model, held)
        out[mode] = {
            "accuracy_5": {f"{w:g}": float(np.mean(_accuracy(model, held, w, FIRST_PAPER_MERGE)))
                           for w in WINDOWS_T1},
            "accuracy_7": {f"{w:g}": float(np.mean(_accuracy(model, held, w)))
                           for w in WINDOWS_T1},
            "decision": decision_summary(decisions, held.labels),
            "thermometer_bias_k": {"train": SHIFT_BIAS_K[0], "test": SHIFT_BIAS_K[1]},
            "calibration_residual_k": {"train": s_a.calibration.to_dict()["residual_k"],
                                       "test": s_b.calibration.to_dict()["residual_k"]}}
    return out


def thermometer_ablation(seed: int, method: str = "effusivity-lda") -> dict:
    """Where the accuracy goes: leave-trials-out on one session with the
    scene's object thermometer calibrated (the product), uncalibrated, and
    ideal (no bias, no noise)."""
    import dataclasses

    rows = {}
    for name in ("fingertip-7", "gripper-case-I-pro"):
        scene = load_scene(name)
        ideal = dataclasses.replace(scene, sensors=dataclasses.replace(
            scene.sensors, object_bias_limit_k=0.0, object_noise_k=0.0,
            object_resolution_k=0.0))
        for label, sc, calibrate in (("calibrated", scene, True),
                                     ("uncalibrated", scene, False), ("ideal", ideal, False)):
            trials, _ = _session_trials(sc, seed, None, calibrate)
            contacts, _ = from_trials(trials, max_s=1.0)
            hits = {0.2: [], 0.5: [], 1.0: []}
            for test in group_folds(contacts.groups, 5):
                train = np.setdiff1d(np.arange(len(contacts)), test)
                model = make(method).fit(contacts.subset(train))
                for w in hits:
                    hits[w] += _accuracy(model, contacts.subset(test), w)
            rows[f"{name}, {scene.sensors.object_thermometer} {label}"] = {
                f"{w:g}": float(np.mean(v)) for w, v in hits.items()}
    return {"method": method, "accuracy": rows}


def run(seed: int = 0, methods=None, progress: Callable[[str], None] | None = None,
        scene: str | None = None, sessions: int = 3, with_limit: bool = True,
        executor=None) -> dict:
    """The papers' tables on their scenes; with ``scene`` (a name or a
    path: a lab's own), each method's grouped 5-fold cross-validation on
    that scene's simulated pad database instead (``identify cv``'s report).
    Each method's sections, and each section of no one method, are a job of
    one sweep on ``executor`` (:mod:`telethermal.bench.executor`; None: one
    worker process a CPU)."""
    from telethermal.bench.executor import describe, open_executor

    step = progress or (lambda _m: None)
    dropped = [] if methods else [
        f"{m} (not in the defaults: its held-out calibration error {DROPPED[m]}; run it with "
        f"--methods {m})" for m in sorted(DROPPED)]
    methods = methods or list(DEFAULT_METHODS)
    report = {"machine": f"{platform.node()} ({platform.machine()}, Python "
                         f"{platform.python_version()})",
              "date": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
              "seed": seed, "sessions": sessions, "methods": {},
              "not_run": ["lstm and rnn on the temperature channel (5 s sequences: "
                          "minutes of training per fold on this machine)"] + dropped}
    own = executor is None
    executor = open_executor("process") if own else executor
    try:
        if scene is not None:
            report["scene"] = str(scene)
            report["not_run"] = ["the papers' sections (Table 1, active/passive, "
                                 "cross-temperature, session shift): they are the papers' "
                                 "scenes'; run without --scene"]
        ran_on = describe(executor)
        _run_methods(report, seed, methods, step, sessions, executor=executor,
                     with_limit=with_limit and scene is None, scene=scene)
        report["executor"] = ran_on
    finally:
        if own:
            executor.shutdown(cancel_futures=True)
        _database.cache_clear()              # trials and models are kept for one run only
        _shift_session.cache_clear()
        _FITS.clear()
    return report


def jobs(methods, with_limit: bool = True, scene: str | None = None) -> list[tuple]:
    """The sweep's jobs, ``(kind, method)``: a method's sections ("method",
    or its cross-validation on ``scene``: "cv"), then the sections of no
    one method."""
    if scene is not None:
        return [("cv", m) for m in methods]
    out = [("method", m) for m in methods] + [("thermometer_ablation", None)]
    out += [("lm_vs_adam", None)] * ("pca-fnn" in methods)
    out += [("lstm_hidden_sweep", None)] * ("lstm" in methods)
    return out + [("limit", None)] * with_limit


def identify_job(kind: str, method: str | None, seed: int, sessions: int,
                 scene: str | None = None) -> dict:
    """One job of the sweep (:func:`jobs`), in whichever process runs it."""
    if kind == "cv":
        from telethermal.ident.crossval import cross_validate
        return cross_validate(_trials(scene, seed), method, 5, scene=scene)
    if kind == "method":
        return method_sections(method, seed, sessions)
    if kind == "limit":
        return limit(load_scene("fingertip-7"), [
            (s, from_trials(_trials("fingertip-7", s), max_s=1.0)[0])
            for s in range(seed, seed + sessions)])
    return {"thermometer_ablation": thermometer_ablation, "lm_vs_adam": lm_vs_adam,
            "lstm_hidden_sweep": lstm_hidden_sweep}[kind](seed)


def method_sections(method: str, seed: int, sessions: int) -> dict:
    """``method``'s Table 1 (with its live counts), active/passive,
    cross-temperature, session shift and temperature-channel rows."""
    t1 = sessions_table1(table1, method, seed, sessions, table1(method, seed))
    if getattr(METHODS[method], "needs_scene", False):
        # It fits one pad's model: the rows below train on one pad (or
        # object temperature) and test on another.
        return {"table1": t1, "live": t1.pop("live"), "not_run": [
            "active/passive, cross-temperature and the temperature channel: its estimate "
            "fits the pad (and object temperature) of the scene it was trained on; these "
            "rows test on another pad or temperature, or read temperature"],
                "session_shift": session_shift(method, seed)}
    out = {"table1": t1, "live": t1.pop("live"), "active_passive": active_passive(method, seed),
           "cross_temperature": cross_temperature(method, seed),
           "session_shift": session_shift(method, seed)}
    if not make(method).streaming:
        out["temperature"] = temperature_rows(method, seed)
    return out


def _run_methods(report: dict, seed: int, methods, step, sessions: int = 1, executor=None,
                 with_limit: bool = False, scene: str | None = None) -> None:
    from telethermal.bench.executor import SerialExecutor, sweep

    work = jobs(methods, with_limit, scene)
    done = sweep(executor or SerialExecutor(), identify_job,
                 [(kind, m, seed, sessions, None if scene is None else str(scene))
                  for kind, m in work], progress=step,
                 label=lambda c: f"{c[1]}: 5 folds on {scene}" if c[0] == "cv"
                 else c[1] or c[0].replace("_", " "))
    for (kind, m), result in zip(work, done):
        if kind in ("method", "cv"):
            report["methods"][m] = result
        else:
            report[kind] = result
    if "limit" in report:
        report["limit_gap_points"] = gaps_to_limit(report["methods"], report["limit"])


def run_and_save(json_path, png_path, seed: int = 0, methods=None, command: str = "",
                 progress: Callable[[str], None] | None = None, scene: str | None = None,
                 sessions: int = 3, with_limit: bool = True, executor=None) -> dict:
    """Run the benchmark, write the JSON report (with ``command``), then
    plot it to ``png_path`` (a plot that fails loses no figure); returns
    the report."""
    from telethermal.jsonfile import write_json

    report = run(seed=seed, methods=methods, progress=progress, scene=scene, sessions=sessions,
                 with_limit=with_limit and scene is None, executor=executor)
    report["command"] = command
    write_json(json_path, report)
    if scene is not None:
        from telethermal.ident.evaluate import plot_accuracy
        plot_accuracy(report["methods"], png_path, f"{scene}: each method, 5 folds by group "
                                                    f"(seed {seed})")
    else:
        from telethermal.bench.identify_plot import plot
        plot(report, png_path)
    return report

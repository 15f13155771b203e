"""The benches' sweeps (seeds, materials, rows, as-built draws) through one
:class:`concurrent.futures.Executor`.

A sweep is a module-level function and a list of JSON-able arguments; each
call's result must be JSON-able too. What crosses a process boundary is the
function's name and JSON text, never a pickled object, and every result is
read back from its JSON whichever executor ran it, so the same sweep gives
the same report in one process, on this machine's workers or on a cluster.

* ``process`` (the default): :class:`JsonProcessPool`, worker processes of
  this Python (``python -m telethermal.bench.worker``) that read one job a
  line on their stdin and write its result a line on their stdout. A worker
  lives for the whole sweep, so what it loads once (a model file, a scene)
  serves every job it runs.
* ``serial``: :class:`SerialExecutor`, in this process (a debugger's, or a
  machine with one core).
* ``dask:ADDRESS`` or ``dask-local``: a Dask ``distributed`` cluster's
  executor (``pip install 'telethermal[dask]'``), at ``ADDRESS`` (its
  scheduler, e.g. ``tcp://10.0.0.5:8786``) or a local one of ``jobs``
  worker processes. Dask's own transport pickles what it sends: here only
  the function's name and JSON text; use it on a cluster you trust, as
  Dask's documentation says of any cluster.
"""

from __future__ import annotations

import importlib
import json
import os
import queue
import subprocess
import sys
import tempfile
import threading
import traceback
from collections.abc import Callable, Iterable
from concurrent.futures import Executor, Future

from telethermal.errors import BenchError

#: The executors :func:`open_executor` knows by name (a Dask one by prefix).
KINDS = ("process", "serial", "dask:ADDRESS", "dask-local")


def function_name(fn: Callable) -> str:
    """``module:qualname`` of a module-level function; a ValueError for
    anything a worker could not import by name (a lambda, a closure)."""
    module, qualname = getattr(fn, "__module__", None), getattr(fn, "__qualname__", "")
    if not module or "<" in qualname or module == "__main__":
        raise ValueError(f"a sweep runs module-level functions, got {fn!r}")
    return f"{module}:{qualname}"


def _function(name: str) -> Callable:
    module, _, qualname = name.partition(":")
    target = importlib.import_module(module)
    for part in qualname.split("."):
        target = getattr(target, part)
    return target


def call_json(name: str, args_json: str) -> str:
    """Run the function ``name`` on ``args_json`` (a JSON list) and return its
    result as JSON text: every executor runs a job through this."""
    return json.dumps(_function(name)(*json.loads(args_json)), default=_plain)


def _plain(value):
    """numpy's scalars and arrays, as JSON has them."""
    if hasattr(value, "tolist"):
        return value.tolist()
    raise TypeError(f"a sweep's result holds {type(value).__name__}, which is not JSON")


class _DeferredFuture(Future):
    """A serial job's future: the job runs when its result (or exception)
    is first asked for, so a sweep reads (and stops at) each job in turn."""

    def __init__(self, fn, args, kwargs):
        super().__init__()
        self._call = (fn, args, kwargs)
        self._taking = threading.Lock()

    def _run_once(self) -> None:
        with self._taking:
            call, self._call = self._call, None
        if call is None or not self.set_running_or_notify_cancel():
            return
        fn, args, kwargs = call
        try:
            self.set_result(fn(*args, **kwargs))
        except BaseException as exc:         # the job's; an interrupt goes up too
            self.set_exception(exc)
            if not isinstance(exc, Exception):
                raise

    def result(self, timeout=None):
        self._run_once()
        return super().result(timeout)

    def exception(self, timeout=None):
        self._run_once()
        return super().exception(timeout)


class SerialExecutor(Executor):
    """Each job in this process, in turn, when its result is asked for."""

    workers = 1

    def submit(self, fn, /, *args, **kwargs) -> Future:
        return _DeferredFuture(fn, args, kwargs)


def cpus() -> int:
    """The CPUs this process may run on (its affinity, not the machine's count)."""
    try:
        return len(os.sched_getaffinity(0)) or 1
    except AttributeError:                    # no affinity on this platform
        return os.cpu_count() or 1


class JsonProcessPool(Executor):
    """``max_workers`` worker processes (``python -P -m telethermal.bench.worker``)
    that take jobs as JSON lines and give results back as JSON lines. Only
    :func:`call_json` jobs (a function's name and JSON text) can be
    submitted; a worker that dies fails its job and is replaced; what a
    worker logs goes to this process's stderr. No pickle crosses to a
    worker."""

    def __init__(self, max_workers: int | None = None):
        self.workers = max(1, max_workers or cpus())
        self._jobs: queue.Queue = queue.Queue()
        self._lock = threading.Lock()
        self._shutdown = False
        #: Each serving thread's worker while it runs a job (killed on cancel).
        self._busy: dict[int, subprocess.Popen] = {}
        self._threads = [threading.Thread(target=self._serve, name=f"bench-worker-{i}",
                                          daemon=True) for i in range(self.workers)]
        for t in self._threads:
            t.start()

    def submit(self, fn, /, *args, **kwargs) -> Future:
        if fn is not call_json or kwargs or len(args) != 2:
            raise ValueError("JsonProcessPool runs call_json(name, args_json) jobs only")
        future: Future = Future()
        with self._lock:
            if self._shutdown:
                raise RuntimeError("cannot submit to a pool that was shut down")
            self._jobs.put((future, json.dumps({"call": args[0], "args": args[1]})))
        return future

    @staticmethod
    def _start() -> subprocess.Popen:
        # The worker imports what this process can (a sweep's function may
        # live in a script's or a test's folder), and not the working
        # folder's files first (-P).
        env = {**os.environ, "PYTHONPATH": os.pathsep.join(p for p in sys.path if p)}
        proc = subprocess.Popen([sys.executable, "-P", "-m", "telethermal.bench.worker"],
                                stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                stderr=subprocess.PIPE, text=True, bufsize=1, env=env,
                                errors="backslashreplace")
        proc.relay = threading.Thread(target=_relay, args=(proc.stderr,),
                                      name="bench-worker-stderr", daemon=True)
        proc.relay.start()
        return proc

    def _serve(self) -> None:
        proc = None
        try:
            while True:
                item = self._jobs.get()
                if item is None:
                    return
                future, line = item
                if not future.set_running_or_notify_cancel():
                    continue
                try:
                    if proc is None:
                        proc = self._start()
                    self._busy[threading.get_ident()] = proc
                    proc = self._run(proc, future, line)
                except BaseException as exc:     # this thread's own failure: the job's
                    if proc is not None:
                        proc.kill()
                        _close(proc)
                        proc = None
                    if not future.done():
                        future.set_exception(BenchError(
                            f"a bench worker's job failed in the pool: "
                            f"{type(exc).__name__}: {exc}"))
                finally:
                    self._busy.pop(threading.get_ident(), None)
        finally:
            if proc is not None:
                _close(proc)

    @staticmethod
    def _run(proc: subprocess.Popen, future: Future, line: str) -> subprocess.Popen | None:
        """One job on ``proc``; the worker to go on with (None: it died)."""
        try:
            proc.stdin.write(line + "\n")
            proc.stdin.flush()
            answer = proc.stdout.readline()
        except OSError:
            answer = ""
        reply = json.loads(answer) if answer.endswith("\n") else None
        if reply is None:                       # the worker died, or its line was cut
            proc.kill()
            _close(proc)
            future.set_exception(BenchError(
                f"a bench worker died (exit code {proc.returncode}); what it said is on "
                "stderr above"))
            return None
        if "error" in reply:
            future.set_exception(BenchError(reply["error"]))
        else:
            future.set_result(reply["result"])
        return proc

    def shutdown(self, wait: bool = True, *, cancel_futures: bool = False) -> None:
        """Stop the workers once their jobs are done; ``cancel_futures``:
        the queued jobs cancelled and the running ones killed (their futures
        fail), as when a sweep failed or was interrupted."""
        with self._lock:
            self._shutdown = True
        if cancel_futures:
            while True:
                try:
                    item = self._jobs.get_nowait()
                except queue.Empty:
                    break
                if item is not None:
                    item[0].cancel()
            for proc in list(self._busy.values()):
                proc.kill()
        for _ in self._threads:
            self._jobs.put(None)
        if wait:
            for t in self._threads:
                t.join()

    def __exit__(self, exc_type, exc, tb):
        # Leaving on an error or an interrupt: no job is waited for.
        self.shutdown(wait=True, cancel_futures=exc_type is not None)
        return False


def _relay(pipe) -> None:
    """A worker's stderr, line by line, into this process's ``sys.stderr``
    (where a command's progress bar, which redirects it, prints it above
    the bar instead of through it)."""
    try:
        for line in pipe:
            sys.stderr.write(line)
            sys.stderr.flush()
    except (OSError, ValueError):           # the pipe closed under it
        pass
    finally:
        pipe.close()


def _close(proc: subprocess.Popen) -> None:
    """A worker's pipes closed (its stdin's end tells it to stop), and the
    worker waited for."""
    for pipe in (proc.stdin, proc.stdout):
        try:
            pipe.close()
        except OSError:                  # a dead worker's stdin: its buffer unflushable
            pass
    proc.wait()
    relay = getattr(proc, "relay", None)
    if relay is not None:                # the worker's last words relayed before it is gone
        relay.join(timeout=5.0)


def open_executor(kind: str | None = None, jobs: int | None = None,
                  work_dir: str | None = None) -> Executor:
    """The executor ``kind`` names (:data:`KINDS`; None: ``process``) with
    ``jobs`` workers (None: one a CPU this process may use). ``work_dir``:
    where a bench writes the files its jobs read (its models), a folder its
    workers see at the same path (None: this machine's temporary folder; a
    remote cluster, ``dask:ADDRESS``, needs one on a file system it shares)."""
    kind = kind or "process"
    if work_dir is not None and not os.path.isdir(work_dir):
        raise BenchError(f"--work-dir {work_dir}: no such folder")
    if kind in ("process", "serial"):
        executor = JsonProcessPool(jobs) if kind == "process" else SerialExecutor()
    elif kind == "dask-local" or kind.startswith("dask:"):
        executor = _dask(kind, jobs, work_dir)
    else:
        raise BenchError(f"--executor must be one of {', '.join(KINDS)}, got {kind!r}")
    executor.work_dir = work_dir
    return executor


def _dask(kind: str, jobs: int | None, work_dir: str | None) -> Executor:
    try:
        from distributed import Client, LocalCluster
    except ImportError:
        raise BenchError(f"--executor {kind} needs Dask's distributed: "
                         "pip install 'telethermal[dask]'") from None
    if kind == "dask-local":
        cluster = LocalCluster(n_workers=jobs or cpus(), threads_per_worker=1, processes=True,
                               dashboard_address=None)
        return _DaskExecutor(Client(cluster), cluster)
    if work_dir is None:
        raise BenchError(f"--executor {kind} needs --work-dir DIR: a folder its workers see at "
                         "the same path (a shared file system), for the models the jobs read; "
                         "a scene file given by path must be on it too")
    try:
        client = Client(kind.removeprefix("dask:"), timeout=30)
    except (OSError, TimeoutError, ValueError) as exc:
        raise BenchError(f"--executor {kind}: no Dask scheduler answered there "
                         f"({type(exc).__name__}: {exc})") from None
    return _DaskExecutor(client)


def work_folder(executor: Executor):
    """A temporary folder for a sweep's files, where ``executor``'s workers
    see it (its ``work_dir``; this machine's temporary folder without)."""
    return tempfile.TemporaryDirectory(prefix="telethermal-bench-",
                                       dir=getattr(executor, "work_dir", None))


def describe(executor: Executor) -> str:
    """How a report names where its sweep ran."""
    if isinstance(executor, _DaskExecutor):
        where = "a local Dask cluster" if executor.cluster is not None else "a Dask cluster"
        return f"{where}, {len(executor.client.nthreads())} workers"
    if isinstance(executor, SerialExecutor):
        return "this process"
    return f"{getattr(executor, 'workers', '?')} worker processes"


class _DaskExecutor(Executor):
    """A Dask client's executor that closes its client (and local cluster)."""

    def __init__(self, client, cluster=None):
        self.client, self.cluster = client, cluster
        self._executor = client.get_executor(pure=False)

    def submit(self, fn, /, *args, **kwargs) -> Future:
        return self._executor.submit(fn, *args, **kwargs)

    def shutdown(self, wait: bool = True, *, cancel_futures: bool = False) -> None:
        self._executor.shutdown(wait=wait)
        self.client.close()
        if self.cluster is not None:
            self.cluster.close()


def sweep(executor: Executor, fn: Callable, calls: Iterable[tuple], progress=None,
          label: Callable[[tuple], str] | None = None,
          done: Callable[[tuple], None] | None = None) -> list:
    """``fn(*args)`` for each ``args`` of ``calls`` on ``executor``, the
    results in the order of ``calls``, each read back from its JSON.
    ``progress(text)`` as each finishes, or ``done(args)`` (a bench that
    says its own steps); a call that raised is a :class:`BenchError`
    naming it (the others are cancelled)."""
    name = function_name(fn)
    calls = [tuple(c) for c in calls]
    futures: list[Future] = []
    out = []
    try:
        futures += [executor.submit(call_json, name, json.dumps(list(c), default=_plain))
                    for c in calls]
        for k, (c, f) in enumerate(zip(calls, futures), 1):
            try:
                result = json.loads(f.result())
            except Exception as exc:
                what = label(c) if label else ", ".join(map(repr, c))
                raise BenchError(f"{name}({what}) failed: {exc}") from exc
            out.append(result)
            if done is not None:
                done(c)
            if progress is not None:
                progress(f"{label(c) if label else name} ({k} of {len(calls)})")
    except BaseException:
        for f in futures:
            f.cancel()
        raise
    return out


#: In a worker, where its answers go (a test cuts one short through it).
ANSWERS = None


def worker_main(stdin=sys.stdin, stdout=sys.stdout) -> None:
    """A :class:`JsonProcessPool` worker: one job a line in, one answer a
    line out (``{"result": ...}`` or ``{"error": ...}``), until stdin closes."""
    global ANSWERS
    ANSWERS = stdout
    try:
        _serve_jobs(stdin, stdout)
    except KeyboardInterrupt:                # Ctrl-C reaches the workers too: quietly
        sys.exit(130)


def _serve_jobs(stdin, stdout) -> None:
    for line in stdin:
        job = json.loads(line)
        try:
            reply = {"result": call_json(job["call"], job["args"])}
        except Exception as exc:            # the job's; the worker goes on
            reply = {"error": f"{type(exc).__name__}: {exc}\n"
                              f"{traceback.format_exc()[-3000:]}"}
        stdout.write(json.dumps(reply) + "\n")
        stdout.flush()

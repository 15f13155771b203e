"""The benches' executor (issue 45): a sweep gives the same results in this
process and on worker processes, in the order of its calls, with only JSON
crossing; a failing or dying job is a clear error, and the pool goes on."""

from __future__ import annotations

import math
import os

import numpy as np
import pytest

from telethermal.bench.executor import (JsonProcessPool, SerialExecutor, call_json, describe,
                                        function_name, open_executor, sweep, work_folder)
from telethermal.errors import BenchError


def square_and_pid(x: float) -> dict:
    """A job: its value, numpy's types (read back as JSON's) and who ran it."""
    return {"x": x, "square": np.float64(x) ** 2, "vector": np.arange(3) * x,
            "pid": os.getpid()}


def fail_on(x: int) -> int:
    if x == 3:
        raise ValueError(f"three is refused ({x})")
    return x


def die(code: int) -> None:
    os._exit(code)


def noisy(x: int) -> int:
    print("a job that prints", x)           # must not reach the pool's answers
    return x


def strip(results):
    return [{k: v for k, v in r.items() if k != "pid"} for r in results]


def test_the_process_pool_and_the_serial_executor_give_the_same_results_in_order():
    calls = [(0.5 * k,) for k in range(12)]
    seen = []
    with JsonProcessPool(2) as pool:
        pooled = sweep(pool, square_and_pid, calls, progress=seen.append)
    with SerialExecutor() as serial:
        here = sweep(serial, square_and_pid, calls)
    assert strip(pooled) == strip(here)
    assert [r["x"] for r in pooled] == [c[0] for c in calls]
    assert pooled[3]["square"] == 2.25 and pooled[3]["vector"] == [0.0, 1.5, 3.0]
    # Two workers, neither of them this process; each ran several jobs.
    pids = {r["pid"] for r in pooled}
    assert os.getpid() not in pids and 1 <= len(pids) <= 2
    assert {r["pid"] for r in here} == {os.getpid()}
    assert len(seen) == 12 and seen[-1].endswith("(12 of 12)")


def test_a_failing_job_is_named_and_the_pool_serves_the_next_sweep():
    with JsonProcessPool(2) as pool:
        with pytest.raises(BenchError, match=r"fail_on\(3\) failed: .*three is refused"):
            sweep(pool, fail_on, [(k,) for k in range(6)])
        assert sweep(pool, fail_on, [(1,), (2,)]) == [1, 2]


def test_a_worker_that_dies_fails_its_job_and_is_replaced():
    with JsonProcessPool(1) as pool:
        with pytest.raises(BenchError, match=r"a bench worker died \(exit code 3\)"):
            sweep(pool, die, [(3,)])
        assert sweep(pool, noisy, [(5,), (6,)]) == [5, 6]


def test_what_a_worker_prints_reaches_this_processs_stderr(capsys):
    """Through sys.stderr (which a command's progress bar redirects above
    itself), not straight onto the terminal's file descriptor."""
    with JsonProcessPool(1) as pool:
        assert sweep(pool, noisy, [(7,)]) == [7]
    assert "a job that prints 7" in capsys.readouterr().err


def cut_answer(x: int) -> None:
    """A worker killed while writing its answer: half a line, then gone."""
    from telethermal.bench import executor
    executor.ANSWERS.write('{"result": "1')
    executor.ANSWERS.flush()
    os._exit(9)


def test_a_cut_answer_fails_its_job_instead_of_hanging_the_sweep():
    with JsonProcessPool(1) as pool:
        with pytest.raises(BenchError, match="a bench worker died"):
            sweep(pool, cut_answer, [(1,)])
        assert sweep(pool, fail_on, [(4,)]) == [4]


calls_made = []


def record_and_fail(x: int) -> int:
    calls_made.append(x)
    return fail_on(x)


def interrupt(x: int) -> int:
    calls_made.append(x)
    raise KeyboardInterrupt


def test_serial_jobs_run_in_turn_and_a_failure_or_an_interrupt_stops_the_sweep():
    calls_made.clear()
    with pytest.raises(BenchError, match="three is refused"):
        sweep(SerialExecutor(), record_and_fail, [(k,) for k in range(6)])
    assert calls_made == [0, 1, 2, 3]                 # none after the failing one
    calls_made.clear()
    with pytest.raises(KeyboardInterrupt):
        sweep(SerialExecutor(), interrupt, [(k,) for k in range(4)])
    assert calls_made == [0]


def test_only_named_functions_and_json_cross():
    with pytest.raises(ValueError, match="module-level"):
        function_name(lambda x: x)
    with JsonProcessPool(1) as pool, pytest.raises(ValueError, match="call_json"):
        pool.submit(print, "x")
    with pytest.raises(TypeError, match="not JSON"):
        call_json(f"{__name__}:_returns_an_object", "[]")
    assert call_json(f"{__name__}:fail_on", "[2]") == "2"
    # NaN survives the round trip (Python's JSON reads what it wrote).
    assert math.isnan(sweep(SerialExecutor(), float, [("nan",)])[0])


def _returns_an_object():
    return object()


def test_an_unknown_executor_is_refused_naming_the_known_ones():
    with pytest.raises(BenchError, match="process, serial, dask:ADDRESS, dask-local"):
        open_executor("threads")


def test_a_remote_cluster_needs_a_shared_work_folder_and_an_answering_scheduler(tmp_path):
    with pytest.raises(BenchError, match="needs --work-dir DIR"):
        open_executor("dask:tcp://127.0.0.1:9")
    with pytest.raises(BenchError, match="no Dask scheduler answered"):
        open_executor("dask:nonsense://", work_dir=str(tmp_path))


def test_a_sweeps_files_go_where_its_workers_see_them(tmp_path):
    with open_executor("serial", work_dir=str(tmp_path)) as executor:
        with work_folder(executor) as folder:
            assert os.path.dirname(folder) == str(tmp_path)
        assert describe(executor) == "this process"
    with open_executor("process", 2) as pool:
        assert describe(pool) == "2 worker processes"


def test_a_local_dask_cluster_gives_the_same_results():
    # The optional extra (telethermal[dask], in the test extras): a lab that
    # outgrows one machine passes its cluster's address instead.
    calls = [(0.25 * k,) for k in range(6)]
    with open_executor("dask-local", 2) as cluster:
        remote = sweep(cluster, square_and_pid, calls)
    assert strip(remote) == strip(sweep(SerialExecutor(), square_and_pid, calls))
    assert os.getpid() not in {r["pid"] for r in remote}


def sleep_then(x: float) -> float:
    import time
    time.sleep(x)
    return x


def test_leaving_a_pool_on_an_error_kills_its_running_jobs_instead_of_waiting():
    # A failed sweep on the pool: the CLI leaves its `with` on the error,
    # and a job running on another worker (a whole method's sections) is
    # killed, not waited for. Counted, not timed: the long job's future
    # fails, it does not finish.
    pool = JsonProcessPool(2)
    with pytest.raises(BenchError, match="three is refused"):
        with pool:
            long = pool.submit(call_json, f"{__name__}:sleep_then", "[120]")
            sweep(pool, fail_on, [(3,)])
    assert long.done() and isinstance(long.exception(), BenchError)


def test_a_serial_future_answers_exception_and_result_alike():
    f = SerialExecutor().submit(fail_on, 3)
    assert isinstance(f.exception(), ValueError)
    with pytest.raises(ValueError):
        f.result()
    assert SerialExecutor().submit(fail_on, 2).exception() is None


def test_a_work_folder_that_is_not_there_is_refused(tmp_path):
    with pytest.raises(BenchError, match="no such folder"):
        open_executor("serial", work_dir=str(tmp_path / "missing"))

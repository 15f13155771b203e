"""The benches' executor (issue 45): a sweep gives the same results in this
process and on worker processes, in the order of its calls, with only JSON
crossing; a failing or dying job is a clear error, and the pool goes on."""

from __future__ import annotations

import math
import os

import numpy as np
import pytest

from telethermal.bench.executor import (JsonProcessPool, SerialExecutor, call_json,
                                        function_name, open_executor, sweep)
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
        with pytest.raises(BenchError, match="a bench worker died"):
            sweep(pool, die, [(3,)])
        assert sweep(pool, noisy, [(5,), (6,)]) == [5, 6]


def test_only_named_functions_and_json_cross():
    with pytest.raises(ValueError, match="module-level"):
        function_name(lambda x: x)
    with pytest.raises(ValueError, match="call_json"):
        JsonProcessPool(1).submit(print, "x")
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


def test_a_local_dask_cluster_gives_the_same_results():
    # The optional extra (telethermal[dask], in the test extras): a lab that
    # outgrows one machine passes its cluster's address instead.
    calls = [(0.25 * k,) for k in range(6)]
    with open_executor("dask-local", 2) as cluster:
        remote = sweep(cluster, square_and_pid, calls)
    assert strip(remote) == strip(sweep(SerialExecutor(), square_and_pid, calls))
    assert os.getpid() not in {r["pid"] for r in remote}

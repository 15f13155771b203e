"""Thread policy for the small dense linear algebra telethermal does."""

from __future__ import annotations

import functools

from threadpoolctl import threadpool_limits


def single_threaded_blas(fn):
    """Run ``fn`` with one BLAS thread.

    The matrices here are a few hundred wide at most; on a shared 2-core
    machine OpenBLAS's threads cost far more than the work they split
    (measured here: 60 Levenberg-Marquardt iterations 2 s against 0.15 s; the
    first paper's pad database 0.41 s against 0.18 s).
    """
    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        with threadpool_limits(limits=1, user_api="blas"):
            return fn(*args, **kwargs)
    return wrapper

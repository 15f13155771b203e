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


def single_threaded_torch(fn):
    """Run ``fn`` with torch on one intra-op thread (restored after).

    The recurrent identifiers' figures moved with torch's thread count (7
    classes at 0.25 s: 66 % on 2 threads, 70 % on 1: a reduction's order
    changes its rounding, and training amplifies it), so training and
    inference are pinned to one thread: the same figures on any machine.
    """
    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        import torch

        threads = torch.get_num_threads()
        torch.set_num_threads(1)
        try:
            return fn(*args, **kwargs)
        finally:
            torch.set_num_threads(threads)
    return wrapper

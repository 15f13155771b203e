"""One piece of work at a time on a worker thread, its result taken by the
service's loop when it is done.

A service's loop must keep its transport's heartbeats going (a peer silent
for ``dead_after_s`` is declared lost). Work that takes longer than a
heartbeat and needs none of the loop's sockets or devices runs here: the
simulated sensing pad's next touch, whose physics the simulator computes in
advance (about 0.3 s on an idle 2-core machine, over a second when the
machine is loaded, which had the master declare the slave lost after every
touch's lift)."""

from __future__ import annotations

import logging
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from typing import Any

log = logging.getLogger("telethermal.background")


class Background:
    """At most one job the loop waits on: ``start`` it, ``take`` its outcome
    (and the tag it was started with) once done, or ``drop`` it. One worker
    thread: jobs run one after another, never two at once."""

    def __init__(self, name: str):
        self.name = name
        self._pool: ThreadPoolExecutor | None = None
        self._job: tuple[Future, tuple] | None = None

    @property
    def pending(self) -> bool:
        return self._job is not None

    @property
    def tag(self) -> tuple | None:
        """The pending job's tag (None: no job)."""
        return self._job[1] if self._job is not None else None

    def start(self, work: Callable[[], Any], tag: tuple = ()) -> None:
        """``work()`` on the worker thread; ``tag``: what the loop needs with
        its result. A job not taken is replaced without waiting for it: not
        run if it has not started, else its result discarded when it ends
        (the one worker runs ``work`` after it)."""
        if self._job is not None:
            future, _ = self._job
            self._job = None
            if not future.cancel():
                future.add_done_callback(self._discarded)
        if self._pool is None:
            self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix=self.name)
        self._job = (self._pool.submit(work), tag)

    def _discarded(self, future: Future) -> None:
        if not future.cancelled() and future.exception() is not None:
            log.debug("%s: a replaced job failed: %s", self.name, future.exception())

    def take(self, wait: bool = False) -> tuple[Any, BaseException | None, tuple] | None:
        """(result, None, tag) once the job is done (at once if ``wait``), or
        (None, its exception, tag) if it failed; None if no job is done."""
        if self._job is None or not (wait or self._job[0].done()):
            return None
        future, tag = self._job
        self._job = None
        try:
            return future.result(), None, tag
        except Exception as exc:
            return None, exc, tag

    def drop(self) -> None:
        """The job not taken is waited for and its result discarded (the
        caller then does on its own thread what the job did: never both at
        once)."""
        if self._job is None:
            return
        future, _ = self._job
        self._job = None
        try:
            future.result()
        except Exception as exc:             # nobody wants it: said, not raised
            log.debug("%s: a dropped job failed: %s", self.name, exc)
        # A job it replaced ran before it (one worker, in order): done too.

    def close(self) -> None:
        """The job not taken is abandoned (not waited for: a service that
        stops closes its sockets and recording first); no more jobs."""
        self._job = None
        if self._pool is not None:
            self._pool.shutdown(wait=False, cancel_futures=True)
            self._pool = None

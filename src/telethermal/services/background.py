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
    """At most one job: ``start`` it, ``take`` its result (and the tag it
    was started with) once done, or ``drop`` it."""

    def __init__(self, name: str):
        self.name = name
        self._pool: ThreadPoolExecutor | None = None
        self._job: tuple[Future, tuple] | None = None

    @property
    def pending(self) -> bool:
        return self._job is not None

    def start(self, work: Callable[[], Any], tag: tuple = ()) -> None:
        """``work()`` on the worker thread, replacing a job not taken;
        ``tag``: what the loop needs with its result."""
        self.drop()
        if self._pool is None:
            self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix=self.name)
        self._job = (self._pool.submit(work), tag)

    def take(self, wait: bool = False) -> tuple[Any, tuple] | None:
        """(result, tag) once the job is done (at once if ``wait``), else
        None; the job's exception is raised here, once."""
        if self._job is None or not (wait or self._job[0].done()):
            return None
        future, tag = self._job
        self._job = None
        return future.result(), tag

    def drop(self) -> None:
        """The job not taken is waited for and its result discarded."""
        if self._job is None:
            return
        future, _ = self._job
        self._job = None
        try:
            future.result()
        except Exception as exc:             # nobody wants it: said, not raised
            log.debug("%s: a dropped job failed: %s", self.name, exc)

    def close(self) -> None:
        """The job not taken is abandoned (not waited for: a service that
        stops closes its sockets and recording first); no more jobs."""
        self._job = None
        if self._pool is not None:
            self._pool.shutdown(wait=False, cancel_futures=True)
            self._pool = None

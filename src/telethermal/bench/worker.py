"""A bench worker process (:class:`~telethermal.bench.executor.JsonProcessPool`):
``python -m telethermal.bench.worker`` reads one job a line on stdin and
writes its answer a line on stdout; what a job prints goes to stderr."""

import os
import sys

from telethermal.bench.executor import worker_main

if __name__ == "__main__":
    answers = os.fdopen(os.dup(1), "w")
    os.dup2(2, 1)                       # a job's own prints (C's too) go to stderr
    sys.stdout = sys.stderr
    worker_main(sys.stdin, answers)

"""Top-level task functions for the executor tests (dask workers import them by name)."""

from __future__ import annotations

import os
import signal
import time
from pathlib import Path

from wallcal.errors import DataError


def square_logged(task):
    """``x * x``; appends the worker's pid to ``log_dir/<x>.runs`` each time it runs."""
    x, log_dir = task
    with open(Path(log_dir) / f"{x}.runs", "a") as fh:
        fh.write(f"{os.getpid()}\n")
    return x * x


def die_once(task):
    """``x * x``, after killing its own worker process the first time task ``x == victim`` runs (mid-run)."""
    x, victim, marker = task
    time.sleep(0.2)
    if x == victim and not Path(marker).exists():
        Path(marker).write_text(str(os.getpid()))
        os.kill(os.getpid(), signal.SIGKILL)
    return x * x


def refuse(task):
    """Raises a DataError for ``x == 3`` (a WallcalError: not retried); logs every attempt."""
    x, log_dir = task
    with open(Path(log_dir) / f"{x}.runs", "a") as fh:
        fh.write("1\n")
    if x == 3:
        raise DataError(f"task {x}: bad input")
    return x


def worker_pid(_task):
    return os.getpid()

"""One executor for every expensive run (EnergyPlus runs, whole calibrations), on dask.distributed.

:class:`Executor` maps a top-level function over a list of tasks on a dask.distributed cluster:

- ``scheduler=None`` and no ``WALLCAL_SCHEDULER`` in the environment: a ``LocalCluster`` of worker
  *processes* with one thread each, as many as the machine has cores (or ``workers``), started on the
  first :meth:`Executor.map` that has something to run and closed when the ``with`` block ends;
- an address (``tcp://host:8786``, ``host:8786``; or ``WALLCAL_SCHEDULER``): an existing cluster
  (``dask scheduler`` + ``dask worker``, dask-jobqueue, ...). An address that does not answer within
  :data:`CONNECT_TIMEOUT_S` is a :class:`ClusterError` naming it.

Results come back in the order of the tasks; a progress line on standard error counts them as they
complete. A task whose worker dies is run again elsewhere (the scheduler's ``allowed-failures``), a
task that raises something other than a :class:`~wallcal.errors.WallcalError` is retried ``retries``
times; a ``WallcalError`` (bad input, EnergyPlus refusing the model) is not retried and is raised as
it is. With ``cache_dir`` each finished result is stored there (atomically, as it completes) under the
task's key, by default a hash of the function's qualified name and the pickled task, so the hash of
the run's inputs; with ``resume=True`` stored results are reused and those tasks do not run again.

Each task runs in its own worker process; a task that needs files makes its own temporary
directory there (the EnergyPlus engine does, one per run). Inside a dask worker (a task that itself
maps tasks) the executor runs its tasks in that worker, one after the other, rather than starting a
cluster in a cluster.

dask is imported only when an executor first needs it (``pip install 'wallcal[cluster]'``).
"""

from __future__ import annotations

import contextvars
import hashlib
import logging
import os
import pickle
import re
import sys
import tempfile
import time
import uuid
from collections.abc import Callable, Sequence
from pathlib import Path

from .errors import WallcalError, require

#: Environment variable naming the scheduler address used when none is given.
SCHEDULER_ENV = "WALLCAL_SCHEDULER"
#: Seconds to wait for a scheduler to answer before giving up with a :class:`ClusterError`.
CONNECT_TIMEOUT_S = 6.0
#: ``scheduler="local"`` asks for a local cluster even when ``WALLCAL_SCHEDULER`` is set.
LOCAL = "local"

_ACTIVE: contextvars.ContextVar[Executor | None] = contextvars.ContextVar("wallcal_executor", default=None)


class ClusterError(WallcalError):
    """The dask cluster cannot be reached or lost a task for good."""


class TaskFailed:
    """A task's :class:`~wallcal.errors.WallcalError`, carried back as a result so that dask does not retry it."""

    def __init__(self, error: BaseException):
        self.error = error


def call_task(fn: Callable, task):
    """Run ``fn(task)`` on a worker: a :class:`~wallcal.errors.WallcalError` comes back as :class:`TaskFailed`
    (deterministic: retrying it would fail again), any other exception is raised (dask retries it)."""
    try:
        return fn(task)
    except WallcalError as exc:
        return TaskFailed(exc)


def current_executor() -> Executor | None:
    """The executor of the innermost active ``with Executor(...)`` block in this context, or None."""
    return _ACTIVE.get()


def task_key(fn: Callable, task) -> str:
    """The default cache key of ``fn(task)``: SHA-256 of the function's qualified name and the pickled task."""
    h = hashlib.sha256(f"{fn.__module__}.{fn.__qualname__}\n".encode())
    try:
        h.update(pickle.dumps(task, protocol=5))
    except (pickle.PicklingError, TypeError, AttributeError):
        import cloudpickle

        h.update(cloudpickle.dumps(task, protocol=5))
    return h.hexdigest()[:40]


def in_dask_worker() -> bool:
    """Whether this code runs inside a dask worker (without importing dask when it was never imported)."""
    if "distributed" not in sys.modules:
        return False
    from distributed import get_worker

    try:
        get_worker()
    except ValueError:
        return False
    return True


class Executor:
    """Runs ``fn(task)`` for many tasks on a dask.distributed cluster (module docstring).

    Parameters
    ----------
    scheduler : str or None
        Scheduler address; None: ``WALLCAL_SCHEDULER``, else a local cluster; ``"local"``: a local cluster.
    workers : int or None
        Worker processes of the local cluster (default: the machine's cores). Ignored with an address.
    cache_dir : path or None
        Where finished results are stored (one pickle per task key), as they complete.
    resume : bool
        Reuse the results stored in ``cache_dir`` instead of running those tasks again.
    progress : bool
        Print a progress line on standard error as tasks complete.
    label : str
        What the tasks are, for the progress line (``"EnergyPlus runs"``).
    """

    def __init__(
        self,
        scheduler: str | None = None,
        *,
        workers: int | None = None,
        cache_dir: str | os.PathLike | None = None,
        resume: bool = False,
        progress: bool = True,
        label: str = "runs",
    ):
        address = scheduler if scheduler is not None else os.environ.get(SCHEDULER_ENV, "").strip() or None
        self.address = None if address in (None, "", LOCAL) else str(address)
        if workers is not None and int(workers) < 1:
            raise ClusterError(f"workers must be at least 1, got {workers}")
        self.workers = int(workers) if workers is not None else None
        self.cache_dir = Path(cache_dir) if cache_dir is not None else None
        self.resume = bool(resume)
        self.progress = bool(progress)
        self.label = label
        self._client = None
        self._cluster = None
        self._token = None
        self.stats = {"submitted": 0, "cached": 0, "completed": 0}

    # ------------------------------------------------------------------ lifetime
    def __enter__(self) -> Executor:
        if self.address is not None and not in_dask_worker():
            self.client()  # an unreachable scheduler fails here, before any work
        self._token = _ACTIVE.set(self)
        return self

    def __exit__(self, *exc) -> None:
        if self._token is not None:
            _ACTIVE.reset(self._token)
            self._token = None
        self.close()

    def close(self) -> None:
        """Close the client and, when this executor started it, the local cluster."""
        client, cluster = self._client, self._cluster
        self._client = self._cluster = None
        if client is not None:
            client.close()
        if cluster is not None:
            cluster.close()

    @property
    def where(self) -> str:
        """Where the tasks run, in words."""
        if self.address is not None:
            return f"the dask cluster at {self.address}"
        return f"a local dask cluster of {self.n_local_workers()} worker processes"

    def n_local_workers(self) -> int:
        if self.workers is not None:
            return self.workers
        try:
            return max(1, len(os.sched_getaffinity(0)))
        except AttributeError:  # pragma: no cover - not on Linux
            return max(1, os.cpu_count() or 1)

    def client(self):
        """The ``distributed.Client`` (connecting, or starting the local cluster, on first use)."""
        if self._client is not None:
            return self._client
        distributed = require("distributed", "cluster")
        if self.address is not None:
            try:
                self._client = distributed.Client(
                    self.address, timeout=CONNECT_TIMEOUT_S, set_as_default=False, asynchronous=False
                )
            except (OSError, TimeoutError, ValueError) as exc:
                raise ClusterError(
                    f"cannot reach the dask scheduler at {self.address} within {CONNECT_TIMEOUT_S:g} s "
                    f"({type(exc).__name__}); start one (`dask scheduler`) or fix --scheduler / {SCHEDULER_ENV}"
                ) from None
            return self._client
        self._cluster = distributed.LocalCluster(
            n_workers=self.n_local_workers(),
            threads_per_worker=1,
            processes=True,
            dashboard_address="127.0.0.1:0",
            silence_logs=logging.CRITICAL,
        )
        self._client = distributed.Client(self._cluster, set_as_default=False)
        return self._client

    # ------------------------------------------------------------------ work
    def map(self, fn: Callable, tasks: Sequence, *, keys: Sequence[str] | None = None, retries: int = 2) -> list:
        """``[fn(t) for t in tasks]`` on the cluster, in the order of ``tasks``.

        Parameters
        ----------
        fn : callable
            A top-level (picklable) function of one task.
        tasks : sequence
            Picklable task descriptions.
        keys : sequence of str, optional
            A stable key per task for the cache (default :func:`task_key`).
        retries : int
            Extra attempts of a task that raised something other than a ``WallcalError``.

        Raises
        ------
        WallcalError
            The first task that raised one (the other tasks are cancelled).
        ClusterError
            A task killed its workers too often, or the cluster went away.
        """
        tasks = list(tasks)
        if keys is not None and len(keys) != len(tasks):
            raise ClusterError(f"{len(keys)} keys for {len(tasks)} tasks")
        if self.cache_dir is not None:
            keys = [safe_key(k) for k in keys] if keys is not None else [task_key(fn, t) for t in tasks]
            self.cache_dir.mkdir(parents=True, exist_ok=True)
        results: list = [None] * len(tasks)
        todo = []
        for i in range(len(tasks)):
            if self.resume and self.cache_dir is not None:
                hit = self._load(keys[i])
                if hit is not None:
                    results[i] = hit[0]
                    self.stats["cached"] += 1
                    continue
            todo.append(i)
        progress = Progress(self.label, len(tasks), len(tasks) - len(todo), self.progress)
        if not todo:
            progress.done()
            return results
        if in_dask_worker():
            for i in todo:
                results[i] = self._finish(i, call_task(fn, tasks[i]), keys, progress)
            progress.done()
            return results
        distributed = require("distributed", "cluster")
        client = self.client()
        futures = {}
        for i in todo:
            name = f"wallcal-{getattr(fn, '__name__', 'task')}-{uuid.uuid4().hex}"
            fut = client.submit(call_task, fn, tasks[i], key=name, retries=int(retries), pure=False)
            futures[fut] = i
        self.stats["submitted"] += len(futures)
        try:
            for fut in distributed.as_completed(list(futures), loop=client.loop):
                i = futures[fut]
                try:
                    value = fut.result()
                except distributed.client.FutureCancelledError as exc:
                    raise ClusterError(f"{self.where} cancelled a task ({exc})") from None
                except Exception as exc:
                    if type(exc).__name__ == "KilledWorker":
                        raise ClusterError(
                            f"a task killed its dask worker each time it ran ({exc}); nothing more was retried"
                        ) from None
                    raise
                results[i] = self._finish(i, value, keys, progress)
                fut.release()
        except BaseException:
            client.cancel(list(futures))
            raise
        progress.done()
        return results

    def _finish(self, i: int, value, keys, progress: Progress):
        if isinstance(value, TaskFailed):
            raise value.error
        if self.cache_dir is not None:
            self._store(keys[i], value)
        self.stats["completed"] += 1
        progress.step()
        return value

    def _path(self, key: str) -> Path:
        return self.cache_dir / f"{key}.pkl"

    def _load(self, key: str):
        path = self._path(key)
        try:
            with open(path, "rb") as fh:
                return (pickle.load(fh),)
        except FileNotFoundError:
            return None
        except (pickle.UnpicklingError, EOFError, AttributeError, ImportError):
            return None  # an unreadable entry is run again

    def _store(self, key: str, value) -> None:
        fd, tmp = tempfile.mkstemp(prefix=f".{key}.", dir=self.cache_dir)
        try:
            with os.fdopen(fd, "wb") as fh:
                pickle.dump(value, fh, protocol=5)
            os.replace(tmp, self._path(key))
        except BaseException:
            Path(tmp).unlink(missing_ok=True)
            raise


def safe_key(key: str) -> str:
    """A user key as a file name: unsafe characters replaced, with a short hash so distinct keys stay distinct."""
    key = str(key)
    clean = re.sub(r"[^A-Za-z0-9_.-]", "_", key)[:80]
    return f"{clean}-{hashlib.sha256(key.encode()).hexdigest()[:10]}"


def executor_from(scheduler: str | None = None, **kwargs) -> Executor:
    """An :class:`Executor` on ``scheduler``, else ``WALLCAL_SCHEDULER``, else a local cluster (``kwargs``: the
    executor's keyword arguments)."""
    return Executor(scheduler, **kwargs)


class Progress:
    """A progress line on standard error: ``label: done/total (cached), elapsed, remaining``.

    On a terminal it is rewritten in place; otherwise a line is printed at most every 10 s and at the end.
    """

    def __init__(self, label: str, total: int, cached: int, enabled: bool):
        self.label, self.total, self.cached = label, total, cached
        self.done_n = cached
        self.enabled = enabled and total > 0
        self.t0 = time.perf_counter()
        self.last = -1e9
        self.shown = -1
        self.tty = sys.stderr.isatty()
        if self.enabled:
            self.show(force=True)

    def step(self) -> None:
        self.done_n += 1
        self.show()

    def show(self, force: bool = False) -> None:
        if not self.enabled:
            return
        now = time.perf_counter()
        if not force and not self.tty and now - self.last < 10.0 and self.done_n < self.total:
            return
        self.last = now
        self.shown = self.done_n
        el = now - self.t0
        ran = self.done_n - self.cached
        left = self.total - self.done_n
        eta = f", ~{el / ran * left:.0f} s left" if ran and left else ""
        width = 20
        fill = int(round(width * self.done_n / self.total))
        bar = "#" * fill + "." * (width - fill)
        cached = f", {self.cached} from the cache" if self.cached else ""
        line = f"wallcal: {self.label} [{bar}] {self.done_n}/{self.total}{cached}, {el:.0f} s{eta}"
        if self.tty:
            sys.stderr.write("\r" + line + "\x1b[K")
        else:
            sys.stderr.write(line + "\n")
        sys.stderr.flush()

    def done(self) -> None:
        if self.enabled:
            if self.shown != self.done_n:
                self.show(force=True)
            if self.tty:
                sys.stderr.write("\n")
            self.enabled = False


__all__ = [
    "CONNECT_TIMEOUT_S",
    "LOCAL",
    "SCHEDULER_ENV",
    "ClusterError",
    "Executor",
    "Progress",
    "TaskFailed",
    "call_task",
    "current_executor",
    "executor_from",
    "in_dask_worker",
    "safe_key",
    "task_key",
]

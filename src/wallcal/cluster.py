"""One executor for every expensive run (EnergyPlus runs, whole calibrations), on dask.distributed.

:class:`Executor` maps a top-level function over a list of tasks on a dask.distributed cluster:

- ``scheduler=None`` and no ``WALLCAL_SCHEDULER`` in the environment: a ``LocalCluster`` of worker
  *processes* with one thread each, as many as the machine has cores (or ``workers``), started on the
  first :meth:`Executor.map` that has something to run and closed when the ``with`` block ends;
- an address (``tcp://host:8786``, ``tls://host:8786``, ``host:8786``; or ``WALLCAL_SCHEDULER``): an existing
  cluster (``dask scheduler`` + ``dask worker``, dask-jobqueue, ...). Before the ``distributed.Client`` is made,
  :func:`probe_scheduler` checks the address: its form, TLS certificates for ``tls://``, then a connection that
  must carry a dask handshake within ``connect_timeout`` seconds (:data:`CONNECT_TIMEOUT_S`, or
  ``WALLCAL_SCHEDULER_TIMEOUT``). Anything else (nothing listening, a silent listener, an HTTP server, random
  bytes) is a one-line :class:`ClusterError` naming the address, never a hang or a traceback from distributed.

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
import math
import os
import pickle
import re
import socket
import struct
import sys
import tempfile
import time
import uuid
from collections.abc import Callable, Sequence
from pathlib import Path

from .errors import WallcalError, require

#: Environment variable naming the scheduler address used when none is given.
SCHEDULER_ENV = "WALLCAL_SCHEDULER"
#: Seconds a scheduler has to accept the connection and send its dask handshake (then again for the Client to
#: connect) before a :class:`ClusterError`; ``WALLCAL_SCHEDULER_TIMEOUT`` or ``connect_timeout=`` change it.
CONNECT_TIMEOUT_S = 10.0
#: Environment variable with the connect-and-handshake time-out in seconds.
TIMEOUT_ENV = "WALLCAL_SCHEDULER_TIMEOUT"
#: Largest first message accepted from a scheduler during the probe (a dask handshake is about 100 bytes).
_MAX_HANDSHAKE = 1 << 16
#: dask transports other than TCP, not probed.
_UNPROBED = ("inproc", "ucx", "ws", "wss")
_ADDRESS = re.compile(
    r"(?:(?P<scheme>[A-Za-z][A-Za-z0-9+.-]*)://)?(?P<host>\[[0-9A-Fa-f:.]+\]|[A-Za-z0-9_.-]+):(?P<port>[0-9]{1,5})/?"
)
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


def connect_timeout_from(value=None) -> float:
    """The connect-and-handshake time-out [s]: ``value``, else ``WALLCAL_SCHEDULER_TIMEOUT``, else
    :data:`CONNECT_TIMEOUT_S`; a :class:`ClusterError` unless a number of seconds in (0, 3600]."""
    where = "the scheduler time-out"
    if value is None:
        value = os.environ.get(TIMEOUT_ENV, "").strip()
        if not value:
            return CONNECT_TIMEOUT_S
        where = TIMEOUT_ENV
    try:
        t = float(value)
    except (TypeError, ValueError):
        t = math.nan
    if not (math.isfinite(t) and 0 < t <= 3600):
        raise ClusterError(f"{where}: must be a number of seconds in (0, 3600], got {str(value)[:40]!r}")
    return t


def split_address(address: str) -> tuple[str, str, int]:
    """``(scheme, host, port)`` of a scheduler address (``tcp://`` by default), or a :class:`ClusterError`."""
    fix = f"fix --scheduler / {SCHEDULER_ENV}"
    m = _ADDRESS.fullmatch(str(address).strip())
    if m is None:
        raise ClusterError(
            f"scheduler address {str(address)[:80]!r}: not an address (expected tcp://HOST:PORT, tls://HOST:PORT "
            f"or HOST:PORT); {fix}"
        )
    scheme, port = (m["scheme"] or "tcp").lower(), int(m["port"])
    if scheme not in ("tcp", "tls"):
        raise ClusterError(
            f"scheduler address {address[:80]!r}: {scheme}:// is not supported (tcp:// or tls://); {fix}"
        )
    if not 1 <= port <= 65535:
        raise ClusterError(f"scheduler address {address[:80]!r}: port {port} is not in 1..65535; {fix}")
    return scheme, m["host"].strip("[]"), port


def _tls_context(address: str):
    """The client's TLS context from the dask configuration (``distributed.comm.tls``), or a ClusterError."""
    from distributed.security import Security

    try:
        ctx = Security().get_connection_args("client")["ssl_context"]
    except Exception as exc:  # missing or unreadable certificate files, bad configuration
        raise ClusterError(
            f"{address}: the dask TLS configuration cannot be used ({type(exc).__name__}: {str(exc)[:120]})"
        ) from None
    if ctx is None:
        raise ClusterError(
            f"{address}: tls:// needs the client's certificates in the dask configuration "
            "(distributed.comm.tls.ca-file, .client.cert, .client.key); none is set (docs/cluster.md)"
        )
    return ctx


class _NotDask(Exception):
    pass


def probe_scheduler(address: str, timeout: float = CONNECT_TIMEOUT_S) -> None:
    """Check that a dask scheduler answers at ``address`` before a ``distributed.Client`` is made.

    Connects (with TLS for ``tls://``) and reads the handshake a dask server sends first on every new
    connection (an 8-byte length, a frame count, a msgpack dict with ``pickle-protocol``), all within
    ``timeout`` seconds and at most 64 KiB (``inproc://``, ``ucx://``, ``ws://`` and ``wss://`` addresses are
    left to the Client's own time-out). Raises a one-line :class:`ClusterError` when nothing listens,
    nothing answers in time (a silent listener, an HTTP server waiting for a request) or the first bytes are
    not a dask handshake (random bytes, another protocol); distributed itself would hang or try to allocate
    what a garbage length announces.
    """
    import ssl

    if "://" in address and address.partition("://")[0].lower() in _UNPROBED:
        return  # dask's other transports: the Client's own time-out applies
    scheme, host, port = split_address(address)
    ctx = _tls_context(address) if scheme == "tls" else None
    fix = f"fix --scheduler / {SCHEDULER_ENV}"
    deadline = time.monotonic() + timeout
    stage = "connect"
    sock = None

    def recv_exact(n: int) -> bytes:
        buf = bytearray()
        while len(buf) < n:
            sock.settimeout(max(1e-3, deadline - time.monotonic()))
            chunk = sock.recv(n - len(buf))
            if not chunk:
                raise _NotDask("closed the connection")
            buf += chunk
        return bytes(buf)

    try:
        sock = socket.create_connection((host, port), timeout=timeout)
        stage = "handshake"
        if ctx is not None:
            sock.settimeout(max(1e-3, deadline - time.monotonic()))
            sock = ctx.wrap_socket(sock, server_hostname=host if ctx.check_hostname else None)
        (total,) = struct.unpack("<Q", recv_exact(8))
        if not 16 <= total <= _MAX_HANDSHAKE:
            raise _NotDask("sent bytes that are not a dask handshake")
        body = recv_exact(total)
        (frames,) = struct.unpack_from("<Q", body)
        if not 1 <= frames <= 16 or 8 + 8 * frames > total or b"pickle-protocol" not in body:
            raise _NotDask("sent bytes that are not a dask handshake")
    except socket.gaierror as exc:
        raise ClusterError(
            f"cannot reach the dask scheduler at {address}: unknown host {host!r} ({exc.strerror}); {fix}"
        ) from None
    except TimeoutError:
        if stage == "connect":
            raise ClusterError(
                f"cannot reach the dask scheduler at {address} within {timeout:g} s (no answer); start one "
                f"(`dask scheduler`), {fix} or raise {TIMEOUT_ENV}"
            ) from None
        raise ClusterError(
            f"{address} accepted the connection but sent no dask handshake within {timeout:g} s: not a dask "
            f"scheduler (an HTTP server? another service?) or a very busy one; {fix} or raise {TIMEOUT_ENV}"
        ) from None
    except ssl.SSLError as exc:
        raise ClusterError(
            f"{address}: the TLS handshake failed ({exc.reason or type(exc).__name__}): not a dask scheduler with "
            f"TLS, or certificates it does not accept; {fix}"
        ) from None
    except _NotDask as exc:
        raise ClusterError(f"{address} {exc}: not a dask scheduler; {fix}") from None
    except OSError as exc:
        what = exc.strerror or type(exc).__name__
        if stage == "connect":
            raise ClusterError(
                f"cannot reach the dask scheduler at {address} ({what}); start one (`dask scheduler`) or {fix}"
            ) from None
        raise ClusterError(f"{address} broke the connection ({what}) without a dask handshake; {fix}") from None
    finally:
        if sock is not None:
            sock.close()


def _discard(client) -> None:
    """Make a Client whose constructor failed inert, so that its ``__del__`` prints no traceback at exit."""
    client.status = "closed"
    try:
        client._loop_runner.stop()
    except Exception:
        pass


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
    connect_timeout : float or None
        Seconds a scheduler address has to answer with a dask handshake [s] (default
        ``WALLCAL_SCHEDULER_TIMEOUT``, else :data:`CONNECT_TIMEOUT_S`).
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
        connect_timeout: float | None = None,
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
        self.connect_timeout = connect_timeout_from(connect_timeout)
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
            t = self.connect_timeout
            probe_scheduler(self.address, t)
            client = distributed.Client.__new__(distributed.Client)
            try:
                client.__init__(self.address, timeout=t, set_as_default=False, asynchronous=False)
            except Exception as exc:
                _discard(client)
                raise ClusterError(
                    f"cannot connect to the dask scheduler at {self.address} within {t:g} s "
                    f"({type(exc).__name__}: {str(exc)[:100]}); fix --scheduler / {SCHEDULER_ENV}"
                ) from None
            self._client = client
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
    "TIMEOUT_ENV",
    "ClusterError",
    "Executor",
    "Progress",
    "TaskFailed",
    "call_task",
    "current_executor",
    "executor_from",
    "connect_timeout_from",
    "in_dask_worker",
    "probe_scheduler",
    "safe_key",
    "split_address",
    "task_key",
]

"""``--scheduler`` and ``--resume`` for the commands that run EnergyPlus (or whole studies) on the executor."""

from __future__ import annotations

import contextlib
import shutil
from pathlib import Path

SCHEDULER_HELP = (
    "dask scheduler address of an existing cluster (tcp://host:8786); default: WALLCAL_SCHEDULER, else a local "
    "cluster of the machine's cores ('local' forces it); docs/cluster.md"
)


def add_scheduler(p) -> None:
    p.add_argument("--scheduler", metavar="ADDRESS", help=SCHEDULER_HELP)
    p.add_argument(
        "--scheduler-timeout",
        metavar="SECONDS",
        help="seconds the --scheduler address has to answer with a dask handshake (default: "
        "WALLCAL_SCHEDULER_TIMEOUT, else 10)",
    )


def add_cluster_options(p) -> None:
    """``--scheduler`` and ``--resume`` (finished runs stored next to ``--out`` are reused)."""
    add_scheduler(p)
    p.add_argument(
        "--resume",
        action="store_true",
        help="reuse the runs an interrupted run of this command finished (stored in .OUT.runs next to --out)",
    )


def runs_cache(out) -> Path:
    """Where the finished runs of a command writing ``out`` are stored until it completes: ``.OUT.runs`` beside it."""
    out = Path(out).resolve()
    return out.parent / f".{out.name}.runs"


@contextlib.contextmanager
def executor_for(args, out, *, label: str = "EnergyPlus runs", progress: bool = True):
    """The command's executor (``args.scheduler``, ``args.resume``) with its runs stored beside ``out``; the store
    is removed when the command completes."""
    from ..cluster import executor_from
    from ..errors import StudyError

    resume = bool(getattr(args, "resume", False))
    if resume and not out:
        raise StudyError(["--resume needs --out: the finished runs are stored next to it"])
    cache = runs_cache(out) if out else None
    with executor_from(
        getattr(args, "scheduler", None),
        cache_dir=cache,
        resume=resume,
        progress=progress,
        label=label,
        connect_timeout=getattr(args, "scheduler_timeout", None),
    ) as ex:
        yield ex
    if cache is not None:
        shutil.rmtree(cache, ignore_errors=True)

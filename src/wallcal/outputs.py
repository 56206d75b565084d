"""Output directories that are never half-written.

Every command writes into a fresh temporary directory next to the target and
moves it into place only when complete (:func:`output_dir`). A lock file keeps
two runs from writing the same target at once; an interrupted run leaves the
previous result (or nothing) and no temporary directory. Each result carries a
``manifest.json`` with the wallcal version, the study file's hash and the
input data's hash.
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import tempfile
import time
from pathlib import Path

from .errors import WallcalError


class OutputBusyError(WallcalError):
    """Another wallcal run is writing the same output directory."""


def _version() -> str:
    from . import __version__

    return __version__


@contextlib.contextmanager
def output_dir(target: str | Path, manifest: dict | None = None):
    """Context manager yielding a temporary directory that replaces ``target`` on success.

    Parameters
    ----------
    target : path
        The final output directory.
    manifest : dict, optional
        Extra entries for ``manifest.json`` (study and data hashes, command...).
    """
    target = Path(target).resolve()
    target.parent.mkdir(parents=True, exist_ok=True)
    lock = target.parent / f".{target.name}.lock"
    try:
        fd = os.open(lock, os.O_CREAT | os.O_EXCL | os.O_WRONLY)
    except FileExistsError:
        pid = lock.read_text().strip() if lock.exists() else "?"
        if pid.isdigit() and not _alive(int(pid)):
            lock.unlink(missing_ok=True)  # stale lock from a killed run
            fd = os.open(lock, os.O_CREAT | os.O_EXCL | os.O_WRONLY)
        else:
            raise OutputBusyError(
                f"{target}: another wallcal run (pid {pid}) is writing this directory; wait for it or "
                f"choose another --out"
            ) from None
    os.write(fd, str(os.getpid()).encode())
    os.close(fd)
    tmp = Path(tempfile.mkdtemp(prefix=f".{target.name}.tmp-", dir=target.parent))
    try:
        yield tmp
        info = {"wallcal_version": _version(), "written": time.strftime("%Y-%m-%dT%H:%M:%S%z")}
        info.update(manifest or {})
        (tmp / "manifest.json").write_text(json.dumps(info, indent=2, default=str))
        old = None
        if target.exists():
            old = target.parent / f".{target.name}.old-{os.getpid()}"
            os.replace(target, old)
        os.replace(tmp, target)
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    finally:
        lock.unlink(missing_ok=True)


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def write_text_atomic(path: str | Path, text: str) -> Path:
    """Write a single output file so that it is either complete or absent (temporary file + rename)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent)
    try:
        with os.fdopen(fd, "w") as fh:
            fh.write(text)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path

"""Output directories that are never half-written.

Every command writes into a fresh temporary directory next to the target and
moves it into place only when complete (:func:`output_dir`). A lock file keeps
two runs from writing the same target at once; an interrupted run leaves the
previous result (or nothing) and no temporary directory, and what a killed run
leaves (``.NAME.tmp-*``) is removed by the next one (:func:`clean_stale`). Each result carries a
``manifest.json`` with the wallcal version, the study file's hash and the
input data's hash.

The output folders other commands read (``--from``) are a contract: each is written and read by one
module (:data:`FORMATS`), and its ``manifest.json`` carries the folder's ``format_version``, which the
reader checks (:func:`check_format`).
"""

from __future__ import annotations

import contextlib
import glob
import json
import os
import shutil
import tempfile
import threading
import time
from dataclasses import dataclass
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
    with _locked(target):
        _clean(target)  # we hold the lock: any temporary directory of this target is a killed run's
        tmp = Path(tempfile.mkdtemp(prefix=f".{target.name}.tmp-", dir=target.parent))
        try:
            yield tmp
            info = {"wallcal_version": _version(), "written": time.strftime("%Y-%m-%dT%H:%M:%S%z")}
            info.update(manifest or {})
            info.update(format_entries(info.get("command")))
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


def clean_stale(target: str | Path) -> list[str]:
    """Remove what killed runs left next to ``target``: temporary directories (``.NAME.tmp-*``) and old copies
    (``.NAME.old-*``; the old copy is put back when a run was killed between its two renames and ``target`` is
    missing). Does nothing while a live run holds the target's lock. Returns the names removed or restored."""
    target = Path(target).resolve()
    if not target.parent.is_dir():
        return []
    try:
        with _locked(target):
            return _clean(target)
    except OutputBusyError:
        return []


def _clean(target: Path) -> list[str]:
    """(under the lock) :func:`clean_stale`'s work."""
    done = []
    name = glob.escape(target.name)
    for p in sorted(target.parent.glob(f".{name}.tmp-*")):
        if p.is_dir() and not p.is_symlink():
            shutil.rmtree(p, ignore_errors=True)
            done.append(p.name)
    olds = [p for p in target.parent.glob(f".{name}.old-*") if p.is_dir() and not p.is_symlink()]
    for p in sorted(olds, key=lambda p: p.stat().st_mtime, reverse=True):
        if not target.exists() and (p / "manifest.json").is_file():
            os.replace(p, target)  # killed between moving the previous result away and the new one in
        else:
            shutil.rmtree(p, ignore_errors=True)
        done.append(p.name)
    for p in target.parent.glob(f".{name}.lock.*"):  # a lock being made by a run that was killed
        pid = p.name[len(f".{target.name}.lock.") :].split(".")[0]
        if pid.isdigit() and not _alive(int(pid)):
            p.unlink(missing_ok=True)
    return done


@contextlib.contextmanager
def _locked(target: Path):
    """Hold the lock file ``.NAME.lock`` (holding the holder's pid) while writing ``target``; a lock whose
    holder is dead is taken over."""
    lock = target.parent / f".{target.name}.lock"
    if not _take(lock):
        text = lock.read_text(errors="replace").strip() if lock.is_file() else "?"
        if not (text.isdigit() and _alive(int(text))):
            lock.unlink(missing_ok=True)  # stale lock from a killed run
            if not _take(lock):
                text = lock.read_text(errors="replace").strip() if lock.is_file() else "?"
                raise OutputBusyError(f"{target}: another wallcal run (pid {text}) is writing this directory")
        else:
            raise OutputBusyError(
                f"{target}: another wallcal run (pid {text}) is writing this directory; wait for it or "
                f"choose another --out"
            )
    try:
        yield
    finally:
        lock.unlink(missing_ok=True)


def _take(lock: Path) -> bool:
    """Create ``lock`` holding our pid, atomically (a file written aside, then hard-linked: it never exists
    empty); False when it exists."""
    pid = str(os.getpid())
    aside = lock.with_name(f"{lock.name}.{pid}.{threading.get_ident()}")
    try:
        aside.write_text(pid)
        try:
            os.link(aside, lock)
            return True
        except FileExistsError:
            return False
        except OSError:  # no hard links on this file system: exclusive creation
            try:
                fd = os.open(lock, os.O_CREAT | os.O_EXCL | os.O_WRONLY)
            except FileExistsError:
                return False
            os.write(fd, pid.encode())
            os.close(fd)
            return True
    finally:
        aside.unlink(missing_ok=True)


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


def write_text_new(directory: str | Path, stem: str, text: str, suffix: str = ".toml", max_files: int = 1000) -> Path:
    """Write ``text`` to a file that did not exist: ``stem + suffix``, else ``stem-2 + suffix``, ``-3``, ...

    Never replaces or truncates an existing file, even one created by another process a moment
    earlier: the text goes to a temporary file first, which is then hard-linked to the first free
    name (``link`` fails when the name exists, atomically), so the file appears complete or not at
    all. On a file system without hard links the name is created exclusively (``O_CREAT | O_EXCL``,
    never following a symbolic link) and written. Returns the path written.
    """
    directory = Path(directory)
    names = [f"{stem}{suffix}"] + [f"{stem}-{k}{suffix}" for k in range(2, max_files + 1)]
    fd, tmp = tempfile.mkstemp(prefix=f".{stem}.", suffix=".tmp", dir=directory)
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            fh.write(text)
        can_link = True
        for name in names:
            path = directory / name
            if can_link:
                try:
                    os.link(tmp, path)
                    return path
                except FileExistsError:
                    continue
                except OSError:  # no hard links here (FAT, some network shares): exclusive creation instead
                    can_link = False
            try:
                out = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_NOFOLLOW", 0), 0o644)
            except FileExistsError:
                continue
            try:
                with os.fdopen(out, "w", encoding="utf-8") as fh:
                    fh.write(text)
            except BaseException:
                path.unlink(missing_ok=True)  # the file this call created, half-written
                raise
            return path
    finally:
        Path(tmp).unlink(missing_ok=True)
    raise WallcalError(f"{directory}: {names[0]} .. {names[-1]} all exist; move some away or choose another name")


# ============================================================================ output formats (the contract)
class OutputFormatError(WallcalError):
    """An output folder this wallcal does not read: written by another format version, or without one."""


@dataclass(frozen=True)
class OutputFormat:
    """An output folder another command reads: the command that writes it, its format version, the file that
    tells it apart, and the module that writes and reads it (a typed reader beside the writer)."""

    command: str
    version: int
    marker: str
    module: str


#: The manifest entry holding an output folder's format version.
FORMAT_KEY = "format_version"
#: Every output folder another command reads, by the command that writes it. Raise a version when the
#: folder's files change in a way an older reader would misread.
FORMATS: dict[str, OutputFormat] = {
    f.command: f
    for f in (
        OutputFormat("calibrate", 1, "calibrated_wall.toml", "wallcal.calibration.output"),
        OutputFormat("crosscheck", 1, "crosscheck.csv", "wallcal.crosscheck"),
        OutputFormat("posterior", 1, "chain.npz", "wallcal.analysis.posterior"),
        OutputFormat("retrofit", 1, "retrofit.json", "wallcal.retrofitting.run"),
    )
}


def format_entries(command: str | None) -> dict:
    """The manifest entries of ``command``'s output format (``{}`` for an output no command reads)."""
    fmt = FORMATS.get(command or "")
    return {FORMAT_KEY: fmt.version} if fmt is not None else {}


def check_format(directory: str | Path, command: str) -> dict:
    """Check that ``directory`` is a ``command`` output of the format version this wallcal reads.

    Returns
    -------
    dict
        The folder's ``manifest.json``.

    Raises
    ------
    OutputFormatError
        No readable manifest.json, no format version in it (an output of a wallcal before format
        versions), another command's output, or another version; the message names the folder, the
        version found and the one expected.
    """
    d = Path(directory)
    expected = FORMATS[command].version
    again = f"run 'wallcal {command}' again to write it in format {expected}"
    path = d / "manifest.json"
    try:
        manifest = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise OutputFormatError(
            f"{d}: no manifest.json, so no output format version (expected a {command} output of format "
            f"{expected}); {again}"
        ) from None
    except (OSError, UnicodeDecodeError, ValueError) as exc:
        raise OutputFormatError(f"{path}: not readable ({exc}); {again}") from exc
    if not isinstance(manifest, dict):
        raise OutputFormatError(f"{path}: not a JSON object; {again}")
    found_command = manifest.get("command")
    if found_command is not None and found_command != command:
        raise OutputFormatError(f"{d}: a {found_command} output, not a {command} output")
    found = manifest.get(FORMAT_KEY)
    if found is None:
        raise OutputFormatError(
            f"{d}: a {command} output without a format version (written by an older wallcal), expected "
            f"format {expected}; {again}"
        )
    if found != expected:
        raise OutputFormatError(
            f"{d}: a {command} output of format version {found}, this wallcal reads version {expected}; {again}"
        )
    return manifest


def write_manifest(directory: str | Path, manifest: dict) -> Path:
    """Write ``manifest.json`` (wallcal version, time, ``manifest``, its format version) into a folder written
    inside another command's output (a stage of ``wallcal run`` that another command may read); returns it."""
    info = {"wallcal_version": _version(), "written": time.strftime("%Y-%m-%dT%H:%M:%S%z")}
    info.update(manifest)
    info.update(format_entries(info.get("command")))
    return write_text_atomic(Path(directory) / "manifest.json", json.dumps(info, indent=2, default=str))

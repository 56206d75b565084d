"""Calibration checkpoints: where they live, what they hold, and the checks before a run resumes from one.

A checkpoint (``.<out>.checkpoint.json`` next to the output directory) is written atomically by
:meth:`wallcal.calibration.algorithms.Recorder.save`. :func:`load_checkpoint` trusts nothing in it: the
file must be a regular file (not a directory, a symbolic link or a pipe) of reasonable size, valid JSON,
of this format, made for the same study, data, algorithm, seed, settings and parameters, and every
entry must have its kind, shape and range (finite numbers, unit coordinates in [0, 1], a history whose
last row is the stored best ...). The caller then re-evaluates the stored best point
(:func:`check_values`): it must reproduce its stored objective. Every problem is one
:class:`CheckpointError` line that says how to start afresh.

The helpers for where a checkpoint lives and how it is written, read and removed (:func:`checkpoint_path`,
:func:`present`, :func:`write_bytes`, :func:`read_bytes`, :func:`remove`) also serve ``wallcal retrofit``'s
checkpoint of its posterior draws (:mod:`wallcal.retrofitting.run`).
"""

from __future__ import annotations

import json
import math
import os
import stat
from pathlib import Path

import numpy as np

from ..errors import WallcalError

#: the checkpoint format written by this version (older or newer checkpoints are refused)
FORMAT = 2
#: a checkpoint larger than this is refused unread [bytes] (a real one is well below 1 MB)
MAX_BYTES = 64 * 1024 * 1024
#: the stored best point's objective must be reproduced to this relative tolerance
REL_TOL = 1e-9
#: the phases a checkpoint may name (the progress label) and the states of pso-hj
PHASES = ("", "particle swarm", "Hooke-Jeeves", "least-squares polish")
PSO_HJ_STATES = ("pso", "hj", "polish", "done")
#: algorithms resumed by replaying their log of batch values from the seed (deterministic)
REPLAYED = ("differential-evolution", "nelder-mead", "cma-es")
AFRESH = "to start afresh, rerun without --resume"
#: the longest message: the CLI's line ("wallcal: error: " + message) stays within 300 characters
MAX_MESSAGE = 300 - len("wallcal: error: ")


class CheckpointError(WallcalError):
    """A checkpoint cannot be trusted: one line naming the file, the problem and how to start afresh."""

    def __init__(self, path, problem: str, fix: str = AFRESH):
        where = str(path)
        msg = f"{where}: not a usable checkpoint: {problem}; {fix}"
        if len(msg) > MAX_MESSAGE:  # keep the line short: the file's name instead of its whole path
            msg = f"{Path(where).name}: not a usable checkpoint: {problem}; {fix}"
        super().__init__(msg[:MAX_MESSAGE])


def checkpoint_path(out_dir, suffix: str = "checkpoint.json") -> Path | None:
    """The checkpoint of output directory ``out_dir``: ``.<name>.<suffix>`` beside it (None without one).

    ``suffix``: ``checkpoint.json`` for ``wallcal calibrate``; other commands name their own
    (``retrofit-checkpoint.npz``)."""
    if out_dir is None:
        return None
    out_dir = Path(out_dir).resolve()
    return out_dir.parent / f".{out_dir.name}.{suffix}"


def present(path: Path | None) -> bool:
    """Whether anything (a file, a directory, a dangling link ...) stands at the checkpoint's path."""
    return path is not None and (path.exists() or path.is_symlink())


def write_bytes(path: Path, data: bytes) -> None:
    """Write a checkpoint atomically: a new file of our own beside it (never one planted at a fixed name), renamed
    over it; :func:`remove` also clears such a temporary file left by a killed run."""
    import tempfile

    fd, tmp = tempfile.mkstemp(prefix=f"{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def remove(path: Path | None) -> None:
    """Delete a checkpoint and its temporary file (after the outputs are in place)."""
    if path is None:
        return
    import glob

    for p in [path, *path.parent.glob(f"{glob.escape(path.name)}.*.tmp")]:
        if p.is_file() or p.is_symlink():
            p.unlink(missing_ok=True)


def _short(v) -> str:
    s = repr(v)
    return s if len(s) <= 40 else s[:37] + "..."


def read_bytes(path: Path) -> bytes:
    """A checkpoint's bytes, read only when it is a regular file (not a symbolic link, a directory or a pipe), not
    empty and at most :data:`MAX_BYTES`; else :class:`CheckpointError`."""
    try:
        st = os.lstat(path)
    except OSError as exc:
        raise CheckpointError(path, f"cannot be read ({exc.strerror})") from None
    if stat.S_ISLNK(st.st_mode):
        raise CheckpointError(
            path, "is a symbolic link (wallcal writes a plain file)", "remove it and rerun without --resume"
        )
    if stat.S_ISDIR(st.st_mode):
        raise CheckpointError(path, "is a directory", "remove it and rerun without --resume to start afresh")
    if not stat.S_ISREG(st.st_mode):
        raise CheckpointError(path, "is not a regular file", "remove it and rerun without --resume to start afresh")
    if st.st_size == 0:
        raise CheckpointError(path, "the file is empty (cut short?)")
    if st.st_size > MAX_BYTES:
        raise CheckpointError(path, f"the file is {st.st_size / 2**20:.0f} MB, far larger than a checkpoint")
    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_NONBLOCK", 0))
        with os.fdopen(fd, "rb") as fh:
            raw = fh.read(MAX_BYTES + 1)
    except OSError as exc:
        raise CheckpointError(path, f"cannot be read ({exc.strerror})") from None
    return raw


def _read(path: Path) -> dict:
    raw = read_bytes(path)
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError:
        raise CheckpointError(path, "not UTF-8 text (damaged)") from None
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise CheckpointError(
            path, f"not valid JSON (cut short or damaged): {exc.msg} at character {exc.pos}"
        ) from None
    except RecursionError:
        raise CheckpointError(path, "not a checkpoint (nested too deeply)") from None
    except ValueError as exc:  # e.g. an integer of more digits than Python converts
        raise CheckpointError(path, f"not a checkpoint ({_short(str(exc))})") from None
    if not isinstance(data, dict):
        kind = {list: "list", str: "string", bool: "true/false", type(None): "null"}.get(type(data), "number")
        raise CheckpointError(path, f"holds a JSON {kind}, not a table of checkpoint entries")
    return data


def _real(v) -> bool:
    """A JSON number that converts to a float (not a boolean, not an integer beyond the float range)."""
    if isinstance(v, bool):
        return False
    return isinstance(v, float) or (isinstance(v, int) and abs(v) < 2**1000)


def _whole(v) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def _numbers(v, depth: int) -> bool:
    """Whether ``v`` is a list nested ``depth`` deep whose leaves are all numbers (not booleans or strings)."""
    if depth == 0:
        return _real(v)
    return isinstance(v, list) and all(_numbers(x, depth - 1) for x in v)


def _array(path, data: dict, key: str, shape: tuple, *, unit=False, allow_inf=False, at: str = "") -> np.ndarray:
    """``data[key]`` as a float array of ``shape`` (-1: any length), finite (or +inf), in [0, 1] if ``unit``."""
    name = f"{at}{key}"
    v = data.get(key)
    if not _numbers(v, len(shape)):
        raise CheckpointError(path, f"{name} must be a list of numbers, got {_short(v)}")
    try:
        a = np.array(v, dtype=float)
    except ValueError:  # ragged
        raise CheckpointError(path, f"{name} must be a table of equal-length rows") from None
    if a.ndim != len(shape) or any(s not in (-1, d) for s, d in zip(shape, a.shape, strict=True)):
        want = " x ".join("any" if s == -1 else str(s) for s in shape)
        raise CheckpointError(path, f"{name} has shape {' x '.join(map(str, a.shape))}, expected {want}")
    bad = np.isnan(a) | (np.isinf(a) if not allow_inf else np.isneginf(a))
    if bad.any():
        raise CheckpointError(path, f"{name} holds a value that is not a finite number")
    if unit and ((a < 0.0) | (a > 1.0)).any():
        raise CheckpointError(path, f"{name} leaves the unit box [0, 1]")
    return a


def _number(path, data: dict, key: str, *, whole=False, lo=None, hi=None, at: str = "") -> float:
    v = data.get(key)
    ok = _whole(v) if whole else _real(v)
    if not ok or not math.isfinite(v):
        kind = "a whole number" if whole else "a finite number"
        raise CheckpointError(path, f"{at}{key} must be {kind}, got {_short(v)}")
    if (lo is not None and v < lo) or (hi is not None and v > hi):
        raise CheckpointError(path, f"{at}{key} = {_short(v)} is out of range")
    return v


def _normal(v):
    """``v`` as JSON would give it back (tuples become lists)."""
    return json.loads(json.dumps(v, default=float))


def load_checkpoint(path: Path, meta: dict, n: int, settings: dict) -> dict:
    """Read and check a checkpoint for resuming the run described by ``meta`` (``n`` parameters).

    Returns the checkpoint's entries; raises :class:`CheckpointError` (one line) on anything wrong.
    The values still have to be confirmed by re-evaluating the stored best point (:func:`check_values`).
    """
    data = _read(path)
    fmt = data.get("format")
    if fmt != FORMAT:
        raise CheckpointError(path, f"format {_short(fmt)}, this wallcal reads format {FORMAT}")
    for key in ("algorithm", "seed", "parameters", "study_sha256", "data_sha256", "settings"):
        if _normal(data.get(key)) != _normal(meta[key]):
            what = "data" if key == "data_sha256" else "study file" if key == "study_sha256" else key
            raise CheckpointError(path, f"it was made with another {what} ({_short(data.get(key))})")
    best_u = _array(path, data, "best_u", (n,), unit=True)
    best_f = _number(path, data, "best_f")
    evaluations = _number(path, data, "evaluations", whole=True, lo=1)
    _number(path, data, "seconds", lo=0.0)
    hist = data.get("history")
    if not isinstance(hist, list) or not hist:
        raise CheckpointError(path, f"history must be a non-empty list, got {_short(hist)}")
    rows = []
    for i, row in enumerate(hist):
        if not (isinstance(row, list) and len(row) == 3 and _whole(row[0]) and all(_real(x) for x in row[1:])):
            raise CheckpointError(
                path, f"history[{i}] must be [evaluations, seconds, best objective], got {_short(row)}"
            )
        if not (math.isfinite(row[1]) and math.isfinite(row[2])) or row[1] < 0 or row[0] < 1:
            raise CheckpointError(path, f"history[{i}] = {_short(row)} is out of range")
        rows.append(row)
    ev = [r[0] for r in rows]
    fb = [r[2] for r in rows]
    if any(b < a for a, b in zip(ev, ev[1:], strict=False)) or any(b > a for a, b in zip(fb, fb[1:], strict=False)):
        raise CheckpointError(path, "its history goes backwards (evaluations falling or the best objective rising)")
    if ev[-1] != evaluations or fb[-1] != best_f:
        raise CheckpointError(path, "its history does not end at its evaluations and best objective (cut short?)")
    phase = data.get("phase")
    if phase not in PHASES:
        raise CheckpointError(path, f"unknown phase {_short(phase)}")
    algorithm = meta["algorithm"]
    state = data.get("state")
    if algorithm == "pso-hj":
        _check_pso_hj_state(path, state, n, settings, best_f)
    elif state is not None and state != {"phase": "done"}:
        raise CheckpointError(path, f"state must be null or {{'phase': 'done'}} for {algorithm}, got {_short(state)}")
    if algorithm in REPLAYED:
        log = data.get("log")
        if not isinstance(log, list) or not log:
            raise CheckpointError(path, f"log must be a non-empty list of batches, got {_short(log)}")
        for i in range(len(log)):
            _array(path, {"": log[i]}, "", (-1,), allow_inf=True, at=f"log[{i}]")
        if sum(len(b) for b in log) != evaluations:
            raise CheckpointError(path, "its log does not hold its evaluations (cut short?)")
    data["best_u"] = best_u
    return data


def _check_pso_hj_state(path, st, n, settings, best_f) -> None:
    if not isinstance(st, dict):
        raise CheckpointError(path, f"state must be a table for pso-hj, got {_short(st)}")
    ph = st.get("phase")
    if ph not in PSO_HJ_STATES:
        raise CheckpointError(path, f"unknown state.phase {_short(ph)} (expected one of {', '.join(PSO_HJ_STATES)})")
    if ph == "pso":
        npart = int(settings["particles"])
        for key in ("x", "pbest"):
            _array(path, st, key, (npart, n), unit=True, at="state.")
        _array(path, st, "v", (npart, n), at="state.")
        pbest_f = _array(path, st, "pbest_f", (npart,), allow_inf=True, at="state.")
        _number(path, st, "generation", whole=True, lo=1, hi=max(1, int(settings["generations"])), at="state.")
        if best_f > pbest_f.min():
            raise CheckpointError(path, "best_f is above the swarm's best (state.pbest_f)")
    elif ph == "hj":
        _array(path, st, "base", (n,), unit=True, at="state.")
        _number(path, st, "step", lo=1e-300, hi=float(settings["hj_initial_step"]), at="state.")
        _number(path, st, "reductions", whole=True, lo=0, hi=int(settings["step_reductions"]) + 1, at="state.")
    if "cache_keys" in st or "cache_values" in st:
        keys = st.get("cache_keys")
        if not (
            isinstance(keys, list) and all(isinstance(k, list) and len(k) == n and all(map(_whole, k)) for k in keys)
        ):
            raise CheckpointError(path, f"state.cache_keys must be a list of {n} whole numbers each")
        vals = _array(path, st, "cache_values", (len(keys),), allow_inf=True, at="state.")
        if len(vals) and best_f > vals.min():
            raise CheckpointError(path, "best_f is above the best value of its cache (state.cache_values)")


def check_values(path: Path, data: dict, objective, name: str = "objective") -> None:
    """Re-evaluate the checkpoint's best point (and for the swarm its particles' bests, in the same batch):
    each must reproduce its stored value to :data:`REL_TOL` (relative), else :class:`CheckpointError`."""
    pts = [np.asarray(data["best_u"], dtype=float)]
    want = [float(data["best_f"])]
    st = data.get("state")
    if isinstance(st, dict) and st.get("phase") == "pso":
        pf = np.asarray(st["pbest_f"], dtype=float)
        keep = np.isfinite(pf)
        pts += list(np.asarray(st["pbest"], dtype=float)[keep])
        want += list(pf[keep])
    got = np.asarray(objective(np.array(pts)), dtype=float)
    want = np.array(want)
    bad = ~(np.abs(got - want) <= REL_TOL * np.maximum(np.abs(want), 1e-300))
    if bad.any():
        i = int(np.argmax(bad))
        which = "its best point" if i == 0 else f"particle best {i - 1}"
        raise CheckpointError(
            path,
            f"{which} gives {name} {got[i]:.9g}, not the stored {want[i]:.9g} (altered, or other inputs)",
        )

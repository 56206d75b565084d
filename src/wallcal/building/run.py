"""One EnergyPlus run of a building: a top-level function of one picklable task (for the executor).

:func:`run_building` writes the task's epJSON model into its own scratch directory, runs EnergyPlus on the
task's weather file (through :mod:`wallcal.eplus`) and returns the figures: heating and cooling delivered
by the ideal loads over the run period [kWh] (the timestep rates summed over the conditioned zones, times the
timestep), their peaks [W]
(largest timestep value of that sum), the conditioned floor area [m2] (EnergyPlus' ``Zone Information``
floor areas times the zone multipliers) and, when asked, the hourly zone mean air temperatures [degC].

A run's scratch directory is removed when it ends; one left by a killed worker is removed by the next run on
that host (:func:`clean_stale_scratch`).
"""

from __future__ import annotations

import json
import os
import re
import shutil
import socket
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

from ..errors import EngineError

SCRATCH_PREFIX = "wallcal_building_"
_SCRATCH = re.compile(SCRATCH_PREFIX + r"(?P<pid>[0-9]+)@(?P<host>[A-Za-z0-9.-]+)_")
_STARTED = time.time()  # this process made no scratch directory before


def _host() -> str:
    return re.sub(r"[^A-Za-z0-9.-]+", "-", socket.gethostname())[:64] or "host"


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's process
        return True
    return True


def clean_stale_scratch(parent: str | os.PathLike | None = None) -> list[Path]:
    """Remove the scratch directories of runs whose process died (a killed worker cannot clean up).

    A scratch directory is named ``wallcal_building_<pid>@<host>_<random>``; one of this host whose process no
    longer exists (or has this process's id but is older than this process: the id was reused) is removed.
    Directories of other hosts (a scratch folder shared by several machines) and of live processes are left
    alone. Returns the directories removed.
    """
    parent = Path(parent) if parent is not None else Path(tempfile.gettempdir())
    host, me, removed = _host(), os.getpid(), []
    try:
        entries = list(os.scandir(parent))
    except OSError:
        return removed
    for entry in entries:
        m = _SCRATCH.match(entry.name)
        if m is None or m["host"] != host:
            continue
        pid = int(m["pid"])
        try:
            if not entry.is_dir(follow_symlinks=False):
                continue
            stale = not _alive(pid) if pid != me else entry.stat(follow_symlinks=False).st_mtime < _STARTED - 1.0
        except OSError:
            continue
        if stale:
            shutil.rmtree(entry.path, ignore_errors=True)
            removed.append(Path(entry.path))
    return removed


def scratch_dir(parent: str | os.PathLike | None = None) -> Path:
    """A new scratch directory for one run (named after this process and host), after removing stale ones."""
    clean_stale_scratch(parent)
    return Path(tempfile.mkdtemp(prefix=f"{SCRATCH_PREFIX}{os.getpid()}@{_host()}_", dir=parent))


def run_building(task: dict) -> dict:
    """Run EnergyPlus on one building model.

    Parameters
    ----------
    task : dict
        ``model`` (epJSON dict), ``weather`` (EPW path), ``steps_per_hour`` (int), ``zones`` (the
        conditioned zones, names), ``temperature_zone`` (zone whose air temperature is returned, or None),
        ``timeout`` [s], ``label`` (for messages), ``scratch`` (parent folder of the scratch directory, or None).

    Returns
    -------
    dict
        ``heating_kWh``, ``cooling_kWh``, ``peak_heating_W``, ``peak_cooling_W``, ``floor_area_m2``,
        ``warnings`` (count of .err warnings), ``zone_temperature`` (``{"time": [...], "value": [...]}`` with
        ``MM-DD HH:MM`` labels of each hour's end, or None).

    Raises
    ------
    EngineError
        EnergyPlus failed (its severe lines are shown) or did not finish within the timeout.
    """
    from ..eplus import launch

    label = task.get("label", "building")
    tmp = scratch_dir(task.get("scratch"))
    try:
        (tmp / "in.epJSON").write_text(json.dumps(task["model"]), encoding="utf-8")
        err_text = launch(
            tmp / "in.epJSON", tmp, weather=Path(task["weather"]), timeout=float(task.get("timeout", 1800)), label=label
        )
        df = read_eplus_csv(tmp / "eplusout.csv")
        area = _floor_area(tmp / "eplusout.eio", task["zones"])
        out = {
            "floor_area_m2": area,
            "warnings": sum(1 for ln in err_text.splitlines() if "** Warning" in ln),
            "zone_temperature": None,
        }
        dt = 3600.0 / int(task["steps_per_hour"])
        for what in ("heating", "cooling"):
            cols = [c for c in df.columns if f"Ideal Loads Supply Air Total {what.title()} Rate" in c]
            rate = df[cols].apply(pd.to_numeric, errors="coerce").sum(axis=1).to_numpy() if cols else np.zeros(0)
            rate = rate[np.isfinite(rate)] if len(rate) else rate
            out[f"{what}_kWh"] = float(rate.sum() * dt / 3.6e6) if len(rate) else 0.0
            out[f"peak_{what}_W"] = float(rate.max()) if len(rate) else 0.0
        zone = task.get("temperature_zone")
        if zone:
            col = [c for c in df.columns if c.upper().startswith(f"{zone.upper()}:ZONE MEAN AIR TEMPERATURE")]
            if not col:
                raise EngineError(f"{label}: EnergyPlus reported no air temperature for zone {zone!r}")
            s = df[["Date/Time", col[0]]].dropna()
            out["zone_temperature"] = {
                "time": [str(t).strip() for t in s["Date/Time"]],
                "value": s[col[0]].astype(float).tolist(),
            }
        return out
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def read_eplus_csv(path: Path) -> pd.DataFrame:
    """EnergyPlus' CSV output as a frame with a ``Date/Time`` column and one column per variable.

    EnergyPlus writes its rows with an empty field after the time when a run reports no timestep-level
    variable (more fields than header names); that field is dropped.
    """
    with open(path, encoding="utf-8", errors="replace") as fh:
        header = [h.strip() for h in fh.readline().rstrip("\n").split(",")]
    raw = pd.read_csv(path, header=None, skiprows=1, dtype=str, keep_default_na=False)
    extra = raw.shape[1] - len(header)
    if extra > 0:
        raw = raw.drop(columns=raw.columns[1 : 1 + extra])
    raw.columns = header
    df = raw.copy()
    for c in header[1:]:
        df[c] = pd.to_numeric(raw[c].str.strip().replace("", np.nan), errors="coerce")
    return df


def _floor_area(eio: Path, zones: list[str]) -> float:
    """Sum of floor area x multiplier of ``zones`` from the ``Zone Information`` lines of the .eio file [m2]."""
    header = None
    area = 0.0
    want = {z.upper() for z in zones}
    for line in eio.read_text(errors="replace").splitlines():
        parts = [p.strip() for p in line.split(",")]
        if parts[0] == "! <Zone Information>":
            header = parts
        elif parts[0] == "Zone Information" and header is not None and parts[1].upper() in want:
            row = dict(zip(header, parts, strict=False))
            mult = float(row.get("Zone Multiplier", 1) or 1) * float(row.get("Zone List Multiplier", 1) or 1)
            area += float(row["Floor Area {m2}"]) * mult
    if area <= 0:
        raise EngineError(f"{eio}: no floor area reported for the conditioned zone(s) {', '.join(zones)}")
    return area


# ============================================================================ the measured zone air
def read_zone_measurements(path: str | Path, column: str) -> pd.Series:
    """The measured zone air temperature [degC]: ``column`` of a CSV whose first column is the time.

    Raises
    ------
    DataError
        An unreadable file, a missing column (with the closest names), times that do not parse or are not
        increasing, no numeric value, or a record that crosses a year boundary.
    """
    from ..errors import DataError, closest

    path = Path(path)
    try:
        df = pd.read_csv(path)
    except (OSError, ValueError, UnicodeDecodeError) as exc:
        raise DataError(f"--measured {path}: cannot read the CSV file ({exc})") from exc
    if df.shape[1] < 2:
        raise DataError(f"--measured {path}: needs a time column and at least one temperature column")
    if column not in df.columns:
        raise DataError(f"--zone-column {column!r}: not a column of {path}; {closest(column, list(df.columns[1:]))}")
    t = pd.to_datetime(df.iloc[:, 0], errors="coerce")
    if t.isna().any():
        i = int(np.flatnonzero(t.isna().to_numpy())[0])
        raise DataError(f"{path}: column {df.columns[0]!r}, row {i + 2}: {df.iloc[i, 0]!r} is not a date-time")
    if t.dt.tz is not None:
        t = t.dt.tz_localize(None)
    if not t.is_monotonic_increasing or t.duplicated().any():
        raise DataError(f"{path}: the times in column {df.columns[0]!r} must increase")
    v = pd.to_numeric(df[column], errors="coerce")
    s = pd.Series(v.to_numpy(dtype=float), index=pd.DatetimeIndex(t), name=column).dropna()
    if len(s) < 2:
        raise DataError(f"{path}: column {column!r} has fewer than two numeric values")
    if s.index[0].year != s.index[-1].year:
        raise DataError(f"{path}: the record crosses a year boundary; split it (EnergyPlus runs within one year)")
    return s


def _eplus_times(labels: list[str], year: int) -> pd.DatetimeIndex:
    """EnergyPlus ``MM/DD  HH:MM:SS`` labels (end of each hour; 24:00 is the next day's 00:00) as times."""
    out = []
    for lab in labels:
        date, clock = lab.split()
        month, day = (int(x) for x in date.split("/"))
        hour = int(clock.split(":")[0])
        out.append(pd.Timestamp(year=year, month=month, day=day) + pd.Timedelta(hours=hour))
    return pd.DatetimeIndex(out)


def compare_zone(sim: dict, measured: pd.Series) -> tuple[float, float, int, pd.Series]:
    """RMSE and MBE (simulated - measured) [K] of the hourly simulated zone air temperature against the
    measured one, linearly interpolated to the simulated hours inside the measured record; and the hours used."""
    times = _eplus_times(sim["time"], measured.index[0].year)
    s = pd.Series(sim["value"], index=times)
    inside = (s.index >= measured.index[0]) & (s.index <= measured.index[-1])
    s = s[inside]
    x = measured.index.asi8.astype(float)
    m = np.interp(s.index.asi8.astype(float), x, measured.to_numpy())
    e = s.to_numpy() - m
    if len(e) == 0:
        return float("nan"), float("nan"), 0, s
    return float(np.sqrt(np.mean(e**2))), float(np.mean(e)), len(e), s

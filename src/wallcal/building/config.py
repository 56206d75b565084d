"""The ``[building]`` table of a study file: validated once, into a frozen :class:`BuildingSpec`.

Every problem is reported with its key path (``building.start: must be a day "MM-DD", got '13-01'``) in the
same :class:`~wallcal.errors.StudyError` as the rest of the study file.
"""

from __future__ import annotations

import datetime as dt
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..schema import Problems, Table, describe
from .model import COOLING_SETPOINT, HEATING_SETPOINT

BUILDING_KEYS = (
    "model",
    "surfaces",
    "weather",
    "start",
    "end",
    "heating_setpoint",
    "cooling_setpoint",
    "timesteps_per_hour",
    "samples",
)
#: Timesteps per hour EnergyPlus accepts (divisors of 60); CondFD walls use at least 20.
ALLOWED_TIMESTEPS = (1, 2, 3, 4, 5, 6, 10, 12, 15, 20, 30, 60)


@dataclass(frozen=True)
class BuildingSpec:
    """The validated ``[building]`` table (defaults: the reference building over the whole weather year).

    Attributes
    ----------
    model : str or None
        A user's EnergyPlus 25.2 model (``.epJSON`` or ``.idf``) as written in the study; None for the
        bundled reference building. ``model_path`` is it resolved against the study's folder.
    surfaces : tuple of str
        Surfaces that get the wall; empty for every outdoor wall.
    weather : str or None
        EPW file (relative to the study) or the name of a shipped weather file; None to use
        ``[retrofit].weather``.
    start, end : (int, int)
        First and last day (month, day) of the run period, inclusive.
    heating_setpoint, cooling_setpoint : float
        Reference building set-points [degC].
    timesteps_per_hour : int
        EnergyPlus timesteps per hour (raised to 20 for a wall with a temperature-dependent conductivity).
    samples : int
        Posterior draws used with ``--from <posterior output>``.
    """

    model: str | None = None
    model_path: Path | None = None
    surfaces: tuple[str, ...] = ()
    weather: str | None = None
    start: tuple[int, int] = (1, 1)
    end: tuple[int, int] = (12, 31)
    heating_setpoint: float = HEATING_SETPOINT
    cooling_setpoint: float = COOLING_SETPOINT
    timesteps_per_hour: int = 6
    samples: int = 20


def parse_day(v: Any, path: str, problems: Problems) -> tuple[int, int] | None:
    """A day ``"MM-DD"`` of a non-leap year as (month, day), or None after recording the problem."""
    if isinstance(v, str):
        try:
            d = dt.datetime.strptime(f"2025-{v.strip()}", "%Y-%m-%d")
            return d.month, d.day
        except ValueError:
            pass
    problems.add(path, f'must be a day "MM-DD" (e.g. "01-15"), got {describe(v)}')
    return None


def parse_building(raw: Any, problems: Problems, base_dir: Path | None) -> BuildingSpec | None:
    """Validate the ``[building]`` table, adding every problem to ``problems`` (key paths ``building....``)."""
    t = Table(raw, "building", problems, BUILDING_KEYS)
    if not t.ok:
        return None
    n0 = len(problems)
    model = t.str("model", None)
    model_path = None
    if model:
        model_path = (base_dir / model) if base_dir else Path(model)
        if not model_path.is_file():
            problems.add("building.model", f"{model!r}: no such file (relative to the study)")
        elif model_path.suffix.lower() not in (".epjson", ".json", ".idf"):
            problems.add("building.model", f"{model!r}: expected an .epJSON or .idf file (EnergyPlus 25.2)")
    surfaces: tuple[str, ...] = ()
    if t.has("surfaces"):
        s = t.raw("surfaces")
        if not isinstance(s, list) or not s or not all(isinstance(x, str) and x.strip() for x in s):
            problems.add("building.surfaces", f"must be a non-empty list of surface names, got {describe(s)}")
        else:
            surfaces = tuple(s)
    start = parse_day(t.raw("start"), "building.start", problems) if t.has("start") else (1, 1)
    end = parse_day(t.raw("end"), "building.end", problems) if t.has("end") else (12, 31)
    if start and end and end < start:
        problems.add("building.end", f"the run period must not wrap the year: end {end} is before start {start}")
    heat = t.num("heating_setpoint", HEATING_SETPOINT, ge=-20.0, le=40.0)
    cool = t.num("cooling_setpoint", COOLING_SETPOINT, ge=-20.0, le=60.0)
    if heat is not None and cool is not None and not cool > heat:
        problems.add("building.cooling_setpoint", f"must be above heating_setpoint ({heat:g}), got {cool:g}")
    steps = t.num("timesteps_per_hour", 6, integer=True)
    if steps is not None and int(steps) not in ALLOWED_TIMESTEPS:
        problems.add(
            "building.timesteps_per_hour", f"must divide 60 ({', '.join(map(str, ALLOWED_TIMESTEPS))}), got {steps:g}"
        )
    samples = t.num("samples", 20, integer=True, ge=1, le=100000)
    weather = t.str("weather", None)
    if len(problems) > n0:
        return None
    return BuildingSpec(
        model=model,
        model_path=model_path,
        surfaces=surfaces,
        weather=weather,
        start=start,
        end=end,
        heating_setpoint=float(heat),
        cooling_setpoint=float(cool),
        timesteps_per_hour=int(steps),
        samples=int(samples),
    )

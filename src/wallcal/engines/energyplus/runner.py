"""The wall engine's EnergyPlus runs: one run of the fictitious-zone model, and the check run of exported objects.

EnergyPlus itself is launched by :mod:`wallcal.eplus` (the one module that starts it); its finder
(:func:`energyplus_binary`, :func:`weather_file`) and :func:`error_lines` are re-exported here.
"""

from __future__ import annotations

import math
import tempfile
from pathlib import Path

import numpy as np

from ...eplus import energyplus_binary, error_lines, launch, warning_lines, weather_file
from ...errors import EngineError
from .model import ALLOWED_STEPS_PER_HOUR, DAY, WALL_SURFACE, YEAR_DAYS, build_idf, guess_node_count
from .results import read_node_depths, read_node_temperatures


def run_once(
    inp,
    tmp: Path,
    epw: Path,
    steps_e,
    steps_i,
    pads,
    *,
    steps_per_hour,
    warmup_days,
    h_max,
    inside_convergence,
    t_range,
    timeout,
    other_surfaces_ctf=False,
) -> dict:
    dt = float(inp.time_step)
    steps_per_day = int(round(DAY / dt))
    n = len(steps_e)
    # EnergyPlus step j (1-based) ends at j * dt after Jan 1 00:00; one pad day first, so grid point k
    # is the end of step steps_per_day + k.
    run_days = 1 + int(math.ceil(n / steps_per_day))
    year_steps = YEAR_DAYS * steps_per_day
    col_e = np.full(year_steps, steps_e[-1])
    col_i = np.full(year_steps, steps_i[-1])
    col_e[:steps_per_day] = pads[0]
    col_i[:steps_per_day] = pads[1]
    col_i[steps_per_day - 1] = pads[2]
    col_e[steps_per_day : steps_per_day + n] = steps_e
    col_i[steps_per_day : steps_per_day + n] = steps_i
    write_schedule(tmp / "boundary.csv", col_e, col_i)

    n_nodes_guess = guess_node_count(inp.wall, inp.grid_constant, dt)
    idf = build_idf(
        inp.wall,
        schedule_file=str(tmp / "boundary.csv"),
        minutes_per_item=int(round(dt / 60)),
        steps_per_hour=steps_per_hour,
        run_days=run_days,
        warmup_days=warmup_days,
        grid_constant=inp.grid_constant,
        scheme=inp.scheme,
        h_max=h_max,
        inside_convergence=inside_convergence,
        t_range=t_range,
        n_node_outputs=n_nodes_guess + 4,
        other_surfaces_ctf=other_surfaces_ctf,
    )
    (tmp / "in.idf").write_text(idf, encoding="utf-8")
    warnings = warning_lines(launch(tmp / "in.idf", tmp, weather=epw, timeout=timeout))
    x = read_node_depths(tmp / "eplusout.eio", inp.wall)
    temps = read_node_temperatures(tmp / "eplusout.csv", len(x))
    # rows: one per timestep of the run period; grid point k = row steps_per_day + k - 1
    first = steps_per_day - 1
    if temps.shape[0] < first + n + 1:
        raise EngineError(f"EnergyPlus reported {temps.shape[0]} timesteps, expected at least {first + n + 1}")
    lo = first - 1
    hi = min(temps.shape[0], first + n + 2)
    return {"x": x, "T": temps[lo:hi], "offset": 1, "warnings": warnings}


def run_idf_objects(
    objects: str,
    construction: str,
    *,
    exterior: float = 0.0,
    interior: float = 20.0,
    days: int = 1,
    steps_per_hour: int = 20,
    timeout: float = 300.0,
) -> dict:
    """Run EnergyPlus on the fictitious-zone model built around given wall objects.

    Used to check exported objects (``wallcal export-idf``): the six zone surfaces use
    ``construction`` from ``objects``, the other side is held at ``exterior`` and the zone air
    at ``interior``.

    Parameters
    ----------
    objects : str
        IDF text with the materials, the construction and (optionally) the CondFD settings.
    construction : str
        Name of the construction in ``objects``.
    exterior, interior : float
        Constant other-side and zone-air temperatures [degC].
    days : int
        Run period [d] (after one warm-up day at least).
    steps_per_hour : int
        EnergyPlus timesteps per hour (20, 30 or 60).
    timeout : float
        Wall-clock limit [s].

    Returns
    -------
    dict
        ``warnings`` (the .err warning lines), ``nodes`` (the .eio CondFD node lines of the
        construction) and ``node_temperatures`` (last reported row of the reported surface [degC]).

    Raises
    ------
    EngineError
        EnergyPlus reported a severe or fatal error (its lines are shown).
    OptionalDependencyError
        EnergyPlus is not installed.
    """
    epw = weather_file()
    if steps_per_hour not in ALLOWED_STEPS_PER_HOUR:
        raise EngineError(f"steps_per_hour must be one of {ALLOWED_STEPS_PER_HOUR}, got {steps_per_hour}")
    minutes = 60 // steps_per_hour
    with tempfile.TemporaryDirectory(prefix="wallcal_eplus_check_") as tmp:
        tmp = Path(tmp)
        n = YEAR_DAYS * 24 * steps_per_hour
        write_schedule(tmp / "boundary.csv", np.full(n, float(exterior)), np.full(n, float(interior)))
        idf = build_idf(
            None,
            schedule_file=str(tmp / "boundary.csv"),
            minutes_per_item=minutes,
            steps_per_hour=steps_per_hour,
            run_days=max(1, int(days)),
            warmup_days=1,
            grid_constant=3.0,
            scheme="cn",
            h_max=1000.0,
            inside_convergence=0.002,
            n_node_outputs=60,
            wall_objects=objects,
            construction=construction,
        )
        (tmp / "in.idf").write_text(idf, encoding="utf-8")
        err_text = launch(tmp / "in.idf", tmp, weather=epw, timeout=timeout)
        nodes = []
        for ln in (tmp / "eplusout.eio").read_text(errors="replace").splitlines():
            parts = [p.strip() for p in ln.split(",")]
            if (
                len(parts) >= 6
                and parts[0] == "ConductionFiniteDifference Node"
                and parts[3].upper() == construction.upper()
            ):
                nodes.append(ln.strip())
        import pandas as pd

        df = pd.read_csv(tmp / "eplusout.csv")
        cols = [c for c in df.columns if c.startswith(f"{WALL_SURFACE}:CondFD Surface Temperature Node")]
        last = df[cols].iloc[-1].to_numpy(dtype=float) if cols else np.array([])
    return {
        "warnings": warning_lines(err_text),
        "nodes": nodes,
        "node_temperatures": last,
    }


def write_schedule(path: Path, col_e: np.ndarray, col_i: np.ndarray) -> None:
    data = np.column_stack([col_e, col_i])
    with open(path, "w", encoding="ascii") as fh:
        fh.write("T_other_side,T_zone_setpoint\n")
        np.savetxt(fh, data, fmt="%.6f", delimiter=",")


__all__ = ["energyplus_binary", "error_lines", "run_idf_objects", "run_once", "weather_file", "write_schedule"]

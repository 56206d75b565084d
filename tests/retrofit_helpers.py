"""Synthetic EPW weather files and small retrofit studies for the retrofit tests."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from conftest import EXAMPLE

HEADER = [
    "LOCATION,Testville,XX,ZZZ,Synthetic,000000,45.00,7.00,1.0,100.0",
    "DESIGN CONDITIONS,0",
    "TYPICAL/EXTREME PERIODS,0",
    "GROUND TEMPERATURES,0",
    "HOLIDAYS/DAYLIGHT SAVINGS,No,0,0,0",
    "COMMENTS 1,synthetic weather for wallcal tests",
    "COMMENTS 2,",
    "DATA PERIODS,1,1,Data,Friday, 1/ 1,12/31",
]


def write_epw(path: Path, temp_air, *, ghi=None, dni=None, dhi=None, rh=None, ir=None, start_day_of_year=1) -> Path:
    """An hourly EPW file with the given air temperatures [degC] (one row per hour from 1 January 00:00 +
    ``start_day_of_year - 1`` days); irradiance 0, RH 70 %, IR from a sky 10 K below the air by default."""
    t = np.asarray(temp_air, dtype=float)
    n = len(t)
    z = np.zeros(n)
    ghi = z if ghi is None else np.asarray(ghi, dtype=float)
    dni = z if dni is None else np.asarray(dni, dtype=float)
    dhi = z if dhi is None else np.asarray(dhi, dtype=float)
    rh = np.full(n, 70.0) if rh is None else np.asarray(rh, dtype=float)
    ir = 5.670374419e-8 * (t + 263.15) ** 4 if ir is None else np.asarray(ir, dtype=float)
    import datetime as dt

    t0 = dt.datetime(2021, 1, 1) + dt.timedelta(days=start_day_of_year - 1)
    lines = list(HEADER)
    for k in range(n):
        when = t0 + dt.timedelta(hours=k)
        fields = [
            2021,
            when.month,
            when.day,
            when.hour + 1,
            60,
            "?9?9?9?9E0?9?9?9?9?9?9?9?9?9?9?9?9?9?9?9*9*9?9?9?9",
            f"{t[k]:.1f}",
            f"{t[k] - 5:.1f}",
            f"{rh[k]:.0f}",
            101325,
            0,
            1415,
            f"{ir[k]:.0f}",
            f"{ghi[k]:.0f}",
            f"{dni[k]:.0f}",
            f"{dhi[k]:.0f}",
            0,
            0,
            0,
            0,
            0,
            2.0,
            5,
            5,
            9999,
            99999,
            9,
            999999999,
            10,
            0.1,
            0,
            88,
            0.2,
            0,
            0,
        ]
        lines.append(",".join(str(f) for f in fields))
    path.write_text("\n".join(lines) + "\n")
    return path


def year_temperature(hours: int = 8760) -> np.ndarray:
    """An annual plus a daily cosine: 8 +- 12 degC over the year, +- 5 degC over the day."""
    h = np.arange(hours)
    return 8.0 - 12.0 * np.cos(2 * np.pi * h / 8760.0) + 5.0 * np.sin(2 * np.pi * (h - 9) / 24.0)


def study_with_retrofit(tmp: Path, retrofit_toml: str, *, wall_mu: bool = True) -> Path:
    """A copy of the bundled example study (data read from the example folder) with a [retrofit] table."""
    text = EXAMPLE.read_text()
    head, sep, _ = text.partition("\n[retrofit]\n")
    text = head
    text = text.replace('file = "measured.csv"', f'file = "{(EXAMPLE.parent / "measured.csv").as_posix()}"')
    text = text.replace('reference_wall = "true_wall.toml"', "")
    if not wall_mu:
        import re

        text = re.sub(r"\nvapour_resistance_factor = [0-9.e+]+[^\n]*", "", text)
    path = tmp / "study.toml"
    path.write_text(text + "\n" + retrofit_toml)
    return path

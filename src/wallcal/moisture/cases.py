"""The verification cases: EN 15026:2007 Annex A and HAMSTAD benchmarks 1, 2 and 5.

Each case builds its layers, boundaries and initial state from the published definitions (the materials
below), runs :func:`wallcal.moisture.solver.solve` and compares with the bundled reference tables
(``data/``, see ``data/README.md`` for their sources). HAMSTAD 1 reads its hourly climate and the
participants' bands from a folder (:func:`load_hamstad1`); wallcal ships neither. :func:`run_case` returns
the comparison rows and the profiles; it writes nothing.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace
from importlib import resources
from pathlib import Path

import numpy as np
import pandas as pd

from ..errors import StudyError
from .materials import (
    GRAVITY,
    RHO_W,
    HygricMaterial,
    exp_polynomial,
    resistance_factor_hamstad,
    rh_from_suction,
    saturation_pressure,
    van_genuchten,
)
from .solver import Boundary, HamResult, Layer, make_grid, solve

DAY = 86400.0
HOUR = 3600.0
#: the allowed relative balance error of every run
BALANCE_LIMIT = 1e-6


# ============================================================================ materials
def en15026_material() -> HygricMaterial:
    """EN 15026:2007 Annex A (= HAMSTAD 1's load-bearing material)."""
    return HygricMaterial(
        name="EN 15026 Annex A",
        storage=van_genuchten(146.0, [(1.0, 8e-8, 1.6, 0.375)]),
        lambda_dry=1.5,
        lambda_w=15.8e-3,
        rho_c_dry=1.824e6,
        resistance_factor=resistance_factor_hamstad(200.0, 146.0, 0.497),
        liquid_conductivity=exp_polynomial([-39.2619, 0.0704, -1.7420e-4, -2.7953e-6, -1.1566e-7, 2.5969e-9], 73.0),
    )


def hamstad2_material() -> HygricMaterial:
    """HAMSTAD 2, material A: ``w = 116 / (1 - ln(phi)/0.118)^0.869``, constant D_w and delta_p."""

    def storage(pc):
        return 116.0 / (1.0 - np.log(rh_from_suction(pc)) / 0.118) ** 0.869

    return HygricMaterial(
        name="HAMSTAD 2 material A",
        storage=storage,
        lambda_dry=0.15,
        rho_c_dry=525.0 * 800.0,
        vapour_permeability=1e-15,
        moisture_diffusivity=lambda w: np.full_like(np.asarray(w, dtype=float), 6e-10),
    )


def _bm5(name, w_sat, modes, mu, k_coef, lam, lam_w, rho_c) -> HygricMaterial:
    modes = [(k, a / (RHO_W * GRAVITY), n, 1.0 - 1.0 / n) for k, a, n in modes]
    return HygricMaterial(
        name=name,
        storage=van_genuchten(w_sat, modes),
        lambda_dry=lam,
        lambda_w=lam_w / RHO_W,
        rho_c_dry=rho_c,
        resistance_factor=resistance_factor_hamstad(mu, w_sat, 0.2),
        liquid_conductivity=exp_polynomial(k_coef, 0.0, RHO_W),
    )


def hamstad5_materials() -> tuple[HygricMaterial, HygricMaterial, HygricMaterial]:
    """HAMSTAD 5: brick, glue mortar, capillary-active insulation."""
    brick = _bm5(
        "HAMSTAD 5 brick",
        373.5,
        [(0.46, 0.47, 1.5), (0.54, 0.2, 3.8)],
        7.5,
        [-36.484, 461.325, -5240.0, 2.907e4, -7.41e4, 6.997e4],
        0.682,
        0.0,
        1600.0 * 1000.0,
    )
    mortar = _bm5(
        "HAMSTAD 5 mortar",
        700.0,
        [(0.2, 0.5, 1.5), (0.8, 0.004, 3.8)],
        50.0,
        [-40.425, 83.319, -175.961, 123.863],
        0.6,
        0.56,
        230.0 * 920.0,
    )
    insulation = _bm5(
        "HAMSTAD 5 insulation",
        871.0,
        [(0.41, 0.006, 2.5), (0.59, 0.012, 2.4)],
        5.6,
        [-46.245, 294.506, -1439.0, 3249.0, -3370.0, 1305.0],
        0.06,
        0.56,
        212.0 * 1000.0,
    )
    return brick, mortar, insulation


# ============================================================================ reference data
def _table(name: str) -> pd.DataFrame:
    with resources.files("wallcal.moisture").joinpath("data", name).open("r", encoding="utf-8") as fh:
        return pd.read_csv(fh)


# ============================================================================ cases
@dataclass
class CaseRun:
    """What a case run gives: the comparison rows, the profiles, the result, the run time [s]."""

    name: str
    checks: pd.DataFrame
    profiles: pd.DataFrame
    result: HamResult
    seconds: float
    #: a case's time series, when it has one (HAMSTAD 1: ``time_s, M_A, M_B``)
    series: pd.DataFrame | None = None


def _profile_at(result: HamResult, k: int, x: float, values: np.ndarray) -> float:
    return float(np.interp(x, result.x, values[k]))


def _balance_rows(name: str, result: HamResult, days: np.ndarray) -> list[dict]:
    rows = []
    for k, d in enumerate(days):
        for q in ("mass_balance_error", "energy_balance_error"):
            err = getattr(result, q)
            rows.append(
                {
                    "case": name,
                    "quantity": q,
                    "day": float(d),
                    "x_m": np.nan,
                    "value": float(err[k]),
                    "lower": 0.0,
                    "upper": BALANCE_LIMIT,
                }
            )
    return rows


def _profiles(result: HamResult) -> pd.DataFrame:
    nt, nx = result.temperature.shape
    return pd.DataFrame(
        {
            "time_s": np.repeat(result.times, nx),
            "x_m": np.tile(result.x, nt),
            "temperature": result.temperature.ravel(),
            "relative_humidity": result.relative_humidity.ravel(),
            "water_content": result.water_content.ravel(),
        }
    )


def hamstad2() -> CaseRun:
    """HAMSTAD 2: isothermal drying/wetting of a 0.2 m wall, against the analytical w(x) at 100/300/1000 h."""
    start = time.perf_counter()
    ref = _table("hamstad2_analytical.csv")
    hours = [100.0, 300.0, 1000.0]
    grid = make_grid([Layer(hamstad2_material(), 0.2)], first=2e-4, ratio=1.15, max_cell=2e-3)
    ext = Boundary("surface", 20.0, 0.45)
    inn = Boundary("surface", 20.0, 0.65)
    res = solve(grid, ext, inn, 20.0, 0.95, [h * HOUR for h in hours], dt_first=1.0, dt_max=1800.0)
    rows = []
    for k, h in enumerate(hours):
        for x, w_ref in zip(ref["x_m"], ref[f"w_{int(h)}h"], strict=True):
            if x <= 0 or x >= 0.2:  # the faces are the boundary values, not cells
                continue
            v = _profile_at(res, k, x, res.water_content)
            rows.append(
                {
                    "case": "hamstad2",
                    "quantity": "water_content",
                    "day": h / 24.0,
                    "x_m": x,
                    "value": v,
                    "lower": w_ref - 1.0,
                    "upper": w_ref + 1.0,
                }
            )
    rows += _balance_rows("hamstad2", res, np.array(hours) / 24.0)
    return _finish("hamstad2", rows, res, start)


def en15026() -> CaseRun:
    """EN 15026:2007 Annex A: semi-infinite wall, surface stepped to 30 degC / 95 %; Tables A.1 and A.2."""
    start = time.perf_counter()
    days = [7.0, 30.0, 365.0]
    t1 = _table("en15026_table_a1.csv")
    t2 = _table("en15026_table_a2.csv")
    grid = make_grid([Layer(en15026_material(), 40.0)], first=2e-4, ratio=1.04, max_cell=0.5)
    ext = Boundary("surface", 30.0, 0.95)
    inn = Boundary("air", 20.0, 0.5)  # far end: adiabatic and sealed (untouched in a year at 40 m)
    res = solve(grid, ext, inn, 20.0, 0.5, [d * DAY for d in days], dt_first=1.0, dt_max=6 * HOUR)
    rows = []
    for k, d in enumerate(days):
        for _, r in t1[t1["day"] == d].iterrows():
            rows.append(
                {
                    "case": "en15026",
                    "quantity": "water_content",
                    "day": d,
                    "x_m": r["x_m"],
                    "value": _profile_at(res, k, r["x_m"], res.water_content),
                    "lower": r["w_min_kg_m3"],
                    "upper": r["w_max_kg_m3"],
                }
            )
        for _, r in t2[t2["day"] == d].iterrows():
            rows.append(
                {
                    "case": "en15026",
                    "quantity": "temperature",
                    "day": d,
                    "x_m": r["x_m"],
                    "value": _profile_at(res, k, r["x_m"], res.temperature),
                    "lower": r["T_min_C"],
                    "upper": r["T_max_C"],
                }
            )
    rows += _balance_rows("en15026", res, np.array(days))
    return _finish("en15026", rows, res, start)


#: HAMSTAD 5's refinement self-check: the largest allowed difference between the default run and a run on a
#: twice-refined grid with half the largest step, at :data:`HAMSTAD5_POSITIONS` at 60 days
HAMSTAD5_REFINEMENT_TOLERANCE = {"water_content": 1.0, "relative_humidity": 0.005, "temperature": 0.05}
#: where the refinement self-check compares [m from the exterior face]: every 10 mm in the brick, and 12
#: positions in the mortar and the insulation (the wet zone at their interface)
HAMSTAD5_POSITIONS = np.concatenate(
    [np.arange(0.005, 0.365, 0.01), [0.366, 0.37, 0.375, 0.379, 0.3805, 0.381, 0.382, 0.385, 0.39, 0.40, 0.41, 0.419]]
)
#: the participants' results (not part of wallcal; used when present), relative to the repository's root
HAMSTAD5_PARTICIPANTS = Path("..") / "shared" / "data" / "ham" / "hamstad" / "bm5_participants.csv"


def _hamstad5_run(refine: int = 1):
    brick, mortar, insulation = hamstad5_materials()
    grid = make_grid(
        [Layer(brick, 0.365), Layer(mortar, 0.015), Layer(insulation, 0.040)],
        first=1e-4 / refine,
        ratio=1.2 ** (1.0 / refine),
        max_cell=5e-3 / refine,
    )
    ext = Boundary("air", 0.0, 0.8, h=25.0, beta=1.8382e-7)
    inn = Boundary("air", 20.0, 0.6, h=8.0, beta=5.8823e-8)
    days = [1.0, 10.0, 30.0, 60.0]
    res = solve(grid, ext, inn, 25.0, 0.6, [d * DAY for d in days], dt_max=HOUR / refine)
    return res, grid, days


def participants_file() -> Path | None:
    """The HAMSTAD 5 participants' results beside the repository (:data:`HAMSTAD5_PARTICIPANTS`), if there."""
    root = Path(__file__).resolve().parents[3]
    path = root / HAMSTAD5_PARTICIPANTS
    return path if path.is_file() else None


def _row(quantity, day, x, value, lower, upper) -> dict:
    return {
        "case": "hamstad5",
        "quantity": quantity,
        "day": day,
        "x_m": x,
        "value": float(value),
        "lower": float(lower),
        "upper": float(upper),
    }


def hamstad5() -> CaseRun:
    """HAMSTAD 5: brick / mortar / capillary-active insulation, 60 days.

    HAMSTAD gives no reference solution for this benchmark, and wallcal bundles none of the participants'
    results. The checks are the run's own: mass and energy balance errors; physical bounds (0 <= RH <= 1 and
    0 <= w <= w_sat in every cell at every output time); a refinement self-check (at 60 days, w, RH and T at
    :data:`HAMSTAD5_POSITIONS` within :data:`HAMSTAD5_REFINEMENT_TOLERANCE` of a run on a grid twice as fine
    with half the largest step). When the participants' results are found beside the repository
    (:data:`HAMSTAD5_PARTICIPANTS`: columns ``code, x_mm, w, phi``), also the envelope check: w and RH at
    60 days between the lowest and the highest of the codes' values, at every position where at least five
    codes report."""
    start = time.perf_counter()
    res, grid, days = _hamstad5_run()
    fine, _, _ = _hamstad5_run(2)
    k = days.index(60.0)
    rows = []
    rh, w = res.relative_humidity, res.water_content
    w_sat = np.array([m.w[0] for m in grid.materials])[grid.mat]  # w at pc = 1 Pa: capillary saturation
    for j, d in enumerate(days):
        rows.append(_row("min_relative_humidity", d, np.nan, rh[j].min(), 0.0, 1.0))
        rows.append(_row("max_relative_humidity", d, np.nan, rh[j].max(), 0.0, 1.0))
        rows.append(_row("min_water_content", d, np.nan, w[j].min(), 0.0, np.inf))
        rows.append(_row("max_saturation_ratio", d, np.nan, (w[j] / w_sat).max(), 0.0, 1.0))
    for q, tol in HAMSTAD5_REFINEMENT_TOLERANCE.items():
        for x in HAMSTAD5_POSITIONS:
            ref = _profile_at(fine, k, x, getattr(fine, q))
            rows.append(_row(f"refinement_{q}", 60.0, x, _profile_at(res, k, x, getattr(res, q)), ref - tol, ref + tol))
    path = participants_file()
    if path is not None:
        ref = pd.read_csv(path)
        env = ref.groupby("x_mm").agg(
            n=("w", "count"), w_lo=("w", "min"), w_hi=("w", "max"), phi_lo=("phi", "min"), phi_hi=("phi", "max")
        )
        for x_mm, e in env[env["n"] >= 5].iterrows():
            x = x_mm / 1000.0
            rows.append(_row("water_content", 60.0, x, _profile_at(res, k, x, w), e["w_lo"], e["w_hi"]))
            rows.append(_row("relative_humidity", 60.0, x, _profile_at(res, k, x, rh), e["phi_lo"], e["phi_hi"]))
    rows += _balance_rows("hamstad5", res, np.array(days))
    return _finish("hamstad5", rows, res, start)


def _finish(name: str, rows: list[dict], res: HamResult, start: float) -> CaseRun:
    checks = pd.DataFrame(rows, columns=["case", "quantity", "day", "x_m", "value", "lower", "upper"])
    checks["passed"] = (checks["value"] >= checks["lower"]) & (checks["value"] <= checks["upper"])
    return CaseRun(name, checks, _profiles(res), res, time.perf_counter() - start)


# ============================================================================ HAMSTAD 1
#: HAMSTAD 1's files, by the archive's names (``HB1/``): the hourly climate and the participants' 99.9 %
#: bands of M_A and M_B for the first and the fifth year
HAMSTAD1_CLIMATE = "ClimateBench1.txt"
HAMSTAD1_BANDS = {
    (1, "M_A"): "Bench1Year1_MA.csv",
    (1, "M_B"): "Bench1Year1_MB.csv",
    (5, "M_A"): "Bench1Year5_MA.csv",
    (5, "M_B"): "Bench1Year5_MB.csv",
}
#: where ``wallcal verify hamstad1`` looks for them without ``--data``, relative to the repository's root
HAMSTAD1_DATA = Path("..") / "shared" / "data" / "ham" / "hamstad"
#: where they are public
HAMSTAD1_SOURCE = "HAMSTAD archive, HB1/; public in LBNL-ETA/HygroThermFEM tst/units/validation/hamstad"
#: the years HAMSTAD 1 runs (the climate file's year, repeated)
HAMSTAD1_YEARS = 5
#: HAMSTAD 1's layers [m], exterior first: the load-bearing layer (A), the insulation (B)
HAMSTAD1_THICKNESS = (0.10, 0.05)
_BAND_COLUMNS = {"time (h)": "hour", "Average": "average", "CI-(p=0.1%)": "lower", "CI+(p=0.1%)": "upper"}


def hamstad1_materials() -> tuple[HygricMaterial, HygricMaterial]:
    """HAMSTAD 1: the load-bearing layer (EN 15026 Annex A's material) and the capillary-inactive insulation
    (w_sat 900 kg/m3, van Genuchten a = 2e-4 /Pa, n = 2, m = 0.5; mu_dry 9.6 with HAMSTAD's f(w), p = 0.497;
    lambda = 0.033 + 0.59e-3 w; rho c = 0.0739e6 J/(m3 K); no liquid transport)."""
    insulation = HygricMaterial(
        name="HAMSTAD 1 insulation",
        storage=van_genuchten(900.0, [(1.0, 2e-4, 2.0, 0.5)]),
        lambda_dry=0.033,
        lambda_w=0.59e-3,
        rho_c_dry=0.0739e6,
        resistance_factor=resistance_factor_hamstad(9.6, 900.0, 0.497),
    )
    return en15026_material(), insulation


@dataclass
class Hamstad1Data:
    """HAMSTAD 1's inputs: the climate (``time_s, t_ext, t_int, p_ext, p_int``: equivalent exterior and
    interior temperatures [degC], exterior and interior vapour pressures [Pa]) and the bands (``hour, average,
    lower, upper`` [kg/m2], hours from the start of their year) by ``(year, "M_A" | "M_B")``."""

    folder: Path
    climate: pd.DataFrame
    bands: dict[tuple[int, str], pd.DataFrame]


def hamstad1_folder(data_dir: str | Path | None = None) -> Path:
    """The folder HAMSTAD 1's files are read from: ``data_dir``, or :data:`HAMSTAD1_DATA` beside the
    repository."""
    if data_dir is not None:
        return Path(data_dir)
    return Path(__file__).resolve().parents[3] / HAMSTAD1_DATA


def hamstad1_missing(data_dir: str | Path | None = None) -> list[str]:
    """The names of HAMSTAD 1's files missing from its folder (empty: it can run)."""
    folder = hamstad1_folder(data_dir)
    return [n for n in (HAMSTAD1_CLIMATE, *HAMSTAD1_BANDS.values()) if not (folder / n).is_file()]


def _read_climate(path: Path) -> pd.DataFrame:
    try:
        raw = pd.read_csv(path, sep=r"\s+", header=None, dtype=float, comment="#")
    except (ValueError, pd.errors.ParserError, pd.errors.EmptyDataError) as e:
        raise StudyError([f"{path.name}: not a table of numbers ({str(e).splitlines()[0][:120]})"]) from None
    if raw.shape[1] != 5 or len(raw) < 2:
        raise StudyError(
            [
                f"{path.name}: need rows of 5 numbers (time s, T_eq,e C, T_eq,i C, p_a,e Pa, p_a,i Pa), at least 2; "
                f"got {len(raw)} rows of {raw.shape[1]}"
            ]
        )
    clim = raw.set_axis(["time_s", "t_ext", "t_int", "p_ext", "p_int"], axis=1)
    t = clim["time_s"].to_numpy()
    if not np.all(np.isfinite(clim.to_numpy())):
        raise StudyError([f"{path.name}: a value is not finite"])
    if t[0] != 0.0 or np.any(np.diff(t) <= 0):
        raise StudyError([f"{path.name}: column 1 (time [s]) must start at 0 and increase"])
    for c, k in (("p_ext", 4), ("p_int", 5)):
        if np.any(clim[c] <= 0):
            raise StudyError([f"{path.name}: column {k} (vapour pressure [Pa]) must be > 0"])
    return clim


def _read_band(path: Path) -> pd.DataFrame:
    try:
        raw = pd.read_csv(path)
    except (ValueError, pd.errors.ParserError, pd.errors.EmptyDataError) as e:
        raise StudyError([f"{path.name}: not a CSV table ({str(e).splitlines()[0][:120]})"]) from None
    missing = [c for c in _BAND_COLUMNS if c not in raw.columns]
    if missing:
        raise StudyError([f"{path.name}: missing column(s) {', '.join(missing)}"])
    band = raw[list(_BAND_COLUMNS)].rename(columns=_BAND_COLUMNS)
    values = band.apply(pd.to_numeric, errors="coerce")
    if values.isna().any().any() or len(values) == 0:
        raise StudyError([f"{path.name}: the columns {', '.join(_BAND_COLUMNS)} need a number on every row"])
    if np.any(np.diff(values["hour"].to_numpy()) <= 0) or values["hour"].iloc[0] < 0:
        raise StudyError([f"{path.name}: column 'time (h)' must be >= 0 and increase"])
    return values.astype(float)


def load_hamstad1(data_dir: str | Path | None = None) -> Hamstad1Data:
    """Read HAMSTAD 1's climate and bands from :func:`hamstad1_folder`; a one-line
    :class:`~wallcal.errors.StudyError` naming the missing files and where they are public when any is
    missing."""
    folder = hamstad1_folder(data_dir)
    missing = hamstad1_missing(data_dir)
    if missing:
        where = folder if data_dir is not None else HAMSTAD1_DATA
        bands = list(HAMSTAD1_BANDS.values())
        if all(b in missing for b in bands):  # name the four at once
            missing = [m for m in missing if m not in bands] + ["Bench1Year{1,5}_M{A,B}.csv"]
        raise StudyError(
            [
                f"case 'hamstad1': its climate file and bands are missing in {where}: {', '.join(missing)} "
                f"({HAMSTAD1_SOURCE}); give their folder with --data DIR"
            ]
        )
    climate = _read_climate(folder / HAMSTAD1_CLIMATE)
    bands = {key: _read_band(folder / name) for key, name in HAMSTAD1_BANDS.items()}
    return Hamstad1Data(folder, climate, bands)


def _repeat_climate(climate: pd.DataFrame, years: int) -> tuple[np.ndarray, np.ndarray]:
    """The climate's rows repeated ``years`` times: its last row is the next year's first instant (HAMSTAD's
    file runs from hour 0 to 8760), so each year takes the rows but the last, and the run ends on the last."""
    period = float(climate["time_s"].iloc[-1])
    values = climate.drop(columns="time_s").to_numpy()
    t = climate["time_s"].to_numpy()
    times = np.concatenate([t[:-1] + y * period for y in range(years)] + [[years * period]])
    rows = np.concatenate([values[:-1]] * years + [values[-1:]])
    return times, rows


def hamstad1_run(data: Hamstad1Data, years: int = HAMSTAD1_YEARS):
    """Run HAMSTAD 1 over ``years`` repetitions of the climate file, output hourly.

    The load-bearing layer (100 mm) is sealed and exchanges heat only on the exterior (alpha_e 25 W/(m2 K)
    with the climate's equivalent exterior temperature; its vapour pressure is passed but ``beta = 0``), the
    insulation (50 mm) exchanges heat and vapour with the room (alpha_i 7, beta_p,i 2e-8 s/m, the climate's
    interior temperature and vapour pressure). Initial state: 145 kg/m3 (A), 0.065 kg/m3 (B), 10 degC.
    Returns ``(result, grid, series)`` with ``series`` the layers' moisture ``M_A, M_B`` [kg/m2] at each hour
    (``time_s``)."""
    load_bearing, insulation = hamstad1_materials()
    grid = make_grid(
        [Layer(load_bearing, HAMSTAD1_THICKNESS[0]), Layer(insulation, HAMSTAD1_THICKNESS[1])],
        first=1e-4,
        ratio=1.2,
        max_cell=5e-3,
    )
    times, rows = _repeat_climate(data.climate, years)
    t_ext, t_int, p_ext, p_int = rows.T
    ext = Boundary(
        "air",
        t_ext,
        np.clip(p_ext / saturation_pressure(t_ext), 1e-6, 1.0),  # no effect: beta = 0
        times=times,
        h=25.0,
        beta=0.0,
    )
    inn = Boundary("air", t_int, p_int / saturation_pressure(t_int), times=times, h=7.0, beta=2e-8)
    w0 = np.where(grid.mat == 0, 145.0, 0.065)
    out = np.arange(0.0, times[-1] + 0.5 * HOUR, HOUR)
    if out[-1] < times[-1]:
        out = np.append(out, times[-1])
    res = solve(grid, ext, inn, 10.0, None, out, initial_water_content=w0, dt_max=HOUR)
    weights = np.stack([np.where(grid.mat == k, grid.dx, 0.0) for k in (0, 1)], axis=1)
    m = res.water_content @ weights
    series = pd.DataFrame({"time_s": res.times, "M_A": m[:, 0], "M_B": m[:, 1]})
    return res, grid, series


def _take(res: HamResult, idx: np.ndarray) -> HamResult:
    """The result at the output times ``idx`` only."""
    per_time = (
        "times",
        "temperature",
        "potential",
        "relative_humidity",
        "water_content",
        "inflow",
        "runoff",
        "face_flux",
        "mass_balance_error",
        "energy_balance_error",
    )
    return replace(res, **{f: getattr(res, f)[idx] for f in per_time})


def hamstad1(data_dir: str | Path | None = None) -> CaseRun:
    """HAMSTAD 1: insulated roof, 5 years of the hourly climate; M_A and M_B hour by hour against the
    participants' 99.9 % band for years 1 and 5.

    The data (:data:`HAMSTAD1_CLIMATE`, :data:`HAMSTAD1_BANDS`) are read from ``data_dir`` or from
    :data:`HAMSTAD1_DATA` beside the repository; wallcal ships neither. The run's length follows the climate
    file (its last time is one year). Rows ``M_A`` / ``M_B``: ``day`` from the start of the run, ``x_m``
    empty (a layer's integral), the band's CI- and CI+ as limits; the band's hours count from the start of
    their year (year 5 starts at 4 climate periods). Balance errors and profiles every half period."""
    start = time.perf_counter()
    data = load_hamstad1(data_dir)
    res, _, series = hamstad1_run(data)
    period = float(data.climate["time_s"].iloc[-1])
    rows = []
    for (year, q), band in data.bands.items():
        t = (year - 1) * period + band["hour"].to_numpy() * HOUR
        keep = t <= series["time_s"].iloc[-1] + 1e-6
        value = np.interp(t[keep], series["time_s"], series[q])
        rows += [
            {"case": "hamstad1", "quantity": q, "day": tk / DAY, "x_m": np.nan, "value": v, "lower": lo, "upper": hi}
            for tk, v, lo, hi in zip(t[keep], value, band["lower"][keep], band["upper"][keep], strict=True)
        ]
    ref = np.searchsorted(res.times, np.arange(2 * HAMSTAD1_YEARS + 1) * 0.5 * period - 1e-6)
    sub = _take(res, np.unique(np.minimum(ref, res.times.size - 1)))
    rows += _balance_rows("hamstad1", sub, sub.times / DAY)
    run = _finish("hamstad1", rows, sub, start)
    run.series = series
    return run


CASES = {"en15026": en15026, "hamstad1": hamstad1, "hamstad2": hamstad2, "hamstad5": hamstad5}


def run_case(name: str, data_dir: str | Path | None = None) -> CaseRun:
    """Run one verification case by name; ``data_dir`` is the folder of HAMSTAD 1's files (see
    :func:`hamstad1`)."""
    if name not in CASES:
        raise StudyError([f"case {name!r}: unknown; the cases are {', '.join(CASES)}"])
    if name == "hamstad1":
        return hamstad1(data_dir)
    return CASES[name]()

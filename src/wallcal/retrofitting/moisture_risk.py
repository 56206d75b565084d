"""Hygrothermal year runs of retrofit variants (EN 15026), the mould index at the layer interfaces and a verdict.

Each variant whose layers all have hygric properties runs with the heat-and-moisture solver
(:func:`wallcal.moisture.solve`) over the weather period, repeated year after year from the last year's end
state until the state is periodic, as EN 15026 asks: every layer's water content [kg/m2] changes by less
than ``max(PERIODIC_RELATIVE * its amount, PERIODIC_ABSOLUTE)`` from one year to the next, at most
``MAX_YEARS`` years.

Boundaries (:func:`ham_boundaries`):

- exterior: air temperature and relative humidity of the weather file, heat transfer coefficient h_e, the
  sol-air radiative term h_e (T_eq - T_e) of :mod:`.boundary` as a heat flux into the face (absorbed solar
  minus the long-wave loss to the sky), vapour transfer coefficient ``beta = LEWIS * h`` and driving rain
  (:func:`driving_rain`);
- interior (:func:`interior_climate`): air with h_i and ``beta = LEWIS * h_i``; with ``moisture_interior_climate
  = "constant"`` at the interior temperature, the relative humidity constant or from the ISO 13788 humidity
  class (Annex A on daily means: p_i = p_e + 1.10 Delta_p(theta_e)); with ``"EN 15026 normal"`` / ``"EN 15026
  high"`` EN 15026 Annex C's indoor temperature and RH from each day's mean outdoor temperature.

Mould: :mod:`wallcal.moisture.mould` on the hourly temperature and relative humidity of the cell next to
each interface, on each side with the sensitivity class of that side's own material (issue 38's rule; a covered
painted or papered old surface is named with ``[retrofit] mould_sensitivity``); the worse side counts, and
the interface with the highest mould index (then the highest RH) is the critical one.

Verdict (:func:`verdict`), in this order:

- ``accumulating``: not periodic after ``MAX_YEARS`` years and the wall's water still rising over the last
  year (``water_content_trend_kg_m2_per_year > 0``);
- ``mould_risk``: mould index >= ``MOULD_LIMIT`` (1: growth visible under the microscope) at an interface;
- ``acceptable``: the highest hourly RH at an interface reaches ``DRY_RH`` but the mould index stays below
  ``MOULD_LIMIT``;
- ``dry``: RH below ``DRY_RH`` (0.80, the lowest RH_min of the mould classes) at every interface all year.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from ..errors import DataError
from ..moisture import mould
from ..moisture.materials import HygricMaterial, potential_from_rh, rh_from_suction
from ..moisture.solver import Boundary, HamResult, Layer, make_grid, solve
from ..weather import Weather, saturation_pressure

#: vapour transfer coefficient per heat transfer coefficient [s/m per W/(m2K)] (HAMSTAD 5's faces:
#: 1.8382e-7 s/m at h = 25, 5.8823e-8 s/m at h = 8, the Lewis relation)
LEWIS = 7.353e-9
#: EN ISO 15927-3: driving rain r_bv = R_1 R_2 v cos(D - theta) r_h^RAIN_EXPONENT [mm/h = kg/(m2 h)]
RAIN_R2 = 2.0 / 9.0  # s/m, the airfield coefficient of EN ISO 15927-3
RAIN_EXPONENT = 0.88  # about 8/9
#: default R_1 = C_R C_T O W (roughness, topography, obstruction, wall factor of EN ISO 15927-3)
RAIN_FACTOR = 0.4
#: periodic state: each layer's water content [kg/m2] changes by less than max(rel * amount, abs) per year
PERIODIC_RELATIVE = 0.01
PERIODIC_ABSOLUTE = 1e-3
MAX_YEARS = 10
#: initial relative humidity of every layer (EN 15026 leaves it to the user; 0.8 is common practice)
INITIAL_RH = 0.8
#: verdict thresholds
MOULD_LIMIT = 1.0
DRY_RH = 0.80
#: EN 15026 Annex C indoor climate from the daily mean outdoor temperature theta_e [degC]: temperature 20 degC for
#: theta_e <= 10, rising linearly to 25 degC at theta_e >= 20; RH 30 % (normal occupancy) or 40 % (high) for
#: theta_e <= -10, rising linearly to 60 % / 70 % at theta_e >= 20. (theta_e, value) at the two ends
EN15026_T = ((10.0, 20.0), (20.0, 25.0))
EN15026_RH = {"EN 15026 normal": ((-10.0, 0.30), (20.0, 0.60)), "EN 15026 high": ((-10.0, 0.40), (20.0, 0.70))}
#: the solver's grid: cells of 0.5 mm at every face and interface growing fourfold to at most 40 mm (first cell,
#: growth, widest cell [m]), and of CAPILLARY_CELL at the faces of a layer that takes up liquid water (a wetted
#: capillary face needs them: rain uptake, condensate taken up behind interior insulation; a thin cell in a
#: capillary layer costs few steps, in a non-capillary one many). The interface conditions (where the mould index
#: is read) are those half a cell into each material. bench/retrofit_grid.py and docs/retrofit.md ("Grid") give
#: its convergence against a grid of 0.1 mm cells growing by 1.3 to 20 mm everywhere
GRID = (5e-4, 4.0, 0.04)
CAPILLARY_CELL = 1e-4
DT_MAX = 3600.0
#: EPW missing-value codes of the rain fields
MISSING_DEPTH, MISSING_QUANTITY, MISSING_WIND = 999.0, 99.0, 999.0
VERDICTS = ("dry", "acceptable", "mould_risk", "accumulating")


# ============================================================================ boundaries
@dataclass(frozen=True)
class RainInfo:
    """What the weather file gives for driving rain (for the notes)."""

    hours_with_data: int
    hours: int
    precipitation_mm: float
    driving_rain_mm: float
    factor: float
    months: str = ""  # the months with precipitation data, e.g. "4" or "1, 2, 3"

    def note(self) -> str:
        if self.hours_with_data == 0:
            return "the weather file has no precipitation (EPW liquid precipitation depth missing): no driving rain"
        s = (
            f"driving rain (EN ISO 15927-3, R_1 = {self.factor:g}, R_2 = 2/9 s/m, r_h^{RAIN_EXPONENT:g}): "
            f"{self.driving_rain_mm:.1f} mm/year on the wall from {self.precipitation_mm:.1f} mm of precipitation"
        )
        if self.hours_with_data < self.hours:
            where = f" (months with data: {self.months})" if self.months else ""
            s += (
                f"; the file gives precipitation for {self.hours_with_data} of {self.hours} hours{where}, the others "
                "count as dry, so the rain load is underestimated"
            )
        return s


def driving_rain(weather: Weather, azimuth: float, factor: float = RAIN_FACTOR) -> tuple[np.ndarray, RainInfo]:
    """Driving rain on the wall per hour of the file [kg/(m2 s)] (EN ISO 15927-3)::

        r_bv = R_1 R_2 v cos(D - theta) r_h^0.88   (cos > 0: wind towards the wall; 0 otherwise)

    r_h [mm/h] the horizontal rainfall (EPW liquid precipitation depth over its quantity of hours, spread
    evenly over those hours, ending at the row), v [m/s] the wind speed and D [degrees from north] the
    direction the wind comes from, theta the wall's outward normal, R_2 = 2/9 s/m, R_1 = ``factor``.
    Hours with a missing depth (999), quantity (99) or wind (999) count as dry.
    """
    d = weather.data
    n = len(d)
    cols = ("liquid_precipitation_depth", "liquid_precipitation_quantity", "wind_speed", "wind_direction")
    if any(c not in d for c in cols):
        return np.zeros(n), RainInfo(0, n, 0.0, 0.0, factor)
    depth = pd.to_numeric(d[cols[0]], errors="coerce").to_numpy(dtype=float)
    qty = pd.to_numeric(d[cols[1]], errors="coerce").to_numpy(dtype=float)
    v = pd.to_numeric(d[cols[2]], errors="coerce").to_numpy(dtype=float)
    direction = pd.to_numeric(d[cols[3]], errors="coerce").to_numpy(dtype=float)
    ok = np.isfinite(depth) & (depth >= 0) & (depth < MISSING_DEPTH)
    qty = np.where(np.isfinite(qty) & (qty >= 1) & (qty < MISSING_QUANTITY), qty, 1.0)
    r_h = np.zeros(n)
    for i in np.flatnonzero(ok & (depth > 0)):
        k = int(round(qty[i]))
        lo = max(i - k + 1, 0)
        r_h[lo : i + 1] += depth[i] / (i + 1 - lo)
    wind_ok = np.isfinite(v) & (v >= 0) & (v < MISSING_WIND) & np.isfinite(direction) & (direction < MISSING_WIND)
    cosine = np.maximum(np.cos(np.radians(np.where(wind_ok, direction, 0.0) - azimuth)), 0.0)
    r_bv = np.where(wind_ok, factor * RAIN_R2 * np.where(wind_ok, v, 0.0) * cosine * r_h**RAIN_EXPONENT, 0.0)
    months = sorted({int(m) for m in d.index[ok].month}) if hasattr(d.index, "month") else []
    info = RainInfo(
        int(ok.sum()), n, float(depth[ok].sum()), float(r_bv.sum()), factor, ", ".join(str(m) for m in months)
    )
    return r_bv / 3600.0, info


def _marks_from_means(x: np.ndarray) -> np.ndarray:
    """Hour means -> values at the hour marks 0..N (periodic) with the same trapezoid sum."""
    return 0.5 * (np.concatenate([[x[-1]], x]) + np.concatenate([x, [x[0]]]))


def _daily_means(weather: Weather) -> tuple[np.ndarray, np.ndarray]:
    """Each row's day mean (blocks of 24 rows from the first) of the outdoor air temperature [degC] and vapour
    pressure [Pa]."""
    d = weather.data
    t = d["temp_air"].to_numpy(dtype=float)
    p = d["relative_humidity"].to_numpy(dtype=float) / 100.0 * saturation_pressure(t)
    day = np.arange(weather.hours) // 24
    t_day = pd.Series(t).groupby(day).transform("mean").to_numpy()
    p_day = pd.Series(p).groupby(day).transform("mean").to_numpy()
    return t_day, p_day


def interior_relative_humidity(weather: Weather, spec) -> np.ndarray:
    """Interior RH (fraction) at the hour marks 0..N of the constant interior: constant, or ISO 13788 Annex A on
    daily means (p_i = p_e + 1.10 Delta_p(theta_e), theta_e and p_e the mean of the 24 hours of each day), at
    most 0.95."""
    from .glaser import interior_vapour_pressure

    n = weather.hours
    if spec.interior_humidity_class is None:
        return np.full(n + 1, float(spec.interior_relative_humidity))
    t_day, p_day = _daily_means(weather)
    p_i = interior_vapour_pressure(t_day, p_day, spec.interior_temperature, None, spec.interior_humidity_class)
    rh = np.minimum(np.asarray(p_i) / saturation_pressure(spec.interior_temperature), 0.95)
    return np.concatenate([[rh[-1]], rh])


def en15026_interior(outdoor_daily_mean, occupancy: str) -> tuple[np.ndarray, np.ndarray]:
    """EN 15026 Annex C's indoor temperature [degC] and RH (fraction) for daily mean outdoor temperatures [degC];
    ``occupancy``: ``"EN 15026 normal"`` or ``"EN 15026 high"`` (:data:`EN15026_T`, :data:`EN15026_RH`)."""
    (t0, ti0), (t1, ti1) = EN15026_T
    (r0, rh0), (r1, rh1) = EN15026_RH[occupancy]
    theta = np.asarray(outdoor_daily_mean, dtype=float)
    return np.interp(theta, [t0, t1], [ti0, ti1]), np.interp(theta, [r0, r1], [rh0, rh1])


def interior_climate(weather: Weather, spec) -> tuple[np.ndarray | float, np.ndarray]:
    """The moisture run's interior air temperature [degC] (a float when constant) and RH (fraction) at the hour
    marks 0..N, after ``spec.moisture_interior_climate`` (module docstring)."""
    if spec.moisture_interior_climate == "constant":
        return float(spec.interior_temperature), interior_relative_humidity(weather, spec)
    t_day, _ = _daily_means(weather)
    t_i, rh_i = en15026_interior(t_day, spec.moisture_interior_climate)
    return np.concatenate([[t_i[-1]], t_i]), np.concatenate([[rh_i[-1]], rh_i])


def ham_boundaries(weather: Weather, spec, yb, rain_factor: float = RAIN_FACTOR) -> tuple[Boundary, Boundary, RainInfo]:
    """Exterior and interior :class:`~wallcal.moisture.Boundary` at the hour marks 0..N [s] (module docstring).

    ``yb``: the :class:`~.boundary.YearBoundaries` of the same weather and spec (its hourly air and sol-air
    temperatures). Raises :class:`~wallcal.errors.DataError` when the file has no relative humidity.
    """
    d = weather.data
    n = weather.hours
    if "relative_humidity" not in d:
        raise DataError(f"{weather.name}: the weather file has no relative humidity (needed by the moisture run)")
    rh_rows = pd.to_numeric(d["relative_humidity"], errors="coerce").to_numpy(dtype=float) / 100.0
    if not np.all(np.isfinite(rh_rows)) or np.any(rh_rows > 1.0 + 1e-9) or np.any(rh_rows < 0):
        bad = int(np.flatnonzero(~np.isfinite(rh_rows) | (rh_rows > 1.0 + 1e-9) | (rh_rows < 0))[0])
        raise DataError(
            f"{weather.name}: relative humidity missing or outside 0..100 % at {d.index[bad]:%m-%d %H:%M}; "
            "the moisture run needs it every hour"
        )
    rh_marks = np.clip(np.concatenate([[rh_rows[-1]], rh_rows]), 0.01, 1.0)
    times = np.arange(n + 1) * 3600.0
    t_air = np.asarray(yb.hourly["temp_air"], dtype=float)
    h_e = spec.exterior_surface_coefficient
    radiative = h_e * (np.asarray(yb.hourly["sol_air_temperature"], dtype=float) - t_air)
    rain, info = driving_rain(weather, spec.azimuth, rain_factor)
    ext = Boundary(
        "air",
        t_air,
        rh_marks,
        times=times,
        h=h_e,
        beta=LEWIS * h_e,
        rain=_marks_from_means(rain),
        heat_flux=radiative,
    )
    h_i = spec.interior_surface_coefficient
    t_i, rh_i = interior_climate(weather, spec)
    intr = Boundary(
        "air",
        t_i,
        rh_i,
        times=times,
        h=h_i,
        beta=LEWIS * h_i,
    )
    return ext, intr, info


# ============================================================================ the periodic run
@dataclass
class Interface:
    """One layer interface: its name ``a|b`` (layer ids), the cells on either side, their mould classes."""

    name: str
    cell_a: int
    cell_b: int
    class_a: mould.MouldClass
    class_b: mould.MouldClass


@dataclass
class HygroResult:
    """One variant's periodic hygrothermal run.

    ``layer_water[k, j]``: water in layer j [kg/m2] at the start of year k (k = 0..years); ``rh``,
    ``temperature`` (n_interfaces, N + 1) at the hour marks of the last year (the higher RH / the colder of
    the two cells at each interface); ``mould`` (n_interfaces, N) the mould index over the last mould cycle
    (the worse side); ``critical``: index of the critical interface.
    """

    years: int
    periodic: bool
    layer_ids: list[str]
    layer_water: np.ndarray
    interfaces: list[Interface]
    rh: np.ndarray
    temperature: np.ndarray
    mould: np.ndarray
    mould_years: int
    critical: int | None
    runoff_kg_m2: float
    seconds: float
    stats: dict = field(default_factory=dict)
    final_state: tuple[np.ndarray, np.ndarray] | None = None

    @property
    def trend(self) -> float:
        """Change of the wall's total water over the last year [kg/(m2 year)], positive = accumulating."""
        tot = self.layer_water.sum(axis=1)
        return float(tot[-1] - tot[-2])

    @property
    def critical_name(self) -> str:
        return self.interfaces[self.critical].name if self.critical is not None else ""

    @property
    def rh_max(self) -> float:
        return float(self.rh[self.critical].max()) if self.critical is not None else math.nan

    @property
    def mould_max(self) -> float:
        return float(self.mould[self.critical].max()) if self.critical is not None else math.nan

    @property
    def verdict(self) -> str:
        return verdict(self.periodic, self.trend, self.mould_max, self.rh_max)


def verdict(periodic: bool, trend: float, mould_max: float, rh_max: float) -> str:
    """The moisture verdict from the run's figures (module docstring)."""
    if not periodic and trend > 0:
        return "accumulating"
    if np.isfinite(mould_max) and mould_max >= MOULD_LIMIT:
        return "mould_risk"
    if np.isfinite(rh_max) and rh_max >= DRY_RH:
        return "acceptable"
    return "dry"


def _layer_water(res_w: np.ndarray, dx: np.ndarray, layer_of_cell: np.ndarray, n_layers: int) -> np.ndarray:
    return np.bincount(layer_of_cell, weights=res_w * dx, minlength=n_layers)


def periodic_run(
    layers: list[Layer],
    layer_ids: list[str],
    classes: list[mould.MouldClass],
    exterior: Boundary,
    interior: Boundary,
    *,
    hours: int,
    max_years: int = MAX_YEARS,
    initial: tuple[np.ndarray, np.ndarray] | None = None,
    decline: float = mould.DECLINE_COEFFICIENT,
    grid: tuple[float, float, float] = GRID,
) -> HygroResult:
    """Run the layers year after year until periodic (module docstring).

    ``initial``: (temperature, relative humidity) per cell to start from (default: the interior temperature
    and ``INITIAL_RH`` everywhere); ``classes``: the mould class of each layer (each side of an interface has
    its own layer's class).
    """
    import time

    t0 = time.perf_counter()
    first, ratio, widest = grid
    g = make_grid(
        layers, [min(CAPILLARY_CELL, first) if lay.material.capillary else first for lay in layers], ratio, widest
    )
    n_layers = len(layers)
    # layer of each cell (make_grid lays the layers out in order, an even number of cells each)
    bounds = np.cumsum([lay.thickness for lay in layers])
    layer_of_cell = np.minimum(np.searchsorted(bounds, g.x), n_layers - 1)
    out_times = np.arange(hours + 1) * 3600.0
    if initial is None:
        t_init = np.full(g.dx.size, float(np.mean(np.atleast_1d(interior.temperature))))
        rh_init = np.full(g.dx.size, INITIAL_RH)
    elif np.shape(initial[0]) != g.dx.shape:  # another grid (a draw with other thicknesses): start afresh
        return periodic_run(
            layers,
            layer_ids,
            classes,
            exterior,
            interior,
            hours=hours,
            max_years=max_years,
            decline=decline,
            grid=grid,
        )
    else:
        t_init, rh_init = initial
    water = [_layer_water(np.asarray(_w_of(g, rh_init)), g.dx, layer_of_cell, n_layers)]
    periodic = False
    res: HamResult | None = None
    stats = {"steps": 0, "newton_iterations": 0}
    years = 0
    while years < max_years:
        res = solve(g, exterior, interior, t_init, rh_init, out_times, dt_max=DT_MAX)
        years += 1
        stats["steps"] += res.stats["steps"]
        stats["newton_iterations"] += res.stats["newton_iterations"]
        water.append(_layer_water(res.water_content[-1], g.dx, layer_of_cell, n_layers))
        t_init = res.temperature[-1].copy()
        rh_init = rh_from_suction(np.exp(res.potential[-1]))
        change = np.abs(water[-1] - water[-2])
        if np.all(change < np.maximum(PERIODIC_RELATIVE * water[-1], PERIODIC_ABSOLUTE)):
            periodic = True
            break
    assert res is not None
    interfaces = []
    for j in range(n_layers - 1):
        cells_a = np.flatnonzero(layer_of_cell == j)
        cells_b = np.flatnonzero(layer_of_cell == j + 1)
        interfaces.append(
            Interface(
                f"{layer_ids[j]}|{layer_ids[j + 1]}", int(cells_a[-1]), int(cells_b[0]), classes[j], classes[j + 1]
            )
        )
    n_i = len(interfaces)
    rh = np.empty((n_i, hours + 1))
    temp = np.empty((n_i, hours + 1))
    m = np.zeros((n_i, hours))
    mould_years = 0
    for k, itf in enumerate(interfaces):
        ta, tb = res.temperature[:, itf.cell_a], res.temperature[:, itf.cell_b]
        ra, rb = res.relative_humidity[:, itf.cell_a], res.relative_humidity[:, itf.cell_b]
        rh[k] = np.maximum(ra, rb)
        temp[k] = np.minimum(ta, tb)
        # each hour's conditions: the mean of its two marks
        ha, hb = 0.5 * (ta[1:] + ta[:-1]), 0.5 * (tb[1:] + tb[:-1])
        qa, qb = 0.5 * (ra[1:] + ra[:-1]), 0.5 * (rb[1:] + rb[:-1])
        ma, ya = mould.periodic_mould_index(ha, qa, itf.class_a, decline=decline)
        mb, yb_ = mould.periodic_mould_index(hb, qb, itf.class_b, decline=decline)
        m[k] = np.maximum(ma, mb)
        mould_years = max(mould_years, ya, yb_)
    critical = None
    if n_i:
        key = [(float(m[k].max()), float(rh[k].max())) for k in range(n_i)]
        critical = max(range(n_i), key=lambda k: key[k])
    return HygroResult(
        years=years,
        periodic=periodic,
        layer_ids=list(layer_ids),
        layer_water=np.array(water),
        interfaces=interfaces,
        rh=rh,
        temperature=temp,
        mould=m,
        mould_years=mould_years,
        critical=critical,
        runoff_kg_m2=float(res.runoff[-1, 0]),
        seconds=time.perf_counter() - t0,
        stats={**stats, "cells": int(g.dx.size)},
        final_state=(t_init, rh_init),
    )


def _w_of(g, rh) -> np.ndarray:
    u = potential_from_rh(np.asarray(rh, dtype=float))
    w = np.empty(g.dx.size)
    for k, m in enumerate(g.materials):
        sel = g.mat == k
        w[sel] = m.water_content(u[sel])
    return w


# ============================================================================ layers: hygric data, mould classes
#: Default mould sensitivity class of the catalogue's materials, from Ojanen et al. (2010), Table 1: untreated wood
#: "very sensitive"; planed wood, paper-coated products and wood-based boards "sensitive"; cement- or plastic-based
#: materials and mineral fibres "medium resistant" (mineral plasters, brick, concrete, calcium silicate taken as
#: cement-like); glass and metal "resistant". Any other material: ``DEFAULT_CLASS``. Each side of an interface has
#: its own material's class (issue 38's rule), the former room face of a wall covered by interior insulation
#: included; ``[retrofit] mould_sensitivity`` overrides them by layer id or material name (a painted or papered
#: old surface: "sensitive", Ojanen's paper-coated products).
DEFAULT_CLASSES = {
    "timber": "very sensitive",
    "osb": "sensitive",
    "plywood": "sensitive",
    "wood fibre board": "sensitive",
    "cellulose": "sensitive",
    "gypsum plasterboard": "sensitive",
    "eps": "medium resistant",
    "xps": "medium resistant",
    "pir": "medium resistant",
    "vapour control layer": "medium resistant",
    "solid brick": "medium resistant",
    "brick": "medium resistant",
    "lime plaster": "medium resistant",
    "gypsum plaster": "medium resistant",
    "cement render": "medium resistant",
    "concrete": "medium resistant",
    "aerated concrete": "medium resistant",
    "calcium silicate board": "medium resistant",
    "mineral wool": "medium resistant",
    "mineral wool board": "medium resistant",
    "glass wool": "medium resistant",
    "wind barrier": "medium resistant",
}
DEFAULT_CLASS = "sensitive"


def hygric_keys(layer) -> dict | None:
    """A layer's hygric keys: its own (``moisture_storage`` ...), else its catalogue material's (the layer's
    own mu and scales win); None when it has none (or is a no-mass layer)."""
    from ..materials import find

    if layer.thermal_resistance is not None:
        return None
    own = layer.hygric_keys() if hasattr(layer, "hygric_keys") else {}
    mat = find(layer.material) if layer.material else None
    if "moisture_storage" in own:
        out = own
    elif mat is not None and mat.has_hygric:
        out = mat.layer_keys(layer.thickness, hygric=True)
        out.update(own)
    else:
        return None
    # both the storage and mu are needed (an incomplete set counts as none)
    return out if out.get("vapour_resistance_factor") is not None else None


_MATERIALS: dict = {}


def layer_material(layer, where: str) -> HygricMaterial:
    """The layer's :class:`HygricMaterial` (cached on its keys and thermal properties).

    Raises
    ------
    StudyError
        One line naming ``where`` when the layer has no hygric properties.
    """
    import json

    from ..errors import StudyError
    from ..materials import catalogue
    from ..moisture.materials import hygric_material

    keys = hygric_keys(layer)
    if keys is None:
        with_data = ", ".join(sorted(n for n, m in catalogue().items() if m.has_hygric))
        what = f"material {layer.material!r}" if layer.material else "no catalogue material"
        raise StudyError(
            [
                f"{where} (layer {layer.id!r}, {what}): no hygric properties for the moisture run; give "
                f"moisture_storage and vapour_resistance_factor (docs/moisture.md) or a catalogue material with "
                f"hygric data ({with_data}), or set retrofit.moisture_check = false"
            ]
        )
    key = (
        layer.material or layer.id,
        json.dumps(keys, sort_keys=True, default=float),
        float(layer.conductivity),
        float(layer.density),
        float(layer.specific_heat),
    )
    mat = _MATERIALS.get(key)
    if mat is None:
        if len(_MATERIALS) > 4096:
            _MATERIALS.clear()
        mat = hygric_material(
            f"{key[0]} ({len(_MATERIALS)})",
            keys,
            conductivity=key[2],
            density=key[3],
            specific_heat=key[4],
            where=where,
        )
        _MATERIALS[key] = mat
    return mat


def layer_classes(wall, overrides: tuple[tuple[str, str], ...] = ()) -> list[mould.MouldClass]:
    """Each layer's mould sensitivity class: ``overrides`` by layer id, then by material name (case-insensitive),
    then :data:`DEFAULT_CLASSES`, else :data:`DEFAULT_CLASS`."""
    by = {k: v for k, v in overrides}
    by_low = {k.strip().lower(): v for k, v in overrides}
    out = []
    for layer in wall.layers:
        name = by.get(layer.id) or by_low.get(layer.material.strip().lower()) if layer.material else by.get(layer.id)
        if name is None:
            name = DEFAULT_CLASSES.get(layer.material.strip().lower(), DEFAULT_CLASS)
        out.append(mould.mould_class(name))
    return out


def ham_layers(wall, where_of: Callable[[int], str]) -> list[Layer]:
    """The solver's layers of a wall (``where_of(k)`` names layer k in messages)."""
    return [Layer(layer_material(layer, where_of(k)), layer.thickness) for k, layer in enumerate(wall.layers)]


def missing_hygric(wall) -> list[str]:
    """Ids of the wall's layers without hygric properties."""
    return [layer.id for layer in wall.layers if hygric_keys(layer) is None]


@dataclass(frozen=True)
class RunSettings:
    """What a variant's run needs besides its wall (picklable, for cluster workers)."""

    exterior: Boundary
    interior: Boundary
    hours: int
    max_years: int
    decline: float
    overrides: tuple[tuple[str, str], ...]


def run_wall(wall, settings: RunSettings, where_of: Callable[[int], str], initial=None) -> HygroResult:
    """One wall's periodic hygrothermal run with its interfaces' mould index."""
    return periodic_run(
        ham_layers(wall, where_of),
        [layer.id for layer in wall.layers],
        layer_classes(wall, settings.overrides),
        settings.exterior,
        settings.interior,
        hours=settings.hours,
        max_years=settings.max_years,
        initial=initial,
        decline=settings.decline,
    )


def draw_task(task) -> tuple[float, float, int, float]:
    """A posterior draw's run (top level, for :class:`wallcal.cluster.Executor`): ``(wall, settings, initial)``
    -> (mould index at the critical interface, water trend [kg/(m2 year)], years, CPU seconds)."""
    import time

    wall, settings, initial = task
    cpu = time.process_time()
    r = run_wall(wall, settings, lambda k: f"layer {k}", initial=initial)
    return r.mould_max, r.trend, r.years, time.process_time() - cpu


def run_draws(
    walls, settings: RunSettings, initial, *, done=None, chunk: int | None = None, on_chunk=None
) -> np.ndarray:
    """Every draw's (mould index, trend, years, CPU seconds), on the active :class:`wallcal.cluster.Executor` when
    there is one, else one after the other here. ``initial``: the point wall's end state (the draws start from it).

    ``done``: the rows of the first draws, already run (a resumed run's), not run again; ``chunk``: draws run per
    call of the executor (default: all at once); ``on_chunk(rows)``: called after each chunk with the rows of every
    draw run so far (to save them and show progress)."""
    from ..cluster import current_executor

    out = np.asarray(done if done is not None else np.zeros((0, 4)), dtype=float).reshape(-1, 4)
    tasks = [(w, settings, initial) for w in walls[len(out) :]]
    ex = current_executor()
    step = max(1, len(tasks) if chunk is None else int(chunk))
    for i in range(0, len(tasks), step):
        part = tasks[i : i + step]
        rows = ex.map(draw_task, part) if ex is not None and len(part) > 1 else [draw_task(t) for t in part]
        out = np.concatenate([out, np.array(rows, dtype=float).reshape(len(part), 4)])
        if on_chunk is not None:
            on_chunk(out)
    return out.reshape(len(walls), 4)

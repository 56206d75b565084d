"""ISO 13788:2012: surface humidity (the f_Rsi criterion) and interstitial condensation (the monthly
Glaser method).

Equations (``docs/retrofit.md`` has them with the standard's clauses):

- saturation vapour pressure (Annex E): p_sat = 610.5 exp(17.269 theta / (237.3 + theta)) for theta >= 0,
  610.5 exp(21.875 theta / (265.5 + theta)) below [Pa];
- interior humidity: a constant relative humidity, or a humidity class 1..5 (Annex A): the excess
  Delta_p over the exterior is 270, 540, 810, 1080, 1350 Pa at theta_e <= 0 degC, falling linearly to 0 at
  20 degC; the calculation uses 1.10 Delta_p (the standard's safety factor);
- f_Rsi (clause 5): the wall's temperature factor f_Rsi = (theta_si - theta_e) / (theta_i - theta_e) =
  1 - Rsi U with Rsi = 0.25 m2K/W; the criterion for each month is the factor at which the surface relative
  humidity reaches 0.8 (mould): theta_si,min from p_sat(theta_si,min) = p_i / 0.8 and
  f_Rsi,min = (theta_si,min - theta_e) / (theta_i - theta_e); the critical month has the largest;
- Glaser (clause 6): steady temperatures through the layers (Rsi, Rse of ISO 6946), layers split into
  sub-layers of at most 0.25 m2K/W; vapour pressure along the cumulative diffusion-equivalent thickness
  s_d = mu d is the taut line from p_e to p_i under p_sat (its lower convex hull); where it touches p_sat
  an interface condenses at g_c = delta_0 (Delta p_in / s_in - Delta p_out / s_out), delta_0 = 2e-10
  kg/(m s Pa); an interface holding condensate stays at p_sat until it has dried (negative g_c
  evaporates); months run from the first month with condensation after a month without, for 12 months.
  Verdict: ``none`` (no month condenses), ``evaporates`` (all condensate gone by the end of the cycle),
  ``accumulates`` (some left: it builds up year on year).
"""

from __future__ import annotations

import calendar
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from ..errors import StudyError
from ..wall import Wall
from ..weather import dew_point_of_pressure, saturation_pressure

DELTA_0 = 2e-10  # water vapour permeability of air [kg/(m s Pa)] (ISO 13788 6.2, ISO 10456)
RSI_MOULD = 0.25  # interior surface resistance for surface humidity [m2K/W] (ISO 13788 4.2.2 / Table 1)
MAX_SUBLAYER_R = 0.25  # [m2K/W]
CRITICAL_SURFACE_RH = 0.8  # mould criterion
HUMIDITY_CLASS_DP = {1: 270.0, 2: 540.0, 3: 810.0, 4: 1080.0, 5: 1350.0}  # Annex A, Pa at theta_e <= 0
SAFETY_FACTOR = 1.10
MIN_SD = 1e-4  # smallest s_d of a sub-layer [m] (a no-mass layer without thickness)


def humidity_class_excess(theta_e, humidity_class: int):
    """Interior vapour pressure excess Delta_p [Pa] of a humidity class (ISO 13788 Annex A), without the
    safety factor: the class value at theta_e <= 0 degC, linearly down to 0 at 20 degC."""
    dp0 = HUMIDITY_CLASS_DP[int(humidity_class)]
    th = np.asarray(theta_e, dtype=float)
    return dp0 * np.clip((20.0 - th) / 20.0, 0.0, 1.0)


def interior_vapour_pressure(theta_e, p_e, theta_i: float, relative_humidity=None, humidity_class=None):
    """Interior vapour pressure p_i [Pa] per month: phi_i p_sat(theta_i), or p_e + 1.10 Delta_p(class)."""
    if humidity_class is not None:
        return np.asarray(p_e, dtype=float) + SAFETY_FACTOR * humidity_class_excess(theta_e, humidity_class)
    return np.full(np.shape(theta_e), float(relative_humidity) * saturation_pressure(theta_i))


# ============================================================================ the layers
@dataclass(frozen=True)
class Sublayers:
    """The wall as the Glaser method sees it: sub-layers with resistance R [m2K/W] and s_d [m]."""

    r: np.ndarray
    sd: np.ndarray
    layer: tuple[str, ...]  # layer id of each sub-layer
    first_interface: tuple[int, ...]  # interface index at each layer's exterior face (and the interior face last)


def sublayers(wall: Wall, max_r: float = MAX_SUBLAYER_R) -> Sublayers:
    """Split each layer into equal sub-layers of at most ``max_r``; contact resistances become vapour-open
    sub-layers. Needs ``vapour_resistance_factor`` on every layer.

    Raises
    ------
    StudyError
        Naming every layer without a vapour resistance factor.
    """
    missing = [layer for layer in wall.layers if layer.vapour_resistance_factor is None]
    if missing:
        names = ", ".join(repr(layer.id) for layer in missing)
        raise StudyError(
            [
                f"layer{'s' if len(missing) > 1 else ''} {names}: vapour_resistance_factor (mu) is missing; "
                "ISO 13788 needs it on every layer (or set retrofit.condensation_check = false)"
            ]
        )
    r, sd, ids, first = [], [], [], []
    for i, layer in enumerate(wall.layers):
        first.append(len(r))
        rl = layer.resistance
        n = max(1, int(np.ceil(rl / max_r - 1e-9)))
        sdl = max(float(layer.vapour_resistance_factor) * layer.thickness, MIN_SD)
        for _ in range(n):
            r.append(rl / n)
            sd.append(sdl / n)
            ids.append(layer.id)
        if layer.contact_resistance and i < len(wall.layers) - 1:
            r.append(layer.contact_resistance)
            sd.append(MIN_SD)
            ids.append(layer.id + "|contact")
    first.append(len(r))
    return Sublayers(r=np.array(r), sd=np.array(sd), layer=tuple(ids), first_interface=tuple(first))


# ============================================================================ one month
@dataclass
class Profile:
    """Steady profiles of one month at the interfaces 0 (exterior surface) .. n (interior surface).

    ``s``: cumulative s_d from the exterior [m]; ``theta`` [degC]; ``p_sat``, ``p`` [Pa];
    ``rate``: condensation rate at each interface [kg/(m2 s)] (negative: evaporation), 0 elsewhere.
    """

    s: np.ndarray
    theta: np.ndarray
    p_sat: np.ndarray
    p: np.ndarray
    rate: np.ndarray


def _lower_hull(xs: np.ndarray, ys: np.ndarray) -> list[int]:
    """Indices of the lower convex hull of points sorted by x (strictly increasing), ends included."""
    hull: list[int] = []
    for k in range(len(xs)):
        while len(hull) >= 2:
            a, b = hull[-2], hull[-1]
            cross = (xs[b] - xs[a]) * (ys[k] - ys[a]) - (ys[b] - ys[a]) * (xs[k] - xs[a])
            if cross <= 0:  # b lies on or above the chord a-k
                hull.pop()
            else:
                break
        hull.append(k)
    return hull


def month_profile(
    sub: Sublayers, theta_i: float, theta_e: float, p_i: float, p_e: float, rsi: float, rse: float, wet=()
) -> Profile:
    """Temperature and vapour-pressure profiles and condensation rates for one month's mean conditions.

    ``wet``: interfaces that hold condensate from earlier months (held at p_sat).
    """
    r_cum = rse + np.concatenate([[0.0], np.cumsum(sub.r)])
    r_tot = r_cum[-1] + rsi
    theta = theta_e + (theta_i - theta_e) * r_cum / r_tot
    s = np.concatenate([[0.0], np.cumsum(sub.sd)])
    ps = saturation_pressure(theta)
    n = len(s) - 1
    anchors = sorted({0, n, *(int(w) for w in wet if 0 < w < n)})
    value = {0: p_e, n: p_i, **{w: ps[w] for w in anchors if 0 < w < n}}
    planes = set(anchors)
    for a, b in zip(anchors[:-1], anchors[1:], strict=True):
        idx = np.arange(a, b + 1)
        ys = ps[idx].copy()
        ys[0], ys[-1] = value[a], value[b]
        for k in _lower_hull(s[idx], ys)[1:-1]:
            planes.add(int(idx[k]))
            value[int(idx[k])] = ps[idx[k]]
    planes_sorted = sorted(planes)
    p = np.interp(s, s[planes_sorted], [value[k] for k in planes_sorted])
    rate = np.zeros(n + 1)
    for j in range(1, len(planes_sorted) - 1):
        lo, c, hi = planes_sorted[j - 1], planes_sorted[j], planes_sorted[j + 1]
        g_in = DELTA_0 * (value[hi] - value[c]) / (s[hi] - s[c])  # from the interior side into the plane
        g_out = DELTA_0 * (value[c] - value[lo]) / (s[c] - s[lo])  # from the plane towards the exterior
        rate[c] = g_in - g_out
    return Profile(s=s, theta=theta, p_sat=ps, p=p, rate=rate)


# ============================================================================ the year
@dataclass
class GlaserResult:
    """ISO 13788 results of one wall.

    Attributes
    ----------
    table : DataFrame
        Per month in calculation order: climate (theta_e, phi_e, p_e, p_i), f_Rsi,min, the month's
        condensation (+) or evaporation (-) [kg/m2], the accumulated amount M_a [kg/m2], and the interfaces.
    verdict : str
        ``none``, ``evaporates`` or ``accumulates``.
    max_accumulated : float
        Largest accumulated amount over the months [kg/m2].
    frsi : float
        The wall's temperature factor (Rsi = 0.25).
    frsi_min : float
        The largest monthly criterion; ``critical_month`` its month.
    profiles : dict
        Month -> :class:`Profile` (for the Glaser diagram).
    worst_month : int
        The month with the largest condensation rate (else the coldest).
    """

    table: pd.DataFrame
    verdict: str
    max_accumulated: float
    frsi: float
    frsi_min: float
    critical_month: int
    worst_month: int
    sub: Sublayers
    profiles: dict = field(default_factory=dict)

    @property
    def mould_ok(self) -> bool:
        return self.frsi > self.frsi_min


def temperature_factor(wall: Wall, rse: float = 0.04, rsi: float = RSI_MOULD) -> float:
    """f_Rsi = 1 - Rsi U of a plane wall, with Rsi = 0.25 m2K/W (ISO 13788 clause 5)."""
    r = wall.resistance
    return (r + rse) / (rsi + r + rse)


def monthly_method(
    wall: Wall,
    climate: pd.DataFrame,
    theta_i: float,
    *,
    relative_humidity: float | None = None,
    humidity_class: int | None = None,
    rsi: float = 0.13,
    rse: float = 0.04,
    year: int = 2021,
) -> GlaserResult:
    """ISO 13788 for a wall under monthly mean climates.

    Parameters
    ----------
    climate : DataFrame
        Indexed by month (1..12, those present), columns ``theta_e`` [degC] and ``p_e`` [Pa].
    theta_i : float
        Interior temperature [degC].
    relative_humidity, humidity_class
        Interior humidity (one of them).
    rsi, rse : float
        Surface resistances of the interstitial calculation [m2K/W].
    """
    sub = sublayers(wall)
    months = [int(m) for m in climate.index]
    th_e = climate["theta_e"].to_numpy(dtype=float)
    p_e = climate["p_e"].to_numpy(dtype=float)
    p_i = interior_vapour_pressure(th_e, p_e, theta_i, relative_humidity, humidity_class)
    p_i = np.asarray(p_i, dtype=float)
    # surface humidity: f_Rsi,min per month (only months with theta_i > theta_e are meaningful)
    theta_si_min = dew_point_of_pressure(p_i / CRITICAL_SURFACE_RH)
    with np.errstate(divide="ignore", invalid="ignore"):
        frsi_min = np.where(theta_i - th_e > 0.5, (theta_si_min - th_e) / (theta_i - th_e), np.nan)
    if np.isfinite(frsi_min).any():
        k_crit = int(np.nanargmax(frsi_min))
        frsi_crit = float(frsi_min[k_crit])
    else:
        k_crit, frsi_crit = int(np.argmin(th_e)), float("nan")
    # dry-wall condensation per month, for the starting month
    dry = [month_profile(sub, theta_i, th_e[k], p_i[k], p_e[k], rsi, rse) for k in range(len(months))]
    condenses = [bool((pr.rate > 0).any()) for pr in dry]
    nm = len(months)
    if not any(condenses):
        start = 0
    elif all(condenses):
        start = (int(np.argmax(th_e)) + 1) % nm
    else:
        start = next(k for k in range(nm) if condenses[k] and not condenses[k - 1])
    n_if = len(sub.r) + 1
    acc = np.zeros(n_if)
    rows, profiles = [], {}
    max_acc = 0.0
    for j in range(nm):
        k = (start + j) % nm
        m = months[k]
        wet = np.flatnonzero(acc > 0)
        pr = month_profile(sub, theta_i, th_e[k], p_i[k], p_e[k], rsi, rse, wet=wet)
        seconds = calendar.monthrange(year, m)[1] * 86400.0
        before = acc.sum()
        acc = np.maximum(acc + pr.rate * seconds, 0.0)
        planes = [i for i in range(n_if) if pr.rate[i] != 0 or acc[i] > 0]
        profiles[m] = pr
        max_acc = max(max_acc, float(acc.sum()))
        rows.append(
            {
                "month": m,
                "theta_e": th_e[k],
                "phi_e": p_e[k] / saturation_pressure(th_e[k]),
                "p_e": p_e[k],
                "p_i": p_i[k],
                "frsi_min": frsi_min[k],
                "condensation_kg_m2": float(pr.rate[pr.rate > 0].sum() * seconds),
                "net_change_kg_m2": float(acc.sum() - before),
                "accumulated_kg_m2": float(acc.sum()),
                "interfaces": " ".join(_interface_name(sub, i) for i in planes),
            }
        )
    table = pd.DataFrame(rows).set_index("month")
    if not any(condenses) and max_acc == 0.0:
        verdict = "none"
    elif acc.sum() > 0:
        verdict = "accumulates"
    else:
        verdict = "evaporates"
    worst = (
        months[int(np.argmax([pr.rate.clip(min=0).sum() for pr in dry]))]
        if any(condenses)
        else months[int(np.argmin(th_e))]
    )
    if worst not in profiles:
        profiles[worst] = dry[months.index(worst)]
    return GlaserResult(
        table=table,
        verdict=verdict,
        max_accumulated=max_acc,
        frsi=temperature_factor(wall, rse=rse),
        frsi_min=frsi_crit,
        critical_month=months[k_crit],
        worst_month=worst,
        sub=sub,
        profiles=profiles,
    )


def _interface_name(sub: Sublayers, i: int) -> str:
    """A readable name of interface ``i``: 'ext', 'int', 'a|b' between layers, 'a@k/n' inside layer a."""
    n = len(sub.r)
    if i == 0:
        return "exterior-surface"
    if i == n:
        return "interior-surface"
    left, right = sub.layer[i - 1], sub.layer[i]
    if left != right:
        return f"{left}|{right}"
    k = sum(1 for j in range(i) if sub.layer[j] == left)
    tot = sum(1 for x in sub.layer if x == left)
    return f"{left}@{k}/{tot}"

"""ISO 9869-1:2014 heat flow meter method: the average method and its acceptance criteria.

Average method (ISO 9869-1:2014, 7.2): the surface-to-surface thermal resistance
is estimated as

    R = sum_j (T_si,j - T_se,j) / sum_j q_j

over equally spaced readings, where q_j is the heat flux density from the
interior to the exterior. wallcal's heat flux densities are positive towards the
**interior**, so this module uses q_out = -q: R = sum(T_si - T_se) / sum(-q).

Acceptance criteria checked (ISO 9869-1:2014, 7.2, for the average method):

a) ``duration``: test duration >= 72 h;
b) ``last_24h``: the final R does not deviate by more than 5 % from the R obtained
   24 h earlier;
c) ``first_last_two_thirds``: R from the first INT(2 DT / 3) days and R from the
   last INT(2 DT / 3) days (DT the duration in days) agree within 5 %;
d) ``storage``: for heavy elements (areal heat capacity > 20 kJ/(m2K)), the change
   of heat stored in the element is less than 5 % of the heat that passed through
   it during the test;
e) ``whole_days``: for heavy elements, the analysis period is an integer multiple
   of 24 h.

The change of stored heat for d) is estimated from the layers of a
:class:`~wallcal.wall.Wall` under a quasi-steady (piecewise-linear) temperature
profile, from the change of the 24 h mean surface temperatures between the first
and the last day of the test; see :func:`stored_heat_change`. The derivation
(not a transcription of the standard's formula) is in ``docs/standards.md``.

The dynamic method of Annex B is not implemented (see ``docs/standards.md``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import DataError, StudyError

DAY_S = 86400.0

#: Areal heat capacity above which ISO 9869-1 treats an element as heavy [J/(m2K)].
HEAVY_AREAL_HEAT_CAPACITY = 20e3


# --------------------------------------------------------------------------- storage model


def _layer_positions(wall):
    """Per mass layer: C_k [J/(m2K)], start s0 and width ds as fractions of R (from the exterior)."""
    rs, cs = [], []
    n = len(wall.layers)
    for i, layer in enumerate(wall.layers):
        rs.append(layer.resistance)
        cs.append(layer.areal_heat_capacity)
        if layer.contact_resistance and i < n - 1:
            rs.append(float(layer.contact_resistance))
            cs.append(0.0)
    rs, cs = np.array(rs, float), np.array(cs, float)
    r_total = rs.sum()
    if not np.isfinite(r_total) or r_total <= 0:
        raise StudyError([f"wall: surface-to-surface resistance must be > 0, got {float(r_total):g} m2K/W"])
    start = np.concatenate([[0.0], np.cumsum(rs)[:-1]]) / r_total
    return cs, start, rs / r_total


def storage_factors(wall, q_side: str = "interior") -> tuple[float, float]:
    """Thermal-mass factors (F_i, F_e) [J/(m2K)] of the heat flux at one face.

    Under a quasi-steady profile, T(s) = T_se + (T_si - T_se) s with s the
    resistance from the exterior face divided by R, heat stored at s splits
    between the faces in the ratio of the resistances, so the energy drawn
    through the interior face into storage when the surface temperatures change
    by dT_i, dT_e is F_i dT_i + F_e dT_e with

        F_i = sum_k C_k <s^2>_k,  F_e = sum_k C_k <s (1 - s)>_k      (interior face)
        F_i = sum_k C_k <s (1 - s)>_k, F_e = sum_k C_k <(1 - s)^2>_k  (exterior face)

    where <.>_k is the mean over layer k (<s^2> = s0^2 + s0 ds + ds^2 / 3 for
    s in [s0, s0 + ds]). For a single homogeneous layer of capacity C at the
    interior face: F_i = C / 3, F_e = C / 6.

    Parameters
    ----------
    wall : Wall
        Layers exterior first, properties at their reference temperature.
    q_side : {"interior", "exterior"}
        Face where the heat flux is measured.

    Returns
    -------
    (F_i, F_e) : tuple of float
    """
    if q_side not in ("interior", "exterior"):
        raise StudyError([f"q_side: must be 'interior' or 'exterior', got {q_side!r}"])
    c, s0, ds = _layer_positions(wall)
    m1 = s0 + ds / 2.0  # <s>
    m2 = s0**2 + s0 * ds + ds**2 / 3.0  # <s^2>
    if q_side == "interior":
        return float(np.sum(c * m2)), float(np.sum(c * (m1 - m2)))
    return float(np.sum(c * (m1 - m2))), float(np.sum(c * (1.0 - 2.0 * m1 + m2)))


def stored_heat_change(wall, delta_t_int_K: float, delta_t_ext_K: float) -> float:
    """Change of heat stored in the wall [J/m2] between two quasi-steady states.

    dQ = sum_k C_k (<s>_k dT_i + (1 - <s>_k) dT_e), with <s>_k the mean relative
    resistance position of layer k from the exterior face (see :func:`storage_factors`).

    Parameters
    ----------
    wall : Wall
    delta_t_int_K, delta_t_ext_K : float
        Changes of the interior and exterior surface temperatures [K].
    """
    c, s0, ds = _layer_positions(wall)
    m1 = s0 + ds / 2.0
    return float(np.sum(c * (m1 * delta_t_int_K + (1.0 - m1) * delta_t_ext_K)))


# --------------------------------------------------------------------------- average method


@dataclass(frozen=True)
class Criterion:
    """One acceptance criterion.

    Attributes
    ----------
    name : str
        ``duration``, ``last_24h``, ``first_last_two_thirds``, ``storage`` or ``whole_days``.
    description : str
        What the standard asks.
    required : bool
        Whether it applies to this element (d and e only for heavy elements).
    passed : bool or None
        None when it could not be evaluated (e.g. ``storage`` without a wall).
    value : float or None
        The figure tested (hours, or a relative deviation [-]).
    limit : float or None
        Its limit.
    detail : str
        How it was evaluated.
    """

    name: str
    description: str
    required: bool
    passed: bool | None
    value: float | None
    limit: float | None
    detail: str = ""


@dataclass(frozen=True)
class Verdict:
    """Verdict of the acceptance criteria.

    Attributes
    ----------
    criteria : tuple of Criterion
    applicable : bool or None
        True when every required criterion passes, False when one fails, None when
        none fails but some required criterion could not be evaluated.
    statement : str
        ``"applicable"``, ``"not applicable: fails ..."`` or ``"undetermined: ..."``.
    """

    criteria: tuple[Criterion, ...]
    applicable: bool | None
    statement: str

    def __getitem__(self, name: str) -> Criterion:
        for c in self.criteria:
            if c.name == name:
                return c
        raise KeyError(name)

    @property
    def failing(self) -> list[str]:
        """Names of the required criteria that fail."""
        return [c.name for c in self.criteria if c.required and c.passed is False]


@dataclass(frozen=True)
class AverageMethodResult:
    """Result of :func:`average_method`.

    Attributes
    ----------
    times_s : ndarray
        Times of the readings [s].
    r_running : ndarray
        Running R after each reading [m2K/W] (NaN while sum(q) is 0).
    r_value : float
        R over the whole test [m2K/W].
    r_storage_corrected : float or None
        R with the storage correction of the face where q is measured:
        sum(T_si - T_se) / (sum(q_out) - (F_i dT_i + F_e dT_e) / dt) (exterior
        face: + instead of -), None without a wall.
    duration_h : float
        N * dt [h].
    areal_heat_capacity : float or None
        Of the wall [J/(m2K)], None without a wall.
    heavy : bool or None
    stored_heat_change_J_m2, heat_through_J_m2 : float or None
        Estimated change of stored heat and heat passed through the face [J/m2].
    verdict : Verdict
    """

    times_s: np.ndarray
    r_running: np.ndarray
    r_value: float
    r_storage_corrected: float | None
    duration_h: float
    areal_heat_capacity: float | None
    heavy: bool | None
    stored_heat_change_J_m2: float | None
    heat_through_J_m2: float | None
    verdict: Verdict


def _as_series(name, values, n=None):
    a = np.asarray(values, dtype=float)
    if a.ndim != 1:
        raise DataError(f"{name}: expected a 1-D series, got shape {a.shape}")
    if n is not None and a.size != n:
        raise DataError(f"{name}: has {a.size} values, times_s has {n}")
    if np.any(~np.isfinite(a)):
        raise DataError(f"{name}: contains NaN or infinite values at index {int(np.flatnonzero(~np.isfinite(a))[0])}")
    return a


def _ratio(r, ref):
    return float(abs(r - ref) / abs(ref)) if ref not in (0.0,) and np.isfinite(ref) and np.isfinite(r) else np.inf


def average_method(
    times_s,
    q_W_m2,
    t_int_surface_C,
    t_ext_surface_C,
    *,
    wall=None,
    q_side: str = "interior",
    heavy: bool | None = None,
    tolerance: float = 0.05,
    min_duration_h: float = 72.0,
) -> AverageMethodResult:
    """ISO 9869-1:2014 average method with its acceptance criteria.

    Parameters
    ----------
    times_s : array
        Reading times [s], strictly increasing and equally spaced (each reading
        stands for one interval dt; duration = N dt).
    q_W_m2 : array
        Heat flux density at the face given by ``q_side`` [W/m2], **positive
        towards the interior** (wallcal's convention).
    t_int_surface_C, t_ext_surface_C : array
        Interior and exterior surface temperatures [degC].
    wall : Wall, optional
        Gives the areal heat capacity (heavy or light) and the storage estimate
        for criterion d).
    q_side : {"interior", "exterior"}
        Face where q was measured (for the storage correction).
    heavy : bool, optional
        Force the heavy/light classification (default: from ``wall``, areal heat
        capacity > 20 kJ/(m2K); unknown without a wall, then d) and e) are required).
    tolerance : float
        Relative tolerance of criteria b), c), d) [-], 0.05 in the standard.
    min_duration_h : float
        Criterion a) [h], 72 in the standard.

    Returns
    -------
    AverageMethodResult
    """
    t = _as_series("times_s", times_s)
    n = t.size
    if n < 2:
        raise DataError(f"times_s: need at least 2 readings, got {n}")
    q = _as_series("q_W_m2", q_W_m2, n)
    ti = _as_series("t_int_surface_C", t_int_surface_C, n)
    te = _as_series("t_ext_surface_C", t_ext_surface_C, n)
    steps = np.diff(t)
    dt = float(np.median(steps))
    if np.any(steps <= 0):
        raise DataError("times_s: must be strictly increasing")
    if np.any(np.abs(steps - dt) > 1e-3 * dt):
        raise DataError(
            f"times_s: readings must be equally spaced for the average method (median step {dt:g} s, "
            f"steps from {steps.min():g} to {steps.max():g} s); resample first"
        )
    if q_side not in ("interior", "exterior"):
        raise StudyError([f"q_side: must be 'interior' or 'exterior', got {q_side!r}"])
    if not (0 < tolerance < 1):
        raise StudyError([f"tolerance: must be in (0, 1), got {tolerance!r}"])

    q_out = -q
    dtemp = ti - te
    cum_t, cum_q = np.cumsum(dtemp), np.cumsum(q_out)
    with np.errstate(divide="ignore", invalid="ignore"):
        r_running = np.where(cum_q != 0.0, cum_t / np.where(cum_q != 0.0, cum_q, 1.0), np.nan)
    r_value = float(r_running[-1])
    duration_s = n * dt
    duration_h = duration_s / 3600.0
    per_day = DAY_S / dt

    kappa = None if wall is None else float(wall.areal_heat_capacity)
    if heavy is None and kappa is not None:
        heavy = kappa > HEAVY_AREAL_HEAT_CAPACITY
    heavy_required = True if heavy is None else bool(heavy)

    crit: list[Criterion] = []
    # a) duration
    crit.append(
        Criterion(
            "duration",
            f"test duration >= {min_duration_h:g} h",
            True,
            duration_h >= min_duration_h - 1e-9,
            duration_h,
            min_duration_h,
            f"N = {n} readings x dt = {dt:g} s",
        )
    )
    # b) final R vs R 24 h before
    k24 = int(round(per_day))
    if abs(k24 - per_day) > 1e-6 * per_day:
        crit.append(
            Criterion(
                "last_24h",
                "final R within 5 % of R 24 h earlier",
                True,
                None,
                None,
                tolerance,
                f"dt = {dt:g} s does not divide 24 h",
            )
        )
    elif n - 1 - k24 < 0:
        crit.append(
            Criterion(
                "last_24h",
                "final R within 5 % of R 24 h earlier",
                True,
                False,
                None,
                tolerance,
                "test shorter than 24 h",
            )
        )
    else:
        r_prev = float(r_running[n - 1 - k24])
        dev = _ratio(r_value, r_prev)
        crit.append(
            Criterion(
                "last_24h",
                "final R within 5 % of R 24 h earlier",
                True,
                dev <= tolerance,
                dev,
                tolerance,
                f"R_end = {r_value:.4g}, R_end-24h = {r_prev:.4g} m2K/W",
            )
        )
    # c) first and last INT(2 DT / 3) days
    n_days = int(np.floor(2.0 * (duration_s / DAY_S) / 3.0 + 1e-9))
    desc_c = "R of the first and of the last INT(2 DT/3) days within 5 %"
    m = int(round(n_days * per_day))
    if n_days < 1 or m > n or abs(n_days * per_day - m) > 1e-6 * per_day:
        crit.append(
            Criterion(
                "first_last_two_thirds",
                desc_c,
                True,
                False,
                None,
                tolerance,
                f"INT(2 DT/3) = {n_days} day(s): not enough data",
            )
        )
    else:
        with np.errstate(divide="ignore", invalid="ignore"):
            r_first = float(dtemp[:m].sum() / q_out[:m].sum())
            r_last = float(dtemp[-m:].sum() / q_out[-m:].sum())
        dev = _ratio(r_first, r_last)
        crit.append(
            Criterion(
                "first_last_two_thirds",
                desc_c,
                True,
                dev <= tolerance,
                dev,
                tolerance,
                f"{n_days} day(s): R_first = {r_first:.4g}, R_last = {r_last:.4g} m2K/W",
            )
        )
    # d) storage
    desc_d = "change of stored heat < 5 % of the heat through the element (heavy elements)"
    d_stored = q_through = r_corr = None
    if wall is not None:
        k = max(1, min(k24, n))
        dti = float(ti[-k:].mean() - ti[:k].mean())
        dte = float(te[-k:].mean() - te[:k].mean())
        d_stored = stored_heat_change(wall, dti, dte)
        q_through = float(abs(q.sum() * dt))
        f_i, f_e = storage_factors(wall, q_side)
        corr = (f_i * dti + f_e * dte) / dt
        denom = q_out.sum() - corr if q_side == "interior" else q_out.sum() + corr
        r_corr = float(dtemp.sum() / denom) if denom != 0 else float("nan")
        ratio = abs(d_stored) / q_through if q_through > 0 else np.inf
        crit.append(
            Criterion(
                "storage",
                desc_d,
                heavy_required,
                ratio < tolerance,
                float(ratio),
                tolerance,
                f"dQ_stored = {d_stored:.4g} J/m2 (quasi-steady estimate from 24 h mean surface "
                f"temperatures: dT_i = {dti:.3g} K, dT_e = {dte:.3g} K), "
                f"heat through = {q_through:.4g} J/m2",
            )
        )
    else:
        crit.append(
            Criterion(
                "storage",
                desc_d,
                heavy_required,
                None,
                None,
                tolerance,
                "not evaluated: pass wall= to estimate the stored heat",
            )
        )
    # e) whole days
    whole = abs(duration_s / DAY_S - round(duration_s / DAY_S)) * DAY_S <= 0.5 * dt
    crit.append(
        Criterion(
            "whole_days",
            "duration an integer multiple of 24 h (heavy elements)",
            heavy_required,
            bool(whole),
            duration_h,
            24.0,
            f"duration {duration_h:g} h",
        )
    )

    failing = [c.name for c in crit if c.required and c.passed is False]
    unknown = [c.name for c in crit if c.required and c.passed is None]
    if failing:
        applicable, statement = False, "not applicable: fails " + ", ".join(failing)
    elif unknown:
        applicable, statement = None, "undetermined: not evaluated " + ", ".join(unknown)
    else:
        applicable, statement = True, "applicable"
    if heavy is None:
        statement += " (element weight unknown: heavy-element criteria required)"
    return AverageMethodResult(
        times_s=t,
        r_running=r_running,
        r_value=r_value,
        r_storage_corrected=r_corr,
        duration_h=duration_h,
        areal_heat_capacity=kappa,
        heavy=heavy,
        stored_heat_change_J_m2=d_stored,
        heat_through_J_m2=q_through,
        verdict=Verdict(tuple(crit), applicable, statement),
    )

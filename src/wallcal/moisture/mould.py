"""The VTT mould-growth model: Hukka & Viitanen (1999) with the sensitivity classes of Ojanen et al. (2010).

References
----------
- A. Hukka, H. A. Viitanen, "A mathematical model of mould growth on wooden material", Wood Science and
  Technology 33 (1999) 475-485.
- T. Ojanen, H. Viitanen, R. Peuhkuri, K. Lahdesmaki, J. Vinha, K. Salminen, "Mold growth modeling of
  building structures using sensitivity classes of materials", Thermal Performance of the Exterior
  Envelopes of Whole Buildings XI, ASHRAE 2010.

The mould index ``M`` (0: no growth, 1: some growth under the microscope, 3: visible, 6: total cover)
follows, with ``T`` [degC] and ``RH`` [%] the conditions at the surface::

    growth (T > 0 degC, T <= 50 degC and RH > RH_crit), t in days:
        dM/dt = k1 k2 / (7 exp(-0.68 ln T - 13.9 ln RH + 0.14 W - 0.33 SQ + 66.02))
        k1 = k1_low (M < 1) or k1_high (M >= 1)                (sensitivity class)
        k2 = max(1 - exp(2.3 (M - M_max)), 0)
        M_max = A + B (RH_crit - RH) / (RH_crit - 100) - C ((RH_crit - RH) / (RH_crit - 100))^2
        RH_crit = max(-0.00267 T^3 + 0.160 T^2 - 3.13 T + 100, RH_min)   for T <= 20 degC
                = RH_min                                                    for T > 20 degC
    decline (any other hour), t in hours since the unfavourable period began (t - t1):
        dM/dt = C_mat * (-0.00133 for t - t1 <= 6 h; 0 for 6 h < t - t1 <= 24 h; -0.000667 beyond)

The growth rate is the inverse of the time to reach ``M = 1`` on pine sapwood (Hukka & Viitanen's
regression gives that time in weeks, hence the 7 days per week); ``W = 0`` (pine) and ``SQ = 0`` (resawn
surface) are the reference of Ojanen's classes, whose table of coefficients is :data:`CLASSES`. ``C_mat``
is Ojanen's relative decline coefficient (1 = the original model for wood, 0.5 significant relapse, 0.25
relatively low decline, 0.1 almost no decline); :data:`DECLINE_COEFFICIENT` is this project's default.
``M`` never falls below 0. Hourly conditions are integrated explicitly (forward Euler, the conditions of
each step held over it), as the model's authors do.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import StudyError, closest, show
from ..jit import kernel


@dataclass(frozen=True)
class MouldClass:
    """One sensitivity class of Ojanen et al. (2010), Table 2 (and its RH_min)."""

    name: str
    k1_low: float  # M < 1
    k1_high: float  # M >= 1
    a: float
    b: float
    c: float
    rh_min: float  # [%]

    def params(self) -> np.ndarray:
        return np.array([self.k1_low, self.k1_high, self.a, self.b, self.c, self.rh_min], dtype=float)


#: Ojanen et al. (2010), Table 2: k1 (M < 1, M >= 1), A, B, C and RH_min [%] per sensitivity class
CLASSES: dict[str, MouldClass] = {
    c.name: c
    for c in (
        MouldClass("very sensitive", 1.0, 2.0, 1.0, 7.0, 2.0, 80.0),
        MouldClass("sensitive", 0.578, 0.386, 0.3, 6.0, 1.0, 80.0),
        MouldClass("medium resistant", 0.072, 0.097, 0.0, 5.0, 1.5, 85.0),
        MouldClass("resistant", 0.033, 0.014, 0.0, 3.0, 1.0, 85.0),
    )
}
#: Ojanen's relative decline coefficient C_mat used unless another is given ("relatively low decline": the
#: cautious choice for the mineral and board surfaces of a retrofit, whose decline is not measured)
DECLINE_COEFFICIENT = 0.25
#: Decline rates of Hukka & Viitanen [1/h] and the ends of their periods [h]
DECLINE_FIRST, DECLINE_LATE = -0.00133, -0.000667
DECLINE_PAUSE_START, DECLINE_PAUSE_END = 6.0, 24.0


def mould_class(name, where: str = "mould sensitivity class") -> MouldClass:
    """The class called ``name`` (case and spacing insensitive; ``_``/``-`` as spaces).

    Raises
    ------
    StudyError
        One line naming ``where``, the bad value and the four classes.
    """
    if isinstance(name, MouldClass):
        return name
    key = " ".join(str(name).lower().replace("_", " ").replace("-", " ").split()) if isinstance(name, str) else None
    if key in CLASSES:
        return CLASSES[key]
    hint = closest(str(name), list(CLASSES)) if isinstance(name, str) else ""
    raise StudyError(
        [
            f"{where}: unknown mould sensitivity class {show(name)}; one of "
            + ", ".join(repr(c) for c in CLASSES)
            + (f" ({hint})" if hint.startswith("did you") else "")
        ]
    )


# ============================================================================ the equations, one point
def critical_rh(temperature: float, cls: MouldClass) -> float:
    """RH_crit [%] at ``temperature`` [degC]."""
    if temperature > 20.0:
        return cls.rh_min
    t = temperature
    return max(-0.00267 * t**3 + 0.160 * t**2 - 3.13 * t + 100.0, cls.rh_min)


def max_index(rh_pct: float, rh_crit: float, cls: MouldClass) -> float:
    """M_max at relative humidity ``rh_pct`` [%] above ``rh_crit`` [%]."""
    x = (rh_crit - rh_pct) / (rh_crit - 100.0)
    return cls.a + cls.b * x - cls.c * x * x


def growth_rate(temperature: float, rh_pct: float, m: float, cls: MouldClass, w: float = 0.0, sq: float = 0.0):
    """dM/dt [1/h] in favourable conditions (0 otherwise; see :func:`decline_rate`)."""
    rc = critical_rh(temperature, cls)
    if not (0.0 < temperature <= 50.0 and rh_pct > rc):
        return 0.0
    k1 = cls.k1_low if m < 1.0 else cls.k1_high
    k2 = max(1.0 - math.exp(2.3 * (m - max_index(rh_pct, rc, cls))), 0.0)
    weeks_to_one = math.exp(-0.68 * math.log(temperature) - 13.9 * math.log(rh_pct) + 0.14 * w - 0.33 * sq + 66.02)
    per_day = k1 * k2 / (7.0 * weeks_to_one)
    return per_day / 24.0


def decline_rate(hours_unfavourable: float, decline: float = DECLINE_COEFFICIENT) -> float:
    """dM/dt [1/h] when the unfavourable period has lasted ``hours_unfavourable`` (end of the step)."""
    if hours_unfavourable <= DECLINE_PAUSE_START:
        return decline * DECLINE_FIRST
    if hours_unfavourable <= DECLINE_PAUSE_END:
        return 0.0
    return decline * DECLINE_LATE


# ============================================================================ time series (compiled)
@kernel
def _index_series(temperature, rh_pct, dt_h, params, decline, w, sq, m0, out):
    """M at the end of each step for rows of (T, RH) series; ``params`` as :meth:`MouldClass.params`."""
    k1_low, k1_high, a, b, c, rh_min = params[0], params[1], params[2], params[3], params[4], params[5]
    n_rows, n = temperature.shape
    for r in range(n_rows):
        m = m0[r]
        dry = 0.0
        for i in range(n):
            t = temperature[r, i]
            rh = rh_pct[r, i]
            if t > 20.0:
                rc = rh_min
            else:
                rc = max(-0.00267 * t * t * t + 0.160 * t * t - 3.13 * t + 100.0, rh_min)
            if t > 0.0 and t <= 50.0 and rh > rc:
                dry = 0.0
                x = (rc - rh) / (rc - 100.0)
                m_max = a + b * x - c * x * x
                k1 = k1_low if m < 1.0 else k1_high
                k2 = 1.0 - math.exp(2.3 * (m - m_max))
                if k2 < 0.0:
                    k2 = 0.0
                weeks = math.exp(-0.68 * math.log(t) - 13.9 * math.log(rh) + 0.14 * w - 0.33 * sq + 66.02)
                m += k1 * k2 / (7.0 * weeks) / 24.0 * dt_h
            else:
                dry += dt_h
                if dry <= 6.0:
                    m += decline * -0.00133 * dt_h
                elif dry > 24.0:
                    m += decline * -0.000667 * dt_h
                if m < 0.0:
                    m = 0.0
            out[r, i] = m
    return out


def mould_index(
    temperature,
    relative_humidity,
    cls,
    *,
    time_step: float = 3600.0,
    decline: float = DECLINE_COEFFICIENT,
    initial: float | np.ndarray = 0.0,
    wood: float = 0.0,
    surface_quality: float = 0.0,
) -> np.ndarray:
    """The mould index after each step of an hourly (or other) series of surface conditions.

    Parameters
    ----------
    temperature : array (..., n)
        Surface temperature [degC], each value held over its step.
    relative_humidity : array (..., n)
        Surface relative humidity, a fraction.
    cls : MouldClass or str
        Sensitivity class (:data:`CLASSES`).
    time_step : float
        [s].
    decline : float
        Ojanen's relative decline coefficient C_mat.
    initial : float or array (...)
        M at the start.

    Returns
    -------
    array (..., n): M at the end of each step.
    """
    cls = mould_class(cls)
    t = np.asarray(temperature, dtype=float)
    rh = np.asarray(relative_humidity, dtype=float) * 100.0
    if t.shape != rh.shape:
        raise ValueError(f"temperature {t.shape} and relative humidity {rh.shape} differ in shape")
    shape = t.shape
    t2 = np.ascontiguousarray(t.reshape(-1, shape[-1]))
    rh2 = np.ascontiguousarray(rh.reshape(-1, shape[-1]))
    m0 = np.broadcast_to(np.asarray(initial, dtype=float), shape[:-1]).reshape(-1).copy()
    out = np.empty_like(t2)
    dt_h = time_step / 3600.0
    _index_series(t2, rh2, dt_h, cls.params(), float(decline), float(wood), float(surface_quality), m0, out)
    return out.reshape(shape)


#: Cycles of the periodic year at most, and the change of M at the year's end that counts as periodic
MOULD_CYCLES = 10
MOULD_TOLERANCE = 0.01


def periodic_mould_index(
    temperature, relative_humidity, cls, *, time_step: float = 3600.0, decline: float = DECLINE_COEFFICIENT
) -> tuple[np.ndarray, int]:
    """M over a periodic year: the year's conditions repeated from M = 0 until M at the year's end changes by
    less than :data:`MOULD_TOLERANCE` (at most :data:`MOULD_CYCLES` years).

    Returns the last year's M series (same shape as the input) and the number of years run. The largest M of
    that year is the year's mould index: M only grows from one cycle to the next of the same conditions
    (it starts higher), so the last year carries the maximum.
    """
    t = np.asarray(temperature, dtype=float)
    m0 = np.zeros(t.shape[:-1])
    years = 0
    while True:
        m = mould_index(t, relative_humidity, cls, time_step=time_step, decline=decline, initial=m0)
        years += 1
        end = m[..., -1]
        if years >= MOULD_CYCLES or np.all(np.abs(end - m0) < MOULD_TOLERANCE):
            return m, years
        m0 = end

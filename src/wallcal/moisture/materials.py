"""Hygric material functions, tabulated on one grid of the moisture potential.

The engine's moisture potential is ``u = ln(pc)``, the logarithm of the capillary suction ``pc`` [Pa]
(positive). Suction and relative humidity are tied by Kelvin's relation at the reference temperature
(EN 15026 and HAMSTAD keep the sorption isotherm temperature independent)::

    pc = -rho_w R_v T_ref ln(phi)

so ``u`` is continuous across layer interfaces (as ``phi`` is) and covers the whole range from nearly
saturated (``pc = 1 Pa``, ``phi = 1 - 7e-9``) to dry (``pc = 1e11 Pa``) with even resolution.

A :class:`HygricMaterial` is built from Python callables (the storage function, the liquid conductivity or
moisture diffusivity, the vapour resistance factor) and tabulated on :data:`U_GRID`; the numba kernel only
interpolates tables, so any material form runs in the same compiled code. The tables are

- ``w``: water content [kg/m3],
- ``kirchhoff``: the liquid Kirchhoff potential ``Phi(u) = int_0^pc K_l dpc'`` [kg/(m s)]; the liquid flux
  between two points of one material is ``(Phi_2 - Phi_1) / dx`` towards the higher suction, exact for any
  ``K_l(pc)``,
- ``delta_ref``: the vapour permeability at ``T_ref`` [s]; the kernel scales it by ``T_ref / T`` (the
  ``M_w / (R T)`` factor of EN 15026 with a fixed diffusion coefficient in air).

Bad input raises :class:`~wallcal.errors.StudyError` with one line naming the material and the problem.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from ..errors import StudyError, clip, closest

R_GAS = 8.314  # J/(mol K)
M_WATER = 0.018  # kg/mol
R_V = R_GAS / M_WATER  # J/(kg K), the specific gas constant of water vapour
RHO_W = 1000.0  # kg/m3
T_REF = 293.15  # K
GRAVITY = 9.81  # m/s2
D_AIR = 26.1e-6  # m2/s, vapour diffusion coefficient in air (HAMSTAD, EN 15026)
C_WATER = 4186.0  # J/(kg K), liquid water
KELVIN = RHO_W * R_V * T_REF  # Pa: pc = -KELVIN ln(phi)

U_MIN = 0.0  # ln(1 Pa)
U_MAX = float(np.log(1e11))
N_TABLE = 4097
U_GRID = np.linspace(U_MIN, U_MAX, N_TABLE)
DU = float(U_GRID[1] - U_GRID[0])


def suction_from_rh(phi):
    """Capillary suction [Pa] in equilibrium with the relative humidity ``phi`` (fraction), at T_ref."""
    return -KELVIN * np.log(phi)


def rh_from_suction(pc):
    """Relative humidity (fraction) in equilibrium with the suction ``pc`` [Pa], at T_ref."""
    return np.exp(-np.asarray(pc, dtype=float) / KELVIN)


def potential_from_rh(phi):
    """The engine's potential ``u = ln(pc)`` for a relative humidity (fraction, < 1)."""
    phi = np.minimum(np.asarray(phi, dtype=float), 1.0 - 1e-9)
    return np.log(suction_from_rh(phi))


def saturation_pressure(t_c):
    """Saturation vapour pressure [Pa] at ``t_c`` [degC] (EN ISO 13788 / EN 15026 formula)."""
    t_c = np.asarray(t_c, dtype=float)
    return np.where(
        t_c >= 0.0, 610.5 * np.exp(17.269 * t_c / (237.3 + t_c)), 610.5 * np.exp(21.875 * t_c / (265.5 + t_c))
    )


# ============================================================================ storage functions
def van_genuchten(w_sat: float, modes: list[tuple[float, float, float, float]]) -> Callable:
    """Multimodal van Genuchten retention ``w(pc) = w_sat sum_i k_i / (1 + (a_i pc)^n_i)^m_i``.

    ``modes`` are ``(k_i, a_i [1/Pa], n_i, m_i)`` (HAMSTAD, EN 15026 Annex A)."""

    def w(pc):
        pc = np.asarray(pc, dtype=float)
        total = np.zeros_like(pc)
        for k, a, n, m in modes:
            total = total + k / (1.0 + (a * pc) ** n) ** m
        return w_sat * total

    return w


def exp_polynomial(coefficients: list[float], shift: float = 0.0, scale: float = 1.0) -> Callable:
    """``K(w) = exp(sum_i c_i ((w - shift) / scale)^i)``: the liquid conductivities of EN 15026 / HAMSTAD."""

    def k(w):
        x = (np.asarray(w, dtype=float) - shift) / scale
        return np.exp(np.polyval(list(reversed(coefficients)), x))

    return k


def resistance_factor_hamstad(mu_dry: float, w_sat: float, p: float) -> Callable:
    """``mu(w) = mu_dry / f(w)``, ``f = (1 - w/w_sat) / ((1 - p)(1 - w/w_sat)^2 + p)`` (HAMSTAD, EN 15026).

    ``f`` vanishes at saturation; the factor is capped at ``1e6 mu_dry`` there."""

    def mu(w):
        s = np.clip(1.0 - np.asarray(w, dtype=float) / w_sat, 0.0, 1.0)
        f = s / ((1.0 - p) * s * s + p)
        return mu_dry / np.maximum(f, 1e-6)

    return mu


# ============================================================================ the material
@dataclass
class HygricMaterial:
    """One material's hygrothermal functions, checked and tabulated on :data:`U_GRID`.

    Parameters
    ----------
    name : str
        Used in error messages.
    storage : callable
        ``w(pc)`` [kg/m3] for suction ``pc`` [Pa]; must be non-increasing in ``pc`` and non-negative.
    lambda_dry, lambda_w, lambda_t : float
        Thermal conductivity ``lambda = lambda_dry + lambda_w w + lambda_t T`` [W/(m K)], ``lambda_w`` per
        kg/m3, ``lambda_t`` per K (``T`` in degC: ``lambda_dry`` is the dry value at 0 degC).
    rho_c_dry : float
        Volumetric heat capacity of the dry material [J/(m3 K)] (the water's ``c_w w`` is added).
    resistance_factor : callable or float
        Vapour resistance factor ``mu(w)`` (>= 1); or give ``vapour_permeability`` instead.
    vapour_permeability : float, optional
        A constant vapour permeability ``delta_p`` [s] (HAMSTAD 2).
    liquid_conductivity : callable, optional
        ``K_l(w)`` [s], the liquid flux being ``K_l grad(pc)`` towards the higher suction.
    moisture_diffusivity : callable, optional
        ``D_w(w)`` [m2/s], the liquid flux being ``-D_w grad(w)``. At most one of the two; neither is a
        capillary-inactive material.
    """

    name: str
    storage: Callable
    lambda_dry: float
    rho_c_dry: float
    lambda_w: float = 0.0
    lambda_t: float = 0.0
    resistance_factor: Callable | float | None = None
    vapour_permeability: float | None = None
    liquid_conductivity: Callable | None = None
    moisture_diffusivity: Callable | None = None
    w: np.ndarray = field(init=False, repr=False)
    kirchhoff: np.ndarray = field(init=False, repr=False)
    delta_ref: np.ndarray = field(init=False, repr=False)

    def __post_init__(self):
        where = f"material {self.name!r}"
        if not (self.lambda_dry > 0 and np.isfinite(self.lambda_dry)):
            raise StudyError([f"{where}: dry thermal conductivity must be > 0, got {self.lambda_dry}"])
        if not (np.isfinite(self.lambda_w) and np.isfinite(self.lambda_t)):
            raise StudyError([f"{where}: lambda_w and lambda_t must be finite"])
        if not (self.rho_c_dry > 0 and np.isfinite(self.rho_c_dry)):
            raise StudyError([f"{where}: dry volumetric heat capacity must be > 0, got {self.rho_c_dry}"])
        if self.liquid_conductivity is not None and self.moisture_diffusivity is not None:
            raise StudyError([f"{where}: give liquid_conductivity or moisture_diffusivity, not both"])
        pc = np.exp(U_GRID)
        w = np.asarray(self.storage(pc), dtype=float)
        if w.shape != pc.shape or not np.all(np.isfinite(w)) or np.any(w < 0):
            raise StudyError([f"{where}: storage function must give finite water contents >= 0 kg/m3"])
        rising = np.flatnonzero(np.diff(w) > 1e-9 * max(1.0, float(w[0])))
        if rising.size:
            k = int(rising[0])
            raise StudyError(
                [
                    f"{where}: storage function is not monotone: w rises from {w[k]:.6g} to {w[k + 1]:.6g} kg/m3 "
                    f"as the relative humidity falls to {float(rh_from_suction(pc[k + 1])):.6g}"
                ]
            )
        self.w = w
        # vapour permeability at T_ref
        if self.vapour_permeability is not None:
            if not self.vapour_permeability >= 0:
                raise StudyError([f"{where}: vapour permeability must be >= 0 s, got {self.vapour_permeability}"])
            self.delta_ref = np.full_like(w, float(self.vapour_permeability))
        else:
            if self.resistance_factor is None:
                raise StudyError([f"{where}: needs a vapour resistance factor or a vapour permeability"])
            mu = self.resistance_factor
            mu = np.full_like(w, float(mu)) if np.isscalar(mu) else np.asarray(mu(w), dtype=float)
            bad = ~np.isfinite(mu) | (mu < 1.0)
            if np.any(bad):
                k = int(np.flatnonzero(bad)[0])
                raise StudyError(
                    [f"{where}: vapour resistance factor must be >= 1, got {mu[k]:.6g} at w = {w[k]:.6g} kg/m3"]
                )
            self.delta_ref = D_AIR / (R_V * T_REF) / mu
        self.kirchhoff = self._kirchhoff(pc, w, where)

    @property
    def capillary(self) -> bool:
        """Whether the material takes up liquid water (it has a liquid transport function)."""
        return self.liquid_conductivity is not None or self.moisture_diffusivity is not None

    def _kirchhoff(self, pc, w, where) -> np.ndarray:
        if not self.capillary:
            return np.zeros_like(w)
        if self.moisture_diffusivity is not None:
            # dPhi = K dpc = -D_w dw (trapezoid in w: exact for a constant D_w)
            d = np.asarray(self.moisture_diffusivity(w), dtype=float)
            inc = -0.5 * (d[1:] + d[:-1]) * np.diff(w)
        else:
            # dPhi = K pc du, integrated on a 8x finer grid of u
            fine = np.linspace(U_MIN, U_MAX, 8 * (N_TABLE - 1) + 1)
            pcf = np.exp(fine)
            g = np.asarray(self.liquid_conductivity(np.asarray(self.storage(pcf), dtype=float)), dtype=float) * pcf
            if not np.all(np.isfinite(g)) or np.any(g < 0):
                raise StudyError([f"{where}: liquid conductivity must be finite and >= 0 s"])
            seg = 0.5 * (g[1:] + g[:-1]) * np.diff(fine)
            inc = seg.reshape(N_TABLE - 1, 8).sum(axis=1)
        if not np.all(np.isfinite(inc)) or np.any(inc < 0):
            raise StudyError([f"{where}: liquid transport must be finite and >= 0"])
        return np.concatenate(([0.0], np.cumsum(inc)))

    # Python-side evaluation (the kernel has its own copies)
    def water_content(self, u):
        """``w`` [kg/m3] at the potential ``u = ln(pc)`` (table interpolation, as in the kernel: beyond the
        table the end segments extended, e.g. a condensing cell's ``pc`` below 1 Pa)."""
        u = np.asarray(u, dtype=float)
        w = np.interp(u, U_GRID, self.w)
        lo = (self.w[1] - self.w[0]) / DU
        hi = (self.w[-1] - self.w[-2]) / DU
        return w + np.minimum(u - U_MIN, 0.0) * lo + np.maximum(u - U_MAX, 0.0) * hi

    def water_content_from_rh(self, phi):
        """``w`` [kg/m3] at relative humidity ``phi`` (fraction)."""
        return self.water_content(potential_from_rh(phi))

    def potential_from_water_content(self, w):
        """The potential ``u`` at which the storage function gives ``w`` (inverse of the table)."""
        wt = self.w[::-1]
        ut = U_GRID[::-1]
        w = np.clip(np.asarray(w, dtype=float), wt[0], wt[-1])
        return np.interp(w, wt, ut)


def stack_tables(materials: list[HygricMaterial]) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The kernel's per-material arrays: ``w``, ``kirchhoff``, ``delta_ref`` (rows) and ``(lambda_dry,
    lambda_w, rho_c_dry, lambda_t)`` per material."""
    w = np.vstack([m.w for m in materials])
    kir = np.vstack([m.kirchhoff for m in materials])
    dlt = np.vstack([m.delta_ref for m in materials])
    thermal = np.array([[m.lambda_dry, m.lambda_w, m.rho_c_dry, m.lambda_t] for m in materials], dtype=float)
    return w, kir, dlt, thermal


# ==================================================== closed forms of the catalogue and study files
def kuenzel_storage(w_80: float, w_f: float) -> Callable:
    """Kuenzel's approximation of the storage function ``w = w_f (b - 1) phi / (b - phi)`` (Kuenzel 1995,
    the WUFI default when only ``w_80`` and the free saturation ``w_f`` are known); ``b`` from ``w(0.8) = w_80``.
    """
    b = 0.8 * (w_f - w_80) / (0.8 * w_f - w_80)

    def w(pc):
        phi = rh_from_suction(pc)
        return w_f * (b - 1.0) * phi / (b - phi)

    return w


def kuenzel_diffusivity(absorption: float, w_f: float) -> Callable:
    """Kuenzel's liquid diffusivity from the water absorption coefficient ``A`` [kg/(m2 s^0.5)]:
    ``D_w(w) = 3.8 (A / w_f)^2 1000^(w / w_f - 1)`` [m2/s] (Kuenzel 1995, eq. 2.27)."""

    def d(w):
        return 3.8 * (absorption / w_f) ** 2 * 1000.0 ** (np.asarray(w, dtype=float) / w_f - 1.0)

    return d


def table_storage(phi: list[float], w: list[float]) -> Callable:
    """A storage function tabulated against relative humidity, linear between points; 0 at phi = 0 and the
    last value up to saturation unless the table gives them."""
    p = np.asarray(phi, dtype=float)
    v = np.asarray(w, dtype=float)
    if p[0] > 0.0:
        p, v = np.concatenate(([0.0], p)), np.concatenate(([0.0], v))

    def f(pc):
        return np.interp(rh_from_suction(pc), p, v)

    return f


def table_diffusivity(w: list[float], d: list[float]) -> Callable:
    """A liquid diffusivity table ``D_w(w)`` [m2/s], log-linear between points, constant beyond the ends."""
    wt = np.asarray(w, dtype=float)
    ld = np.log(np.maximum(np.asarray(d, dtype=float), 1e-300))

    def f(x):
        return np.exp(np.interp(np.asarray(x, dtype=float), wt, ld))

    return f


#: The hygric keys of a layer table (study files, wall files, the material catalogue).
HYGRIC_KEYS = (
    "moisture_storage",
    "liquid_transport",
    "vapour_resistance_factor",
    "vapour_resistance_shape",
    "moisture_conductivity_coefficient",
    "sorption_scale",
    "liquid_transport_scale",
)


def saturation_content(storage: dict) -> float:
    """The water content at capillary saturation [kg/m3] of a ``moisture_storage`` table."""
    form = storage.get("form", "table")
    if form == "kuenzel":
        return float(storage["w_f"])
    if form == "van_genuchten":
        return float(storage["w_sat"])
    return float(np.max(storage["w"]))  # table, suction_table


def suction_table_storage(log10_pc: list[float], w: list[float]) -> Callable:
    """A storage function tabulated against ``log10(pc)`` (DELPHIN's ``Theta_l(pC)``), linear between points,
    constant beyond the ends."""
    x = np.asarray(log10_pc, dtype=float)
    v = np.asarray(w, dtype=float)

    def f(pc):
        return np.interp(np.log10(np.asarray(pc, dtype=float)), x, v)

    return f


def conductivity_table(w: list[float], log10_k: list[float]) -> Callable:
    """A liquid conductivity table ``log10 K_l(w)`` [s] (DELPHIN's ``lgKl``), linear in the logarithm."""
    wt = np.asarray(w, dtype=float)
    lk = np.asarray(log10_k, dtype=float)

    def f(x):
        return 10.0 ** np.interp(np.asarray(x, dtype=float), wt, lk)

    return f


def storage_function(storage: dict, where: str) -> Callable:
    """The callable ``w(pc)`` of a ``moisture_storage`` table (checked by :class:`HygricMaterial`)."""
    form = storage.get("form", "table")
    _check_table(storage, "moisture_storage", STORAGE_FORMS, where)
    try:
        if form == "kuenzel":
            w_80 = _water(storage, "w_80", f"{where}.moisture_storage")
            w_f = _water(storage, "w_f", f"{where}.moisture_storage")
            if not w_f > 0.0:
                raise StudyError([f"{where}.moisture_storage.w_f: must be > 0 kg/m3, got {w_f}"])
            if not (0.0 <= w_80 < 0.8 * w_f):
                raise StudyError(
                    [f"{where}.moisture_storage.w_80: needs 0 <= w_80 < 0.8 w_f, got w_80 = {w_80}, w_f = {w_f}"]
                )
            return kuenzel_storage(w_80, w_f)
        if form == "van_genuchten":
            modes = [(float(k), float(a), float(n), 1.0 - 1.0 / float(n)) for k, a, n in storage["modes"]]
            return van_genuchten(_water(storage, "w_sat", f"{where}.moisture_storage"), modes)
        if form == "table":
            phi = [float(v) for v in storage["phi"]]
            w = [float(v) for v in storage["w"]]
            if len(phi) != len(w) or len(phi) < 2:
                raise StudyError([f"{where}.moisture_storage: phi and w need the same length (>= 2)"])
            if np.any(np.diff(phi) <= 0) or phi[0] < 0 or phi[-1] > 1:
                raise StudyError([f"{where}.moisture_storage: phi must rise strictly within 0..1"])
            if np.any(np.diff(w) < 0):
                k = int(np.flatnonzero(np.diff(w) < 0)[0])
                raise StudyError(
                    [
                        f"{where}.moisture_storage: storage function is not monotone: w falls from {w[k]:g} to "
                        f"{w[k + 1]:g} kg/m3 as phi rises from {phi[k]:g} to {phi[k + 1]:g}"
                    ]
                )
            return table_storage(phi, w)
        if form == "suction_table":
            x = [float(v) for v in storage["log10_pc"]]
            w = [float(v) for v in storage["w"]]
            if len(x) != len(w) or len(x) < 2 or np.any(np.diff(x) <= 0):
                raise StudyError([f"{where}.moisture_storage: log10_pc must rise strictly, one w per point (>= 2)"])
            if np.any(np.diff(w) > 0):
                k = int(np.flatnonzero(np.diff(w) > 0)[0])
                raise StudyError(
                    [
                        f"{where}.moisture_storage: storage function is not monotone: w rises from {w[k]:g} to "
                        f"{w[k + 1]:g} kg/m3 as log10(pc) rises from {x[k]:g} to {x[k + 1]:g}"
                    ]
                )
            return suction_table_storage(x, w)
    except (KeyError, TypeError, ValueError, OverflowError, ZeroDivisionError) as exc:
        raise StudyError([f"{where}.moisture_storage: form {form!r} is incomplete or malformed ({exc})"]) from None
    raise StudyError([f"{where}.moisture_storage.form: unknown form {form!r} ({', '.join(STORAGE_FORMS)})"])


#: the largest water content a porous material can hold [kg/m3]: its pores full of liquid water
MAX_WATER_CONTENT = 1000.0


def _water(table: dict, key: str, where: str) -> float:
    """``table[key]``, a water content [kg/m3] in 0..:data:`MAX_WATER_CONTENT` (KeyError when absent)."""
    v = table[key]
    if isinstance(v, bool) or not isinstance(v, int | float):
        raise StudyError([f"{where}.{key}: must be a water content [kg/m3] (a number), got {clip(str(v), 40)}"])
    try:
        x = float(v)
    except (TypeError, ValueError, OverflowError):
        raise StudyError([f"{where}.{key}: must be a water content [kg/m3], got {str(v)[:40]}"]) from None
    if not 0.0 <= x <= MAX_WATER_CONTENT:
        raise StudyError([f"{where}.{key}: must lie in 0..{MAX_WATER_CONTENT:g} kg/m3, got {x:g}"])
    return x


#: the forms of a ``moisture_storage`` table
STORAGE_FORMS = ("kuenzel", "van_genuchten", "table", "suction_table")
#: the keys each form of a ``moisture_storage`` or ``liquid_transport`` table takes (``form`` besides)
FORM_KEYS = {
    ("moisture_storage", "kuenzel"): ("w_80", "w_f"),
    ("moisture_storage", "van_genuchten"): ("w_sat", "modes"),
    ("moisture_storage", "table"): ("phi", "w"),
    ("moisture_storage", "suction_table"): ("log10_pc", "w"),
    ("liquid_transport", "kuenzel"): ("absorption",),
    ("liquid_transport", "exp_polynomial"): ("coefficients", "shift", "scale"),
    ("liquid_transport", "table"): ("w", "diffusivity"),
    ("liquid_transport", "conductivity_table"): ("w", "log10_k"),
}


def _numeric(v) -> bool:
    """A number, or a list (of lists) of numbers, as a hygric table's entries are."""
    if isinstance(v, list):
        return all(_numeric(x) for x in v)
    return isinstance(v, int | float) and not isinstance(v, bool)


def _finite(v) -> bool:
    """Whether every entry of a number or a list (of lists) of numbers is a finite float."""
    if isinstance(v, list):
        return all(_finite(x) for x in v)
    try:
        return math.isfinite(float(v))
    except OverflowError:
        return False


def _check_table(table: dict, kind: str, forms: tuple[str, ...], where: str) -> None:
    """Every problem of a ``kind`` table's shape at once: its ``form`` (a name of ``forms``), keys that form does
    not take (a misspelt key is never ignored) and water contents outside 0..:data:`MAX_WATER_CONTENT`."""
    problems = []
    form = table.get("form", "table")
    if not isinstance(form, str):
        problems.append(f"{where}.{kind}.form: must be a name ({', '.join(forms)})")
    else:
        valid = ("form", *FORM_KEYS.get((kind, form), ()))
        for key in table:
            if key not in valid:
                hint = closest(str(key), valid)
                problems.append(
                    f"{where}.{kind}.{clip(str(key), 40)}: unknown key for form {form!r}"
                    + (f"; {hint}" if hint else "")
                )
    bad = set()
    for key, v in table.items():
        if key == "form":
            continue
        if not _numeric(v):
            problems.append(f"{where}.{kind}.{clip(str(key), 40)}: must be a number or a list of numbers")
            bad.add(key)
        elif not _finite(v):
            problems.append(f"{where}.{kind}.{clip(str(key), 40)}: must be finite numbers (no nan, inf or overflow)")
            bad.add(key)
    for key in ("w_80", "w_f", "w_sat"):
        if key in table and key not in bad:
            try:
                _water(table, key, f"{where}.{kind}")
            except StudyError as exc:
                problems.extend(exc.problems)
    if problems:
        raise StudyError(problems)


#: the largest water absorption coefficient A taken [kg/(m2 s^0.5)] (the most absorbent building materials, e.g.
#: calcium silicate boards, are below 2)
MAX_ABSORPTION = 10.0
#: the forms of a ``liquid_transport`` table
LIQUID_FORMS = ("kuenzel", "exp_polynomial", "table", "conductivity_table")


def liquid_transport_functions(lt: dict, where: str, w_sat: float, scale: float = 1.0, lscale: float = 1.0):
    """``(k_l, d_w)`` of a ``liquid_transport`` table: the liquid conductivity K_l(w) [s] or the diffusivity
    D_w(w) [m2/s] (the other None; both None for a zero absorption coefficient), ``scale`` the sorption scale and
    ``lscale`` the liquid transport scale."""
    form = lt.get("form", "table")
    _check_table(lt, "liquid_transport", LIQUID_FORMS, where)
    k_l = d_w = None
    try:
        if form == "kuenzel":
            a = float(lt["absorption"])
            if not 0.0 <= a <= MAX_ABSORPTION:
                raise StudyError(
                    [f"{where}.liquid_transport.absorption: must lie in 0..{MAX_ABSORPTION:g} kg/(m2 s^0.5), got {a:g}"]
                )
            if a > 0:
                d0 = kuenzel_diffusivity(a, scale * w_sat)
                d_w = lambda w: lscale * d0(w)  # noqa: E731
        elif form == "exp_polynomial":
            k0 = exp_polynomial(
                [float(c) for c in lt["coefficients"]], float(lt.get("shift", 0.0)), float(lt.get("scale", 1.0))
            )
            k_l = lambda w: lscale * k0(np.asarray(w, dtype=float) / scale)  # noqa: E731
        elif form == "table":
            d0 = table_diffusivity(lt["w"], lt["diffusivity"])
            d_w = lambda w: lscale * d0(w)  # noqa: E731
        elif form == "conductivity_table":
            k0 = conductivity_table(lt["w"], lt["log10_k"])
            k_l = lambda w: lscale * k0(np.asarray(w, dtype=float) / scale)  # noqa: E731
        else:
            raise StudyError([f"{where}.liquid_transport.form: unknown form {form!r} ({', '.join(LIQUID_FORMS)})"])
    except (KeyError, TypeError, ValueError, OverflowError) as exc:
        raise StudyError([f"{where}.liquid_transport: form {form!r} is incomplete or malformed ({exc})"]) from None
    return k_l, d_w


def hygric_material(
    name: str,
    keys: dict,
    *,
    conductivity: float,
    density: float,
    specific_heat: float,
    where: str | None = None,
) -> HygricMaterial:
    """A :class:`HygricMaterial` from a layer's thermal properties and its hygric keys (:data:`HYGRIC_KEYS`).

    ``keys``: ``moisture_storage`` (a table ``{form = "kuenzel", w_80, w_f}``, ``{form = "van_genuchten",
    w_sat, modes = [[k, a (1/Pa), n], ...]}`` or ``{phi = [...], w = [...]}``), ``vapour_resistance_factor``
    (mu, >= 1; with ``vapour_resistance_shape`` p the HAMSTAD form ``mu / f(w)``), ``liquid_transport``
    (``{form = "kuenzel", absorption}`` A [kg/(m2 s^0.5)], ``{form = "exp_polynomial", coefficients,
    shift, scale}`` K_l(w) [s], ``{w = [...], diffusivity = [...]}`` D_w [m2/s]; absent: none),
    ``moisture_conductivity_coefficient`` b (``lambda = lambda_dry (1 + b w / density)``, ISO 10456's f_u),
    ``sorption_scale`` and ``liquid_transport_scale`` (multipliers, 1 by default).
    """
    where = where or f"material {name!r}"
    for key in ("moisture_storage", "vapour_resistance_factor"):
        if keys.get(key) is None:
            raise StudyError(
                [f'{where}: missing hygric key {key!r} (give it, a catalogue material = "..." or a hygric_file)']
            )
    storage = dict(keys["moisture_storage"])
    base = storage_function(storage, where)
    w_sat = saturation_content(storage)
    scale = float(keys.get("sorption_scale", 1.0))
    if not scale > 0:
        raise StudyError([f"{where}.sorption_scale: must be > 0, got {scale}"])
    store = base if scale == 1.0 else (lambda pc: scale * base(pc))
    mu = float(keys["vapour_resistance_factor"])
    if not mu >= 1.0:
        raise StudyError([f"{where}.vapour_resistance_factor: must be >= 1, got {mu:g}"])
    p = keys.get("vapour_resistance_shape")
    resistance = mu if p is None else resistance_factor_hamstad(mu, scale * w_sat, float(p))
    lt = keys.get("liquid_transport")
    lscale = float(keys.get("liquid_transport_scale", 1.0))
    if not lscale >= 0:
        raise StudyError([f"{where}.liquid_transport_scale: must be >= 0, got {lscale}"])
    k_l = d_w = None
    if lt:
        k_l, d_w = liquid_transport_functions(dict(lt), where, w_sat, scale, lscale)
    b = float(keys.get("moisture_conductivity_coefficient", 0.0))
    with np.errstate(all="ignore"):  # a form that gives nan or inf is refused by HygricMaterial's checks
        return HygricMaterial(
            name=name,
            storage=store,
            lambda_dry=float(conductivity),
            lambda_w=float(conductivity) * b / float(density),
            rho_c_dry=float(density) * float(specific_heat),
            resistance_factor=resistance,
            liquid_conductivity=k_l,
            moisture_diffusivity=d_w,
        )

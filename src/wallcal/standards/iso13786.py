"""ISO 13786:2017 dynamic thermal characteristics, and the exact periodic solution.

The heat transfer matrix method of ISO 13786:2017 (clause 6 and Annex A):
for a sinusoidal excitation of period T, the complex amplitudes of temperature
theta and heat flow density q on the two sides of a homogeneous layer are
related by

    [theta_2, q_2]^T = Z [theta_1, q_1]^T,

    Z11 = Z22 = cosh(xi) cos(xi) + i sinh(xi) sin(xi)
    Z12 = -delta / (2 lambda) {sinh(xi) cos(xi) + cosh(xi) sin(xi)
                               + i [cosh(xi) sin(xi) - sinh(xi) cos(xi)]}
    Z21 = -lambda / delta {sinh(xi) cos(xi) - cosh(xi) sin(xi)
                           + i [sinh(xi) cos(xi) + cosh(xi) sin(xi)]}

with the periodic penetration depth delta = sqrt(lambda T / (pi rho c)) and
xi = d / delta. These are cosh(k d), -sinh(k d) / (lambda k) and
-lambda k sinh(k d) with k = (1 + i) / delta, the form used here. A no-mass
layer or surface of resistance R has Z = [[1, -R], [0, 1]]. The matrix of a
component is the product Z = Z_s2 Z_N ... Z_1 Z_s1, side 1 being the interior
(ISO numbering: layer 1 faces the interior). In ISO's matrix, q is positive
from side 1 to side 2 (interior -> exterior).

From Z (with surface resistances):

- periodic thermal transmittance Y12 = -1 / Z12 (= Y21 since det Z = 1),
- internal and external thermal admittances Y11 = -Z11 / Z12, Y22 = -Z22 / Z12,
- decrement factor f = |Y12| / U,
- time shifts Delta t = T / (2 pi) arg(Y) (the standard's definition).

wallcal reports the **time shift of Y12 as a positive lag** [h]: how long the
interior heat flow density response lags the exterior temperature excitation,
i.e. ``-T/(2 pi) arg(Y12)``, with the phase unwrapped continuously from zero
frequency (so a lag beyond T/2 is reported as such, not wrapped to a lead).
The admittance time shifts are reported as positive **leads** [h],
``T/(2 pi) arg(Y11)`` and ``T/(2 pi) arg(Y22)`` (heat flow at a surface leads
the temperature swing on that surface).

Areal heat capacities kappa_1 = T/(2 pi) |(Z11 - 1) / Z12| and
kappa_2 = T/(2 pi) |(Z22 - 1) / Z12| are computed from the surface-to-surface
matrix (no surface resistances), see :func:`dynamic_characteristics`.

:func:`periodic_profile` gives the exact solution inside the wall for imposed
sinusoidal surface temperatures (no surface resistances), in wallcal's
conventions (depth from the exterior face, q positive towards the interior).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from ..errors import StudyError
from .iso6946 import resolve_layers, surface_resistances

DAY_S = 86400.0

#: Largest total xi = sum(d / delta) :func:`periodic_profile` accepts (cosh overflows near 710).
MAX_XI = 300.0


def _check_period(period_s) -> float:
    p = float(period_s)
    if not np.isfinite(p) or p <= 0:
        raise StudyError([f"period_s: must be a finite period > 0 s, got {period_s!r}"])
    return p


def penetration_depth(conductivity, density, specific_heat, period_s: float = DAY_S):
    """Periodic penetration depth delta = sqrt(lambda T / (pi rho c)) (ISO 13786:2017 eq. A.1).

    Parameters
    ----------
    conductivity : float or array
        lambda [W/(m K)].
    density : float or array
        rho [kg/m3].
    specific_heat : float or array
        c [J/(kg K)].
    period_s : float
        Period T [s].

    Returns
    -------
    float or array
        delta [m].
    """
    period_s = _check_period(period_s)
    out = np.sqrt(
        np.asarray(conductivity, float)
        * period_s
        / (np.pi * np.asarray(density, float) * np.asarray(specific_heat, float))
    )
    return float(out) if np.ndim(out) == 0 else out


def layer_matrix(thickness_m, conductivity, density, specific_heat, period_s: float = DAY_S) -> np.ndarray:
    """Heat transfer matrix of a homogeneous layer (ISO 13786:2017 eq. A.2 to A.5).

    Parameters
    ----------
    thickness_m : float or array
        d [m].
    conductivity, density, specific_heat : float or array
        lambda [W/(m K)], rho [kg/m3], c [J/(kg K)].
    period_s : float
        T [s].

    Returns
    -------
    ndarray, complex, shape (..., 2, 2)
        Z with Z12 in [m2K/W] and Z21 in [W/(m2K)].
    """
    lam = np.asarray(conductivity, float)
    delta = penetration_depth(lam, density, specific_heat, period_s)
    xi = np.asarray(thickness_m, float) / delta
    ch, sh, c, s = np.cosh(xi), np.sinh(xi), np.cos(xi), np.sin(xi)
    z = np.empty(np.broadcast(xi, lam).shape + (2, 2), dtype=complex)
    z[..., 0, 0] = ch * c + 1j * sh * s
    z[..., 1, 1] = z[..., 0, 0]
    z[..., 0, 1] = -delta / (2.0 * lam) * ((sh * c + ch * s) + 1j * (ch * s - sh * c))
    z[..., 1, 0] = -lam / delta * ((sh * c - ch * s) + 1j * (sh * c + ch * s))
    return z


def resistance_matrix(resistance) -> np.ndarray:
    """Matrix [[1, -R], [0, 1]] of a no-mass layer or surface of resistance R [m2K/W] (ISO 13786 eq. 5)."""
    z = np.zeros((2, 2), dtype=complex)
    z[0, 0] = z[1, 1] = 1.0
    z[0, 1] = -float(resistance)
    return z


def _layer_list(wall, air_layers, direction):
    layers, cut = resolve_layers(wall, air_layers=air_layers, direction=direction)
    problems = []
    for layer in layers:
        if layer.is_massless:
            if not np.isfinite(layer.thermal_resistance) or layer.thermal_resistance < 0:
                problems.append(f"wall.layers[{layer.id!r}].thermal_resistance: must be >= 0")
            continue
        for name in ("conductivity", "density", "specific_heat"):
            v = getattr(layer, name)
            if v is None or not np.isfinite(v) or v <= 0:
                problems.append(f"wall.layers[{layer.id!r}].{name}: must be > 0 for ISO 13786, got {v!r}")
        if layer.thickness <= 0:
            problems.append(f"wall.layers[{layer.id!r}].thickness: must be > 0, got {layer.thickness!r}")
    if problems:
        raise StudyError(problems)
    return layers, cut


def wall_matrix(
    wall,
    period_s: float = DAY_S,
    *,
    rsi: float | None = 0.13,
    rse: float | None = 0.04,
    air_layers: Mapping[str, str] | None = None,
    direction: str = "horizontal",
) -> np.ndarray:
    """Heat transfer matrix of a wall, Z = Z_s2 Z_N ... Z_1 Z_s1 (ISO 13786:2017 eq. 6).

    Side 1 is the interior, side 2 the exterior; q positive from interior to
    exterior (ISO convention). With wallcal's exterior-first layer order the
    product reads Z_se Z(layer 0) C_0 Z(layer 1) ... Z(last layer) Z_si, where C_k
    is the contact resistance of layer k.

    Parameters
    ----------
    wall : Wall
    period_s : float
        T [s].
    rsi, rse : float or None
        Surface resistances [m2K/W]; 0 or None for the surface-to-surface matrix.
    air_layers, direction
        ISO 6946 air-layer handling (:func:`wallcal.standards.iso6946.find_air_layers`).
        A well-ventilated air layer cuts the wall; then Rse is taken equal to Rsi.

    Returns
    -------
    ndarray, complex, shape (2, 2)
    """
    period_s = _check_period(period_s)
    layers, cut = _layer_list(wall, air_layers, direction)
    rsi = float(rsi or 0.0)
    rse = float(rse or 0.0)
    if cut and rse:
        rse = rsi
    z = resistance_matrix(rse)
    for i, layer in enumerate(layers):
        if layer.is_massless:
            z = z @ resistance_matrix(layer.thermal_resistance)
        else:
            z = z @ layer_matrix(layer.thickness, layer.conductivity, layer.density, layer.specific_heat, period_s)
        if layer.contact_resistance and i < len(layers) - 1:
            z = z @ resistance_matrix(layer.contact_resistance)
    return z @ resistance_matrix(rsi)


def _unwrapped_phase(wall_fn, period_s: float, xi_total: float) -> float:
    """arg(f(T)) unwrapped continuously from zero frequency (period -> infinity).

    The period goes from 1e8 T down to T in log steps small enough that xi (~ T^-1/2)
    changes by < 0.3 per step, so the phase cannot jump by pi between steps.
    """
    n = int(max(200, np.ceil(8 * np.log(10) * max(xi_total, 1e-9) / 0.6)))
    periods = period_s * np.logspace(8, 0, n)  # from quasi-steady to the requested period
    vals = np.array([wall_fn(p) for p in periods])
    return float(np.unwrap(np.angle(vals))[-1])


@dataclass(frozen=True)
class DynamicCharacteristics:
    """ISO 13786:2017 dynamic thermal characteristics of a wall.

    Attributes
    ----------
    period_s : float
        T [s].
    Z : ndarray (2, 2) complex
        Heat transfer matrix with surface resistances (side 1 interior).
    Z_surface : ndarray (2, 2) complex
        Surface-to-surface heat transfer matrix.
    Y11, Y22 : complex
        Internal and external thermal admittance [W/(m2K)].
    Y12, Y21 : complex
        Periodic thermal transmittance [W/(m2K)] (equal: reciprocity).
    u_value : float
        Steady-state U = 1 / (Rsi + R + Rse) [W/(m2K)].
    decrement_factor : float
        f = |Y12| / U [-].
    time_shift_h : float
        Lag of the interior heat flow behind the exterior temperature [h], positive,
        = -T/(2 pi) arg(Y12) unwrapped from zero frequency.
    admittance_time_lead_interior_h, admittance_time_lead_exterior_h : float
        T/(2 pi) arg(Y11), T/(2 pi) arg(Y22) [h]: lead of the surface heat flow
        over the surface temperature.
    kappa1, kappa2 : float
        Internal / external areal heat capacity [J/(m2K)] from the surface-to-surface matrix.
    kappa1_with_surfaces, kappa2_with_surfaces : float
        The same formulas applied to Z (with surface resistances), as some tools report.
    penetration_depths_m, xi : dict
        Layer id -> delta [m] and xi = d / delta [-] (massive layers only).
    """

    period_s: float
    Z: np.ndarray = field(repr=False)
    Z_surface: np.ndarray = field(repr=False)
    Y11: complex
    Y12: complex
    Y21: complex
    Y22: complex
    u_value: float
    decrement_factor: float
    time_shift_h: float
    admittance_time_lead_interior_h: float
    admittance_time_lead_exterior_h: float
    kappa1: float
    kappa2: float
    kappa1_with_surfaces: float
    kappa2_with_surfaces: float
    penetration_depths_m: dict
    xi: dict

    def summary(self) -> str:
        """One block of text with the main figures."""
        return (
            f"period {self.period_s / 3600:g} h: U = {self.u_value:.4f} W/(m2K), "
            f"|Y12| = {abs(self.Y12):.5f} W/(m2K), f = {self.decrement_factor:.4f}, "
            f"time shift (lag) = {self.time_shift_h:.2f} h, |Y11| = {abs(self.Y11):.3f} W/(m2K) "
            f"(lead {self.admittance_time_lead_interior_h:.2f} h), |Y22| = {abs(self.Y22):.3f} W/(m2K) "
            f"(lead {self.admittance_time_lead_exterior_h:.2f} h), "
            f"kappa1 = {self.kappa1 / 1000:.2f} kJ/(m2K), kappa2 = {self.kappa2 / 1000:.2f} kJ/(m2K)"
        )


def dynamic_characteristics(
    wall,
    period_s: float = DAY_S,
    *,
    rsi: float | None = None,
    rse: float | None = None,
    air_layers: Mapping[str, str] | None = None,
    direction: str = "horizontal",
) -> DynamicCharacteristics:
    """ISO 13786:2017 characteristics of a wall (clause 6: eq. 7 to 12; Annex A).

    Parameters
    ----------
    wall : Wall
        Layers exterior first; contact resistances included as no-mass layers.
    period_s : float
        T [s], default 86400.
    rsi, rse : float, optional
        Surface resistances [m2K/W]; default ISO 6946 values for ``direction``
        (0.13 and 0.04 for walls).
    air_layers, direction
        ISO 6946 air-layer handling; see :mod:`wallcal.standards.iso6946`.

    Returns
    -------
    DynamicCharacteristics
    """
    period_s = _check_period(period_s)
    rsi_d, rse_d = surface_resistances(direction)
    rsi = rsi_d if rsi is None else float(rsi)
    rse = rse_d if rse is None else float(rse)
    layers, cut = _layer_list(wall, air_layers, direction)
    rse_used = rsi if cut else rse

    def z_full(p):
        return wall_matrix(wall, p, rsi=rsi, rse=rse, air_layers=air_layers, direction=direction)

    z = z_full(period_s)
    zs = wall_matrix(wall, period_s, rsi=0.0, rse=0.0, air_layers=air_layers, direction=direction)
    y12 = -1.0 / z[0, 1]
    y21 = -(z[0, 0] * z[1, 1] - z[0, 1] * z[1, 0]) / z[0, 1]  # general form; = Y12 as det Z = 1
    y11 = -z[0, 0] / z[0, 1]
    y22 = -z[1, 1] / z[0, 1]
    r_total = (
        rsi
        + rse_used
        + sum(
            (layer.thermal_resistance if layer.is_massless else layer.thickness / layer.conductivity)
            + (layer.contact_resistance if i < len(layers) - 1 else 0.0)
            for i, layer in enumerate(layers)
        )
    )
    u = 1.0 / r_total
    # lag of interior heat flow behind exterior temperature: phase of -Z12 (= 1/Y12) unwrapped from 0 Hz
    xi_total = sum(
        layer.thickness / penetration_depth(layer.conductivity, layer.density, layer.specific_heat, period_s)
        for layer in layers
        if not layer.is_massless
    )
    lag_rad = _unwrapped_phase(lambda p: -z_full(p)[0, 1], period_s, xi_total)
    w = period_s / (2.0 * np.pi)
    deltas = {
        layer.id: penetration_depth(layer.conductivity, layer.density, layer.specific_heat, period_s)
        for layer in layers
        if not layer.is_massless
    }
    thick = {layer.id: layer.thickness for layer in layers}
    return DynamicCharacteristics(
        period_s=period_s,
        Z=z,
        Z_surface=zs,
        Y11=complex(y11),
        Y12=complex(y12),
        Y21=complex(y21),
        Y22=complex(y22),
        u_value=u,
        decrement_factor=float(abs(y12) / u),
        time_shift_h=lag_rad * w / 3600.0,
        admittance_time_lead_interior_h=float(np.angle(y11)) * w / 3600.0,
        admittance_time_lead_exterior_h=float(np.angle(y22)) * w / 3600.0,
        kappa1=float(w * abs((zs[0, 0] - 1.0) / zs[0, 1])),
        kappa2=float(w * abs((zs[1, 1] - 1.0) / zs[0, 1])),
        kappa1_with_surfaces=float(w * abs((z[0, 0] - 1.0) / z[0, 1])),
        kappa2_with_surfaces=float(w * abs((z[1, 1] - 1.0) / z[0, 1])),
        penetration_depths_m=deltas,
        xi={k: thick[k] / d for k, d in deltas.items()},
    )


# --------------------------------------------------------------------------- exact periodic profile


@dataclass(frozen=True)
class PeriodicProfile:
    """Exact periodic solution for imposed surface temperatures.

    The physical fields are ``Re(A exp(i 2 pi t / T))`` for each complex amplitude A.

    Attributes
    ----------
    period_s : float
        T [s].
    depths_m : ndarray
        Depths from the exterior face [m].
    temperature : ndarray complex
        Temperature amplitudes at ``depths_m`` [K].
    heat_flux : ndarray complex
        Heat flux density amplitudes at ``depths_m`` [W/m2], positive towards the interior.
    q_exterior, q_interior : complex
        Heat flux density amplitudes at the exterior (x = 0) and interior (x = L)
        faces [W/m2], positive towards the interior.
    """

    period_s: float
    depths_m: np.ndarray
    temperature: np.ndarray
    heat_flux: np.ndarray
    q_exterior: complex
    q_interior: complex

    def at_times(self, times_s) -> np.ndarray:
        """Periodic part of the temperatures, Re(theta e^{i 2 pi t / T}) [K], shape (n_times, n_depths).

        Parameters
        ----------
        times_s : array
            Times [s].
        """
        t = np.asarray(times_s, float)[:, None]
        return np.real(self.temperature[None, :] * np.exp(2j * np.pi * t / self.period_s))


def _segments(wall):
    """Exterior-to-interior pieces: ('mass', x0, x1, lam, k) | ('lin', x0, x1, R) | ('jump', x, R)."""
    segs = []
    x = 0.0
    n = len(wall.layers)
    for i, layer in enumerate(wall.layers):
        x1 = x + layer.thickness
        if layer.is_massless:
            if layer.thickness > 0:
                segs.append(("lin", x, x1, float(layer.thermal_resistance)))
            else:
                segs.append(("jump", x, float(layer.thermal_resistance)))
        else:
            segs.append(("mass", x, x1, layer))
        if layer.contact_resistance and i < n - 1:
            segs.append(("jump", x1, float(layer.contact_resistance)))
        x = x1
    return segs, x


def _check_profile_wall(wall):
    problems = []
    if not wall.layers:
        problems.append("wall.layers: the wall has no layers")
    for layer in wall.layers:
        if layer.is_massless:
            r, d = layer.thermal_resistance, layer.thickness
            if not np.isfinite(r) or r < 0 or d < 0:
                problems.append(
                    f"wall.layers[{layer.id!r}]: no-mass layer needs thermal_resistance >= 0 and thickness >= 0, "
                    f"got {r!r} m2K/W and {d!r} m"
                )
            continue
        if layer.thickness <= 0:
            problems.append(f"wall.layers[{layer.id!r}].thickness: must be > 0, got {layer.thickness!r}")
        for name in ("conductivity", "density", "specific_heat"):
            v = getattr(layer, name)
            if v is None or not np.isfinite(v) or v <= 0:
                problems.append(f"wall.layers[{layer.id!r}].{name}: must be > 0, got {v!r}")
    if problems:
        raise StudyError(problems)


def periodic_profile(
    wall,
    period_s: float,
    t_ext_amplitude: complex,
    t_int_amplitude: complex,
    depths_m,
    *,
    interface_side: str = "mean",
) -> PeriodicProfile:
    """Exact periodic temperatures and heat fluxes in a wall with imposed surface temperatures.

    Solves rho c dT/dt = d/dx(lambda dT/dx) in each layer (constant properties at
    each layer's reference temperature) with T(0, t) = Re(theta_e e^{i w t}) on the
    exterior face and T(L, t) = Re(theta_i e^{i w t}) on the interior face
    (Dirichlet, no surface resistances), w = 2 pi / T, in the periodic regime. In a
    layer the solution is theta(x) = A cosh(k x) + B sinh(k x), k = (1 + i) / delta,
    i.e. the transfer-matrix relation of ISO 13786:2017 Annex A (eq. A.2-A.5), here
    written with x increasing inwards and q positive towards the interior.

    Numerically it superposes the response to each face, each integrated from the
    opposite (zero-temperature) face towards the excited one, so that only growing
    exponentials are formed: exact to rounding for any xi up to :data:`MAX_XI`.

    No-mass layers of thickness > 0 have their resistance spread uniformly over
    their thickness (temperature linear in depth); a no-mass layer of zero
    thickness or a contact resistance is a temperature jump at one depth.

    Parameters
    ----------
    wall : Wall
        Layers exterior first.
    period_s : float
        T [s].
    t_ext_amplitude, t_int_amplitude : complex
        Complex amplitudes theta_e, theta_i [K] of the exterior (x = 0) and interior
        (x = L) surface temperatures.
    depths_m : float or array
        Depths from the exterior face [m], 0 <= x <= L.
    interface_side : {"mean", "exterior", "interior"}
        At a depth carrying a temperature jump: which side's temperature
        (``"mean"`` matches :class:`wallcal.wall.Probe` with ``side=None``).

    Returns
    -------
    PeriodicProfile
    """
    period_s = _check_period(period_s)
    if interface_side not in ("mean", "exterior", "interior"):
        raise StudyError([f"interface_side: must be 'mean', 'exterior' or 'interior', got {interface_side!r}"])
    _check_profile_wall(wall)
    segs, length = _segments(wall)
    x = np.atleast_1d(np.asarray(depths_m, dtype=float))
    if x.ndim != 1 or np.any(~np.isfinite(x)) or np.any(x < -1e-12 * length) or np.any(x > length * (1 + 1e-12)):
        raise StudyError([f"depths_m: depths must lie in [0, {length:g}] m, got {np.asarray(depths_m)!r}"])
    x = np.clip(x, 0.0, length)
    ks = {}
    xi_total = 0.0
    for seg in segs:
        if seg[0] == "mass":
            layer = seg[3]
            delta = penetration_depth(layer.conductivity, layer.density, layer.specific_heat, period_s)
            ks[id(seg)] = (1.0 + 1.0j) / delta
            xi_total += layer.thickness / delta
    if xi_total > MAX_XI:
        raise StudyError(
            [
                f"period_s: the wall is {xi_total:.0f} penetration depths thick at this period "
                f"(limit {MAX_XI:g}); "
                "the response is below rounding, use a longer period"
            ]
        )

    def forward(seg, state, dx):
        """State (theta, q) at distance dx inwards of `state` within seg."""
        th, q = state
        kind = seg[0]
        if kind == "mass":
            lam = seg[3].conductivity
            k = ks[id(seg)]
            ch, sh = np.cosh(k * dx), np.sinh(k * dx)
            return ch * th - sh / (lam * k) * q, -lam * k * sh * th + ch * q
        if kind == "lin":
            r = seg[3] * dx / (seg[2] - seg[1])
            return th - r * q, q + 0 * dx
        return th - seg[2] * q, q  # jump

    def backward(seg, state, dx):
        """State at distance dx outwards of `state` within seg."""
        th, q = state
        kind = seg[0]
        if kind == "mass":
            lam = seg[3].conductivity
            k = ks[id(seg)]
            ch, sh = np.cosh(k * dx), np.sinh(k * dx)
            return ch * th + sh / (lam * k) * q, lam * k * sh * th + ch * q
        if kind == "lin":
            r = seg[3] * dx / (seg[2] - seg[1])
            return th + r * q, q + 0 * dx
        return th + seg[2] * q, q

    # states at the exterior side of every segment (forward pass, h: theta(0)=0, q(0)=1)
    h_in = []
    state = (0.0 + 0j, 1.0 + 0j)
    for seg in segs:
        h_in.append(state)
        length_seg = (seg[2] - seg[1]) if seg[0] != "jump" else 0.0
        state = forward(seg, state, length_seg)
    h_end = state
    # states at the interior side of every segment (backward pass, g: theta(L)=0, q(L)=1)
    g_out = [None] * len(segs)
    state = (0.0 + 0j, 1.0 + 0j)
    for j in range(len(segs) - 1, -1, -1):
        g_out[j] = state
        seg = segs[j]
        length_seg = (seg[2] - seg[1]) if seg[0] != "jump" else 0.0
        state = backward(seg, state, length_seg)
    g_start = state
    m12 = h_end[0]  # theta(L) of h = Z12 of the exterior->interior matrix
    g0 = g_start[0]  # theta(0) of g = -Z12
    th_e, th_i = complex(t_ext_amplitude), complex(t_int_amplitude)

    def evaluate(order):
        theta = np.full(x.shape, np.nan + 0j)
        flux = np.full(x.shape, np.nan + 0j)
        done = np.zeros(x.shape, bool)
        for j in order:
            seg = segs[j]
            if seg[0] == "jump":
                continue
            a, b = seg[1], seg[2]
            m = (~done) & (x >= a) & (x <= b)
            if not np.any(m):
                continue
            h_th, h_q = forward(seg, h_in[j], x[m] - a)
            g_th, g_q = backward(seg, g_out[j], b - x[m])
            theta[m] = th_i * h_th / m12 + th_e * g_th / g0
            flux[m] = th_i * h_q / m12 + th_e * g_q / g0
            done |= m
        # depths only reachable through zero-thickness jumps (all-jump walls are rejected above)
        return theta, flux

    theta_ext_side, flux = evaluate(range(len(segs)))
    if interface_side == "exterior":
        theta = theta_ext_side
    else:
        theta_int_side, _ = evaluate(range(len(segs) - 1, -1, -1))
        theta = theta_int_side if interface_side == "interior" else 0.5 * (theta_ext_side + theta_int_side)
    if np.any(np.isnan(theta)):
        raise StudyError(["wall: the wall has no finite-thickness layer to evaluate depths in"])
    q_ext = th_i * 1.0 / m12 + th_e * g_start[1] / g0
    q_int = th_i * h_end[1] / m12 + th_e * 1.0 / g0
    return PeriodicProfile(
        period_s=period_s,
        depths_m=x,
        temperature=theta,
        heat_flux=flux,
        q_exterior=complex(q_ext),
        q_interior=complex(q_int),
    )

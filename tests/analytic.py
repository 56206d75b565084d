"""Independent analytic solutions used to verify the engines.

Periodic regime of a multilayer slab with imposed sinusoidal surface
temperatures: the complex transfer-matrix solution (the method of ISO 13786,
written here independently of :mod:`wallcal.standards.iso13786`).
State vector (T, q) with q = -lambda dT/dx positive towards the interior; across a
layer of thickness d with k = sqrt(i omega / alpha):

    [T(x+d)]   [ cosh(kd)          -sinh(kd)/(lambda k) ] [T(x)]
    [q(x+d)] = [ -lambda k sinh(kd)  cosh(kd)           ] [q(x)]
"""

from __future__ import annotations

import numpy as np


def layer_matrix(d, lam, rho_c, omega):
    if d == 0:
        return np.eye(2, dtype=complex)
    k = np.sqrt(1j * omega * rho_c / lam)
    ch, sh = np.cosh(k * d), np.sinh(k * d)
    return np.array([[ch, -sh / (lam * k)], [-lam * k * sh, ch]], dtype=complex)


def resistance_matrix(r):
    return np.array([[1.0, -r], [0.0, 1.0]], dtype=complex)


def periodic_solution(wall, period_s, amp_e, amp_i, depths, with_flux=False):
    """Complex amplitudes of T at ``depths`` (with ``with_flux``: rows (T, q)) and of q at both faces.

    Surface temperatures T_e(t) = Re(amp_e e^{i w t}), T_i(t) = Re(amp_i e^{i w t}).
    Contact resistances of layers are included (a probe at such an interface reads the exterior side).
    """
    omega = 2 * np.pi / period_s
    total = np.eye(2, dtype=complex)
    x = 0.0
    segs = []
    for layer in wall.layers:
        if layer.is_massless:
            m = resistance_matrix(layer.thermal_resistance)
        else:
            m = layer_matrix(layer.thickness, layer.conductivity, layer.volumetric_heat_capacity, omega)
        segs.append((x, x + layer.thickness, layer))
        total = m @ total
        x += layer.thickness
        if layer.contact_resistance:
            total = resistance_matrix(layer.contact_resistance) @ total
            segs.append((x, x, "contact", layer.contact_resistance))
    q_e = (amp_i - total[0, 0] * amp_e) / total[0, 1]
    out = []
    for d in np.atleast_1d(depths):
        state = np.array([amp_e, q_e], dtype=complex)
        for seg in segs:
            if len(seg) == 4:  # contact
                if seg[0] < d:
                    state = resistance_matrix(seg[3]) @ state
                continue
            a, b, layer = seg
            if d >= b:
                m = (
                    resistance_matrix(layer.thermal_resistance)
                    if layer.is_massless
                    else layer_matrix(layer.thickness, layer.conductivity, layer.volumetric_heat_capacity, omega)
                )
                state = m @ state
            elif d > a:
                if layer.is_massless:
                    m = resistance_matrix(layer.thermal_resistance * (d - a) / (b - a))
                else:
                    m = layer_matrix(d - a, layer.conductivity, layer.volumetric_heat_capacity, omega)
                state = m @ state
                break
            else:
                break
        out.append(state if with_flux else state[0])
    q_i = total[1, 0] * amp_e + total[1, 1] * q_e
    return np.array(out), q_e, q_i

"""Boundary conditions of the finite-volume engine: every boundary type is defined here, once.

A face of the wall is one of (codes are what the numba kernels see; nothing else uses the numbers):

- :data:`SURFACE_TEMPERATURE` (Dirichlet): the face node's temperature is the input ``u`` [degC];
  the face node is *known* and not an unknown of the linear system. The face heat flux is the
  scheme's own flux through the face half-cell (link flux plus the half-cell's storage).
- :data:`AIR_TEMPERATURE` (Robin): the face node exchanges ``h (u - T_s)`` with the air at ``u``
  [degC] through the surface coefficient ``h`` [W/(m2K)]; the face node is unknown.
- :data:`HEAT_FLUX` (Neumann): a heat flux density ``u`` [W/m2], positive towards the interior on
  both faces, enters (exterior) or leaves (interior) the face node.
- ``"sol_air_temperature"``: an exterior face in the weather (absorbed solar radiation and long-wave
  exchange with sky and ground, linearised): the input is the sol-air temperature
  ``T_eq = T_e + (alpha_s I_sol - F_sky h_r (T_e - T_sky)) / h_e`` [degC] exchanged through the combined
  coefficient ``h_e`` (convective plus radiative), built from a weather file by
  :func:`wallcal.retrofitting.boundary.year_boundaries`. For the scheme it is a Robin face, so it
  shares :data:`AIR_TEMPERATURE`'s code and branches; its face flux ``h_e (T_eq - T_s)`` is the net
  heat entering the wall's exterior surface.

Sign conventions: ``side`` is +1 at the exterior face and -1 at the interior face; face fluxes
are positive towards the interior at both faces.

Every path asks this module what a face contributes: to the operator (:func:`face_conductance`,
:func:`input_coupling`), to a step's right-hand side (:func:`step_input`) and flux
(:func:`step_flux`), to the modal path's flux rows (:func:`flux_row`), to the steady-state guess
and the face-flux outputs (:func:`imposes_flux`). A new type (say an exterior face with absorbed
solar radiation and long-wave exchange, linearised: a Robin face with an equivalent temperature
and a radiative coefficient) that is one of the three kinds with another input is one registration in
:mod:`wallcal.engines.boundary_types` (its code follows from its kind); a new kind is a new code here and its
branch in each of these functions.
"""

from __future__ import annotations

from collections.abc import Mapping

from ..jit import inner, kernel
from .boundary_types import boundary_type, boundary_type_names

SURFACE_TEMPERATURE = 0
AIR_TEMPERATURE = 1
HEAT_FLUX = 2

#: kind of a registered boundary type (:mod:`wallcal.engines.boundary_types`) -> kernel code
KIND_CODES = {"dirichlet": SURFACE_TEMPERATURE, "robin": AIR_TEMPERATURE, "neumann": HEAT_FLUX}


class _Codes(Mapping):
    """Boundary type name -> kernel code, for every registered type (read from the registry, so a type
    registered later has its code)."""

    def __getitem__(self, name: str) -> int:
        return KIND_CODES[boundary_type(name).kind]

    def __iter__(self):
        return iter(boundary_type_names())

    def __len__(self) -> int:
        return len(boundary_type_names())


#: boundary type names of the study file / :class:`~wallcal.engines.base.BoundaryInput` -> kernel code
CODES = _Codes()


def face_parameters(kind: str, surface_coefficient: float | None) -> tuple[int, float]:
    """Kernel code and coefficient ``h`` [W/(m2K)] of a face given by its type name."""
    code = CODES[kind]
    h = float(surface_coefficient or 0.0) if code == AIR_TEMPERATURE else 0.0
    return code, h


@kernel
def is_known(code):
    """Whether the face node's temperature is imposed (not an unknown)."""
    return code == SURFACE_TEMPERATURE


@kernel
def imposes_flux(code):
    """Whether the input is the face heat flux itself (reported as the face flux; does not tie the
    wall's temperature level)."""
    return code == HEAT_FLUX


@inner()
def face_conductance(code, h):
    """Conductance [W/(m2K)] between the (unknown) face node and the input, added to the face node's
    diagonal of the operator K (0 for a known face or a heat flux)."""
    if code == AIR_TEMPERATURE:
        return h
    return 0.0


@inner()
def input_coupling(code, h, g_face_link, side):
    """Coefficient ``p`` of the input ``u`` in the first (last) unknown row of ``K T = p u``:
    the face link's conductance for a known face (its node is the input), ``h`` for air, and
    +-1 for a heat flux (entering at the exterior, leaving at the interior)."""
    if code == SURFACE_TEMPERATURE:
        return g_face_link
    if code == AIR_TEMPERATURE:
        return h
    return 1.0 * side


@inner()
def step_input(code, h, theta_b, side, u1, u0, ts0, theta_g_link):
    """What the input adds to the first (last) unknown row of a step's right-hand side.

    ``u1, u0``: input at the new and old time level; ``ts0``: face node temperature at the old level;
    ``theta_b``: theta of the boundary term; ``theta_g_link``: theta g of the link to a known face
    node (its old-level part is in the link's explicit flux)."""
    if code == SURFACE_TEMPERATURE:
        return theta_g_link * u1
    if code == AIR_TEMPERATURE:
        return h * (theta_b * u1 + (1.0 - theta_b) * (u0 - ts0))
    return side * (theta_b * u1 + (1.0 - theta_b) * u0)


@inner()
def step_flux(code, h, theta_b, side, u1, u0, ts1, ts0, half_cell_flux):
    """Face heat flux averaged over a step [W/m2], positive towards the interior.

    ``ts1, ts0``: face node temperature at the new and old level; ``half_cell_flux``: for a known face,
    the flux through the face half-cell (link flux + its storage), computed by the caller."""
    if code == SURFACE_TEMPERATURE:
        return half_cell_flux
    if code == AIR_TEMPERATURE:
        return side * h * (theta_b * (u1 - ts1) + (1.0 - theta_b) * (u0 - ts0))
    return theta_b * u1 + (1.0 - theta_b) * u0


@inner()
def flux_row(code, h, g_face_link, cap_face, side):
    """The face flux as a linear form, for the modal path's output rows:
    ``q = a T_face_unknown + b u + c du/dt + d u_interp``, returned as (a, b, c, d), where ``T_face_unknown``
    is the first (last) unknown (the node next to a known face, else the face node), ``u`` and
    ``du/dt`` are the energy-consistent two-step averages of the input and its rate, and
    ``u_interp`` the input interpolated in time. Known face: ``q_e = g (u - T_1) + c_0 du/dt``;
    air: ``q_e = h (u - T_s)``; heat flux: the input (interior face: signs by ``side``)."""
    if code == SURFACE_TEMPERATURE:
        return -side * g_face_link, side * g_face_link, side * cap_face, 0.0
    if code == AIR_TEMPERATURE:
        return -side * h, side * h, 0.0, 0.0
    return 0.0, 0.0, 0.0, 1.0

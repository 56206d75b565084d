"""``fd-reference``: the finite-volume schemes written plainly in numpy and scipy, as a yardstick.

This engine solves the same discrete equations as ``fd-cn``/``fd-implicit``
(:mod:`wallcal.engines.fd`) with none of their speed: a dense matrix per step,
``numpy.linalg.solve``, Python loops over nodes, links and steps. It exists so that
the fast paths (tridiagonal kernels, modal diagonalisation) can be checked against
something that can be read next to the equations in ``docs/reference-engine.md``.
Only the node placement is shared with the fast engine (:func:`wallcal.grid.build_grid`:
the node rule is part of the model's definition); capacities, conductances, the
thetas, the steady start, the lambda(T) step, the outputs and the heat flux at a
depth are computed here from the wall's layers.

Equations (``docs/reference-engine.md`` has them in full)
--------------------------------------------------------
Nodes ``j`` at depths ``x_j``, links ``l`` between nodes ``l`` and ``l + 1``.

- A massive layer of ``n`` intervals ``dx = d / n``: each interval is a link of
  conductance ``g = lambda(T_ref) / dx`` and gives ``rho c dx / 2`` to each end node.
  A no-mass layer: one link ``g = 1 / R``. A contact resistance: one link
  ``g = 1 / max(R_c, 1e-7)`` between two nodes at the same depth.
- Link flux over step ``n -> n + 1`` (positive towards the interior):
  ``F_l = E_l + theta_l g0_l (T_l^{n+1} - T_{l+1}^{n+1})`` with
  ``E_l = (1 - theta_l) g_l (T_l^n - T_{l+1}^n)`` for constant conductances (``g0 = g``).
- Node balance of every node without an imposed temperature:
  ``c_j (T_j^{n+1} - T_j^n) / dt = F_{j-1} - F_j (+ face term)``, the face terms
  ``h (theta_b (u^{n+1} - T^{n+1}) + (1 - theta_b)(u^n - T^n))`` (air temperature) or
  ``theta_b q^{n+1} + (1 - theta_b) q^n`` (heat flux; minus at the interior face).
- ``theta_l = theta`` (1/2 or 1) except 1 on links that touch a node without heat
  capacity, and raised to ``1 - (1 - theta) L / s`` on links whose stiffer node has a stiffness
  ``s = dt (sum of its conductances) / c`` above ``L = 1 / (1 - theta)`` (the discrete maximum
  principle; see :func:`link_thetas`); the same for an air face's term.
- lambda(T): ``g*_l`` is the Kirchhoff mean of lambda over ``[T_{l+1}, T_l]`` at the
  extrapolated mid-step temperature ``1.5 T^n - 0.5 T^{n-1}``; the matrix is kept at
  ``g0`` and ``E_l = g*_l (theta_l dT~_l + (1 - theta_l) dT^n_l) - theta_l g0_l dT~_l``
  with the predictor ``T~ = 2 T^n - T^{n-1}``; ``g0 <- g*`` (all links) whenever some
  ``|g*_l - g0_l| > min(drift g0_l, 0.05 / (theta_l dt (1/c_a + 1/c_b)))``.
- Outputs: probes linear between nodes, face fluxes and fluxes at a depth from the
  step fluxes averaged over the two steps around a grid time; linear in time between
  grid times.
- ``scheme = "exact"``: the semi-discrete system solved exactly for inputs linear between grid
  times, by the matrix exponential of an augmented system (:func:`solve_exact`); lambda(T) walls
  run Crank-Nicolson at the grid's own step (:func:`substepped`).
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass

import numpy as np
import scipy.linalg

from ..errors import EngineError, check_finite
from ..grid import MIN_CONTACT_RESISTANCE, build_grid, refine_in_time, substeps
from ..wall import Wall
from .base import BOUNDARY_TYPES, Capabilities, Engine, EngineOutput, SimulationInput

SCHEME_THETA = {"cn": 0.5, "implicit": 1.0}
SCHEMES = ("cn", "implicit", "exact")


# ---------------------------------------------------------------------------- the discrete wall
@dataclass
class Link:
    """One link between node ``a`` and node ``a + 1``.

    kind: ``"layer"`` (an interval of a massive layer), ``"no-mass"`` or ``"contact"``.
    g_ref: conductance at the layer's reference temperature [W/(m2K)].
    half_capacity: heat capacity the interval gives to each of its two nodes [J/(m2K)].
    dx: interval length [m] (0 for a contact link).
    layer: the layer it belongs to (for a contact link: the layer whose contact resistance it is).
    """

    a: int
    kind: str
    g_ref: float
    half_capacity: float
    dx: float
    layer: int


@dataclass
class Discretisation:
    """Nodes and links of one candidate wall on the prepared grid."""

    x: np.ndarray  # node depths [m]
    links: list[Link]
    capacity: np.ndarray  # node heat capacities [J/(m2K)]

    @property
    def n_nodes(self) -> int:
        return len(self.x)


def discretise(wall: Wall, nodes_per_layer: tuple[int, ...], contact_after: tuple[int, ...]) -> Discretisation:
    """Capacities and conductances of ``wall``: ``nodes_per_layer[i]`` intervals in massive layer i
    (0 for a no-mass layer), a contact link after each layer listed in ``contact_after``."""
    x = [0.0]
    links: list[Link] = []
    depth = 0.0
    for i, layer in enumerate(wall.layers):
        if layer.is_massless:
            if nodes_per_layer[i] != 0:
                raise EngineError(f"layer {layer.id!r}: a no-mass layer on a grid built for a massive one")
            links.append(Link(len(x) - 1, "no-mass", 1.0 / float(layer.thermal_resistance), 0.0, layer.thickness, i))
            depth += layer.thickness
            x.append(depth)
        else:
            n = nodes_per_layer[i]
            if n < 1:
                raise EngineError(f"layer {layer.id!r}: a massive layer on a grid built for a no-mass one")
            dx = layer.thickness / n
            lam = float(layer.conductivity_at(layer.reference_temperature))
            for k in range(1, n + 1):
                links.append(Link(len(x) - 1, "layer", lam / dx, 0.5 * layer.volumetric_heat_capacity * dx, dx, i))
                x.append(depth + k * dx if k < n else depth + layer.thickness)
            depth += layer.thickness
        if i in contact_after:
            r = max(layer.contact_resistance, MIN_CONTACT_RESISTANCE)
            links.append(Link(len(x) - 1, "contact", 1.0 / r, 0.0, 0.0, i))
            x.append(depth)
        elif i < len(wall.layers) - 1 and layer.contact_resistance > 0:
            raise EngineError(f"layer {layer.id!r}: a contact resistance where the grid has no contact link")
    cap = np.zeros(len(x))
    for lk in links:
        cap[lk.a] += lk.half_capacity
        cap[lk.a + 1] += lk.half_capacity
    return Discretisation(x=np.array(x), links=links, capacity=cap)


# ---------------------------------------------------------------------------- lambda(T)
def kirchhoff_mean_conductivity(layer, ta: float, tb: float) -> float:
    """Mean of lambda(T) over [tb, ta] [W/(m K)]: (1 / (ta - tb)) * integral of lambda dT.

    Exponential law lambda = lambda_ref exp(f (T - T_ref)): the closed form
    lambda(T_m) sinh(z) / z with T_m = (ta + tb) / 2 and z = f (ta - tb) / 2.
    Table (piecewise linear, constant beyond its ends): the exact integral, segment by
    segment between the table's points that lie inside [tb, ta].
    """
    if layer.conductivity_table is None:
        f = layer.conductivity_temperature_coefficient
        z = 0.5 * f * (ta - tb)
        sinhc = 1.0 if z == 0.0 else np.sinh(z) / z
        return float(layer.conductivity_at(0.5 * (ta + tb))) * float(sinhc)
    lo, hi = min(ta, tb), max(ta, tb)
    if hi == lo:
        return float(layer.conductivity_at(lo))
    breaks = [float(t) for t, _ in layer.conductivity_table if lo < t < hi]
    pts = [lo, *breaks, hi]
    integral = 0.0
    for s0, s1 in zip(pts[:-1], pts[1:], strict=True):
        integral += (s1 - s0) * 0.5 * (float(layer.conductivity_at(s0)) + float(layer.conductivity_at(s1)))
    return integral / (hi - lo)


def link_conductances(wall: Wall, d: Discretisation, temps: np.ndarray) -> np.ndarray:
    """Conductance of every link at node temperatures ``temps`` [W/(m2K)]: Kirchhoff mean for
    lambda(T) layers, the reference value otherwise."""
    g = np.empty(len(d.links))
    for k, lk in enumerate(d.links):
        layer = wall.layers[lk.layer]
        if lk.kind == "layer" and layer.is_temperature_dependent:
            g[k] = kirchhoff_mean_conductivity(layer, temps[lk.a], temps[lk.a + 1]) / lk.dx
        else:
            g[k] = lk.g_ref
    return g


# ---------------------------------------------------------------------------- results
@dataclass
class ReferenceResult:
    """Everything one reference run produces.

    Attributes
    ----------
    grid_temperatures : ndarray, shape (n_steps + 1, n_nodes)
        Node temperatures [degC] at every grid time.
    step_fluxes : ndarray, shape (n_steps, n_links)
        Link heat fluxes F_l over each step [W/m2], positive towards the interior.
    face_step_fluxes : ndarray, shape (n_steps, 2)
        Exterior and interior face heat fluxes over each step [W/m2].
    temperatures, fluxes : dict
        Probe temperatures and face fluxes at the output times (as :class:`EngineOutput`).
    depth_fluxes : dict[float, ndarray]
        Heat flux [W/m2] at each requested depth [m], at the output times.
    implicit_links : int
        Links made fully implicit (no-capacity node or stiff).
    refactorisations : int
        lambda(T): how often ``g0`` was reset to ``g*`` after the start.
    energy_residual : float
        Stored-energy change minus net energy in over the run [J/m2].
    """

    disc: Discretisation
    grid_temperatures: np.ndarray
    step_fluxes: np.ndarray
    face_step_fluxes: np.ndarray
    temperatures: dict
    fluxes: dict
    depth_fluxes: dict
    implicit_links: int
    refactorisations: int
    energy_residual: float
    energy_throughput: float


# ---------------------------------------------------------------------------- the engine
@dataclass(frozen=True)
class ReferencePrepared:
    """The input, kept as it is (the reference prepares nothing ahead)."""

    inp: SimulationInput


class ReferenceEngine(Engine):
    """Plain dense theta-scheme engine ``fd-reference`` (see module docstring).

    The scheme is the input's ``scheme`` (``"cn"`` or ``"implicit"``); a study run with
    ``engine = "fd-reference"`` gets Crank-Nicolson (:func:`wallcal.engines.scheme_of`).
    Options read from ``SimulationInput.options``: ``stiff_limit`` (default None: ``1 / (1 - theta)``),
    ``refactor_drift`` (default 0.02), ``grid_time_step`` (build the grid for another step).
    """

    name = "fd-reference"
    capabilities = Capabilities(
        batches=False,
        conductivity_laws=True,
        flux_at_depth=True,
        contact_resistance=True,
        massless_layers=True,
        substitute="fd-cn",
        substitute_verified="fd-cn matches fd-reference within 1e-6 K on a generated matrix of walls "
        "(tests/test_reference_engine.py)",
    )

    def prepare(self, inp: SimulationInput) -> ReferencePrepared:
        """Nothing to prepare: the reference builds everything on every run, plainly."""
        self.check(inp)
        return ReferencePrepared(inp)

    def run_wall(self, prepared: ReferencePrepared, wall: Wall) -> EngineOutput:
        """Run one wall (same layer structure as the input's) on the grid of the input's wall."""
        inp = prepared.inp
        t = time.perf_counter()
        depths = tuple(d for _, d in inp.flux_depths)
        res = self.solve(inp, wall=wall, flux_depths=depths)
        out = self._output(inp, res, time.perf_counter() - t)
        for name, depth in inp.flux_depths:
            out.fluxes[name] = res.depth_fluxes[float(depth)]
        check_finite({**out.temperatures, **out.fluxes}, self.name, wall.nonfinite_cause())
        return out

    def _output(self, inp: SimulationInput, res: ReferenceResult, seconds: float) -> EngineOutput:
        info = {
            "engine": self.name,
            "scheme": inp.scheme,
            "path": "reference",
            "nodes": res.disc.n_nodes,
            "implicit_links": res.implicit_links,
            "refactorisations": res.refactorisations,
            "energy_residual_J_m2": res.energy_residual,
            "energy_throughput_J_m2": res.energy_throughput,
            "seconds": seconds,
        }
        return EngineOutput(temperatures=res.temperatures, fluxes=res.fluxes, info=info)

    # ------------------------------------------------------------------ one run
    def solve(
        self,
        inp: SimulationInput,
        wall: Wall | None = None,
        flux_depths: tuple[float, ...] = (),
        contact_layers: frozenset[int] | None = None,
        initial_state: np.ndarray | None = None,
    ) -> ReferenceResult:
        """Run one wall and keep everything.

        Parameters
        ----------
        inp : SimulationInput
            Boundary series, output times, grid settings; its wall fixes the grid.
        wall : Wall, optional
            A candidate wall with the same layer structure (default ``inp.wall``); its probes are used.
        flux_depths : tuple of float
            Depths [m] at which the heat flux density is wanted (see :func:`flux_at_depth`).
        contact_layers : frozenset of int, optional
            Layers that get a contact link even with a zero contact resistance (as in
            :func:`wallcal.grid.build_grid`); default the input's ``options.contact_layers``.
        initial_state : ndarray, optional
            Node temperatures [degC] at grid time 0; default the steady state of the first boundary values.
        """
        wall = inp.wall if wall is None else wall
        if inp.scheme == "exact" and not wall.is_linear:
            # lambda(T): Crank-Nicolson at the grid's own step (sub-steps of the run's step)
            return self.solve(substepped(inp), wall, flux_depths, contact_layers, initial_state)
        theta0, stiff_limit, drift = self._settings(inp)
        ext, intr = inp.exterior, inp.interior
        for face, b in (("exterior", ext), ("interior", intr)):
            if b.type not in BOUNDARY_TYPES:
                raise EngineError(f"{face} boundary: unknown type {b.type!r}; one of {BOUNDARY_TYPES}")
            if b.type in ("air_temperature", "sol_air_temperature") and not (
                b.surface_coefficient and b.surface_coefficient > 0
            ):
                raise EngineError(f"{face} boundary: an air temperature needs a surface coefficient > 0")
        if ext.type == "heat_flux" and intr.type == "heat_flux":
            raise EngineError("heat-flux boundaries on both faces leave the temperature level undetermined")
        # a sol-air face is an air face whose input is the sol-air temperature (h: the combined coefficient)
        ext, intr = (
            dataclasses.replace(b, type="air_temperature") if b.type == "sol_air_temperature" else b
            for b in (ext, intr)
        )
        ue = np.asarray(ext.values, dtype=float)
        ui = np.asarray(intr.values, dtype=float)
        n_steps = len(ue) - 1
        if n_steps < 1 or len(ui) != len(ue):
            raise EngineError("boundary series must have the same length, at least two values")
        dt = float(inp.time_step)

        grid_dt = inp.options.grid_time_step or inp.time_step
        if contact_layers is None:
            contact_layers = inp.options.contact_layers
        grid = build_grid(inp.wall, grid_dt, inp.grid_constant, inp.node_rule, contact_layers)
        contact_after = tuple(int(li) for li in grid.link_contact_of if li >= 0)
        disc = discretise(wall, grid.nodes_per_layer, contact_after)
        if not np.allclose(disc.x, grid.x, rtol=0, atol=1e-12 * max(1.0, wall.thickness)) and wall is inp.wall:
            raise EngineError("internal: node depths differ from wallcal.grid.build_grid")
        cap = disc.capacity
        n_nodes = disc.n_nodes
        n_links = len(disc.links)
        g_ref = np.array([lk.g_ref for lk in disc.links])
        known = np.zeros(n_nodes, dtype=bool)  # nodes whose temperature is imposed
        known[0] = ext.type == "surface_temperature"
        known[-1] = intr.type == "surface_temperature"

        face_h = [b.surface_coefficient if b.type == "air_temperature" else 0.0 for b in (ext, intr)]
        if inp.scheme == "exact":
            if initial_state is None:
                initial_state = steady_state(wall, disc, ext.type, intr.type, ext, intr, ue[0], ui[0])
            return solve_exact(inp, wall, disc, (ext.type, intr.type), face_h, ue, ui, flux_depths, initial_state)
        theta, bc_theta = link_thetas(cap, g_ref, known, face_h, theta0, dt, stiff_limit)
        implicit_links = int(np.sum(theta != theta0))
        nonlinear = any(lk.kind == "layer" and wall.layers[lk.layer].is_temperature_dependent for lk in disc.links)
        # drift tolerance of a lambda(T) step (see module docstring); 0 on links touching a node without capacity
        lim = np.empty(n_links)
        for k, lk in enumerate(disc.links):
            a, b = lk.a, lk.a + 1
            if (cap[a] <= 0 and not known[a]) or (cap[b] <= 0 and not known[b]):
                lim[k] = 0.0
                continue
            stiff = theta[k] * dt * ((0.0 if known[a] else 1.0 / cap[a]) + (0.0 if known[b] else 1.0 / cap[b]))
            lim[k] = 0.05 / stiff if stiff > 0 else np.inf

        # initial state
        if initial_state is None:
            T = steady_state(wall, disc, ext.type, intr.type, ext, intr, ue[0], ui[0])
        else:
            T = np.array(initial_state, dtype=float)
            if known[0]:
                T[0] = ue[0]
            if known[-1]:
                T[-1] = ui[0]
        T_prev = T.copy()  # T^{n-1} (= T^0 before the first step)
        g0 = link_conductances(wall, disc, T) if nonlinear else g_ref.copy()
        tol = np.minimum(drift * g0, lim)
        refactorisations = 0

        Ts = np.empty((n_steps + 1, n_nodes))
        Ts[0] = T
        F = np.empty((n_steps, n_links))
        Fface = np.empty((n_steps, 2))
        for n in range(n_steps):
            # conductances of the step and the explicit part E of every link flux
            pred = 2.0 * T - T_prev  # predictor of T^{n+1}
            if known[0]:
                pred[0] = ue[n + 1]
            if known[-1]:
                pred[-1] = ui[n + 1]
            if nonlinear:
                gs = link_conductances(wall, disc, 1.5 * T - 0.5 * T_prev)
                if n > 0 and np.any(np.abs(gs - g0) > tol):
                    g0 = gs.copy()
                    tol = np.minimum(drift * g0, lim)
                    refactorisations += 1
            else:
                gs = g0
            E = np.empty(n_links)
            for k, lk in enumerate(disc.links):
                a, b = lk.a, lk.a + 1
                dpred = pred[a] - pred[b]
                E[k] = gs[k] * (theta[k] * dpred + (1 - theta[k]) * (T[a] - T[b])) - theta[k] * g0[k] * dpred

            # the system A T^{n+1} = r: one row per node
            A = np.zeros((n_nodes, n_nodes))
            r = np.zeros(n_nodes)
            for j in range(n_nodes):
                A[j, j] = cap[j] / dt
                r[j] = cap[j] / dt * T[j]
            for k, lk in enumerate(disc.links):  # F_l = E_l + theta g0 (T_a - T_b) leaves a, enters b
                a, b = lk.a, lk.a + 1
                tg = theta[k] * g0[k]
                A[a, a] += tg
                A[a, b] -= tg
                A[b, b] += tg
                A[b, a] -= tg
                r[a] -= E[k]
                r[b] += E[k]
            face_row(A, r, 0, ext.type, ext.surface_coefficient, bc_theta[0], ue[n], ue[n + 1], T[0], +1.0)
            face_row(A, r, n_nodes - 1, intr.type, intr.surface_coefficient, bc_theta[1], ui[n], ui[n + 1], T[-1], -1.0)
            T_new = np.linalg.solve(A, r)
            T_new[known] = r[known]  # imposed temperatures exactly (the solve may round them)

            # link and face fluxes of the step
            for k, lk in enumerate(disc.links):
                F[n, k] = E[k] + theta[k] * g0[k] * (T_new[lk.a] - T_new[lk.a + 1])
            Fface[n, 0] = face_step_flux(
                ext.type, ext.surface_coefficient, bc_theta[0], ue[n], ue[n + 1], T[0], T_new[0], +1.0
            )
            Fface[n, 1] = face_step_flux(
                intr.type, intr.surface_coefficient, bc_theta[1], ui[n], ui[n + 1], T[-1], T_new[-1], -1.0
            )
            if known[0]:  # imposed surface temperature: link flux plus the face node's storage
                Fface[n, 0] = F[n, 0] + cap[0] * (T_new[0] - T[0]) / dt
            if known[-1]:
                Fface[n, 1] = F[n, -1] - cap[-1] * (T_new[-1] - T[-1]) / dt
            T_prev, T = T, T_new
            Ts[n + 1] = T

        # energy balance: stored-energy change against the net energy in through the faces
        stored = float(np.dot(cap, Ts[-1]) - np.dot(cap, Ts[0]))
        e_in, e_out = dt * Fface[:, 0].sum(), dt * Fface[:, 1].sum()

        # outputs at the output times
        pos = np.asarray(inp.output_positions, dtype=float)
        if len(pos) and (pos.min() < -1e-9 or pos.max() > n_steps + 1e-9 or np.any(np.diff(pos) < 0)):
            raise EngineError("output times must be increasing and inside the simulated period")
        temps = {}
        for name in inp.probes:
            p = wall.probe(name)
            w_node = probe_node_weights(disc.x, p.depth, p.side)
            temps[name] = in_time(Ts @ w_node, pos)
        face_q = {
            "exterior": grid_time_values(Fface[:, 0], ext.type, ue),
            "interior": grid_time_values(Fface[:, 1], intr.type, ui),
        }
        fluxes = {face: in_time(face_q[face], pos) for face in inp.flux_faces}
        depth_fluxes = {}
        for depth in flux_depths:
            q, face = flux_at_depth(disc, F, Ts, dt, float(depth))
            q_grid = face_q[face] if face else grid_time_values(q, None, None)
            depth_fluxes[float(depth)] = in_time(q_grid, pos)
        return ReferenceResult(
            disc=disc,
            grid_temperatures=Ts,
            step_fluxes=F,
            face_step_fluxes=Fface,
            temperatures=temps,
            fluxes=fluxes,
            depth_fluxes=depth_fluxes,
            implicit_links=implicit_links,
            refactorisations=refactorisations,
            energy_residual=stored - (e_in - e_out),
            energy_throughput=abs(e_in) + abs(e_out),
        )

    @staticmethod
    def _settings(inp: SimulationInput) -> tuple[float, float, float]:
        if inp.scheme not in SCHEMES:
            raise EngineError(f"simulation scheme must be one of {SCHEMES}, got {inp.scheme!r}")
        theta0 = SCHEME_THETA.get(inp.scheme, 0.5)  # (the exact scheme has no theta)
        stiff_limit = inp.options.stiff_limit
        drift = float(inp.options.refactor_drift)
        return theta0, stiff_limit, drift


# ---------------------------------------------------------------------------- pieces of the scheme
def link_thetas(cap, g, known, face_h, theta0, dt, stiff_limit=None):
    """theta of every link and of the two face terms (see module docstring): the discrete maximum principle.

    Node stiffness ``s_j = dt (sum of the conductances at node j, face term included) / c_j`` (0 for a node
    whose temperature is imposed, infinite for a node without capacity). A term whose stiffest node has
    ``(1 - theta0) s > (1 - theta0) L`` gets ``theta = 1 - (1 - theta0) L / s`` (1 for infinite s), with
    ``L = stiff_limit`` or ``1 / (1 - theta0)``; the others keep theta0. A face term counts when the face
    has a surface coefficient ``face_h`` > 0 or its node has no capacity.
    """
    n_nodes = len(cap)
    theta = np.full(len(g), float(theta0))
    bc_theta = np.full(2, float(theta0))
    if theta0 >= 1.0:
        return theta, bc_theta
    limit = 1.0 / (1.0 - theta0) if stiff_limit is None else float(stiff_limit)
    budget = (1.0 - theta0) * limit
    s = np.empty(n_nodes)
    for j in range(n_nodes):
        total = 0.0
        if j > 0:
            total += g[j - 1]
        if j < n_nodes - 1:
            total += g[j]
        if j == 0:
            total += face_h[0]
        if j == n_nodes - 1:
            total += face_h[1]
        if known[j]:
            s[j] = 0.0
        elif cap[j] > 0:
            s[j] = dt * total / cap[j]
        else:
            s[j] = np.inf

    def raised(sj):
        if not np.isfinite(sj):
            return 1.0
        if (1.0 - theta0) * sj > budget:
            return 1.0 - budget / sj
        return float(theta0)

    for k in range(len(g)):
        theta[k] = raised(max(s[k], s[k + 1]))
    for f, j in ((0, 0), (1, n_nodes - 1)):
        if face_h[f] > 0 or not np.isfinite(s[j]):
            bc_theta[f] = raised(s[j])
    return theta, bc_theta


def face_row(A, r, j, kind, h, th, u0, u1, t_old, sign):
    """Add a face's boundary condition to row ``j`` of ``A T^{n+1} = r``.

    ``sign`` is +1 at the exterior face (a flux towards the interior enters the wall) and -1 at the
    interior face (it leaves the wall).
    """
    if kind == "surface_temperature":
        A[j, :] = 0.0
        A[j, j] = 1.0
        r[j] = u1
    elif kind == "air_temperature":  # h (T_air - T_s) enters the face node
        A[j, j] += th * h
        r[j] += h * (th * u1 + (1.0 - th) * (u0 - t_old))
    else:  # heat flux density q, positive towards the interior
        r[j] += sign * (th * u1 + (1.0 - th) * u0)


def face_step_flux(kind, h, th, u0, u1, t_old, t_new, sign):
    """Face heat flux over a step for air-temperature and heat-flux faces (positive towards the interior)."""
    if kind == "air_temperature":
        return sign * h * (th * (u1 - t_new) + (1.0 - th) * (u0 - t_old))
    if kind == "heat_flux":
        return th * u1 + (1.0 - th) * u0
    return np.nan  # surface temperature: set by the caller from the link flux


def steady_state(wall, disc, ext_type, int_type, ext, intr, ue0, ui0, tol=1e-12, max_iter=200):
    """Steady node temperatures for constant boundary values ``ue0``, ``ui0`` (Picard iterations on the
    Kirchhoff-mean conductances when lambda(T))."""
    n = disc.n_nodes
    guess = 0.5 * (ue0 + ui0)
    if ext_type == "heat_flux":
        guess = ui0
    if int_type == "heat_flux":
        guess = ue0
    T = np.full(n, guess)
    last_change = np.inf
    for _ in range(max_iter):
        g = link_conductances(wall, disc, T)
        A = np.zeros((n, n))
        r = np.zeros(n)
        for k, lk in enumerate(disc.links):
            a, b = lk.a, lk.a + 1
            A[a, a] += g[k]
            A[a, b] -= g[k]
            A[b, b] += g[k]
            A[b, a] -= g[k]
        face_row(A, r, 0, ext_type, ext.surface_coefficient, 1.0, ue0, ue0, 0.0, +1.0)
        face_row(A, r, n - 1, int_type, intr.surface_coefficient, 1.0, ui0, ui0, 0.0, -1.0)
        T_new = np.linalg.solve(A, r)
        if ext_type == "surface_temperature":
            T_new[0] = ue0
        if int_type == "surface_temperature":
            T_new[-1] = ui0
        change = float(np.max(np.abs(T_new - T)))
        T = T_new
        # converged: below tol, or at the round-off floor (the change no longer decreases, and is tiny)
        if change < tol or (change < 1e-8 and change >= last_change):
            return T
        last_change = change
    raise EngineError("steady initial state: Picard iterations did not converge")


def probe_node_weights(x: np.ndarray, depth: float, side: str | None) -> np.ndarray:
    """Weights w with T(depth) = w . T_nodes: exact on a node, linear between nodes. Where several
    nodes share the depth (a contact resistance), ``side`` picks the exterior-most (``"exterior"``),
    the interior-most (``"interior"``) or the mean of the two (None)."""
    n = len(x)
    w = np.zeros(n)
    d = min(max(depth, 0.0), x[-1])
    tol = 1e-12 * max(1.0, x[-1])
    on = [j for j in range(n) if abs(x[j] - d) <= tol]
    if on:
        first, last = on[0], on[-1]
        if first == last or side == "exterior":
            w[first] = 1.0
        elif side == "interior":
            w[last] = 1.0
        else:
            w[first] += 0.5
            w[last] += 0.5
        return w
    j = max(k for k in range(n) if x[k] < d)
    s = (d - x[j]) / (x[j + 1] - x[j])
    w[j] = 1.0 - s
    w[j + 1] = s
    return w


def grid_time_values(step_values: np.ndarray, face_type: str | None, imposed: np.ndarray | None) -> np.ndarray:
    """Values at the grid times of a quantity known per step: (q^{j-1/2} + q^{j+1/2}) / 2, one-sided at
    the first and last grid time; an imposed heat flux is reported as imposed."""
    if face_type == "heat_flux":
        return np.asarray(imposed, dtype=float).copy()
    s = np.asarray(step_values, dtype=float)
    out = np.empty(len(s) + 1)
    out[0] = s[0]
    out[-1] = s[-1]
    out[1:-1] = 0.5 * (s[:-1] + s[1:])
    return out


def in_time(grid_values: np.ndarray, pos: np.ndarray) -> np.ndarray:
    """Values at fractional grid positions ``pos``, linear between grid times."""
    n_steps = len(grid_values) - 1
    out = np.empty(len(pos))
    for k, p in enumerate(pos):
        step = min(max(int(np.floor(p + 1e-9)), 0), n_steps - 1)
        w = min(max(p - step, 0.0), 1.0)
        out[k] = (1.0 - w) * grid_values[step] + w * grid_values[step + 1]
    return out


def flux_at_depth(disc: Discretisation, F: np.ndarray, Ts: np.ndarray, dt: float, depth: float):
    """Heat flux density through the plane at ``depth`` over every step [W/m2], positive towards the interior,
    and the face (``"exterior"``/``"interior"``) when the plane is a face (None inside the wall).

    The scheme's own flux: inside a link, the link flux ``F_l``; on a node ``k`` (the innermost node at
    that depth when several share it), the flux into the next link plus the heat stored by the part of
    the node's control volume on the interior side of the plane,
    ``F_k + c_k^+ (T_k^{n+1} - T_k^n) / dt`` with ``c_k^+`` the half capacity of the interval towards the
    interior (the node balance makes this equal to ``F_{k-1} - c_k^- dT_k/dt``); on the faces, the face
    fluxes (returned as ``(None, face)``: the caller takes its face-flux series). Consistent with the
    face fluxes and the energy balance of every slice of the wall.
    """
    x = disc.x
    n = len(x)
    d = min(max(depth, 0.0), x[-1])
    tol = 1e-12 * max(1.0, x[-1])
    on = [j for j in range(n) if abs(x[j] - d) <= tol]
    if not on:
        k = max(j for j in range(n) if x[j] < d)  # the link from node k to node k + 1
        return F[:, k].copy(), None
    k = on[-1]
    if k == n - 1:
        return None, "interior"
    if on[0] == 0 and d == 0.0:
        return None, "exterior"
    c_plus = disc.links[k].half_capacity
    return F[:, k] + c_plus * (Ts[1:, k] - Ts[:-1, k]) / dt, None


# ---------------------------------------------------------------------------- the exact scheme
def substepped(inp: SimulationInput) -> SimulationInput:
    """The input run by Crank-Nicolson at the grid's own step: ``grid_time_step`` (default the run's step)
    divides the run's step into :func:`wallcal.grid.substeps` sub-steps; inputs linear in between, output
    positions on the finer grid (the exact scheme's lambda(T) walls)."""
    grid_dt = inp.options.grid_time_step or inp.time_step
    n_sub = substeps(inp.time_step, grid_dt)
    ext, intr = inp.exterior, inp.interior
    return inp.replace(
        scheme="cn",
        time_step=inp.time_step / n_sub,
        exterior=dataclasses.replace(ext, values=refine_in_time(ext.values, n_sub)),
        interior=dataclasses.replace(intr, values=refine_in_time(intr.values, n_sub)),
        output_positions=np.asarray(inp.output_positions, dtype=float) * n_sub,
        options=inp.options.replace(grid_time_step=grid_dt),
    )


def exact_system(disc: Discretisation, g: np.ndarray, types, face_h):
    """The semi-discrete system ``Cap T' = -K T + P u(t)`` (``u = (u_e, u_i)``) reduced to the nodes with heat
    capacity: known face nodes (``T = u``) and nodes without capacity (``K_zz T_z = P_z u - K_zm T_m``)
    eliminated. Returns ``(A, B, L_m, L_u, massive)``: ``T_m' = A T_m + B u`` and every node's temperature
    ``T = L_m T_m + L_u u``; ``massive`` the indices of the nodes with capacity."""
    n = disc.n_nodes
    cap = disc.capacity
    K = np.zeros((n, n))
    for k, lk in enumerate(disc.links):
        a, b = lk.a, lk.a + 1
        K[a, a] += g[k]
        K[b, b] += g[k]
        K[a, b] -= g[k]
        K[b, a] -= g[k]
    P = np.zeros((n, 2))
    known = np.zeros(n, dtype=bool)
    for f, (j, sign) in enumerate(((0, 1.0), (n - 1, -1.0))):
        if types[f] == "surface_temperature":
            known[j] = True
        elif types[f] == "air_temperature":
            K[j, j] += face_h[f]
            P[j, f] += face_h[f]
        else:  # heat flux, positive towards the interior
            P[j, f] += sign
    S = np.zeros((n, 2))  # known nodes: T = S u
    S[0, 0] = 1.0 if known[0] else 0.0
    S[-1, 1] = 1.0 if known[-1] else 0.0
    unk = np.flatnonzero(~known)
    m_idx = unk[cap[unk] > 0]
    z_idx = unk[cap[unk] <= 0]
    kn = np.flatnonzero(known)
    Bu = P - K[:, kn] @ S[kn]  # forcing of every node by u once the known nodes are substituted
    # T_z = Z_m T_m + Z_u u
    if len(z_idx):
        Kzz = K[np.ix_(z_idx, z_idx)]
        Z_m = -np.linalg.solve(Kzz, K[np.ix_(z_idx, m_idx)])
        Z_u = np.linalg.solve(Kzz, Bu[z_idx])
    else:
        Z_m = np.zeros((0, len(m_idx)))
        Z_u = np.zeros((0, 2))
    Ks = K[np.ix_(m_idx, m_idx)] + K[np.ix_(m_idx, z_idx)] @ Z_m
    Bs = Bu[m_idx] - K[np.ix_(m_idx, z_idx)] @ Z_u
    c = cap[m_idx]
    A = -Ks / c[:, None]
    B = Bs / c[:, None]
    L_m = np.zeros((n, len(m_idx)))
    L_u = S.copy()
    L_m[m_idx, np.arange(len(m_idx))] = 1.0
    L_m[z_idx] = Z_m
    L_u[z_idx] = Z_u
    return A, B, L_m, L_u, m_idx


def solve_exact(inp, wall, disc, types, face_h, ue, ui, flux_depths, T0) -> ReferenceResult:
    """The exact scheme of a wall with constant properties: the exact solution of the semi-discrete system
    (:func:`exact_system`) for inputs linear between grid times, by the matrix exponential of the augmented
    system ``(T_m, u, du/dt, E_e, E_i)``, whose last two states integrate the face fluxes (the energy balance).

    Outputs are instantaneous at the output times (between grid times from the exact state at that time):
    probes linear between nodes; face fluxes ``h (u - T_s)``, ``g (u - T_1) + c_0 du/dt`` (known face: the
    input's rate as a central difference at grid times, linear in between), the imposed flux; a flux at a
    depth is the link flux ``g (T_a - T_b)``, on a node ``k`` the flux into the next link plus the heat
    stored by the node's interior part, ``F_k + c_k^+ dT_k/dt`` with ``c_k dT_k/dt = F_{k-1} - F_k``.
    """
    dt = float(inp.time_step)
    n_steps = len(ue) - 1
    n = disc.n_nodes
    cap = disc.capacity
    g = np.array([lk.g_ref for lk in disc.links])
    A, B, L_m, L_u, m_idx = exact_system(disc, g, types, face_h)
    nm = len(m_idx)
    U = np.column_stack([ue, ui])  # (n_steps + 1, 2)
    rate = np.empty_like(U)  # central differences at grid times (one-sided at the ends)
    rate[1:-1] = (U[2:] - U[:-2]) / (2.0 * dt)
    rate[0] = (U[1] - U[0]) / dt
    rate[-1] = (U[-1] - U[-2]) / dt
    slope = (U[1:] - U[:-1]) / dt  # du/dt over each step
    # face fluxes as rows over the node temperatures, the input and its rate: q = a . T + b . u + c . du/dt
    qa = np.zeros((2, n))
    qb = np.zeros((2, 2))
    qc = np.zeros((2, 2))
    for f, (j, jn, lk, sign) in enumerate(((0, 1, 0, 1.0), (n - 1, n - 2, len(g) - 1, -1.0))):
        if types[f] == "surface_temperature":
            qa[f, jn] -= sign * g[lk]
            qb[f, f] += sign * g[lk]
            qc[f, f] += sign * cap[j]
        elif types[f] == "air_temperature":
            qa[f, j] -= sign * face_h[f]
            qb[f, f] += sign * face_h[f]
        else:
            qb[f, f] += 1.0
    # the augmented system: states (T_m, u, du/dt, E_e, E_i), E the energy through each face
    na = nm + 6
    aug = np.zeros((na, na))
    aug[:nm, :nm] = A
    aug[:nm, nm : nm + 2] = B
    aug[nm : nm + 2, nm + 2 : nm + 4] = np.eye(2)
    aug[nm + 4 :, :nm] = qa @ L_m
    aug[nm + 4 :, nm : nm + 2] = qa @ L_u + qb
    aug[nm + 4 :, nm + 2 : nm + 4] = qc
    phi = scipy.linalg.expm(dt * aug)
    T0 = np.asarray(T0, dtype=float)
    Tm = T0[m_idx].copy()
    Ts = np.empty((n_steps + 1, n))
    Ts[0] = L_m @ Tm + L_u @ U[0]
    Tm_steps = np.empty((n_steps + 1, nm))
    Tm_steps[0] = Tm
    energy = np.zeros(2)
    for k in range(n_steps):
        x = np.concatenate([Tm, U[k], slope[k], [0.0, 0.0]])
        x = phi @ x
        Tm = x[:nm]
        energy += x[nm + 4 :]
        Tm_steps[k + 1] = Tm
        Ts[k + 1] = L_m @ Tm + L_u @ U[k + 1]
    stored = float(cap @ (Ts[-1] - Ts[0]))
    pos = np.asarray(inp.output_positions, dtype=float)
    if len(pos) and (pos.min() < -1e-9 or pos.max() > n_steps + 1e-9 or np.any(np.diff(pos) < 0)):
        raise EngineError("output times must be increasing and inside the simulated period")
    # the state, the input and its rate at the output times
    steps = np.clip(np.floor(pos + 1e-9).astype(int), 0, n_steps - 1)
    ws = np.clip(pos - steps, 0.0, 1.0)
    phis: dict[float, np.ndarray] = {}
    T_out = np.empty((len(pos), n))
    u_out = np.empty((len(pos), 2))
    r_out = np.empty((len(pos), 2))
    for i, (k, w) in enumerate(zip(steps, ws, strict=True)):
        u_out[i] = (1.0 - w) * U[k] + w * U[k + 1]
        r_out[i] = (1.0 - w) * rate[k] + w * rate[k + 1]
        if w == 0.0:
            T_out[i] = Ts[k]
            continue
        if w not in phis:
            phis[w] = scipy.linalg.expm(w * dt * aug[: nm + 4, : nm + 4])
        x = phis[w] @ np.concatenate([Tm_steps[k], U[k], slope[k]])
        T_out[i] = L_m @ x[:nm] + L_u @ u_out[i]
    temps = {}
    for name in inp.probes:
        p = wall.probe(name)
        temps[name] = T_out @ probe_node_weights(disc.x, p.depth, p.side)
    face_q = T_out @ qa.T + u_out @ qb.T + r_out @ qc.T
    fluxes = {face: face_q[:, 0 if face == "exterior" else 1].copy() for face in inp.flux_faces}
    link_F = (T_out[:, :-1] - T_out[:, 1:]) * g  # link fluxes at the output times
    depth_fluxes = {}
    x = disc.x
    tol = 1e-12 * max(1.0, x[-1])
    for depth in flux_depths:
        d = min(max(float(depth), 0.0), x[-1])
        on = [j for j in range(n) if abs(x[j] - d) <= tol]
        if not on:
            depth_fluxes[float(depth)] = link_F[:, max(j for j in range(n) if x[j] < d)].copy()
        elif on[-1] == n - 1:
            depth_fluxes[float(depth)] = face_q[:, 1].copy()
        elif on[0] == 0 and d == 0.0:
            depth_fluxes[float(depth)] = face_q[:, 0].copy()
        else:
            k = on[-1]
            frac = disc.links[k].half_capacity / cap[k] if cap[k] > 0 else 0.0
            depth_fluxes[float(depth)] = link_F[:, k] + frac * (link_F[:, k - 1] - link_F[:, k])
    return ReferenceResult(
        disc=disc,
        grid_temperatures=Ts,
        step_fluxes=np.diff(Ts, axis=0)[:, :0],
        face_step_fluxes=np.full((n_steps, 2), np.nan),
        temperatures=temps,
        fluxes=fluxes,
        depth_fluxes=depth_fluxes,
        implicit_links=0,
        refactorisations=0,
        energy_residual=stored - (energy[0] - energy[1]),
        energy_throughput=float(abs(energy[0]) + abs(energy[1])),
    )

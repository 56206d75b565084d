"""The finite-volume engine ``fd`` (``fd-cn``: Crank-Nicolson, ``fd-implicit``: fully implicit, ``fd-exact``).

The engine contract (:mod:`wallcal.engines.base`) on a build-once, run-many core:
:meth:`FDEngine.prepare` turns a :class:`SimulationInput`
into a :class:`PreparedFD` (grid, boundary series, output positions, conductivity
laws); :meth:`PreparedFD.run_batch` then runs any number of candidate walls
(same layer structure, other properties or probe depths) in one call of the
numba kernel, split over threads by candidate (:func:`in_threads`).

Scheme details
--------------
- theta = 1/2 (``cn``) or 1 (``implicit``) on every link, raised where the scheme would
  otherwise break the discrete maximum principle (a step response would ring): with the node
  stiffness ``s_i = dt sum g / c_i`` (Robin terms included, inf without capacity), a link gets
  ``theta = max(theta0, 1 - 1 / max(s_a, s_b))`` (see :func:`wallcal.engines.operator.link_thetas`
  and docs/engine.md). Walls whose layers are several grid spacings thick (C = 2) have s <= 2
  and keep Crank-Nicolson on every link; thin, very conductive layers (metal sheets), thin layers
  at coarse steps, light half-cells next to a contact resistance and nodes without capacity get a
  raised theta; ``info["implicit_links"]`` says how
  many terms. ``stiff_limit`` (option) replaces the limit 2 (``inf``: theta0 everywhere).
- lambda(T): each link's conductance is the Kirchhoff mean of lambda over its two
  node temperatures, evaluated at the mid-step temperature extrapolated from the
  last two steps (``1.5 T^n - 0.5 T^{n-1}``); the matrix stays factorised at
  conductances ``g0`` and the difference ``g* - g0`` is applied explicitly to the
  predicted ``T^{n+1}`` (``2 T^n - T^{n-1}``), link by link (exactly
  conservative); the matrix is refactorised when ``g*`` drifts more than 2 % from
  ``g0``. Second order for CN, exact steady state, no inner iterations (see
  :func:`wallcal.engines.kernels._run_one`).
- Initial state: the steady profile of the first boundary values (Picard
  iterations for lambda(T)), then the warm-up period.
- Outputs: probe temperatures exact on a node and linear between nodes; face
  heat fluxes from the surface half-node energy balance
  ``q_e = g_01 (T_0 - T_1) + c_0 dT_0/dt`` (central difference of the imposed
  series) for surface-temperature faces, ``h (T_air - T_s)`` for air faces. A heat flux inside the
  wall (``SimulationInput.flux_depths``) is the scheme's own flux through the plane at that depth
  (:func:`depth_plane`): the link flux between nodes, plus on a node the heat stored by the node's
  part on the interior side of the plane; the face flux on a face. Outputs between grid times are
  interpolated linearly in time.
- ``fd-exact`` (scheme ``exact``): walls with constant conductances are solved exactly in time for inputs
  linear between samples (:mod:`wallcal.engines.exact`, path ``"exact"``); lambda(T) walls run
  Crank-Nicolson on the general path at the grid's own step (``options.grid_time_step``), in
  :func:`wallcal.grid.substeps` sub-steps per step, outputs at the run's times.
- Paths: walls with constant conductances take the exact modal fast path (:mod:`wallcal.engines.modal`),
  raised thetas and nodes without capacity included; lambda(T) walls the general tridiagonal path
  (:mod:`wallcal.engines.kernels`), which runs any wall with ``path="general"``.
  ``run_batch(path="auto")`` chooses, the result's ``path`` says which ran.
- Per call, Python calls two small numba functions (:func:`wallcal.grid.assemble_lines`: capacities,
  conductances, temperature coefficients and the validity check; :func:`wallcal.engines.operator.link_thetas`)
  and the batch kernel; everything that depends only on the boundary data, output times or batch size
  (theta-weighted inputs, the modal output plan, probe weights at the prepared wall's depths, empty arrays)
  is computed once per :class:`PreparedFD`. The modal kernel calls two LAPACK routines on arrays of a few
  dozen nodes (:mod:`wallcal.engines.modal`), which run in the calling thread: no threads of their own
  oversubscribe ours.
"""

from __future__ import annotations

import functools
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numba
import numpy as np

from ..errors import EngineError, check_finite
from ..grid import (
    LAMBDA_CONSTANT,
    LAMBDA_EXPONENTIAL,
    LAMBDA_TABLE,
    Grid,
    PropertyArrays,
    assemble_lines,
    build_grid,
    probe_weights,
    refine_in_time,
    substeps,
)
from ..wall import Wall
from . import boundary, exact, kernels, modal, operator
from .base import BatchOutput, Capabilities, Engine, EngineOutput, SimulationInput, WallBatch, is_batch

SCHEME_THETA = {"cn": 0.5, "implicit": 1.0}
#: the schemes: the theta schemes, and ``exact`` (:mod:`wallcal.engines.exact`; lambda(T) walls: Crank-Nicolson at
#: the grid's own step)
SCHEMES = ("cn", "implicit", "exact")
DEFAULT_STIFF_LIMIT = None  # 1 / (1 - theta): the discrete maximum principle (see operator.link_thetas)


@dataclass
class BatchResult:
    """Raw outputs of a batch run.

    Attributes
    ----------
    out : ndarray, shape (n_candidates, n_probes + 2 + n_depths, n_times)
        Probe temperatures [degC], then exterior and interior face heat flux, then the heat flux at each
        of the input's ``flux_depths`` [W/m2].
    energy : ndarray, shape (n_candidates, 3)
        Change of stored energy, energy in (exterior face), energy out (interior face) [J/m2].
    final_state : ndarray, shape (n_candidates, n_nodes)
    implicit_links : ndarray of int, shape (n_candidates,)
    path : str
        ``"modal"`` (exact fast path), ``"general"`` (tridiagonal theta scheme) or ``"exact"`` (the exact
        scheme, :mod:`wallcal.engines.exact`).
    energy is NaN on the modal path (the balance is checked on the general path; both paths
    are the same linear algebra).
    """

    out: np.ndarray
    energy: np.ndarray
    final_state: np.ndarray
    implicit_links: np.ndarray
    path: str = "general"

    @property
    def energy_residual(self) -> np.ndarray:
        """Stored-energy change minus net energy in [J/m2] (0 up to round-off)."""
        return self.energy[:, 0] - (self.energy[:, 1] - self.energy[:, 2])


_POOL: ThreadPoolExecutor | None = None


def in_threads(part, n: int) -> None:
    """Run ``part(slice)`` over ``n`` candidates split into contiguous chunks, one per thread (the
    kernels release the GIL). Each part writes its candidates' results into arrays that the caller
    allocated once for the whole batch, in its own thread: the outputs are neither copied nor
    allocated per thread (on the batch of 256 they are 24 MB, and memory that worker threads allocate
    and release is page-faulted in again on the next call). Threads: numba's ``NUMBA_NUM_THREADS``
    (the number of cores unless set). A single chunk (one candidate, or one thread) runs on the calling
    thread as ``part(None)``: all candidates, nothing to slice.
    """
    global _POOL
    n_threads = min(n, max(1, int(numba.config.NUMBA_NUM_THREADS)))
    if n_threads <= 1:
        part(None)
        return
    if _POOL is None or _POOL._max_workers < n_threads:
        _POOL = ThreadPoolExecutor(max_workers=n_threads, thread_name_prefix="wallcal-fd")
    bounds = np.linspace(0, n, n_threads + 1).round().astype(int)
    list(_POOL.map(lambda i: part(slice(bounds[i], bounds[i + 1])), range(n_threads)))


class PreparedFD:
    """A wall, its grid and its boundary data, ready to run candidate walls."""

    def __init__(self, inp: SimulationInput, grid: Grid, stiff_limit: float = DEFAULT_STIFF_LIMIT):
        self.inp = inp
        self.grid = grid
        self.wall = inp.wall
        self.stiff_limit = None if stiff_limit is None else float(stiff_limit)
        if inp.scheme not in SCHEMES:
            raise EngineError(f"simulation scheme must be one of {SCHEMES}, got {inp.scheme!r}")
        self.exact = inp.scheme == "exact"
        self.theta = SCHEME_THETA.get(inp.scheme, 0.5)  # the exact scheme's lambda(T) walls: Crank-Nicolson
        # the theta rule's limit L (operator.link_thetas): 1 / (1 - theta) unless given
        self.theta_limit = self.stiff_limit if self.stiff_limit is not None else 1.0 / max(1.0 - self.theta, 1e-300)
        self._per_size: dict[int, dict[str, np.ndarray]] = {}
        self.dt = float(inp.time_step)
        (code_e, h_e), (code_i, h_i) = (
            boundary.face_parameters(face.type, face.surface_coefficient) for face in (inp.exterior, inp.interior)
        )
        self.bc_type = np.array([code_e, code_i], dtype=np.int64)
        self.bc_h = np.array([h_e, h_i])
        if boundary.imposes_flux(code_e) and boundary.imposes_flux(code_i):
            raise EngineError(
                "heat-flux boundaries on both faces leave the wall's temperature level undetermined: "
                "impose a temperature on at least one face"
            )
        self.ue = np.ascontiguousarray(inp.exterior.values, dtype=float)
        self.ui = np.ascontiguousarray(inp.interior.values, dtype=float)
        pos = np.asarray(inp.output_positions, dtype=float)
        n_steps = len(self.ue) - 1
        if n_steps < 1:
            raise EngineError("the simulation needs at least one time step")
        if len(pos) and (pos.min() < -1e-9 or pos.max() > n_steps + 1e-9 or np.any(np.diff(pos) < 0)):
            raise EngineError("output times must be increasing and inside the simulated period")
        self.out_step, self.out_w = output_steps(pos, n_steps)
        self.probe_names = tuple(inp.probes)
        self.probe_sides = [self.wall.probe(p).side for p in self.probe_names]
        # heat flux at depths: the planes on the grid (a face, or the link and node of an inner plane)
        planes = [depth_plane(grid.x, float(depth)) for _, depth in inp.flux_depths]
        self.depth_face = np.array([f for f, _, _ in planes], dtype=np.int64)
        self.depth_inner = np.flatnonzero(self.depth_face < 0)  # the planes inside the wall
        self.face_planes = [(d, int(f)) for d, f in enumerate(self.depth_face) if f >= 0]  # (plane, face)
        self._all_rows = np.ones(len(self.probe_names) + 2 + len(planes), dtype=np.bool_)  # output rows wanted
        self.depth_link = np.array([planes[d][1] for d in self.depth_inner], dtype=np.int64)
        self.depth_node = np.array([planes[d][2] for d in self.depth_inner], dtype=np.int64)
        # conductivity laws per link (constant over candidates except through g_ref); layers whose
        # temperature coefficient is a calibration parameter use the exponential law even at f = 0
        self.exponential_layers = frozenset(inp.options.exponential_layers)
        # lambda(T): refactorise the tridiagonal matrix when a conductance drifts this much (0: every step)
        self.refactor_drift = float(inp.options.refactor_drift)
        self._laws()
        #: sub-steps per step (the exact scheme on a lambda(T) wall runs Crank-Nicolson at the grid's step)
        self.substeps = 1
        if self.exact and self.nonlinear:
            self.substeps = substeps(self.dt, inp.options.grid_time_step or self.dt)
        if self.substeps > 1:
            k = self.substeps
            self.dt /= k
            self.ue = refine_in_time(self.ue, k)
            self.ui = refine_in_time(self.ui, k)
            self.out_step, self.out_w = output_steps(pos * k, len(self.ue) - 1)

    # ------------------------------------------------------------------ setup
    def _laws(self):
        grid, wall = self.grid, self.wall
        nl = grid.n_links
        kind = np.zeros(nl, dtype=np.int64)
        tref = np.zeros(nl)
        tab_start = np.zeros(nl, dtype=np.int64)
        tab_len = np.zeros(nl, dtype=np.int64)
        tabs_T: list[float] = []
        tabs_v: list[float] = []
        table_of_layer: dict[int, tuple[int, int]] = {}
        for lnk in range(nl):
            li = grid.link_layer[lnk]
            if li < 0 or grid.link_intervals[lnk] == 0.0:
                continue
            layer = wall.layers[li]
            if layer.conductivity_table is not None:
                if li not in table_of_layer:
                    tab = np.asarray(layer.conductivity_table, dtype=float)
                    ref = np.interp(layer.reference_temperature, tab[:, 0], tab[:, 1])
                    table_of_layer[li] = (len(tabs_T), len(tab))
                    tabs_T.extend(tab[:, 0])
                    tabs_v.extend(tab[:, 1] / ref)
                kind[lnk] = LAMBDA_TABLE
                tab_start[lnk], tab_len[lnk] = table_of_layer[li]
            elif layer.conductivity_temperature_coefficient != 0.0 or li in self.exponential_layers:
                kind[lnk] = LAMBDA_EXPONENTIAL
            else:
                kind[lnk] = LAMBDA_CONSTANT
            tref[lnk] = layer.reference_temperature
        self.kind = kind
        self.tref = tref
        self.tab_start = tab_start
        self.tab_len = tab_len
        self.tab_T = np.array(tabs_T if tabs_T else [0.0])
        self.tab_v = np.array(tabs_v if tabs_v else [1.0])
        self.nonlinear = bool((kind != LAMBDA_CONSTANT).any())
        # what grid.assemble_lines reads of the grid; the temperature coefficient f on the exponential links only
        law_layer = np.where(kind == LAMBDA_EXPONENTIAL, grid.link_layer, -1)
        self.links = (grid.link_layer, grid.link_contact_of, grid.link_intervals, law_layer)

    def _sized(self, nc: int) -> dict[str, np.ndarray]:
        """Arrays that depend on the batch size only, formed once per size (the kernels only read them):
        the faces' surface coefficients ``face_h`` (nc, 2) [W/(m2K)], the empty initial state ``no_state``
        (nc, 0), the plane capacities ``no_planes`` (nc, 0) and modal depth weights ``no_depth_weights``
        (nc, 0, 4) of a study without inner depth planes; :meth:`_probe_weights` adds the prepared wall's probe
        depths and their interpolation weights."""
        sized = self._per_size.get(nc)
        if sized is None:
            sized = {
                "face_h": np.repeat(self.bc_h[None, :], nc, axis=0),
                "no_state": np.zeros((nc, 0)),
                "no_planes": np.zeros((nc, 0)),
                "no_depth_weights": np.zeros((nc, 0, 4)),
            }
            self._per_size[nc] = sized
        return sized

    def _face_h(self, nc: int) -> np.ndarray:
        """The faces' surface coefficients [W/(m2K)] for each of nc candidates, shape (nc, 2)."""
        return self._sized(nc)["face_h"]

    def _thetas(self, cap: np.ndarray, g: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """theta per link and per boundary term, and the number of links made implicit."""
        return operator.link_thetas(
            cap, g, self.bc_type, self._face_h(cap.shape[0]), self.theta, self.dt, self.theta_limit
        )

    # ------------------------------------------------------------------ running
    def _probe_weights(self, probe_depths: np.ndarray | None, nc: int) -> tuple[np.ndarray, ...]:
        """Probe interpolation (grid.probe_weights); at the prepared wall's own depths (``probe_depths``
        None or equal to them) computed once per batch size."""
        sized = self._sized(nc)
        if "probe_weights" not in sized:
            sized["probe_depths"] = self.probe_depth_matrix(n=nc)
            sized["probe_weights"] = probe_weights(self.grid, sized["probe_depths"], self.probe_sides)
        if probe_depths is None or np.array_equal(probe_depths, sized["probe_depths"]):
            return sized["probe_weights"]
        return probe_weights(self.grid, np.asarray(probe_depths, dtype=float), self.probe_sides)

    def probe_depth_matrix(self, walls: list[Wall] | None = None, n: int = 1) -> np.ndarray:
        """Probe depths [m], shape (n_candidates, n_probes)."""
        if walls is None:
            return np.tile([self.wall.probe(p).depth for p in self.probe_names], (n, 1)).astype(float)
        return np.array([[w.probe(p).depth for p in self.probe_names] for w in walls], dtype=float)

    @property
    def unknown_range(self) -> tuple[int, int]:
        """(first, count) of the unknown nodes (faces with an imposed temperature are known)."""
        j0, m = operator.unknown_range(self.grid.n_nodes, self.bc_type)
        return int(j0), int(m)

    @functools.cached_property
    def modal_possible(self) -> bool:
        """Whether the exact modal fast path applies: constant conductivities (no lambda(T)) and at
        least one unknown node (:mod:`wallcal.engines.modal`)."""
        return not self.nonlinear and self.unknown_range[1] >= 1

    def run_batch(
        self,
        props: PropertyArrays,
        probe_depths: np.ndarray | None = None,
        initial_state: np.ndarray | None = None,
        path: str = "auto",
        rows: np.ndarray | None = None,
    ) -> BatchResult:
        """Run candidate walls given as property arrays.

        Parameters
        ----------
        props : PropertyArrays
            Layer properties, shape (n_candidates, n_layers) each.
        probe_depths : ndarray, shape (n_candidates, n_probes), optional
            Probe depths [m]; default: the prepared wall's.
        initial_state : ndarray, shape (n_candidates, n_nodes), optional
            Initial node temperatures [degC]; default: steady state of the first boundary values.
        path : {"auto", "modal", "general"}
            ``"auto"`` takes the exact modal fast path when the wall allows it (constant
            conductivities, see :mod:`wallcal.engines.modal`), else the general tridiagonal path.
            The result's ``path`` attribute says which ran.
        rows : ndarray of bool, shape (n_probes + 2 + n_depths,), optional
            Output rows wanted (probes, then exterior and interior flux, then the fluxes at depths); the
            fast path forms only these (the others are NaN), which saves time when calibrating on a few
            targets.
        """
        nc = props.n_candidates
        cap, g, coef, valid = assemble_lines(*props.line_arrays(), *self.links)
        if not valid:
            raise EngineError("candidate wall with non-positive or non-finite properties")
        theta, bc_theta, n_forced = self._thetas(cap, g)
        pa, pb, pw = self._probe_weights(probe_depths, nc)
        if path == "modal" and not self.modal_possible:
            raise EngineError("the modal fast path needs constant conductivities (no lambda(T)); use path='general'")
        cplus = self._plane_capacities(props)
        if self.exact and self.modal_possible:
            if path == "general":
                raise EngineError("the exact scheme runs walls with constant conductivities on the modal path only")
            res = self._run_exact(cap, g, pa, pb, pw, cplus, initial_state, rows)
        elif path in ("auto", "modal") and self.modal_possible:
            res = self._run_modal(cap, g, theta, bc_theta, pa, pb, pw, cplus, initial_state, n_forced, rows)
        else:
            res = self._run_general(cap, g, coef, theta, bc_theta, n_forced, pa, pb, pw, cplus, initial_state)
        npr = len(self.probe_names)
        for d, face in self.face_planes:  # a plane on a face: the face flux
            res.out[:, npr + 2 + d] = res.out[:, npr + face]
        return res

    def _plane_capacities(self, props: PropertyArrays) -> np.ndarray:
        """Per candidate and inner depth plane on a node, the heat capacity [J/(m2K)] of the node's part on
        the interior side of the plane: half the capacity of the interval that starts there (0 for a
        no-mass or contact link, and for a plane between two nodes), shape (n_candidates, n_inner)."""
        grid = self.grid
        if not len(self.depth_link):
            return self._sized(props.n_candidates)["no_planes"]
        out = np.zeros((props.n_candidates, len(self.depth_link)))
        for k, (lnk, node) in enumerate(zip(self.depth_link, self.depth_node, strict=True)):
            li, n = grid.link_layer[lnk], grid.link_intervals[lnk]
            if node >= 0 and li >= 0 and n > 0:
                out[:, k] = 0.5 * props.volumetric_heat_capacity[:, li] * props.thickness[:, li] / n
        return out

    def _run_general(self, cap, g, coef, theta, bc_theta, n_forced, pa, pb, pw, cplus, initial_state) -> BatchResult:
        nc = cap.shape[0]
        sized = self._sized(nc)
        tinit = sized["no_state"] if initial_state is None else np.ascontiguousarray(initial_state, dtype=float)
        cp = cplus / self.dt if cplus.size else cplus
        out = np.full((nc, pa.shape[1] + 2 + len(self.depth_link), len(self.out_step)), np.nan)
        energy = np.zeros((nc, 3))
        tend = np.zeros(cap.shape)
        per_candidate = (cap, g, theta, coef, sized["face_h"], bc_theta, pa, pb, pw, cp, tinit, out, energy, tend)

        def part(sl):
            cap, g, theta, coef, bc_h, bc_theta, pa, pb, pw, cp, t0, o, e, te = (
                per_candidate if sl is None else (a[sl] for a in per_candidate)
            )
            kernels.run_batch(
                (cap, g, theta),
                (self.kind, coef, self.tref, self.tab_start, self.tab_len, self.tab_T, self.tab_v),
                (self.bc_type, bc_h, bc_theta, self.ue, self.ui),
                (self.out_step, self.out_w, pa, pb, pw, self.depth_link, self.depth_node, cp),
                self.dt,
                self.refactor_drift,
                t0,
                (o, e, te),
            )

        in_threads(part, nc)
        out = self._with_depth_rows(out)
        return BatchResult(out=out, energy=energy, final_state=tend, implicit_links=n_forced, path="general")

    def _with_depth_rows(self, out: np.ndarray, inner: np.ndarray | None = None) -> np.ndarray:
        """The output array with one row per flux depth after the face rows: ``inner`` (or the rows after
        the face rows of ``out``) for the planes inside the wall, NaN for the faces' (filled by the caller)."""
        npr = len(self.probe_names)
        if not len(self.depth_face):
            return out[:, : npr + 2]
        if inner is None:
            inner = out[:, npr + 2 :]
        full = np.full((out.shape[0], npr + 2 + len(self.depth_face), out.shape[2]), np.nan)
        full[:, : npr + 2] = out[:, : npr + 2]
        full[:, npr + 2 + self.depth_inner] = inner
        return full

    # ------------------------------------------------------------------ the exact scheme
    def _run_exact(self, cap, g, pa, pb, pw, cplus, initial_state, rows=None) -> BatchResult:
        """The exact scheme (:mod:`wallcal.engines.exact`): one kernel call per thread over the candidates."""
        nc, n_nodes = cap.shape
        npr, n_in = pa.shape[1], len(self.depth_link)
        want = self._all_rows if rows is None else np.asarray(rows, dtype=np.bool_)
        want_x = np.zeros(npr + 2 + n_in, dtype=np.bool_)
        want_x[: npr + 2] = want[: npr + 2]
        if len(want) > npr + 2:
            want_x[npr + 2 :] = want[npr + 2 + self.depth_inner]
            for d in np.flatnonzero(want[npr + 2 :]):
                if self.depth_face[d] >= 0:
                    want_x[npr + self.depth_face[d]] = True
        # f = c+ / c of a plane on a node (0 between nodes)
        if n_in:
            c_node = cap[:, self.depth_link]
            dfr = np.where(c_node > 0, cplus / np.where(c_node > 0, c_node, 1.0), 0.0)
        else:
            dfr = self._sized(nc)["no_planes"]
        dfr = np.ascontiguousarray(dfr)
        if getattr(self, "_exact_plan", None) is None:
            self._exact_plan = exact.exact_plan(self.out_step, self.out_w, self.ue, self.ui, self.dt)
        plan = self._exact_plan
        t0 = self._sized(nc)["no_state"] if initial_state is None else np.ascontiguousarray(initial_state, dtype=float)
        out = np.empty((nc, npr + 2 + n_in, len(self.out_step)))
        tend = np.empty((nc, n_nodes))
        per_candidate = (cap, g, pa, pb, pw, dfr, t0)
        rows_all = np.arange(nc)

        def part(sl):
            c, gg, a, b, w, f, t = per_candidate if sl is None else (x[sl] for x in per_candidate)
            exact.exact_batch(
                c, gg, a, b, w, self.depth_link, f, self.bc_type, self.bc_h, self.dt, self.ue, self.ui, plan,
                want_x, t, rows_all if sl is None else rows_all[sl], out, tend,
            )  # fmt: skip

        in_threads(part, nc)
        if not np.isfinite(tend).all():
            raise EngineError("the modal eigen-decomposition failed (LAPACK's reduction or the QL)")
        out = self._with_depth_rows(out)
        energy = np.full((nc, 3), np.nan)
        return BatchResult(
            out=out, energy=energy, final_state=tend, implicit_links=np.zeros(nc, dtype=np.int64), path="exact"
        )

    # ------------------------------------------------------------------ fast path
    def _output_plan(self, input_thetas: tuple[float, float] | None = None) -> modal.ModalPlan:
        """The modal plan for these input thetas (:func:`wallcal.engines.modal.input_thetas`; default: the
        scheme's theta on both, kept on the prepared engine). A plan for other thetas (a candidate whose
        face terms are stiff) is formed for the call and not kept: it is as large as the record."""
        default = (self.theta, self.theta)
        if input_thetas is not None and input_thetas != default:
            return modal.modal_plan(self.out_step, self.out_w, input_thetas, self.ue, self.ui, self.dt)
        if getattr(self, "_plan", None) is None:
            self._plan = modal.modal_plan(self.out_step, self.out_w, default, self.ue, self.ui, self.dt)
        return self._plan

    def _run_modal(self, cap, g, theta, bc_theta, pa, pb, pw, cplus, initial_state, n_forced, rows=None):
        """The modal path; candidates whose inputs enter through terms with a raised theta run with a
        plan of their own (one call per distinct pair of input thetas).

        A flux at an inner depth plane is the step flux ``F^{n+1/2} = alpha . T^{n+1} + beta . T^n`` of the
        plane's link (plus the storage of the node's interior part, on a node), so the kernel forms two
        rows per plane, one over the new and one over the old level (:func:`wallcal.engines.modal.output_plan`);
        their sum, plus what a known face node on the link adds through its input, is the flux."""
        nc, n_nodes = cap.shape
        npr, n_d = pa.shape[1], len(self.depth_face)
        sized = self._sized(nc)
        want = self._all_rows if rows is None else np.asarray(rows, dtype=np.bool_)
        if n_d:
            want_k, dws = self._modal_depth_rows(theta, g, cplus, want)
        else:
            want_k, dws = want[: npr + 2], sized["no_depth_weights"]
        t0 = sized["no_state"] if initial_state is None else np.ascontiguousarray(initial_state, dtype=float)
        per_candidate = (cap, g, theta, bc_theta, pa, pb, pw, dws, t0)
        out = np.empty((nc, npr + 2 + 2 * len(self.depth_link), len(self.out_step)))
        tend = np.empty((nc, n_nodes))
        if not np.count_nonzero(n_forced):  # no theta raised: every input enters with the scheme's theta
            self._modal_group(per_candidate, None, self._output_plan(), want_k, out, tend)
        else:
            keys = [(a, b) for a, b in modal.input_thetas(theta, bc_theta, self.bc_type).tolist()]
            for key in dict.fromkeys(keys):
                idx = np.flatnonzero([k == key for k in keys])
                self._modal_group(per_candidate, idx, self._output_plan(key), want_k, out, tend)
        if not np.isfinite(tend).all():
            raise EngineError(
                "the modal eigen-decomposition failed: a layer is too thin or too "
                "conductive next to massive ones; declare it massless with thermal_resistance (thickness / "
                "conductivity), or use a shorter simulation.time_step or a smaller grid_constant"
            )
        if n_d:
            inner = out[:, npr + 2 :: 2] + out[:, npr + 3 :: 2] + self._known_node_terms(dws, n_nodes)
            out = self._with_depth_rows(out[:, : npr + 2], inner)
            out[:, npr + 2 :][:, ~want[npr + 2 :]] = np.nan
        energy = np.full((nc, 3), np.nan)  # the balance is the general path's
        return BatchResult(out=out, energy=energy, final_state=tend, implicit_links=n_forced, path="modal")

    def _modal_group(self, per_candidate, idx, plan, want_k, out, tend) -> None:
        """The modal kernel over the candidates ``idx`` (None: all) of ``per_candidate`` (cap, g, theta,
        bc_theta, pa, pb, pw, dws, t0) with one output plan, in threads (:func:`in_threads`), writing
        their rows of ``out`` and ``tend``."""
        n = len(per_candidate[0]) if idx is None else len(idx)
        rows = np.arange(n) if idx is None else idx

        def part(sl):
            i = idx if sl is None else (sl if idx is None else idx[sl])
            cap, g, theta, bc_theta, pa, pb, pw, dws, t0 = per_candidate if i is None else (a[i] for a in per_candidate)
            modal.modal_batch(
                cap, g, theta, bc_theta, pa, pb, pw, self.depth_link, dws, self.bc_type, self.bc_h, self.theta, self.dt,
                self.ue, self.ui, plan, want_k, t0, rows if sl is None else rows[sl], out, tend,
            )  # fmt: skip

        in_threads(part, n)

    def _modal_depth_rows(self, theta, g, cplus, want):
        """The modal kernel's rows wanted (the depth planes' two level rows each; a plane on a face needs
        the face's row) and the planes' weights on their link's nodes (a, a + 1), shape (c, d, 4): new
        level (a, b), old level (a, b)."""
        npr, n_d, n_in = len(self.probe_names), len(self.depth_face), len(self.depth_link)
        if len(want) == npr + 2:
            want = np.concatenate([want, np.zeros(n_d, dtype=np.bool_)])
        want_k = np.zeros(npr + 2 + 2 * n_in, dtype=np.bool_)
        want_k[: npr + 2] = want[: npr + 2]
        for d in np.flatnonzero(want[npr + 2 :]):
            if self.depth_face[d] >= 0:
                want_k[npr + self.depth_face[d]] = True
        inner_want = want[npr + 2 + self.depth_inner]
        want_k[npr + 2 :: 2] = inner_want
        want_k[npr + 3 :: 2] = inner_want
        th, gl = theta[:, self.depth_link], g[:, self.depth_link]
        cp = cplus / self.dt
        dws = np.stack([th * gl + cp, -th * gl, (1.0 - th) * gl - cp, -(1.0 - th) * gl], axis=2)
        return want_k, np.ascontiguousarray(dws)

    def _known_node_terms(self, dws: np.ndarray, n_nodes: int) -> np.ndarray:
        """What a known face node on an inner plane's link adds to the plane's flux at the output times:
        its weights in the new and old level times the input's grid-time values over the new levels
        ``(u^j + u^{j+1}) / 2`` and the old levels ``(u^{j-1} + u^j) / 2`` (one-sided at the ends),
        interpolated to the output times like every output. Shape (n_candidates, n_inner, n_times)."""
        nc, n_in = dws.shape[0], dws.shape[1]
        terms = np.zeros((nc, n_in, len(self.out_step)))
        for f, e, u in ((0, 0, self.ue), (1, 1, self.ui)):
            if not boundary.is_known(self.bc_type[f]):
                continue
            node = 0 if f == 0 else n_nodes - 1
            hit = np.flatnonzero(self.depth_link + e == node)
            if not len(hit):
                continue
            new = np.empty(len(u))
            old = np.empty(len(u))
            new[1:-1] = 0.5 * (u[1:-1] + u[2:])
            old[1:-1] = 0.5 * (u[:-2] + u[1:-1])
            new[0], old[0] = u[1], u[0]
            new[-1], old[-1] = u[-1], u[-2]
            at = [(1.0 - self.out_w) * v[self.out_step] + self.out_w * v[self.out_step + 1] for v in (new, old)]
            for k in hit:
                terms[:, k] += dws[:, k, e, None] * at[0] + dws[:, k, 2 + e, None] * at[1]
        return terms

    def run_walls(self, walls: list[Wall], path: str = "auto") -> BatchResult:
        """Run candidate walls (same layer structure as the prepared wall)."""
        return self.run_batch(PropertyArrays.from_walls(walls), self.probe_depth_matrix(walls), path=path)

    def to_output(self, res: BatchResult, c: int = 0, elapsed: float | None = None) -> EngineOutput:
        """The :class:`EngineOutput` of candidate ``c``."""
        npr = len(self.probe_names)
        temps = {name: res.out[c, k].copy() for k, name in enumerate(self.probe_names)}
        fluxes = {}
        for face in self.inp.flux_faces:
            fluxes[face] = res.out[c, npr + (0 if face == "exterior" else 1)].copy()
        for d, (name, _) in enumerate(self.inp.flux_depths):
            fluxes[name] = res.out[c, npr + 2 + d].copy()
        e_in, e_out = res.energy[c, 1], res.energy[c, 2]
        info = {
            "engine": f"fd-{self.inp.scheme}",
            "path": res.path,
            "nodes": self.grid.n_nodes,
            "nodes_per_layer": list(self.grid.nodes_per_layer),
            "node_rule": self.grid.rule,
            "implicit_links": int(res.implicit_links[c]),
            "substeps": self.substeps,
            "energy_residual_J_m2": None if np.isnan(e_in) else float(res.energy_residual[c]),
            "energy_throughput_J_m2": None if np.isnan(e_in) else float(abs(e_in) + abs(e_out)),
            "nonlinear": self.nonlinear,
        }
        if elapsed is not None:
            info["seconds"] = elapsed
        return EngineOutput(temperatures=temps, fluxes=fluxes, info=info)


class FDEngine(Engine):
    """Finite-volume theta-scheme engine (see module docstring) behind the engine contract.

    :meth:`prepare` returns a :class:`PreparedFD`; :meth:`run` runs it for the prepared wall,
    another wall or a batch through :meth:`PreparedFD.run_batch`.
    """

    capabilities = Capabilities(
        batches=True,
        conductivity_laws=True,
        flux_at_depth=True,
        contact_resistance=True,
        massless_layers=True,
        initial_state=True,
    )

    def __init__(self, scheme: str = "cn"):
        if scheme not in SCHEMES:
            raise EngineError(f"simulation scheme must be one of {SCHEMES}, got {scheme!r}")
        self.scheme = scheme
        self.name = f"fd-{scheme}"
        self._walls: dict[int, tuple[Wall, tuple[str, ...], WallBatch]] = {}  # arrays of recently run walls

    def _batch_of(self, wall: Wall, probes: tuple[str, ...]) -> WallBatch:
        """The arrays of one wall, kept for the walls run last (walls are immutable: a repeated run of the
        same wall object skips rebuilding them)."""
        hit = self._walls.get(id(wall))
        if hit is not None and hit[0] is wall and hit[1] == probes:
            return hit[2]
        batch = WallBatch.from_walls([wall], probes)
        if len(self._walls) >= 8:
            self._walls.pop(next(iter(self._walls)))
        self._walls[id(wall)] = (wall, probes, batch)
        return batch

    def prepare(self, inp: SimulationInput) -> PreparedFD:
        """Grid, boundary series, laws and output plan of ``inp`` (the grid follows C and the time step, or
        ``options.grid_time_step``; contact links at ``options.contact_layers`` even without resistance)."""
        opts = inp.options
        grid_dt = opts.grid_time_step or inp.time_step
        grid = build_grid(inp.wall, grid_dt, inp.grid_constant, inp.node_rule, opts.contact_layers)
        return PreparedFD(inp, grid, stiff_limit=opts.stiff_limit)

    def run(self, prepared: PreparedFD | SimulationInput, walls=None, *, initial_state=None, path: str = "auto"):
        """Run the prepared wall, another wall (:class:`EngineOutput`) or a batch (:class:`BatchOutput`).

        ``prepared`` may be a :class:`SimulationInput` (prepared on the fly); ``initial_state`` node
        temperatures (n_nodes,) or (n_candidates, n_nodes) on the prepared grid, as a ``final_state``;
        ``path`` as in :meth:`PreparedFD.run_batch` (default: the exact modal path when the walls allow it).
        """
        if isinstance(prepared, SimulationInput):
            prepared = self.prepare(prepared)
        t = time.perf_counter()
        inp = prepared.inp
        npr = len(inp.probes)
        if is_batch(walls):
            batch = walls if isinstance(walls, WallBatch) else WallBatch.from_walls(walls, inp.probes)
            rows = np.zeros(npr + 2 + len(inp.flux_depths), dtype=bool)
            rows[:npr] = True
            rows[npr + 2 :] = True
            for face in inp.flux_faces:
                rows[npr + (0 if face == "exterior" else 1)] = True
        else:
            batch = self._batch_of(inp.wall if walls is None else walls, inp.probes)
            rows = None
        depths = batch.probe_depths
        if depths is not None:
            depths = np.asarray(depths, dtype=float).reshape(batch.n, npr)
        if initial_state is not None:
            initial_state = np.broadcast_to(np.asarray(initial_state, dtype=float), (batch.n, prepared.grid.n_nodes))
        res = prepared.run_batch(batch.properties, depths, initial_state=initial_state, path=path, rows=rows)
        if not is_batch(walls):
            out = prepared.to_output(res, 0, elapsed=None)
            wall = inp.wall if walls is None else walls
            check_finite({**out.temperatures, **out.fluxes}, self.name, wall.nonfinite_cause())
            out.info["seconds"] = time.perf_counter() - t
            out.final_state = res.final_state[0]
            return out
        temps = {name: res.out[:, k] for k, name in enumerate(inp.probes)}
        fluxes = {face: res.out[:, npr + (0 if face == "exterior" else 1)] for face in inp.flux_faces}
        for d, (name, _) in enumerate(inp.flux_depths):
            fluxes[name] = res.out[:, npr + 2 + d]
        info = {
            "engine": self.name,
            "path": res.path,
            "nodes": prepared.grid.n_nodes,
            "implicit_links": res.implicit_links,
            "seconds": time.perf_counter() - t,
        }
        return BatchOutput(temperatures=temps, fluxes=fluxes, info=info, final_state=res.final_state)


def output_steps(pos: np.ndarray, n_steps: int) -> tuple[np.ndarray, np.ndarray]:
    """Output times as fractional grid positions ``pos`` -> (step ``nk``, weight ``w``), the time ``nk + w``
    with ``0 <= nk < n_steps`` (the last grid time is ``n_steps - 1`` with ``w = 1``)."""
    step = np.clip(np.floor(pos + 1e-9).astype(np.int64), 0, n_steps - 1)
    return step, np.clip(pos - step, 0.0, 1.0)


def depth_plane(x: np.ndarray, depth: float) -> tuple[int, int, int]:
    """Where the plane at ``depth`` [m] lies on a grid with node depths ``x``: (face, link, node).

    On a face: ``(0, -1, -1)`` (exterior) or ``(1, -1, -1)`` (interior); its flux is the face flux.
    Strictly between two nodes: ``(-1, l, -1)``, the link ``l`` whose flux crosses it. On a node inside
    the wall: ``(-1, k, k)``, the node (the interior-most of the nodes at that depth, so that at a
    contact resistance the plane lies between the contact link and the next layer) and the link that
    leaves it towards the interior. (:func:`wallcal.engines.reference.flux_at_depth` says the same from
    the reference's own grid.)
    """
    n = len(x)
    d = min(max(float(depth), 0.0), float(x[-1]))
    tol = 1e-12 * max(1.0, float(x[-1]))
    on = np.flatnonzero(np.abs(x - d) <= tol)
    if not len(on):
        return -1, int(np.flatnonzero(x < d)[-1]), -1
    k = int(on[-1])
    if k == n - 1:
        return 1, -1, -1
    if on[0] == 0 and d == 0.0:
        return 0, -1, -1
    return -1, k, k

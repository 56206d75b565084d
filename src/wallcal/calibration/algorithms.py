"""Optimisation algorithms over the unit box [0, 1]^n, each evaluating whole batches.

Every algorithm receives ``f(U) -> objectives`` (U: candidates x parameters, in
unit coordinates) and a :class:`Recorder` that keeps the best point, the history
and the checkpoints. ``pso-hj`` is wallcal's own hybrid (after GenOpt's
GPSPSOCCHJ): a particle swarm with constriction coefficient on a mesh, then a
Hooke-Jeeves generalized pattern search from the best point, then (by default)
a bounded least-squares polish whose Jacobian columns are evaluated as one
batch. The others come from well-kept libraries (scipy, cma).

Defaults of ``pso-hj`` (``[calibration.settings]``):

==========================  =======  ===============================================================
setting                     default  meaning
==========================  =======  ===============================================================
particles                   16       swarm size (GenOpt suggests 10-30)
generations                 20       swarm generations
cognitive                   2.8      c1, attraction to the particle's own best (GenOpt default)
social                      1.3      c2, attraction to the neighbourhood best (GenOpt default)
constriction_gain           0.5      kappa in Clerc's constriction chi = 2 kappa / |2 - phi - sqrt(phi^2 - 4 phi)|
max_velocity                0.5      velocity limit, fraction of each parameter's range
topology                    "vonneumann"  neighbourhood: von Neumann lattice, or "gbest"
mesh_divisions              64       the swarm evaluates points of a mesh with range/64 spacing
hj_initial_step             0.0625   Hooke-Jeeves initial step, fraction of the range
mesh_divider                2        step reduction factor
step_reductions             4        Hooke-Jeeves stops after this many step reductions (GenOpt suggests 4)
min_improvement             1e-6     a Hooke-Jeeves move counts as a success only if it lowers the
                                     objective by more than this fraction (flat valleys would otherwise
                                     creep on at one step size for thousands of simulations)
polish                      true     finish with a bounded least-squares polish (for RMSE-type objectives it
                                     minimises the sum of squared RMSE/scale, a smooth surrogate)
polish_max_evaluations      60       Jacobian batches allowed in the polish (each n + 1 simulations)
==========================  =======  ===============================================================
"""

from __future__ import annotations

import json
import math
import os
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import StudyError, closest
from ..schema import Problems, check_number, describe

PSO_HJ_DEFAULTS = {
    "particles": 16,
    "generations": 20,
    "cognitive": 2.8,
    "social": 1.3,
    "constriction_gain": 0.5,
    "max_velocity": 0.5,
    "topology": "vonneumann",
    "mesh_divisions": 64,
    "hj_initial_step": 0.0625,
    "mesh_divider": 2,
    "step_reductions": 4,
    "min_improvement": 1e-6,
    "polish": True,
    "polish_max_evaluations": 60,
}
DE_DEFAULTS = {"popsize": 10, "maxiter": 60, "tol": 1e-8, "mutation": [0.5, 1.0], "recombination": 0.7}
NM_DEFAULTS = {"maxfev": 3000, "xatol": 1e-6, "fatol": 1e-8}
CMA_DEFAULTS = {"sigma0": 0.25, "maxfevals": 4000, "popsize": 0}
LS_DEFAULTS = {"max_nfev": 100, "diff_step": 1e-6}


#: each algorithm's settings and their defaults (``[calibration.settings]``)
DEFAULT_SETTINGS = {
    "pso-hj": PSO_HJ_DEFAULTS,
    "differential-evolution": DE_DEFAULTS,
    "nelder-mead": NM_DEFAULTS,
    "cma-es": CMA_DEFAULTS,
    "least-squares": LS_DEFAULTS,
}
#: whole-number settings that must be >= 1 (the others may be 0: no generations, no reductions, ...)
_AT_LEAST_ONE = ("particles", "mesh_divisions", "mesh_divider")
#: real-valued settings that may be 0 (the others must be > 0)
_MAY_BE_ZERO = ("min_improvement", "tol", "xatol", "fatol", "cognitive", "social")
TOPOLOGIES = ("vonneumann", "gbest")
#: algorithms without a generation state (all but pso-hj) save their checkpoint this often [s]
AUTOSAVE_SECONDS = 1.0


def check_settings(algorithm: str, user: dict, path: str, problems: Problems) -> dict:
    """The user's settings of ``algorithm`` that are valid; every problem recorded at ``path.NAME``.

    A setting must be one of the algorithm's (:data:`DEFAULT_SETTINGS`) and of its default's kind:
    true/false, a whole number (>= 0; >= 1 for swarm and population sizes and mesh divisions), a
    number (> 0, or >= 0 for tolerances and the swarm's attraction coefficients), ``topology`` one
    of :data:`TOPOLOGIES`, ``mutation`` a pair [lower, upper] within [0, 2].
    """
    defaults = DEFAULT_SETTINGS[algorithm]
    out = {}
    for k, v in user.items():
        at = f"{path}.{k}"
        if k not in defaults:
            problems.add(at, f"unknown setting for {algorithm}; {closest(k, defaults)}")
            continue
        d = defaults[k]
        n0 = len(problems)
        if isinstance(d, bool):
            if not isinstance(v, bool):
                problems.add(at, f"must be true or false, got {describe(v)}")
        elif isinstance(d, str):
            if v not in TOPOLOGIES:
                problems.add(at, f"must be one of {', '.join(TOPOLOGIES)}, got {describe(v)}")
        elif isinstance(d, list):
            if not (isinstance(v, list) and len(v) == 2):
                problems.add(at, f"must be a pair [lower, upper], got {describe(v)}")
            else:
                lo = check_number(v[0], at + "[0]", problems, ge=0.0, le=2.0)
                hi = check_number(v[1], at + "[1]", problems, ge=0.0, le=2.0)
                if lo is not None and hi is not None and hi < lo:
                    problems.add(at, f"upper must not be below lower, got [{lo:g}, {hi:g}]")
        elif isinstance(d, int):
            at_least_one = k in _AT_LEAST_ONE or (k == "popsize" and d > 0)  # cma-es: popsize 0 is its default
            v = check_number(v, at, problems, integer=True, ge=1.0 if at_least_one else 0.0)
            v = None if v is None else int(v)
        elif k in _MAY_BE_ZERO:
            v = check_number(v, at, problems, ge=0.0)
        else:
            v = check_number(v, at, problems, gt=0.0, le=1.0 if k == "recombination" else None)
        if len(problems) == n0:
            out[k] = tuple(v) if isinstance(v, list) else v
    return out


def settings_for(algorithm: str, user: dict) -> dict:
    """The algorithm's settings: documented defaults updated by the user's (checked as at load)."""
    problems = Problems()
    checked = check_settings(algorithm, user, "calibration.settings", problems)
    if problems:
        raise StudyError(problems)
    out = dict(DEFAULT_SETTINGS[algorithm])
    out.update(checked)
    return out


# ============================================================================ progress and checkpoints
class Progress:
    """A one-line progress display on stderr (rewritten in place on a terminal)."""

    def __init__(self, label: str, enabled: bool = True, stream=None):
        self.label = label
        self.stream = stream or sys.stderr
        self.enabled = enabled
        self.tty = hasattr(self.stream, "isatty") and self.stream.isatty()
        self.last = 0.0

    def update(self, text: str, force: bool = False):
        if not self.enabled:
            return
        now = time.perf_counter()
        if self.tty:
            self.stream.write(f"\r{self.label}: {text}\033[K")
            self.stream.flush()
        elif force or now - self.last > 2.0:
            self.stream.write(f"{self.label}: {text}\n")
            self.stream.flush()
            self.last = now

    def close(self, text: str | None = None):
        if not self.enabled:
            return
        if text:
            self.update(text, force=True)
        if self.tty:
            self.stream.write("\n")
            self.stream.flush()


@dataclass
class Recorder:
    """Best point, history and checkpoints of one optimisation run.

    ``history`` rows: (evaluations, seconds, best objective). With ``log`` (a list) every batch's objective
    values are kept in order and saved in the checkpoint: a deterministic algorithm resumes by running again
    from its seed while :meth:`start_replay` answers its first batches from that log (no simulation), so it
    reaches the uninterrupted result within the same budget.
    """

    f: callable
    n: int
    progress: Progress | None = None
    checkpoint: Path | None = None
    meta: dict = field(default_factory=dict)
    best_u: np.ndarray | None = None
    best_f: float = math.inf
    evaluations: int = 0
    history: list = field(default_factory=list)
    t0: float = field(default_factory=time.perf_counter)
    seconds_before: float = 0.0
    phase: str = ""
    autosave: bool = False
    last_save: float = 0.0
    log: list | None = None
    replay: list = field(default_factory=list)
    replay_end: dict | None = None

    def __call__(self, U) -> np.ndarray:
        U = np.clip(np.atleast_2d(np.asarray(U, dtype=float)), 0.0, 1.0)
        if self.replay:
            vals = np.asarray(self.replay.pop(), dtype=float)  # (the log is stored reversed: pop from the end)
            if len(vals) != len(U):
                self._replay_failed(f"batch {len(self.log or [])} had {len(vals)} candidates, the run asks {len(U)}")
        else:
            vals = np.asarray(self.f(U), dtype=float)
        if self.log is not None:
            self.log.append(vals.tolist())
        self.evaluations += len(U)
        k = int(np.argmin(vals))
        if vals[k] < self.best_f:
            self.best_f = float(vals[k])
            self.best_u = U[k].copy()
        self.history.append((self.evaluations, self.elapsed, self.best_f))
        if self.replay_end is not None and not self.replay:
            self._end_replay()
        if self.progress:
            self.progress.update(f"{self.phase} evaluations {self.evaluations}, best {self.best_f:.6g}")
        if self.autosave and time.perf_counter() - self.last_save > AUTOSAVE_SECONDS:
            self.save(None)  # algorithms without a resumable state: keep the best point on disk
        return vals

    @property
    def elapsed(self) -> float:
        return self.seconds_before + time.perf_counter() - self.t0

    def save(self, state: dict | None = None):
        """Write the checkpoint atomically (best so far, history, algorithm state, log of batch values)."""
        if self.checkpoint is None or self.best_u is None or self.replay_end is not None:
            return  # nothing evaluated yet, or still replaying (the checkpoint on disk is further on)
        from .checkpoint import FORMAT

        data = {
            "format": FORMAT,
            **self.meta,
            "best_u": self.best_u.tolist(),
            "best_f": self.best_f,
            "evaluations": self.evaluations,
            "seconds": self.elapsed,
            "history": self.history,
            "phase": self.phase,
            "state": state,
        }
        if self.log is not None:
            data["log"] = self.log
        # a new file of our own (never one planted at a fixed name), then renamed over the checkpoint
        fd, tmp = tempfile.mkstemp(prefix=f"{self.checkpoint.name}.", suffix=".tmp", dir=self.checkpoint.parent)
        try:
            with os.fdopen(fd, "w") as fh:
                fh.write(json.dumps(data, default=float))
            os.replace(tmp, self.checkpoint)
        except BaseException:
            Path(tmp).unlink(missing_ok=True)
            raise
        self.last_save = time.perf_counter()

    def restore(self, data: dict):
        """Continue from a checked checkpoint (:func:`wallcal.calibration.checkpoint.load_checkpoint`)."""
        self.best_u = np.array(data["best_u"], dtype=float)
        self.best_f = float(data["best_f"])
        self.evaluations = int(data["evaluations"])
        self.history = [tuple(h) for h in data["history"]]
        self.seconds_before = float(data["seconds"])
        self.phase = str(data.get("phase", ""))

    def start_replay(self, data: dict):
        """Answer the next batches from the checkpoint's log; when it is used up, the run must stand exactly
        where the checkpoint did (evaluations, best point and value), else :class:`CheckpointError`."""
        self.replay = [list(b) for b in reversed(data["log"])]
        self.replay_end = data
        self.log = []

    def check_replayed(self):
        """After the algorithm ended: a replay must have used up the checkpoint's log."""
        if self.replay_end is not None:
            self._replay_failed("the run ended before its log")

    def _replay_failed(self, what: str):
        from .checkpoint import CheckpointError

        raise CheckpointError(
            self.checkpoint, f"the run does not retrace its log ({what}): made by another wallcal, or altered"
        )

    def _end_replay(self):
        end = self.replay_end
        if not (
            self.evaluations == int(end["evaluations"])
            and self.best_f == float(end["best_f"])
            and np.array_equal(self.best_u, np.asarray(end["best_u"], dtype=float))
        ):
            self._replay_failed("its best point or evaluations differ")
        self.replay_end = None
        self.history = [tuple(h) for h in end["history"]]
        self.seconds_before = float(end["seconds"])
        self.t0 = time.perf_counter()


# ============================================================================ pso-hj
def _neighbours(n_particles: int, topology: str) -> list[np.ndarray]:
    if topology == "gbest":
        return [np.arange(n_particles)] * n_particles
    cols = int(math.ceil(math.sqrt(n_particles)))
    rows = int(math.ceil(n_particles / cols))
    out = []
    for i in range(n_particles):
        r, c = divmod(i, cols)
        nb = {i}
        for dr, dc in ((-1, 0), (1, 0), (0, -1), (0, 1)):
            j = ((r + dr) % rows) * cols + (c + dc) % cols
            if j < n_particles:
                nb.add(j)
        out.append(np.array(sorted(nb)))
    return out


class _Cache:
    """Objective values of mesh points already evaluated (keys: rounded unit coordinates)."""

    def __init__(self, rec: Recorder, resolution: float):
        self.rec = rec
        self.res = resolution
        self.values: dict[tuple, float] = {}

    def key(self, u):
        return tuple(np.round(np.asarray(u) / self.res).astype(np.int64).tolist())

    def __call__(self, U) -> np.ndarray:
        U = np.atleast_2d(U)
        keys = [self.key(u) for u in U]
        todo = []
        seen = set()
        for i, k in enumerate(keys):
            if k not in self.values and k not in seen:
                todo.append(i)
                seen.add(k)
        if todo:
            vals = self.rec(U[todo])
            for i, v in zip(todo, vals, strict=True):
                self.values[keys[i]] = float(v)
        return np.array([self.values[k] for k in keys])

    def to_state(self) -> dict:
        """The cache as checkpoint entries (so that a resumed run evaluates no point twice, as the uninterrupted
        one)."""
        return {"cache_keys": [list(k) for k in self.values], "cache_values": list(self.values.values())}

    def restore(self, state: dict) -> None:
        keys = state.get("cache_keys") or []
        self.values = {
            tuple(int(i) for i in k): float(v) for k, v in zip(keys, state.get("cache_values") or [], strict=True)
        }


def _reflect(x, v):
    over = x > 1.0
    under = x < 0.0
    x = np.where(over, 2.0 - x, np.where(under, -x, x))
    v = np.where(over | under, -v, v)
    return np.clip(x, 0.0, 1.0), v


def pso_hj(
    rec: Recorder, n: int, seed: int, settings: dict, u0: np.ndarray, residuals=None, state: dict | None = None
) -> None:
    """Particle swarm (constriction, mesh) + Hooke-Jeeves pattern search + least-squares polish.

    ``state`` (from a checkpoint) resumes where the run stopped.
    """
    s = settings
    rng = np.random.default_rng(seed)
    h_mesh = 1.0 / float(s["mesh_divisions"])
    finest = float(s["hj_initial_step"]) / float(s["mesh_divider"]) ** int(s["step_reductions"])
    cache = _Cache(rec, min(h_mesh, finest) / 4)
    npart = int(s["particles"])
    phi = float(s["cognitive"]) + float(s["social"])
    chi = (
        2 * float(s["constriction_gain"]) / abs(2 - phi - math.sqrt(max(phi * phi - 4 * phi, 0.0)))
        if phi > 4
        else float(s["constriction_gain"])
    )
    vmax = float(s["max_velocity"])
    nbrs = _neighbours(npart, str(s["topology"]))

    def on_mesh(x):
        return np.clip(np.round(x / h_mesh) * h_mesh, 0.0, 1.0)

    st = state or {}
    cache.restore(st)

    def save(state: dict) -> None:
        rec.save({**state, **cache.to_state()})

    if st.get("phase", "pso") == "pso":
        if "x" in st:
            x, v = np.array(st["x"]), np.array(st["v"])
            pbest, pbest_f = np.array(st["pbest"]), np.array(st["pbest_f"])
            gen0 = int(st["generation"])
            rng = np.random.default_rng([seed, gen0])
        else:
            x = rng.uniform(0, 1, (npart, n))
            x[0] = u0  # the base case is one of the particles
            v = rng.uniform(-vmax, vmax, (npart, n)) * 0.5
            xm = on_mesh(x)
            fx = cache(xm)
            pbest, pbest_f = xm.copy(), fx.copy()
            gen0 = 1
        rec.phase = "particle swarm"
        for gen in range(gen0, int(s["generations"])):
            lbest = np.array([pbest[nb[np.argmin(pbest_f[nb])]] for nb in nbrs])
            r1 = rng.uniform(size=(npart, n))
            r2 = rng.uniform(size=(npart, n))
            v = chi * (v + float(s["cognitive"]) * r1 * (pbest - x) + float(s["social"]) * r2 * (lbest - x))
            v = np.clip(v, -vmax, vmax)
            x, v = _reflect(x + v, v)
            xm = on_mesh(x)
            fx = cache(xm)
            better = fx < pbest_f
            pbest[better] = xm[better]
            pbest_f[better] = fx[better]
            save(
                {
                    "phase": "pso",
                    "x": x.tolist(),
                    "v": v.tolist(),
                    "pbest": pbest.tolist(),
                    "pbest_f": pbest_f.tolist(),
                    "generation": gen + 1,
                }
            )
            rng = np.random.default_rng([seed, gen + 1])
        st = {"phase": "hj", "base": rec.best_u.tolist(), "step": float(s["hj_initial_step"]), "reductions": 0}
        save(st)

    if st.get("phase") == "hj":
        rec.phase = "Hooke-Jeeves"
        base = np.array(st["base"])
        step = float(st["step"])
        reductions = int(st["reductions"])
        fb = float(cache(base[None])[0])
        eye = np.eye(n)
        tol = float(s["min_improvement"])

        def explore(center, fc):
            pts = np.vstack([np.clip(center + step * eye, 0, 1), np.clip(center - step * eye, 0, 1)])
            f = cache(pts)
            # composite of every improving coordinate move (the sequential HJ exploratory move, batched)
            comp = center.copy()
            for i in range(n):
                fp, fm = f[i], f[n + i]
                if min(fp, fm) < fc:
                    comp[i] = pts[i, i] if fp <= fm else pts[n + i, i]
            fcomp = cache(comp[None])[0]
            allp = np.vstack([pts, comp[None]])
            allf = np.append(f, fcomp)
            k = int(np.argmin(allf))
            if allf[k] < fc - tol * abs(fc):
                return allp[k], float(allf[k])
            return center, fc

        while reductions <= int(s["step_reductions"]):
            x1, f1 = explore(base, fb)
            if f1 < fb:
                while True:
                    p = np.clip(x1 + (x1 - base), 0, 1)
                    base, fb = x1, f1
                    fp = float(cache(p[None])[0])
                    x2, f2 = explore(p, fp)
                    if f2 < fb - tol * abs(fb):
                        x1, f1 = x2, f2
                    else:
                        break
            else:
                step /= float(s["mesh_divider"])
                reductions += 1
            save({"phase": "hj", "base": base.tolist(), "step": step, "reductions": reductions})
        st = {"phase": "polish"}
        save(st)

    if st.get("phase") == "polish" and s.get("polish", True) and residuals is not None:
        rec.phase = "least-squares polish"
        least_squares_refine(rec, residuals, rec.best_u, max_jacobians=int(s["polish_max_evaluations"]))
    rec.save({"phase": "done"})  # (the cache is no longer needed)


# ============================================================================ least squares
def least_squares_refine(rec: Recorder, residuals, u0, max_jacobians: int = 60, diff_step: float = 1e-6):
    """Bounded least squares (scipy TRF) from u0; the Jacobian's columns are one batch of n + 1 runs.

    ``residuals(U) -> (objective (c,), residuals (c, n_res))``: least squares minimises sum(r^2), which is
    the objective for the squared-error objectives and a smooth surrogate (sum of squared RMSE / scale)
    for the RMSE-type ones; the recorder keeps the true objective of every point evaluated.
    """
    from scipy.optimize import least_squares

    cache: dict[bytes, np.ndarray] = {}

    def res_batch(U):
        f, R = residuals(U)
        # record the evaluations (best point, history)
        rec.evaluations += len(U)
        k = int(np.argmin(f))
        if f[k] < rec.best_f:
            rec.best_f, rec.best_u = float(f[k]), np.clip(U[k], 0, 1).copy()
        rec.history.append((rec.evaluations, rec.elapsed, rec.best_f))
        if rec.progress:
            rec.progress.update(f"{rec.phase} evaluations {rec.evaluations}, best {rec.best_f:.6g}")
        return R

    def fun(u):
        key = np.asarray(u).tobytes()
        if key not in cache:
            cache[key] = res_batch(np.asarray(u)[None])[0]
        return cache[key]

    def jac(u):
        u = np.asarray(u)
        r0 = fun(u)
        n = len(u)
        h = diff_step * np.ones(n)
        U = np.repeat(u[None], n, axis=0)
        # forward differences, backwards where the forward step would leave the box
        sign = np.where(u + h > 1.0, -1.0, 1.0)
        U[np.arange(n), np.arange(n)] += sign * h
        R = res_batch(U)
        return ((R - r0[None]) / (sign * h)[:, None]).T

    lo = np.zeros(len(u0))
    hi = np.ones(len(u0))
    start = np.clip(np.asarray(u0, dtype=float), lo + 1e-12, hi - 1e-12)
    least_squares(
        fun,
        start,
        jac=jac,
        bounds=(lo, hi),
        method="trf",
        x_scale="jac",
        max_nfev=max_jacobians,
        ftol=1e-12,
        xtol=1e-12,
        gtol=1e-12,
    )


# ============================================================================ library algorithms
def differential_evolution(rec: Recorder, n, seed, settings, u0):
    from scipy.optimize import differential_evolution as de

    def f(x):  # vectorized: x has shape (n, S)
        return rec(np.asarray(x).T)

    de(
        f,
        bounds=[(0.0, 1.0)] * n,
        seed=seed,
        vectorized=True,
        updating="deferred",
        polish=False,
        popsize=int(settings["popsize"]),
        maxiter=int(settings["maxiter"]),
        tol=float(settings["tol"]),
        mutation=tuple(settings["mutation"]),
        recombination=float(settings["recombination"]),
        x0=u0,
    )


def nelder_mead(rec: Recorder, n, seed, settings, u0):
    from scipy.optimize import minimize

    minimize(
        lambda u: float(rec(u[None])[0]),
        u0,
        method="Nelder-Mead",
        bounds=[(0.0, 1.0)] * n,
        options={
            "maxfev": int(settings["maxfev"]),
            "xatol": float(settings["xatol"]),
            "fatol": float(settings["fatol"]),
            "adaptive": True,
        },
    )


def cma_es(rec: Recorder, n, seed, settings, u0):
    from ..errors import require

    cma = require("cma", "analysis")
    opts = {"bounds": [0.0, 1.0], "seed": seed + 1, "maxfevals": int(settings["maxfevals"]), "verbose": -9}
    if int(settings["popsize"]):
        opts["popsize"] = int(settings["popsize"])
    es = cma.CMAEvolutionStrategy(list(u0), float(settings["sigma0"]), opts)
    while not es.stop():
        X = np.array(es.ask())
        es.tell(list(X), list(rec(X)))


def least_squares_only(rec: Recorder, residuals, settings, u0):
    least_squares_refine(
        rec, residuals, u0, max_jacobians=int(settings["max_nfev"]), diff_step=float(settings["diff_step"])
    )

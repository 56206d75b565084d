"""Calibrating with EnergyPlus itself: from the fast engine's optimum, a few EnergyPlus runs in parallel.

A study with ``simulation.engine = "energyplus"`` is searched with ``fd-cn`` (EnergyPlus runs no batches;
:func:`wallcal.engines.engine_for`); :func:`refine_with_energyplus` then moves the optimum to where
EnergyPlus itself fits the data best, by output space mapping:

1. EnergyPlus runs at the fast engine's optimum x_0; its target series minus fd-cn's at the same wall is
   the engines' difference d_k(t) (their grids and face treatments differ: about 1e-3 K on the bundled
   example, docs/energyplus.md).
2. fd-cn corrected by that difference, fd(x) + d_k, is minimised by bounded least squares (fd-cn batches,
   milliseconds per wall) from the best point so far, giving x*.
3. EnergyPlus runs at x_k + t (x* - x_k) for t in ``steps`` (one batch on the executor, in parallel); the best
   EnergyPlus objective is the new x_k.

It stops when a round improves the EnergyPlus objective by less than ``tol`` (relative), after ``rounds``
rounds, or before it would exceed ``max_runs`` EnergyPlus runs (1 + 3 per round: at most 13 by default).
The objective is the calibration's own (``calibration.objective`` over the targets, the same valid samples,
the measured signals corrected by the candidates' sensor offsets when the space has ``offset`` parameters).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

#: Fractions of the step from the best point to the corrected fast optimum run in EnergyPlus each round.
STEPS = (0.5, 1.0, 1.5)


@dataclass
class Refinement:
    """Outcome of :func:`refine_with_energyplus`.

    Attributes
    ----------
    runs : int
        EnergyPlus runs made.
    rounds : int
        Rounds of corrected fast search + EnergyPlus batch.
    x_start, x_opt : ndarray
        Parameters [SI units] of the fast engine's optimum and of the best EnergyPlus point.
    f_start, f_opt : float
        The calibration objective in EnergyPlus at those points.
    rmse_start, rmse_opt : dict
        Target -> EnergyPlus RMSE [target unit] at those points.
    wall_opt : Wall
    history : list of (runs, best EnergyPlus objective)
    seconds : float
    """

    runs: int
    rounds: int
    x_start: np.ndarray
    x_opt: np.ndarray
    f_start: float
    f_opt: float
    rmse_start: dict
    rmse_opt: dict
    wall_opt: object
    history: list = field(default_factory=list)
    seconds: float = 0.0

    def table(self) -> pd.DataFrame:
        """EnergyPlus RMSE per target at the fast engine's optimum and after the refinement."""
        return pd.DataFrame(
            {
                "rmse_energyplus_fast_optimum": pd.Series(self.rmse_start),
                "rmse_energyplus_refined": pd.Series(self.rmse_opt),
            }
        ).rename_axis("target")

    def to_json(self, names) -> dict:
        return {
            "energyplus_runs": self.runs,
            "rounds": self.rounds,
            "objective_fast_optimum": self.f_start,
            "objective_refined": self.f_opt,
            "parameters_fast_optimum": dict(zip(names, map(float, self.x_start), strict=True)),
            "parameters_refined": dict(zip(names, map(float, self.x_opt), strict=True)),
            "rmse_fast_optimum": self.rmse_start,
            "rmse_refined": self.rmse_opt,
            "history": [list(h) for h in self.history],
            "seconds": self.seconds,
        }


def refine_with_energyplus(
    study,
    space,
    prepared,
    x0,
    *,
    max_runs: int = 40,
    rounds: int = 4,
    steps=STEPS,
    tol: float = 1e-4,
    max_jacobians: int = 30,
    progress: bool = True,
) -> Refinement:
    """Refine the fast engine's optimum ``x0`` with EnergyPlus runs (module docstring).

    Parameters
    ----------
    study : Study
    space : ParameterSpace
    prepared : Prepared
        The fast engine's data (``prepare(study, needs=BATCH_NEEDS)``).
    x0 : ndarray
        The fast engine's optimum [SI units].
    max_runs : int
        At most this many EnergyPlus runs.
    rounds : int
        At most this many rounds.
    steps : sequence of float
        Fractions of the step to the corrected optimum tried in EnergyPlus each round (in parallel).
    tol : float
        A round that improves the EnergyPlus objective by less than this fraction ends the refinement.
    max_jacobians : int
        Least-squares iterations of each corrected fast search.
    progress : bool

    Returns
    -------
    Refinement
    """
    from ..simulation import prepare
    from . import algorithms as alg
    from .objective import Evaluator, residual_weights

    t0 = time.perf_counter()
    ev = Evaluator(prepared, space)
    prep_e = prepare(study, study.simulation.engine, measurements=prepared.measurements)
    engine = prep_e.engine
    w = residual_weights(space.objective, ev.n_valid, ev.weights, ev.scale)
    prog = alg.Progress("EnergyPlus refinement", enabled=progress)

    def eplus(X) -> np.ndarray:
        inputs = [prep_e.inp.replace(wall=space.wall_at(study.wall, x)) for x in X]
        outs = engine.run_inputs(inputs)
        S = np.empty((len(X), len(ev.keys), ev.y.shape[1]))
        for c, out in enumerate(outs):
            for k, (kind, key) in enumerate(ev.keys):
                S[c, k] = getattr(out, kind)[key]
        return S

    def measured(X):  # the targets' measured signals with the candidates' sensor offsets, if any
        y = ev.y[None]
        return y + space.offsets(X)[:, :, None] if ev.has_offsets else y

    def score(S, X):
        e = np.where(ev.mask[None], S - measured(X), 0.0)
        cse = np.einsum("ctk,ctk->ct", e, e)
        return ev.objective_from(cse), np.sqrt(cse / ev.n_valid[None])

    x0 = np.asarray(x0, dtype=float)
    S_best = eplus(x0[None])
    f, rmse = score(S_best, x0[None])
    runs = 1
    f_start, rmse_start = float(f[0]), rmse[0]
    x_best, f_best, rmse_best, S_best = x0, float(f[0]), rmse[0], S_best[0]
    history = [(runs, f_best)]
    done_rounds = 0
    for r in range(int(rounds)):
        prog.update(f"round {r + 1}: {runs} EnergyPlus runs, best {f_best:.6g}")
        d = np.where(ev.mask, S_best - ev.simulate(x_best[None])[0], 0.0)

        def residuals(U, d=d):
            X = space.from_unit(U)
            S = ev.simulate(X) + d[None]
            e = np.where(ev.mask[None], S - measured(X), 0.0)
            fu = ev.objective_from(np.einsum("ctk,ctk->ct", e, e))
            return np.where(np.isfinite(fu), fu, np.inf), (e * np.sqrt(w)[None, :, None]).reshape(len(U), -1)

        u_best = space.to_unit(x_best)
        rec = alg.Recorder(f=lambda U: residuals(U)[0], n=space.n)
        rec(u_best[None])
        alg.least_squares_refine(rec, residuals, u_best, max_jacobians=int(max_jacobians))
        u_star = rec.best_u
        cand = []
        for t in steps:
            u = np.clip(u_best + float(t) * (u_star - u_best), 0.0, 1.0)
            if not any(np.array_equal(u, c) for c in cand) and not np.array_equal(u, u_best):
                cand.append(u)
        cand = cand[: max(0, int(max_runs) - runs)]
        if not cand:
            break
        X = np.array([space.from_unit(u) for u in cand])
        S = eplus(X)
        runs += len(X)
        done_rounds += 1
        fs, rms = score(S, X)
        k = int(np.argmin(fs))
        improved = fs[k] < f_best * (1.0 - tol)
        if fs[k] < f_best:
            x_best, f_best, rmse_best, S_best = X[k], float(fs[k]), rms[k], S[k]
        history.append((runs, f_best))
        if not improved:
            break
    prog.close(f"{runs} EnergyPlus runs, objective {f_start:.6g} -> {f_best:.6g}")
    targets = list(space.targets)
    return Refinement(
        runs=runs,
        rounds=done_rounds,
        x_start=x0,
        x_opt=np.asarray(x_best, dtype=float),
        f_start=f_start,
        f_opt=f_best,
        rmse_start={t: float(v) for t, v in zip(targets, rmse_start, strict=True)},
        rmse_opt={t: float(v) for t, v in zip(targets, rmse_best, strict=True)},
        wall_opt=space.wall_at(study.wall, x_best),
        history=history,
        seconds=time.perf_counter() - t0,
    )

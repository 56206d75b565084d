"""The calibration objective, evaluated for whole batches of candidate walls.

Objectives (``calibration.objective``), over the target sensors i and their
valid measured samples t (missing values and spikes excluded):

- ``cse``: sum_i sum_t (s_it - y_it)^2, the study's sum of cumulative squared errors
  [unit^2; degC^2 for temperatures];
- ``rmse_accuracy``: sum_i RMSE_i / accuracy_i (dimensionless; heat fluxes and
  temperatures can then be mixed);
- ``weighted_cse``: sum_i w_i CSE_i with the sensors' ``weight``;
- ``weighted_rmse``: sum_i w_i RMSE_i.
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np

from ..engines.fd import FDEngine, PreparedFD
from ..simulation import Prepared
from .space import ParameterSpace


def accuracy_scale(accuracy: float | None, accuracy_relative: float | None, y: np.ndarray) -> float:
    """A sensor's accuracy [unit of the signal] for ``rmse_accuracy``: the absolute one, else the relative one
    times the effective value sqrt(mean(y^2)) of its valid measured samples ``y``."""
    if accuracy is not None:
        return float(accuracy)
    return float(accuracy_relative) * float(np.sqrt(np.mean(np.asarray(y, dtype=float) ** 2)))


def objective_value(kind: str, cse, n_valid, weights, scale) -> np.ndarray:
    """The objective ``kind`` (module docstring) from the CSE per candidate and target.

    Parameters
    ----------
    kind : {"cse", "weighted_cse", "weighted_rmse", "rmse_accuracy"}
    cse : ndarray, shape (c, n_targets)
        Sum of squared errors per candidate and target [unit^2].
    n_valid : ndarray, shape (n_targets,)
        Valid samples per target.
    weights, scale : sequence, length n_targets
        Sensor weights [-] and accuracies [unit] (``scale`` is used by ``rmse_accuracy`` only).

    Returns
    -------
    ndarray, shape (c,)
    """
    cse = np.asarray(cse, dtype=float)
    rmse = np.sqrt(cse / np.asarray(n_valid)[None])
    w = np.asarray(weights, dtype=float)[None]
    if kind == "cse":
        return cse.sum(axis=1)
    if kind == "weighted_cse":
        return (w * cse).sum(axis=1)
    if kind == "weighted_rmse":
        return (w * rmse).sum(axis=1)
    return (rmse / np.asarray(scale, dtype=float)[None]).sum(axis=1)


def residual_weights(kind: str, n_valid, weights, scale) -> np.ndarray:
    """Per-target weights ``w`` of the squared errors in the least-squares residuals ``r = e sqrt(w)``: sum(r^2) is
    the objective for ``cse`` / ``weighted_cse``, and sum_i w_i RMSE_i^2 (``weighted_rmse``) or
    sum_i (RMSE_i / accuracy_i)^2 (``rmse_accuracy``), a smooth surrogate, for the RMSE-type objectives."""
    n_valid = np.asarray(n_valid, dtype=float)
    if kind == "weighted_cse":
        return np.asarray(weights, dtype=float)
    if kind == "weighted_rmse":
        return np.asarray(weights, dtype=float) / n_valid
    if kind == "rmse_accuracy":
        return 1.0 / (np.asarray(scale, dtype=float) ** 2 * n_valid)
    return np.ones(len(n_valid))


class Evaluator:
    """Runs candidate parameter vectors through the batched engine and scores them.

    Parameters
    ----------
    prepared : Prepared
        The study's data on the engine grid (:func:`wallcal.simulation.prepare`).
    space : ParameterSpace
    """

    def __init__(self, prepared: Prepared, space: ParameterSpace):
        self.prepared = prepared
        self.space = space
        study = prepared.study
        inp = prepared.inp
        opts = dict(inp.options)
        opts["exponential_layers"] = frozenset(
            i for p in space.parameters if p.property == "conductivity_temperature_coefficient" for i in p.layers
        )
        inp = dataclasses.replace(inp, options=opts)
        self.engine: PreparedFD = FDEngine(inp.scheme).prepare(inp, contact_layers=space.contact_layers)
        self.wall = study.wall
        # rows of the engine output for each target
        probe_rows = {name: k for k, name in enumerate(self.engine.probe_names)}
        npr = len(self.engine.probe_names)
        self.rows = []
        self.y = []
        self.mask = []
        self.weights = []
        self.scale = []
        self.depth_fluxes = []  # (target index, rows of the three hidden probes, half-interval geometry)
        for name in space.targets:
            s = study.sensor(name)
            if s.quantity == "heat_flux" and s.depth is not None:
                from ..simulation import flux_probe_depths, flux_probe_names

                rows3 = [probe_rows[n] for n in flux_probe_names(name)]
                xs = flux_probe_depths(inp.wall, s.depth)
                halves = []
                for a, b in ((0, 1), (1, 2)):
                    if xs[b] > xs[a]:
                        li = int(
                            np.clip(
                                np.searchsorted(inp.wall.interfaces, 0.5 * (xs[a] + xs[b]), side="right") - 1,
                                0,
                                len(inp.wall.layers) - 1,
                            )
                        )
                        halves.append((rows3[a], rows3[b], xs[b] - xs[a], li))
                self.depth_fluxes.append((len(self.rows), halves))
                self.rows.append(rows3[1])  # placeholder row, replaced by the flux in simulate()
            elif s.quantity == "heat_flux":
                self.rows.append(npr + (0 if s.face == "exterior" else 1))
            else:
                self.rows.append(probe_rows[name])
            y = prepared.measured[name].to_numpy(dtype=float)
            ok = np.isfinite(y)
            self.y.append(np.where(ok, y, 0.0))
            self.mask.append(ok)
            self.weights.append(s.weight)
            self.scale.append(
                accuracy_scale(s.accuracy, s.accuracy_relative, y[ok]) if space.objective == "rmse_accuracy" else 1.0
            )
        self.wanted_rows = np.zeros(npr + 2, dtype=bool)
        self.wanted_rows[self.rows] = True
        for _, halves in self.depth_fluxes:
            for ra, rb, _h, _li in halves:
                self.wanted_rows[[ra, rb]] = True
        self.y = np.array(self.y)
        self.mask = np.array(self.mask)
        self.n_valid = self.mask.sum(axis=1)
        self.probe_params = {p.probe: j for j, p in enumerate(space.parameters) if p.probe is not None}
        self.evaluations = 0
        self.seconds = 0.0

    # ------------------------------------------------------------------ evaluation
    def simulate(self, X: np.ndarray) -> np.ndarray:
        """Target series of every candidate, shape (n_candidates, n_targets, n_times)."""
        X = np.atleast_2d(X)
        t = time.perf_counter()
        props, depths = self.space.properties(self.wall, X)
        pd_ = self.engine.probe_depth_matrix(n=X.shape[0])
        for k, name in enumerate(self.engine.probe_names):
            if name in depths:
                pd_[:, k] = depths[name]
        res = self.engine.run_batch(props, pd_, rows=self.wanted_rows)
        self.evaluations += X.shape[0]
        self.seconds += time.perf_counter() - t
        sim = res.out[:, self.rows, :]
        for k, halves in self.depth_fluxes:  # as simulation.flux_at_depth, with each candidate's properties
            qs, bs = [], []
            for ra, rb, h, li in halves:
                ta, tb = res.out[:, ra, :], res.out[:, rb, :]
                lam = props.conductivity[:, li, None]
                if self.wall.layers[li].is_massless:
                    lam = self.wall.layers[li].thickness / props.thermal_resistance[:, li, None]
                    bs.append(np.zeros((len(X), 1)))
                else:
                    bs.append(np.sqrt(props.conductivity[:, li, None] * props.volumetric_heat_capacity[:, li, None]))
                    f = props.temperature_coefficient[:, li, None]
                    lam = lam * np.exp(f * (0.5 * (ta + tb) - props.reference_temperature[:, li, None]))
                qs.append(lam * (ta - tb) / h)
            if len(qs) == 1:
                sim[:, k, :] = qs[0]
            elif halves[0][3] == halves[1][3] or not (bs[0] + bs[1]).all():
                sim[:, k, :] = 0.5 * (qs[0] + qs[1])
            else:
                sim[:, k, :] = (bs[1] * qs[0] + bs[0] * qs[1]) / (bs[0] + bs[1])
        return sim

    def errors(self, X: np.ndarray) -> np.ndarray:
        """Simulated minus measured at the valid samples (0 elsewhere), shape (c, targets, times)."""
        sim = self.simulate(X)
        return np.where(self.mask[None], sim - self.y[None], 0.0)

    def per_target(self, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """CSE and RMSE per candidate and target, each shape (c, n_targets)."""
        e = self.errors(X)
        cse = np.einsum("ctk,ctk->ct", e, e)
        return cse, np.sqrt(cse / self.n_valid[None])

    def objective_from(self, cse: np.ndarray) -> np.ndarray:
        return objective_value(self.space.objective, cse, self.n_valid, self.weights, self.scale)

    def objective(self, X: np.ndarray) -> np.ndarray:
        """Objective of every candidate (see module docstring), shape (c,)."""
        cse, _ = self.per_target(X)
        out = self.objective_from(cse)
        return np.where(np.isfinite(out), out, np.inf)

    def objective_and_residuals(self, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The objective and the residual vectors of every candidate from one batch run."""
        R = self.residuals(X)
        e2 = self._last_cse
        out = self.objective_from(e2)
        return np.where(np.isfinite(out), out, np.inf), R

    def residuals(self, X: np.ndarray) -> np.ndarray:
        """Residual vectors r with sum(r^2) = objective for the squared-error objectives, shape (c, n_res).

        For the RMSE-type objectives the residuals are scaled so that sum(r^2) is the
        sum of squared RMSE/scale (a smooth surrogate used by least squares).
        """
        e = self.errors(X)
        self._last_cse = np.einsum("ctk,ctk->ct", e, e)
        w = residual_weights(self.space.objective, self.n_valid, self.weights, self.scale)
        r = e * np.sqrt(w)[None, :, None]
        return r.reshape(e.shape[0], -1)  # missing samples carry a zero residual

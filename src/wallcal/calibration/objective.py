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

import math
import time

import numpy as np

from ..engines.base import WallBatch
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


def first_order_lag(x: np.ndarray, step: float, tau: np.ndarray) -> np.ndarray:
    """Series ``x`` (shape (c, n_times)) read by a first-order sensor of response time ``tau`` [s] (shape (c,)),
    sampled every ``step`` [s]: m_t = m_{t-1} + a (x_t - m_{t-1}), a = 1 - exp(-step / tau), m_0 = x_0 (tau 0:
    ``x`` itself)."""
    from scipy.signal import lfilter

    out = np.array(x, dtype=float, copy=True)
    for c, tc in enumerate(np.asarray(tau, dtype=float)):
        if tc > 0:
            a = 1.0 - math.exp(-step / tc)
            out[c] = lfilter([a], [1.0, a - 1.0], x[c], zi=[(1.0 - a) * x[c][0]])[0]
    return out


class Evaluator:
    """Runs candidate parameter vectors through the engine's batch interface and scores them.

    Parameters
    ----------
    prepared : Prepared
        The study's data on the engine grid (:func:`wallcal.simulation.prepare`); its engine must
        run batches (prepare with ``needs=("batches",)``).
    space : ParameterSpace
    """

    def __init__(self, prepared: Prepared, space: ParameterSpace):
        self.prepared = prepared
        self.space = space
        study = prepared.study
        if not prepared.engine.capabilities.batches:
            from ..errors import EngineError

            raise EngineError(
                f"the {prepared.engine_name} engine runs no batches: prepare the data with needs=('batches',)"
            )
        # the engine input asks for the targets only; layers whose temperature coefficient or contact
        # resistance is a parameter get the exponential law and a contact link even at zero
        sensors = [study.sensor(name) for name in space.targets]
        self.inp = prepared.inp.replace(
            probes=tuple(s.name for s in sensors if s.quantity == "temperature"),
            flux_faces=tuple(dict.fromkeys(s.face for s in sensors if s.quantity == "heat_flux" and s.depth is None)),
            flux_depths=tuple((s.name, s.depth) for s in sensors if s.quantity == "heat_flux" and s.depth is not None),
            options=prepared.inp.options.replace(
                exponential_layers=frozenset(
                    i
                    for p in space.parameters
                    if p.property == "conductivity_temperature_coefficient"
                    for i in p.layers
                ),
                contact_layers=space.contact_layers,
            ),
        )
        self.engine = prepared.engine
        self.engine_prepared = self.engine.prepare(self.inp)
        self.wall = study.wall
        self.keys = []  # (kind, key) of each target in the engine output
        self.y = []
        self.mask = []
        self.weights = []
        self.scale = []
        for s in sensors:
            if s.quantity == "heat_flux":
                self.keys.append(("fluxes", s.name if s.depth is not None else s.face))
            elif s.quantity in ("relative_humidity", "water_content"):  # the moisture engines' outputs
                self.keys.append((s.quantity, s.name))
            else:
                self.keys.append(("temperatures", s.name))
            y = prepared.measured[s.name].to_numpy(dtype=float)
            ok = np.isfinite(y)
            self.y.append(np.where(ok, y, 0.0))
            self.mask.append(ok)
            self.weights.append(s.weight)
            self.scale.append(
                accuracy_scale(s.accuracy, s.accuracy_relative, y[ok]) if space.objective == "rmse_accuracy" else 1.0
            )
        self.y = np.array(self.y)
        self.mask = np.array(self.mask)
        self.n_valid = self.mask.sum(axis=1)
        self.evaluations = 0
        self.seconds = 0.0
        self.has_offsets = any(p.property == "offset" for p in space.parameters)
        t = prepared.times
        #: the outputs' sampling interval [s] (the median: a response time filters at this step)
        self.step = float(np.median((t[1:] - t[:-1]).total_seconds())) if len(t) > 1 else 1.0

    # ------------------------------------------------------------------ evaluation
    def simulate(self, X: np.ndarray) -> np.ndarray:
        """Target series of every candidate, shape (n_candidates, n_targets, n_times)."""
        X = np.atleast_2d(X)
        t = time.perf_counter()
        props, depths = self.space.properties(self.wall, X)
        probes = self.inp.probes
        pd_ = np.tile([self.inp.wall.probe(p).depth for p in probes], (X.shape[0], 1)).astype(float)
        for k, name in enumerate(probes):
            if name in depths:
                pd_[:, k] = depths[name]
        out = self.engine.run(self.engine_prepared, WallBatch(props, pd_))
        sim = np.empty((X.shape[0], len(self.keys), self.y.shape[1]))
        for k, (kind, key) in enumerate(self.keys):
            sim[:, k] = getattr(out, kind)[key]
        for k, tau in self.space.response_times(X).items():  # probes read through a first-order lag
            sim[:, k] = first_order_lag(sim[:, k], self.step, tau)
        self.evaluations += X.shape[0]
        self.seconds += time.perf_counter() - t
        return sim

    def errors(self, X: np.ndarray) -> np.ndarray:
        """Simulated minus measured at the valid samples (0 elsewhere), shape (c, targets, times).

        The measured signal includes the candidates' sensor offsets (``offset`` parameters), if any.
        """
        sim = self.simulate(X)
        y = self.y[None]
        if self.has_offsets:
            y = y + self.space.offsets(X)[:, :, None]
        return np.where(self.mask[None], sim - y, 0.0)

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

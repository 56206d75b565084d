"""The held-out validation window: ``[period] validation_start .. validation_end``.

No fitting sees the window: :func:`wallcal.simulation.prepare` leaves its measured values out of the comparison
period (inside ``[start, end]``, the fitting uses the rest of the period), and the window is scored apart, on a
study whose comparison period is the window itself (:func:`validation_study`: simulated from the warm-up start
through the window's end, so a window after ``end`` is a forecast from the fitted period). ``calibrate``,
``diagnose`` and ``posterior`` write its scores as ``validation.csv`` (columns
:data:`wallcal.metrics.VALIDATION_COLUMNS`: ``sensor, rmse, mbe, n``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from . import metrics as _metrics
from .errors import DataError
from .metrics import VALIDATION_CSV
from .metrics import write_validation as write  # noqa: F401 (validation.write: the writer of validation.csv)
from .study import PeriodSpec, Study

#: the file every command that fits writes when the study has a validation window


def validation_study(study: Study) -> Study | None:
    """The study whose comparison period is the validation window (same warm-up start), or None without one."""
    p = study.period
    if p.validation is None:
        return None
    return study.replace(
        period=PeriodSpec(warmup_start=p.warmup_start or p.start, start=p.validation_start, end=p.validation_end)
    )


def prepare_window(study: Study, batches: bool = True, **settings):
    """The validation window's data prepared for the engine (for batches by default); None without a window.
    ``settings``: ``engine``, ``time_step``, ``grid_constant``, ``node_rule`` instead of the study's."""
    from .simulation import BATCH_NEEDS, prepare

    vs = validation_study(study)
    if vs is None:
        return None
    try:
        return prepare(vs, needs=BATCH_NEEDS if batches else (), purpose="the held-out validation", **settings)
    except DataError as exc:
        raise DataError(
            f"period.validation_start/validation_end ({study.period.validation_start} .. "
            f"{study.period.validation_end}): the window must lie inside the data; {exc}"
        ) from None


def score_wall(
    study: Study,
    wall=None,
    offsets: dict[str, float] | None = None,
    response_times: dict[str, float] | None = None,
    **settings,
) -> pd.DataFrame | None:
    """Every sensor's RMSE and MBE over the validation window with ``wall`` (default the study's).

    ``offsets``: sensor -> correction [degC or W/m2] added to its measured signal (calibrated ``offset``
    parameters); ``response_times``: probe -> first-order response time [s] of its reading (calibrated
    ``response_time`` parameters); ``settings``: ``engine``, ``time_step``, ``grid_constant``, ``node_rule``
    instead of the study's. None when the study has no validation window.
    """
    prep = prepare_window(study, batches=False, **settings)
    if prep is None:
        return None
    from .simulation import simulate

    res = simulate(prep.study, prepared=prep, wall=wall)
    names = [s.name for s in study.sensors]
    y = res.measured[names].to_numpy(dtype=float).T
    if offsets:
        y = y + np.array([offsets.get(n, 0.0) for n in names])[:, None]
    sim = res.simulated[names].to_numpy(dtype=float).T
    if response_times:
        from .calibration.objective import first_order_lag

        t = prep.times
        step = float(np.median((t[1:] - t[:-1]).total_seconds())) if len(t) > 1 else 1.0
        for k, n in enumerate(names):
            if response_times.get(n, 0.0) > 0:
                sim[k] = first_order_lag(sim[k][None], step, np.array([response_times[n]]))[0]
    return _metrics.validation_table(names, y, sim)


class Validator:
    """Scores parameter vectors of a calibration space on the validation window (each call one engine batch).

    Parameters
    ----------
    study : Study
        With a validation window.
    space : ParameterSpace
        Of this study (or of an extension of it: same wall and sensors).
    prepared : Prepared, optional
        :func:`prepare_window` of the study, to share between several spaces.
    """

    def __init__(self, study: Study, space, prepared=None):
        from .calibration.objective import Evaluator

        prep = prepared if prepared is not None else prepare_window(study, batches=True)
        if prep is None:
            raise DataError("period.validation_start: the study has no validation window")
        self.prepared = prep
        self.ev = Evaluator(prep, space)
        self.targets = tuple(space.targets)

    @property
    def times(self) -> pd.DatetimeIndex:
        return self.prepared.times

    def simulate(self, X) -> np.ndarray:
        """Target series, shape (c, n_targets, n_times)."""
        return self.ev.simulate(np.atleast_2d(X))

    def measured(self, X) -> np.ndarray:
        """Measured target series with the candidates' offsets, shape (c, n_targets, n_times); NaN missing."""
        X = np.atleast_2d(X)
        y = self.ev.y[None] + self.ev.space.offsets(X)[:, :, None]
        return np.where(self.ev.mask[None], y, np.nan)

    def rmse(self, X) -> np.ndarray:
        """Held-out RMSE per candidate and target, shape (c, n_targets)."""
        e = self.ev.errors(np.atleast_2d(X))
        return np.sqrt(np.einsum("ctk,ctk->ct", e, e) / np.maximum(self.ev.n_valid[None], 1))

    def table(self, x) -> pd.DataFrame:
        """:data:`wallcal.metrics.VALIDATION_COLUMNS` of every target at ``x``."""
        x = np.atleast_2d(x)
        return _metrics.validation_table(self.targets, self.measured(x)[0], self.simulate(x)[0])


def read(directory: str | Path) -> pd.DataFrame | None:
    """``validation.csv`` of an output directory, or None when absent."""
    path = Path(directory) / VALIDATION_CSV
    return pd.read_csv(path) if path.exists() else None

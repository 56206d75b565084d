"""Let the data choose the model structure: ``wallcal diagnose``.

Starting from a calibrated wall, :func:`diagnose` looks at the residuals of each target (bias, lag,
daily pattern), proposes structural extensions of the calibration's parameter space -

- ``depth[P]``: the depth of probe P (a sensor placed a few millimetres off its nominal depth),
- ``contact_resistance[L]``: a contact resistance at each layer interface next to a target probe,
- ``conductivity_temperature_coefficient[L...]``: lambda(T) of each insulation layer or tied group, and of all
  of them sharing one coefficient,
- ``offset[S]``: a constant offset of target sensor S beyond the bias its accuracy allows,

and scores each, and each useful combination, by recalibrating warm-started from the calibrated point
(the study's objective with each target's sensor bias profiled out, :func:`debiased_residuals`; bounded
Levenberg-Marquardt: :func:`refine`; each Jacobian one engine batch). The score is the Bayesian information
criterion on the AR(1) likelihood of the residuals at the recalibrated point, each target's constant sensor bias
integrated out under the posterior's prior N(0, (accuracy/2)^2) (see :func:`ar1_loglike` and
``docs/identifiability.md``, "Choosing the model structure"):

    BIC = -2 sum_k log L_k(AR(1) + bias, phi_k and sigma_k at their maximum) + p ln N

with p the calibration parameters and N the residual pairs over all targets. An extension (or a set) is
adopted when it lowers BIC by at least :data:`ADOPT_DELTA` (10: "very strong" evidence) against the
structure adopted so far (forward selection; the close contenders of each step fitted to convergence first;
extensions within :data:`TIE_DELTA` of the best adopted together), or by :data:`WEAK_DELTA` (2: "positive") while
the structure so far holds some of the study's parameters at a bound of their prior box and the extension frees
one of them: such a structure fails its own check and is no null worth protecting. The extended study
(:attr:`Diagnosis.study`) is the study with the adopted extensions added to its ``[calibration]`` table.

This module is the run and its result; beside it, :mod:`.diagnose_candidates` (the residual analysis and the
proposed extensions), :mod:`.diagnose_scoring` (the criterion and the warm-started recalibration) and
:mod:`.diagnose_adoption` (forward selection). Their names are importable from here.
"""

from __future__ import annotations

import copy
import json
import math
import os
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from ..errors import StudyError, WallcalError

# the candidates, their scoring and the adoption rule live beside this module (the run and its result); their
# names are importable from here as before
from .diagnose_adoption import (  # noqa: F401
    ADOPT_DELTA,
    BOUND_BAND,
    MAX_ADOPTED,
    MAX_TRIALS,
    POLISH_MARGIN,
    TIE_DELTA,
    WEAK_DELTA,
    forward_select,
    held_at_bounds,
)
from .diagnose_candidates import (  # noqa: F401
    COEFFICIENT_PLAUSIBLE,
    COEFFICIENT_RANGE,
    CONTACT_BOUNDS,
    CONTACT_PLAUSIBLE,
    DEPTH_RANGE,
    INSULATION_LAMBDA,
    OFFSET_ACCURACIES,
    OFFSET_PLAUSIBLE_ACCURACIES,
    OFFSET_SPREAD,
    PROBE_TOLERANCE,
    Extension,
    common_step,
    plausibility,
    propose,
    residual_analysis,
    unit_label,
)
from .diagnose_scoring import (  # noqa: F401
    FTOL,
    MAX_JACOBIANS,
    SCORE_RESOLUTION,
    ar1_loglike,
    ar1_profile,
    block_means,
    debiased_residuals,
    refine,
)

__all__ = [
    "ADOPT_DELTA",
    "WEAK_DELTA",
    "Diagnosis",
    "Extension",
    "ar1_loglike",
    "debiased_residuals",
    "diagnose",
    "forward_select",
    "held_at_bounds",
    "node_starts",
    "propose",
    "residual_analysis",
]

#: prior sd of a target's constant sensor bias, integrated out of the criterion, as a share of its stated
#: accuracy (a 95 % bound: its sd is about half of it; the posterior's error model)
BIAS_ACCURACY_SHARE = 0.5
#: the base structure's re-polish (and a close contender's) may take this many times the Jacobians of a candidate's
BASE_JACOBIANS = 4
#: a probe depth that starts on a contact's double node is also fitted from this far off it on each side [m]
#: (at most NODE_SHARE of its range; see :func:`node_starts`)
NODE_STEP = 0.001
NODE_SHARE = 0.1
CRITERION = "delta_bic"


# ============================================================================ the result
@dataclass
class Diagnosis:
    """Outcome of :func:`diagnose`.

    Attributes
    ----------
    adopted : list of str
        Names of the adopted extensions ([] when the data support the study's structure).
    candidates : DataFrame
        One row per candidate or combination scored, the columns of ``candidates.csv``: ``extension``
        (names joined by " + "), ``delta_bic`` (BIC change against the study's structure; negative: better),
        ``RMSE <target>`` for every target [its unit], ``adopted`` (the row of the adopted set).
    study : Study
        The study with the adopted extensions added to its ``[calibration]`` table (loadable and runnable
        like :func:`wallcal.load_study`'s; relative paths resolve against the original study's folder).
    residuals : DataFrame
        :func:`residual_analysis` at the calibrated point of the study's structure.
    extensions : list of Extension
        Every candidate proposed.
    x : dict
        Parameter name -> value [SI] at the recalibrated optimum of the adopted structure.
    """

    adopted: list
    candidates: pd.DataFrame
    study: object
    residuals: pd.DataFrame
    extensions: list
    x: dict
    base_study: object
    rmse_base: dict
    bic_base: float
    n_pairs: int
    evaluations: int = 0
    seconds: float = 0.0
    raw: dict = field(default_factory=dict, repr=False)
    notes: list = field(default_factory=list)
    validation: pd.DataFrame | None = None  # validation.csv: the adopted structure on the held-out window
    validation_base: dict = field(default_factory=dict)  # target -> held-out RMSE of the study's structure

    # ------------------------------------------------------------------ words
    def summary(self) -> str:
        """Which structure the data support and by how much, in words."""
        study = self.base_study
        units = {t: unit_label(study, t) for t in self.rmse_base}
        c = self.candidates
        lines = []
        if self.adopted:
            row = c[c["adopted"]].iloc[0]
            rm = ", ".join(f"{t} {self.rmse_base[t]:.3f} -> {row[f'RMSE {t}']:.3f} {units[t]}" for t in self.rmse_base)
            vals = ", ".join(f"{n} = {self.x[n]:.4g}" for n in self.adopted)
            if self.validation is not None:
                held = ", ".join(
                    f"{t} {self.validation_base[t]:.3f} -> {row[f'validation RMSE {t}']:.3f} {units[t]}"
                    for t in self.rmse_base
                )
                lines.append(
                    f"The held-out window supports extending the calibration with {' + '.join(self.adopted)}: "
                    f"held-out RMSE {held} (every temperature target lower, every value plausible; BIC change "
                    f"{row[CRITERION]:+.1f}, adoption refuses a rise of {ADOPT_DELTA:g} or more). In-sample RMSE "
                    f"{rm}. Recalibrated values: {vals}."
                )
            else:
                lines.append(
                    f"The data support extending the calibration with {' + '.join(self.adopted)}: BIC falls by "
                    f"{-row[CRITERION]:.1f} against the study's structure (adoption needs a fall of at least "
                    f"{ADOPT_DELTA:g}). RMSE {rm}. Recalibrated values: {vals}."
                )
        elif self.validation is not None:
            lines.append(
                "The data support the study's structure: no plausible candidate extension lowers the held-out RMSE "
                "of every temperature target."
            )
        else:
            lines.append(
                f"The data support the study's structure: no candidate extension lowers BIC by {ADOPT_DELTA:g} or more."
            )
        single = ~c["extension"].str.contains(r" \+ ", regex=True)
        rest = c[single & ~c["extension"].isin(self.adopted)].sort_values(CRITERION)
        if len(rest):
            best = rest.iloc[0]
            lines.append(
                f"Best candidate left out: {best['extension']} (delta BIC {best[CRITERION]:+.1f} on its own); "
                f"{len(c)} candidates and combinations scored ({self.evaluations} simulations, {self.seconds:.1f} s)."
            )
        r = self.residuals
        feats = []
        for t, row in r.iterrows():
            feats.append(
                f"{t}: RMSE {row['rmse']:.3f} {units.get(t, '')}, bias {row['bias']:+.3f}, lag {row['lag_min']:+.1f} "
                f"min, daily pattern {row['daily_amplitude']:.3f} peak to peak ({100 * row['daily_share']:.0f} % of "
                f"the variance), phi {row['phi']:.3f}"
                + (f", largest step of its daily mean {row['step']:+.3f} at {row['step_at']}" if row["step_at"] else "")
            )
        lines.append("Residuals of the calibrated study structure: " + "; ".join(feats) + ".")
        lines += self.notes
        return "\n".join(lines)

    def to_json(self) -> dict:
        return {
            "adopted": list(self.adopted),
            "criterion": "BIC on the AR(1) likelihood of the residuals, each target's sensor bias integrated out "
            "(prior sd half its accuracy)",
            "adopt_delta": ADOPT_DELTA,
            "weak_delta": WEAK_DELTA,
            "bic_base": self.bic_base,
            "residual_pairs": self.n_pairs,
            "rmse_base": self.rmse_base,
            "values": self.x,
            "extensions": [
                {"name": e.name, "kind": e.kind, "table": e.table, "reason": e.reason} for e in self.extensions
            ],
            "evaluations": self.evaluations,
            "seconds": self.seconds,
            "summary": self.summary(),
        }

    def study_toml(self, out_dir) -> str:
        """The extended study as TOML, with every relative path rewritten to resolve from ``out_dir``."""
        import tomli_w

        raw = _relocate(self.raw, self.base_study, Path(out_dir))
        src = self.base_study.path or "the study"
        head = (
            f"# wallcal diagnose: {src} with the adopted extensions "
            f"({', '.join(self.adopted) if self.adopted else 'none'}) added to [calibration];\n"
            "# relative paths point to the original study's files.\n"
        )
        return head + tomli_w.dumps(raw)

    def write_into(self, d: Path) -> list[str]:
        """Write ``candidates.csv``, ``study.toml``, ``residuals.csv`` and ``diagnose.json`` into ``d``."""
        from ..study import load_study

        d = Path(d)
        self.candidates.to_csv(d / "candidates.csv", index=False, float_format="%.6g")
        (d / "study.toml").write_text(self.study_toml(d))
        self.residuals.to_csv(d / "residuals.csv", float_format="%.6g")
        (d / "diagnose.json").write_text(json.dumps(self.to_json(), indent=2, default=float))
        load_study(d / "study.toml")  # the written study must load (relative paths resolve)
        from ..validation import write as write_validation

        return ["candidates.csv", "study.toml", "residuals.csv", "diagnose.json"] + write_validation(self.validation, d)

    def write(self, out_dir) -> Path:
        """Write every output atomically into ``out_dir`` (it appears only when complete)."""
        from ..outputs import output_dir
        from ..simulation import manifest_of

        target = Path(out_dir).resolve()
        with output_dir(target, manifest=manifest_of(self.base_study, "diagnose")) as tmp:
            # tmp sits next to target: paths relative to target resolve from tmp too
            self.write_into(Path(tmp))
        return target


def _relocate(raw: dict, study, out_dir: Path) -> dict:
    """A copy of the study's TOML tables with every file path relative to the study made relative to
    ``out_dir`` (data files, wall file, reference wall, a weather file next to the study)."""
    raw = copy.deepcopy(raw)
    base = Path(study.path).resolve().parent if study.path else Path.cwd()
    out_dir = Path(out_dir).resolve()

    def move(value):
        if not isinstance(value, str) or Path(value).is_absolute():
            return value
        target = (base / value).resolve()
        if os.path.commonpath([target, out_dir]) == os.path.sep:
            return str(target)  # nothing in common but the root: an absolute path reads better
        return os.path.relpath(target, out_dir)

    wall = raw.get("wall")
    if isinstance(wall, dict) and "file" in wall:
        wall["file"] = move(wall["file"])
    data = raw.get("data")
    if isinstance(data, dict):
        if "file" in data:
            data["file"] = move(data["file"])
        for f in data.get("files", []) or []:
            if isinstance(f, dict) and "file" in f:
                f["file"] = move(f["file"])
    cal = raw.get("calibration")
    if isinstance(cal, dict) and "reference_wall" in cal:
        cal["reference_wall"] = move(cal["reference_wall"])
    ret = raw.get("retrofit")
    if isinstance(ret, dict) and isinstance(ret.get("weather"), str) and (base / ret["weather"]).is_file():
        ret["weather"] = move(ret["weather"])
    return raw


# ============================================================================ the run
def _values_from_wall(space, wall, study) -> np.ndarray:
    ids = [layer.id for layer in study.wall.layers]
    if [layer.id for layer in wall.layers] != ids:
        raise WallcalError(
            f"the starting wall's layers ({', '.join(layer.id for layer in wall.layers)}) are not the study's "
            f"({', '.join(ids)})"
        )
    depths = {p.name: p.depth for p in wall.probes}
    out = []
    for p in space.parameters:
        if p.sensor is not None:
            out.append(0.0)
        elif p.probe is not None:
            out.append(depths.get(p.probe, p.base))
        else:
            v = getattr(wall.layers[p.layers[0]], p.property)
            out.append(p.base if v is None else float(v))
    return np.array(out, dtype=float)


def start_point(study, space, start, progress) -> tuple[np.ndarray, str]:
    """The calibrated parameter values [SI] to start from, and where they came from."""
    from ..wall import Wall

    if start is None:
        from ..calibration import calibrate

        res = calibrate(study, progress=progress is True, space=space)
        return res.x_opt, f"calibrated now ({res.algorithm}, {res.evaluations} simulations)"
    if hasattr(start, "x_opt") and hasattr(start, "space"):  # a CalibrationResult
        vals = dict(zip(start.space.names, start.x_opt, strict=True))
        x = np.array([vals.get(p.name, p.base) for p in space.parameters], dtype=float)
        return x, "the calibration result given"
    if isinstance(start, Wall):
        return _values_from_wall(space, start, study), "the wall given"
    path = Path(start)
    if path.is_dir():
        from . import load_optimum

        return load_optimum(space, path), f"{path / 'calibration.json'}"
    if path.is_file():
        from ..study import load_wall

        return _values_from_wall(space, load_wall(path), study), str(path)
    raise WallcalError(f"--from {start}: no such calibration output directory or wall file")


def node_starts(space, wall, contact_layers, x) -> list[np.ndarray]:
    """The starts of a recalibration from ``x``: ``x`` itself, and where a probe's depth starts on a contact's
    double node, also just off the node on each side.

    At a contact link the grid has two nodes at one depth (:func:`wallcal.grid.contact_node_depths`); a probe
    on it reads one side or the mean of both, so its reading - and the objective - jumps when the depth moves off
    the node either way. A gradient fit (finite-difference Jacobians) started on the node cannot leave it; started
    :data:`NODE_STEP` (at most :data:`NODE_SHARE` of the range) to either side, inside the bounds, it follows the
    objective on that side. Each such depth gets the three values (on, before and after the node); several such
    depths, every combination.

    Parameters
    ----------
    space : ParameterSpace
    wall : Wall
        The wall the engine builds its grid from.
    contact_layers : set of int
        Layers with a contact link even at zero resistance (the engine input's ``options.contact_layers``).
    x : ndarray, shape (n,)
        Parameter values [SI].

    Returns
    -------
    list of ndarray, shape (n,)
        ``x`` first.
    """
    from ..grid import contact_node_depths, node_tolerance

    x = np.asarray(x, dtype=float)
    nodes = np.array(list(contact_node_depths(wall, contact_layers).values()))
    tol = node_tolerance(wall.thickness)
    starts = [x]
    for j, p in enumerate(space.parameters):
        if p.probe is None or not len(nodes) or np.abs(nodes - x[j]).min() > tol:
            continue
        step = min(NODE_STEP, NODE_SHARE * (p.upper - p.lower))
        values = [v for v in (x[j] - step, x[j] + step) if p.lower <= v <= p.upper]
        more = []
        for s in starts:
            for v in values:
                t = s.copy()
                t[j] = v
                more.append(t)
        starts = starts + more
    return starts


class _Say:
    def __init__(self, progress):
        from ..calibration.algorithms import Progress

        self.fn = progress if callable(progress) else None
        self.bar = Progress("diagnose", enabled=progress is True)

    def __call__(self, text: str, force: bool = False):
        if self.fn is not None:
            self.fn(text)
        self.bar.update(text, force=force)

    def close(self, text: str):
        if self.fn is not None:
            self.fn(text)
        self.bar.close(text)


@dataclass
class _Fit:
    names: tuple
    x: np.ndarray  # SI, of the space of this structure
    space: object
    bic: float
    rmse: np.ndarray
    ll: float


def _period_table(table: dict, period) -> dict:
    """The ``[period]`` table of ``period`` (a :class:`~wallcal.study.PeriodSpec`): ``table``'s keys with the
    period's dates, so that the study file diagnose writes holds the period it diagnosed, also when the study was
    given a window in code (``study.replace(period=...)``)."""
    out = dict(table)
    for key in ("warmup_start", "start", "end", "validation_start", "validation_end"):
        value = getattr(period, key)
        if value is None:
            out.pop(key, None)
        else:
            out[key] = value
    return out


def _extended_raw(study, tables: list[dict]) -> dict:
    raw = copy.deepcopy(study.raw)
    cal = raw.setdefault("calibration", {})
    params = cal.get("parameters")
    cal["parameters"] = list(params or []) + [copy.deepcopy(t) for t in tables]
    return raw


def diagnose(
    study,
    *,
    start=None,
    progress: bool | Callable[[str], None] | None = None,
    prepared=None,
    max_jacobians: int = MAX_JACOBIANS,
    max_adopted: int = MAX_ADOPTED,
    kinds: tuple[str, ...] | None = None,
    score_resolution: float | None = None,
    effective_bias_prior: bool = True,
    selection: str = "held-out",
) -> Diagnosis:
    """Which extensions of the calibration's structure the data support.

    Parameters
    ----------
    study : Study
        With a ``[calibration]`` table.
    start : path, Wall or CalibrationResult, optional
        The calibrated point: a ``wallcal calibrate`` output directory (its ``calibration.json``), a wall
        file or :class:`~wallcal.wall.Wall`, or a calibration result. None: calibrate the study first.
    progress : bool or callable, optional
        True: a progress line on stderr; a callable receives each progress message; None/False: quiet.
    prepared : Prepared, optional
        The study's data prepared for batches (:func:`wallcal.simulation.prepare`).
    max_jacobians : int
        Jacobians allowed in each warm-started recalibration.
    max_adopted : int
        Most extensions adopted together.
    kinds : tuple of str, optional
        Candidate kinds to consider (default all: depth, contact_resistance,
        conductivity_temperature_coefficient, offset, response_time, face_offset).
    score_resolution : float or None
        Score the criterion on the residuals' means over blocks of this length [s] (e.g. 3600: hourly means;
        default None: every sample).
    effective_bias_prior : bool
        Weigh each target's bias prior in the recalibrations against the residuals' effective samples
        n (1 - phi) / (1 + phi) (default), not all n of them (False: the bias absorbs any level error).
    selection : {"held-out", "criterion"}
        ``"held-out"`` (default): adopt only plausible extensions, and with a validation window only those that
        lower the held-out RMSE of every temperature target (the held-out evidence decides); ``"criterion"``: the
        in-sample criterion alone, as before the validation window existed (for comparison; the held-out RMSEs are
        still reported).

    Returns
    -------
    Diagnosis

    Raises
    ------
    StudyError, WallcalError
        The study has no ``[calibration]`` table, the start does not fit the study, ...
    """
    from ..calibration.objective import Evaluator
    from ..calibration.space import parse_space, space_of
    from ..simulation import BATCH_NEEDS, prepare
    from .identifiability import sensor_sigma

    t0 = time.perf_counter()
    space = space_of(study)
    all_kinds = (
        "depth",
        "contact_resistance",
        "conductivity_temperature_coefficient",
        "moisture_conductivity_coefficient",
        "offset",
        "response_time",
        "face_offset",
    )
    if kinds is not None:
        bad = [k for k in kinds if k not in all_kinds]
        if bad:
            raise StudyError([f"kinds: unknown extension kind(s) {', '.join(map(repr, bad))}; valid: {all_kinds}"])
    if selection not in ("held-out", "criterion"):
        raise StudyError([f"selection: {selection!r} is not one of 'held-out', 'criterion'"])
    say = _Say(progress)
    prepared = prepared or prepare(study, needs=BATCH_NEEDS, purpose="the structure diagnosis")
    x0, origin = start_point(study, space, start, progress)
    x0 = np.clip(np.asarray(x0, dtype=float), space.lower, space.upper)
    evaluations = 0
    evaluators: dict[tuple, Evaluator] = {}

    def evaluator(sp):
        key = tuple(sp.names)
        if key not in evaluators:
            evaluators[key] = Evaluator(prepared, sp)
        return evaluators[key]

    def fit(tables: list[dict], names: tuple, starts: list, jacobians=None) -> _Fit:
        """Recalibrate a structure from each of ``starts`` (the study's objective with the sensor biases profiled
        out, warm-started) and score it by its AR(1) log-likelihood (biases integrated out), the best of the starts.
        ``starts``: (x_start, ll_before) pairs, ``x_start`` a dict of parameter values (the structure it extends;
        the new parameters at their base values); the score of a fit from it is ``ll_before`` plus the fit's gain
        over its starting point - a contact link or the lambda(T) path changes the discrete model slightly even at
        the base value, and that change is no evidence for the extension. ``ll_before`` None: the
        log-likelihood at the fit."""
        nonlocal evaluations
        sp = space if not tables else parse_space(study, _extended_raw(study, tables)["calibration"])
        ev = evaluator(sp)
        best = None
        for x_start, ll_before in starts:
            xs = np.array([x_start.get(n, p.base) for n, p in zip(sp.names, sp.parameters, strict=True)])
            xs = np.clip(xs, sp.lower, sp.upper)
            ll0 = ar1_profile(ev.errors(xs[None])[0], ev.mask, tau, block)[0] if ll_before is not None else 0.0
            # a probe depth starting on a contact's double node is also fitted from just off it (node_starts)
            for s in node_starts(sp, ev.inp.wall, ev.inp.options.contact_layers, xs):
                u, n_runs = refine(
                    lambda U: debiased_residuals(ev, sp.from_unit(U), tau, noise),
                    sp.to_unit(s),
                    jacobians or max_jacobians,
                    FTOL,
                )
                x = sp.from_unit(u)
                E = ev.errors(x[None])[0]
                evaluations += n_runs + 2
                ll, n, _, _ = ar1_profile(E, ev.mask, tau, block)
                if ll_before is not None:
                    ll = ll_before + (ll - ll0)
                if best is None or ll > best[0]:
                    best = (ll, n, x, E)
        ll, n, x, E = best
        rmse = np.sqrt(np.einsum("tk,tk->t", E, E) / ev.n_valid)
        return _Fit(names, x, sp, -2.0 * ll + sp.n * math.log(max(n, 2)), rmse, ll)

    # every target's constant sensor bias is part of the error model, as in the posterior: prior sd half the
    # stated accuracy (a 95 % bound), integrated out of the criterion
    ev_study = evaluator(space)
    tau = np.array(
        [
            BIAS_ACCURACY_SHARE * sensor_sigma(study, t, ev_study.y[k][ev_study.mask[k]])
            for k, t in enumerate(space.targets)
        ]
    )
    tau = np.where(np.isfinite(tau) & (tau > 0), tau, 0.0)
    # the criterion's resolution: hourly means of the residuals (SCORE_RESOLUTION), whole samples
    block = 1
    if score_resolution and len(prepared.times) > 1:
        step = float(np.median((prepared.times[1:] - prepared.times[:-1]).total_seconds()))  # sampling [s]
        block = max(1, int(round(score_resolution / step)))
    E0 = ev_study.errors(x0[None])[0]
    noise = np.array([float(np.std(E0[k][ev_study.mask[k]])) for k in range(len(tau))])
    noise = np.where(np.isfinite(noise) & (noise > 0), noise, 1.0)
    if effective_bias_prior:
        # the bias's prior weighed against the residuals' effective samples n (1 - phi) / (1 + phi), not all n of
        # them: with phi ~ 0.995 the n samples are worth about n / 400 independent ones, and counted as n they
        # swamp the prior, so that the fit leaves any level error to the "bias" (docs/identifiability.md, "Real
        # walls")
        from .posterior_likelihood import lag1

        ph0 = np.array(
            [
                lag1(np.where(ev_study.mask[k], E0[k] - E0[k][ev_study.mask[k]].mean(), 0.0), ev_study.mask[k])
                for k in range(len(tau))
            ]
        )
        ph0 = np.clip(np.nan_to_num(ph0), 0.0, 0.995)
        noise = noise * np.sqrt((1.0 + ph0) / (1.0 - ph0))
    say("recalibrating the study's structure (warm start)", force=True)
    # the start is the optimum of the study's objective, which counts a sensor's bias as misfit: the base structure
    # is re-polished to convergence under the criterion's error model, so that no candidate gains from that alone
    base = fit([], (), [(dict(zip(space.names, x0, strict=True)), None)], jacobians=BASE_JACOBIANS * max_jacobians)
    ev0 = evaluator(space)
    _, n_pairs, _, _ = ar1_profile(ev0.errors(base.x[None])[0], ev0.mask, tau, block)
    resid = residual_analysis(ev0, base.x, prepared.times)
    y = {t: ev0.y[k][ev0.mask[k]] for k, t in enumerate(space.targets)}
    exts = [
        e for e in propose(study, space, resid, y, prepared.engine.capabilities) if kinds is None or e.kind in kinds
    ]
    by_name = {e.name: e for e in exts}
    fits: dict[tuple, _Fit] = {}

    def compatible(names) -> bool:
        """No layer's lambda(T) twice (a group and the shared coefficient overlap)."""
        seen: set = set()
        for n in names:
            t = by_name[n].table
            if t.get("property") != "conductivity_temperature_coefficient":
                continue
            if seen & set(t["layers"]):
                return False
            seen |= set(t["layers"])
        return True

    def score(names: tuple, warm: _Fit) -> _Fit:
        """Fit and score a structure, warm-started from ``warm`` and from every other scored structure it extends
        by one extension: a combination's optimum can lie far from one parent's (on the ``all`` campaign of
        ``bench/posterior_coverage.py``, lambda(T) + contact + depth fitted from the lambda(T) + contact optimum,
        whose contact absorbs the probe's offset, stayed in that valley or left it depending on the engine's
        round-off; see docs/identifiability.md, step 4)."""
        key = tuple(sorted(names))
        if key not in fits:
            say(f"scoring {' + '.join(names)} ({len(fits) + 1} scored, {evaluations} simulations)")
            parents = [warm] + [
                f for k, f in fits.items() if len(k) == len(key) - 1 and set(k) < set(key) and f is not warm
            ]
            fits[key] = fit(
                [by_name[n].table for n in names],
                names,
                [(dict(zip(p.space.names, p.x, strict=True)), p.ll) for p in parents],
            )
        return fits[key]

    polished: set = set()

    def polish(f: _Fit) -> _Fit:
        key = tuple(sorted(f.names))
        if key in polished:
            return fits[key]
        polished.add(key)
        say(f"polishing {' + '.join(f.names)} ({evaluations} simulations)")
        fits[key] = fit(
            [by_name[n].table for n in f.names],
            f.names,
            [(dict(zip(f.space.names, f.x, strict=True)), f.ll)],
            jacobians=BASE_JACOBIANS * max_jacobians,
        )
        return fits[key]

    own = set(space.names)

    def held(f: _Fit) -> frozenset:
        """The study's own parameters at a bound of their prior box at the fit's optimum."""
        return held_at_bounds(f.space, f.x, own)

    # held-out validation ([period] validation_start/end): every fit is scored on the window no fit sees
    from ..validation import Validator, prepare_window

    vprep = prepare_window(study)
    validators: dict[tuple, Validator] = {}
    vcache: dict[tuple, np.ndarray] = {}

    def held_out(f: _Fit) -> np.ndarray | None:
        """Held-out RMSE of every target at the fit's optimum (None without a validation window)."""
        if vprep is None:
            return None
        ck = (tuple(f.space.names), f.x.tobytes())
        if ck not in vcache:
            key = tuple(f.space.names)
            if key not in validators:
                validators[key] = Validator(study, f.space, prepared=vprep)
            vcache[ck] = validators[key].rmse(f.x[None])[0]
            nonlocal evaluations
            evaluations += 1
        return vcache[ck]

    temps = [k for k, t in enumerate(space.targets) if study.sensor(t).quantity == "temperature"]
    refused: dict[tuple, str] = {}

    def implausible(f: _Fit) -> list[str]:
        return plausibility(study, f.space, f.x, set(f.names), BOUND_BAND)

    def accept(f: _Fit, current: _Fit) -> bool:
        """Plausible values, off their bounds, and a lower held-out RMSE of every temperature target."""
        why = implausible(f)
        v, vc = held_out(f), held_out(current)
        if v is not None:
            worse = [space.targets[k] for k in temps if not v[k] < vc[k]]
            if worse:
                why.append(
                    "held-out RMSE not lower for "
                    + ", ".join(f"{space.targets[k]} ({vc[k]:.3f} -> {v[k]:.3f})" for k in temps if not v[k] < vc[k])
                )
        if why:
            refused.setdefault(tuple(sorted(f.names)), "; ".join(why))
        return not why

    singles = {e.name: score((e.name,), base) for e in exts}

    def rank(f: _Fit) -> float:
        """The held-out score: mean over the temperature targets (all targets without one) of the held-out RMSE
        relative to the study's structure's."""
        v, v0 = held_out(f), held_out(base)
        ks = temps or list(range(len(v)))
        return float(np.mean([v[k] / max(v0[k], 1e-12) for k in ks]))

    current, adopted, tied, weak = forward_select(
        base,
        singles,
        score,
        polish,
        compatible,
        max_adopted,
        held,
        accept=accept if selection == "held-out" else None,
        rank=rank if vprep is not None and selection == "held-out" else None,
    )
    rows = []
    for key, f in fits.items():
        vf = held_out(f)
        rows.append(
            {
                "extension": " + ".join(f.names),
                CRITERION: f.bic - base.bic,
                **{f"RMSE {t}": float(r) for t, r in zip(space.targets, f.rmse, strict=True)},
                **{
                    f"validation RMSE {t}": float(vf[k]) if vf is not None else np.nan
                    for k, t in enumerate(space.targets)
                },
                "plausible": not implausible(f),
                "adopted": bool(adopted) and key == tuple(sorted(adopted)),
                "held_at_bounds": ", ".join(sorted(held(f))),
            }
        )
    cols = (
        ["extension", CRITERION]
        + [f"RMSE {t}" for t in space.targets]
        + [f"validation RMSE {t}" for t in space.targets]
        + ["plausible", "adopted", "held_at_bounds"]
    )
    cand = pd.DataFrame(rows, columns=cols)
    if len(cand):
        cand["n"] = cand["extension"].str.count(r" \+ ")
        cand = cand.sort_values(["n", CRITERION], kind="stable").drop(columns="n").reset_index(drop=True)
    cand["adopted"] = cand["adopted"].astype(bool)
    raw = _extended_raw(study, [by_name[n].table for n in adopted]) if adopted else copy.deepcopy(study.raw)
    raw["period"] = _period_table(raw.get("period", {}), study.period)
    # the study as given (a period, a wall or an engine set in code stays) with the adopted parameters; extended,
    # it is no longer the file the hash was taken of
    ext_space = parse_space(study, raw["calibration"]) if adopted else study.calibration
    ext_study = study.replace(
        calibration=ext_space,
        features={**study.features, "calibration": ext_space},
        raw=raw,
        sha256=study.sha256 if not adopted else "",
    )
    seconds = time.perf_counter() - t0
    say.close(
        f"{len(fits)} candidates and combinations scored, {evaluations} simulations, {seconds:.1f} s; adopted: "
        + (", ".join(adopted) if adopted else "none")
    )
    notes = [f"Started from {origin}."]
    event = common_step(study, resid)
    if event:
        notes.append(event)
    vtable = None
    if vprep is not None:
        vb = held_out(base)
        notes.append(
            f"Held-out window {study.period.validation_start} .. {study.period.validation_end} (no fit saw it): "
            "RMSE of the study's structure "
            + ", ".join(f"{t} {v:.3f} {unit_label(study, t)}" for t, v in zip(space.targets, vb, strict=True))
            + "."
        )
        vtable = Validator(study, current.space, prepared=vprep).table(current.x)
    for names, why in refused.items():
        if names != tuple(sorted(adopted)):
            notes.append(f"Not adopted: {' + '.join(names)}: {why}.")
    for names, cost in tied:
        notes.append(
            f"{' and '.join(names)} explain the misfit equally well (criterion within {TIE_DELTA:g}): the data cannot "
            f"choose between them, so both are adopted (criterion {cost:+.1f} against one alone) and the posterior "
            "averages over them."
        )
    for names, cost, before, after in weak:
        notes.append(
            f"{' + '.join(names)} adopted on positive evidence (criterion {cost:+.1f}; {WEAK_DELTA:g} suffices): the "
            f"structure without it holds {', '.join(sorted(before))} at a bound of the prior box (a structure its own "
            "optimum rejects); with it "
            + (", ".join(sorted(after)) if after else "none of the study's parameters")
            + " sit(s) at a bound."
        )
    if held(current):
        notes.append(
            f"At the chosen structure's optimum {', '.join(sorted(held(current)))} sit(s) at a bound of the prior "
            "box: the data want a value the bounds forbid (or do not identify it), and no candidate frees it with "
            "positive evidence."
        )
    if prepared.note:
        notes.append(prepared.note)
    return Diagnosis(
        adopted=list(adopted),
        candidates=cand,
        study=ext_study,
        residuals=resid,
        extensions=exts,
        x=dict(zip(current.space.names, map(float, current.x), strict=True)),
        base_study=study,
        rmse_base=dict(zip(space.targets, map(float, base.rmse), strict=True)),
        bic_base=base.bic,
        n_pairs=n_pairs,
        evaluations=evaluations,
        seconds=seconds,
        raw=raw,
        notes=notes,
        validation=vtable,
        validation_base=dict(zip(space.targets, map(float, held_out(base)), strict=True)) if vprep is not None else {},
    )

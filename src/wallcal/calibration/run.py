"""Automatic calibration: from a study to the optimal wall, with checkpoints and a report.

:func:`calibrate` validates the parameter space, prepares the data once, runs the
chosen algorithm with every generation's candidates as one engine batch, keeps
the best point and a checkpoint after every generation (so Ctrl-C or a crash
loses nothing and ``resume=True`` continues), and returns a
:class:`CalibrationResult`. :meth:`CalibrationResult.write` produces
``calibrated_wall.toml``, ``calibration.json``, ``metrics.csv`` (every sensor,
base and calibrated: the paper's Table VIII), ``convergence.png`` and ``fit.png``
(measured vs base vs calibrated per target: the paper's Fig. 5).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from ..engines import entry
from ..errors import StudyError, WallcalError, interrupted
from ..simulation import BATCH_NEEDS, Prepared, prepare, simulate
from ..study import Study, dump_wall, load_wall
from . import algorithms as alg
from .checkpoint import REPLAYED, CheckpointError, check_values, checkpoint_path, load_checkpoint, present
from .checkpoint import remove as remove_checkpoint
from .objective import Evaluator
from .space import ALGORITHMS, ParameterSpace, space_of

#: A target whose calibrated RMSE is this much below its noise floor is flagged (degC or W/m2 ...)
FLOOR_MARGIN_ABS = 0.05
FLOOR_MARGIN_REL = 0.2


@dataclass
class CalibrationResult:
    """Outcome of a calibration.

    Attributes
    ----------
    space : ParameterSpace
    x_base, x_opt : ndarray
        Parameter values [SI units] of the base case and of the optimum.
    f_base, f_opt : float
        Objective values.
    evaluations : int
        Simulations run.
    seconds : float
        Wall time [s].
    history : list of (evaluations, seconds, best objective)
    status : str
        ``"complete"`` or ``"interrupted"`` (best point so far).
    wall_base, wall_opt : Wall
    metrics : DataFrame
        Every sensor, base and calibrated (column ``case``).
    floors : dict
        Target -> RMSE of the reference wall (noise floor), when the study names one.
    notes : list of str
        Plain-language remarks (targets below their noise floor, parameters at a bound...).
    """

    study: Study
    space: ParameterSpace
    algorithm: str
    settings: dict
    seed: int
    x_base: np.ndarray
    x_opt: np.ndarray
    f_base: float
    f_opt: float
    evaluations: int
    seconds: float
    history: list
    status: str
    wall_base: object
    wall_opt: object
    metrics: pd.DataFrame
    simulated: dict = field(default_factory=dict)
    measured: pd.DataFrame | None = None
    floors: dict = field(default_factory=dict)
    notes: list = field(default_factory=list)
    refinement: object = None
    checkpoint: Path | None = None

    # ------------------------------------------------------------------ reporting
    def parameter_table(self) -> pd.DataFrame:
        rows = []
        sides = self.space.bound_sides(self.x_opt)
        for p, xb, xo, side in zip(self.space.parameters, self.x_base, self.x_opt, sides, strict=True):
            rows.append(
                {
                    "parameter": p.name,
                    "base": xb,
                    "lower": p.lower,
                    "upper": p.upper,
                    "optimum": xo,
                    "change": (xo - xb) / xb if xb else np.nan,
                    "at_bound": bool(side),
                }
            )
        return pd.DataFrame(rows).set_index("parameter")

    def to_json(self) -> dict:
        return {
            "status": self.status,
            "study": str(self.study.path) if self.study.path else None,
            "algorithm": self.algorithm,
            "settings": self.settings,
            "seed": self.seed,
            "objective": self.space.objective,
            "targets": list(self.space.targets),
            "objective_base": self.f_base,
            "objective_optimum": self.f_opt,
            "evaluations": self.evaluations,
            "wall_time_s": self.seconds,
            "parameters": [
                {
                    "name": p.name,
                    "property": p.property,
                    "layers": [self.study.wall.layers[i].id for i in p.layers],
                    "probe": p.probe,
                    "base": xb,
                    "bounds": [p.lower, p.upper],
                    "optimum": xo,
                }
                for p, xb, xo in zip(self.space.parameters, self.x_base, self.x_opt, strict=True)
            ],
            "rmse": {
                case: self.metrics[self.metrics["case"] == case].set_index("signal")["rmse"].to_dict()
                for case in ("base", "calibrated")
            },
            "noise_floors": self.floors,
            "notes": self.notes,
            "history": [list(h) for h in self.history],
            **(
                {"energyplus_refinement": self.refinement.to_json(self.space.names)}
                if self.refinement is not None
                else {}
            ),
        }

    def write(self, out_dir) -> Path:
        """Write every output atomically into ``out_dir``."""
        from ..outputs import output_dir
        from ..simulation import manifest_of

        with output_dir(out_dir, manifest=manifest_of(self.study, "calibrate")) as tmp:
            self.write_into(Path(tmp))
        # the checkpoint goes only now that the outputs are in place (a kill before this line resumes from it)
        if self.status == "complete" and self.checkpoint is not None and checkpoint_path(out_dir) == self.checkpoint:
            remove_checkpoint(self.checkpoint)
        return Path(out_dir)

    def write_into(self, d: Path) -> None:
        header = (
            f"Calibrated wall ({self.status}) from {self.study.path or 'study'}\n"
            f"algorithm {self.algorithm}, objective {self.space.objective} {self.f_base:.6g} -> {self.f_opt:.6g}"
        )
        (d / "calibrated_wall.toml").write_text(dump_wall(self.wall_opt, header))
        (d / "calibration.json").write_text(json.dumps(self.to_json(), indent=2, default=float))
        self.metrics.to_csv(d / "metrics.csv", index=False, float_format="%.6g")
        self.parameter_table().to_csv(d / "parameters.csv", float_format="%.6g")
        from ..validation import score_wall
        from ..validation import write as write_validation

        # the held-out window ([period] validation_start/end), which the fit never saw
        lags = {self.space.targets[k]: float(v[0]) for k, v in self.space.response_times(self.x_opt).items()}
        write_validation(score_wall(self.study, self.wall_opt, self.space.offset_values(self.x_opt), lags), d)
        from .plots import plot_convergence, plot_fit

        plot_convergence(self, d / "convergence.png")
        plot_fit(self, d / "fit.png")
        if self.refinement is not None:
            ref = self.refinement
            (d / "energyplus_wall.toml").write_text(
                dump_wall(
                    ref.wall_opt,
                    f"Calibrated wall refined with EnergyPlus ({ref.runs} EnergyPlus runs) from "
                    f"{self.study.path or 'study'}\nEnergyPlus objective {self.space.objective} "
                    f"{ref.f_start:.6g} at the fast engine's optimum -> {ref.f_opt:.6g}",
                )
            )
            ref.table().to_csv(d / "energyplus_refinement.csv", float_format="%.6g")


# ============================================================================ the run
def complete_output(out_dir, study: Study) -> bool:
    """Whether ``out_dir`` holds a complete calibration of ``study`` (status complete, its manifest naming the
    same study file and data)."""
    out_dir = Path(out_dir)
    try:
        man = json.loads((out_dir / "manifest.json").read_text())
        cal = json.loads((out_dir / "calibration.json").read_text())
        from ..data import data_sha256

        return (
            isinstance(man, dict)
            and isinstance(cal, dict)
            and cal.get("status") == "complete"
            and man.get("study_sha256") == study.sha256
            and man.get("data_sha256") == data_sha256(study)
        )
    except (OSError, ValueError):
        return False


def calibrate(
    study: Study,
    *,
    algorithm: str | None = None,
    settings: dict | None = None,
    seed: int | None = None,
    out_dir: str | Path | None = None,
    resume: bool = False,
    progress: bool = True,
    prepared: Prepared | None = None,
    space: ParameterSpace | None = None,
    refine: bool | None = None,
) -> CalibrationResult:
    """Calibrate the study's wall.

    Parameters
    ----------
    study : Study
        With a ``[calibration]`` table (see ``docs/calibration.md``).
    algorithm : str, optional
        ``pso-hj`` (default), ``least-squares``, ``differential-evolution``, ``nelder-mead``, ``cma-es``.
    settings : dict, optional
        Algorithm settings overriding the study's ``calibration.settings``.
    seed : int, optional
    out_dir : path, optional
        Where results will be written; its checkpoint file sits next to it
        (``.<name>.checkpoint.json``), updated after every generation. It stays after the run and
        :meth:`CalibrationResult.write` into ``out_dir`` deletes it once the outputs are in place.
    resume : bool
        Continue from the checkpoint of ``out_dir``. The checkpoint is checked first
        (:mod:`wallcal.calibration.checkpoint`: its kind, format, entries, and its best point re-evaluated);
        a bad one is a :class:`~wallcal.calibration.checkpoint.CheckpointError`.
    progress : bool
        Show a progress line on stderr.
    refine : bool, optional
        Refine the optimum with EnergyPlus runs (:func:`wallcal.calibration.refine.refine_with_energyplus`, on
        the executor); default: when the study's engine is ``energyplus``.

    Returns
    -------
    CalibrationResult
        ``status`` is ``"interrupted"`` when Ctrl-C stopped the run (the best point so far).
    """
    space = space or space_of(study)
    algorithm = algorithm or space.algorithm
    if algorithm not in ALGORITHMS:
        from ..errors import closest

        raise StudyError([f"calibration.algorithm: unknown algorithm {algorithm!r}; {closest(algorithm, ALGORITHMS)}"])
    user_settings = dict(space.settings if algorithm == space.algorithm else {})
    user_settings.update(settings or {})
    sett = alg.settings_for(algorithm, user_settings)
    seed = space.seed if seed is None else int(seed)
    ckpt = checkpoint_path(out_dir)
    meta = {
        "algorithm": algorithm,
        "seed": seed,
        "settings": sett,
        "parameters": space.names,
        "study_sha256": study.sha256,
        "data_sha256": _data_hash(study) if ckpt is not None else None,
    }
    data = None
    if resume:
        if not present(ckpt):
            raise WallcalError(f"nothing to resume: no checkpoint {ckpt} (run without --resume)")
        data = load_checkpoint(ckpt, meta, space.n, sett)  # before any simulation: a bad file is refused at once
    elif present(ckpt) and ckpt.is_dir() and not ckpt.is_symlink():
        raise CheckpointError(ckpt, "a directory stands where the checkpoint goes", "remove it to calibrate")
    if ckpt is not None:
        ckpt.parent.mkdir(parents=True, exist_ok=True)
    prepared = prepared or prepare(study, needs=BATCH_NEEDS, purpose="calibration")
    ev = Evaluator(prepared, space)

    def f(U):
        return ev.objective(space.from_unit(U))

    def residuals(U):  # (objective, residuals) from one batch
        return ev.objective_and_residuals(space.from_unit(U))

    prog = alg.Progress(f"calibrate ({algorithm})", enabled=progress)
    replayed = algorithm in REPLAYED
    rec = alg.Recorder(
        f=f,
        n=space.n,
        progress=prog,
        checkpoint=ckpt,
        meta=meta,
        autosave=algorithm != "pso-hj",
        log=[] if replayed else None,
    )
    state = None
    if data is not None:
        check_values(ckpt, data, f, space.objective)  # its best point must give its stored value
        state = data.get("state")
        if replayed and state is None:
            rec.start_replay(data)  # run again from the seed, the logged batches answered from the log
        else:
            rec.restore(data)
            if replayed:
                rec.log = list(data["log"])
    u0 = space.to_unit(space.base)
    f_base = float(ev.objective(space.base[None])[0])
    status = "complete"
    done = isinstance(state, dict) and state.get("phase") == "done"
    try:
        if rec.best_u is None:
            rec(u0[None])
        if done and algorithm != "pso-hj":
            pass  # finished before: only the outputs are missing
        elif algorithm == "pso-hj":
            alg.pso_hj(rec, space.n, seed, sett, u0, residuals=residuals, state=state)
        elif algorithm == "least-squares":
            alg.least_squares_only(rec, residuals, sett, rec.best_u)
        elif algorithm == "differential-evolution":
            alg.differential_evolution(rec, space.n, seed, sett, rec.best_u)
        elif algorithm == "nelder-mead":
            alg.nelder_mead(rec, space.n, seed, sett, rec.best_u)
        elif algorithm == "cma-es":
            alg.cma_es(rec, space.n, seed, sett, rec.best_u)
        rec.check_replayed()
        if algorithm != "pso-hj":  # (pso-hj saves its own "done")
            rec.save({"phase": "done"})
    except (KeyboardInterrupt, SystemError) as exc:  # (a Ctrl-C inside a numba kernel: a SystemError)
        if not interrupted(exc):
            raise
        status = "interrupted"
        if algorithm != "pso-hj":  # pso-hj's checkpoint already holds its last complete generation
            rec.save(None)
    prog.close(
        f"{rec.phase or algorithm}: {rec.evaluations} simulations, best {rec.best_f:.6g}, "
        f"{rec.elapsed:.1f} s ({status})"
    )
    x_opt = space.from_unit(rec.best_u)
    result = _finish(study, space, prepared, ev, algorithm, sett, seed, f_base, x_opt, rec, status)
    if refine is None:
        refine = entry(study.simulation.engine).refines_calibration
    if refine and status == "complete":
        from .refine import refine_with_energyplus

        ref = refine_with_energyplus(study, space, prepared, x_opt, progress=progress)
        result.refinement = ref
        result.notes.append(
            f"refined with EnergyPlus from the fast engine's optimum in {ref.runs} EnergyPlus runs: EnergyPlus "
            f"objective {ref.f_start:.6g} -> {ref.f_opt:.6g} (energyplus_wall.toml, energyplus_refinement.csv)"
        )
    result.checkpoint = ckpt  # deleted by result.write(out_dir) once the outputs are in place
    return result


def _data_hash(study: Study) -> str | None:
    from ..data import data_sha256

    try:
        return data_sha256(study)
    except OSError:
        return None


def _finish(study, space, prepared, ev, algorithm, sett, seed, f_base, x_opt, rec, status) -> CalibrationResult:
    wall_opt = space.wall_at(study.wall, x_opt)
    base_res = simulate(study, prepared=prepared)
    offsets = space.offset_values(x_opt)
    if offsets:  # the calibrated case compares with the measured signals corrected by the calibrated offsets
        opt_res = simulate(with_sensor_offsets(study, offsets), engine=prepared.engine_name, wall=wall_opt)
    else:
        opt_res = simulate(study, prepared=prepared, wall=wall_opt)
    met = pd.concat([base_res.metrics.assign(case="base"), opt_res.metrics.assign(case="calibrated")])
    met = met[["case"] + [c for c in met.columns if c != "case"]]
    floors = {}
    notes = [prepared.note] if prepared.note else []
    if space.reference_wall:
        ref_wall = load_wall(space.reference_wall)  # resolved against the study's folder at load
        ref_res = simulate(study, prepared=prepared, wall=ref_wall)
        floors = ref_res.metrics.set_index("signal")["rmse"].to_dict()
    rm_opt = opt_res.metrics.set_index("signal")["rmse"]
    rm_base = base_res.metrics.set_index("signal")["rmse"]
    for name in space.targets:
        if name in floors:
            floor = floors[name]
            if rm_opt[name] < floor - max(FLOOR_MARGIN_ABS, FLOOR_MARGIN_REL * floor):
                notes.append(
                    f"{name}: calibrated RMSE {rm_opt[name]:.3f} is well below its noise floor {floor:.3f} "
                    f"(the reference wall's RMSE): the fit absorbs that sensor's bias or noise, i.e. "
                    f"the calibrated properties compensate a measurement error"
                )
        if rm_opt[name] > rm_base[name] * 1.001:
            notes.append(
                f"{name}: RMSE rose from {rm_base[name]:.3f} to {rm_opt[name]:.3f}: the objective traded "
                "it against the other targets"
            )
    x_base = space.base
    at_bound = [f"{n} ({side})" for n, side in zip(space.names, space.bound_sides(x_opt), strict=True) if side]
    if at_bound:
        notes.append(
            f"{len(at_bound)} of {space.n} parameters ended at a bound: {', '.join(at_bound)}. The data "
            "would move them further, or they are not identified from these data (several walls fit "
            "equally well: see wallcal posterior); review the bounds before trusting these values"
        )
    if offsets:
        notes.append(
            "calibrated sensor offsets (added to the measured signals; the calibrated metrics use the corrected "
            "signals): " + ", ".join(f"{k} {v:+.4g}" for k, v in offsets.items())
        )
    sim = {"base": base_res.simulated, "calibrated": opt_res.simulated}
    return CalibrationResult(
        study=study,
        space=space,
        algorithm=algorithm,
        settings=sett,
        seed=seed,
        x_base=x_base,
        x_opt=x_opt,
        f_base=f_base,
        f_opt=float(rec.best_f),
        evaluations=rec.evaluations,
        seconds=rec.elapsed,
        history=rec.history,
        status=status,
        wall_base=study.wall,
        wall_opt=wall_opt,
        metrics=met.reset_index(drop=True),
        simulated=sim,
        measured=base_res.measured,
        floors=floors,
        notes=notes,
    )


def with_sensor_offsets(study: Study, offsets: dict[str, float]) -> Study:
    """The study with ``offsets`` [degC or W/m2] added to its sensors' ``offset`` (corrections of the measured
    signals), e.g. the calibrated values of ``offset`` parameters."""
    import dataclasses

    return study.replace(
        sensors=tuple(
            dataclasses.replace(s, offset=s.offset + float(offsets[s.name])) if s.name in offsets else s
            for s in study.sensors
        )
    )


def convergence_table(history, optimum: float, levels=(0.01, 0.001, 0.0001)) -> list[tuple]:
    """Simulations and seconds needed to come within each relative level of ``optimum``.

    Returns rows (level, evaluations or None, seconds or None).
    """
    rows = []
    for lev in levels:
        hit = next(((e, s) for e, s, f in history if f <= optimum * (1 + lev)), (None, None))
        rows.append((lev, hit[0], hit[1]))
    return rows

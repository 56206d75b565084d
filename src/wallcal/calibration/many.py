"""Many studies calibrated at once, each study one task on the executor (:mod:`wallcal.cluster`).

:func:`calibrate_many` loads every study (so a bad file stops everything before any work), sends one
task per study (:func:`calibrate_task`: :func:`~wallcal.calibration.calibrate` of that study, with the
same algorithm and seed as a calibration of that study alone, so the same result bit for bit) and
returns the results in the order of the files. Each task reads its study and data files on its worker:
on several machines the files must sit at the same path on each (a shared file system).
"""

from __future__ import annotations

from pathlib import Path

from ..errors import StudyError


def calibrate_task(task):
    """One study's calibration on a worker: ``task`` = (study file, algorithm or None, seed or None)."""
    from ..study import load_study
    from .run import calibrate

    path, algorithm, seed = task
    return calibrate(load_study(path), algorithm=algorithm, seed=seed, progress=False)


def study_stems(paths) -> list[str]:
    """The output folder name of each study file (its stem); two files with one stem are a :class:`StudyError`."""
    stems = [Path(p).stem for p in paths]
    dup = sorted({s for s in stems if stems.count(s) > 1})
    if dup:
        raise StudyError(
            [
                f"{', '.join(str(p) for p in paths if Path(p).stem == s)}: one output folder OUT/{s}/ for several "
                f"studies; rename the files"
                for s in dup
            ]
        )
    return stems


def calibrate_many(paths, *, algorithm: str | None = None, seed: int | None = None, executor=None) -> list:
    """Calibrate each study file as its own task.

    Parameters
    ----------
    paths : sequence of path
        Study files (each with a ``[calibration]`` table); their stems must differ.
    algorithm : str, optional
        For every study; default each study's ``calibration.algorithm``.
    seed : int, optional
        For every study; default each study's ``calibration.seed``.
    executor : wallcal.cluster.Executor, optional
        Default: the active one, else :func:`wallcal.cluster.executor_from`.

    Returns
    -------
    list of CalibrationResult
        In the order of ``paths``.
    """
    from ..cluster import current_executor, executor_from
    from ..data import data_sha256
    from ..study import load_study
    from .space import space_of

    paths = [str(Path(p).resolve()) for p in paths]
    stems = study_stems(paths)
    keys = []
    for p, stem in zip(paths, stems, strict=True):
        study = load_study(p)
        space = space_of(study)  # every study checked here, before any work is sent
        run = f"{algorithm or space.algorithm}-{space.seed if seed is None else seed}"
        keys.append(f"{stem}-{study.sha256[:16]}-{data_sha256(study)[:16]}-{run}")
    tasks = [(p, algorithm, seed) for p in paths]
    ex = executor or current_executor()
    if ex is not None:
        return ex.map(calibrate_task, tasks, keys=keys)
    with executor_from(label="studies calibrated") as ex:
        return ex.map(calibrate_task, tasks, keys=keys)

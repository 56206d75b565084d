"""Analyses around a calibration: grid study, sensitivity, identifiability, Bayesian posterior.

Each analysis is a library function returning a result object (DataFrames, a
``summary()`` text and ``write_into(dir)``); the ``wallcal grid-study``,
``sensitivity``, ``identifiability`` and ``posterior`` commands are thin layers
over them. Every numerical evaluation goes through the batched engine
(:class:`wallcal.calibration.objective.Evaluator`), one batch per step.

Helpers shared by the analyses live here.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np

from ..errors import StudyError, WallcalError, closest

__all__ = ["load_optimum", "reference_values", "space_with_targets"]


def space_with_targets(study, space, targets=None):
    """The parameter space with other target sensors (validated against the study's sensors).

    Parameters
    ----------
    study : Study
    space : ParameterSpace
    targets : list of str, optional
        Sensor names; default the space's own.
    """
    if not targets:
        return space
    names = [s.name for s in study.sensors]
    bad = [f"--targets: {t!r} is not a sensor; {closest(t, names)}" for t in targets if t not in names]
    if bad:
        raise StudyError(bad)
    return dataclasses.replace(space, targets=tuple(dict.fromkeys(targets)))


def load_optimum(space, from_dir) -> np.ndarray:
    """Calibrated parameter values [SI] from a ``wallcal calibrate`` output directory (``calibration.json``)."""
    path = Path(from_dir) / "calibration.json"
    if not path.exists():
        raise WallcalError(f"{from_dir}: no calibration.json (run `wallcal calibrate STUDY --out {from_dir}` first)")
    data = json.loads(path.read_text())
    got = {p["name"]: float(p["optimum"]) for p in data.get("parameters", [])}
    missing = [n for n in space.names if n not in got]
    if missing:
        raise WallcalError(
            f"{path}: made with another parameter space (missing {', '.join(missing)}); calibrate this study again"
        )
    return np.array([got[n] for n in space.names])


def reference_values(study, space) -> np.ndarray | None:
    """Parameter values [SI] of the study's ``calibration.reference_wall`` (the true wall of a synthetic campaign).

    Returns None when the study names no reference wall. A probe the reference wall does not list keeps its
    base depth; a layer property it leaves unset (a contact resistance, a temperature coefficient) is its default.
    """
    if not space.reference_wall:
        return None
    from ..study import load_wall

    ref = load_wall(Path(space.reference_wall))  # resolved against the study's folder when the study was loaded
    out = []
    for p in space.parameters:
        if p.sensor is not None:
            out.append(np.nan)  # a wall file holds no sensor offsets
        elif p.probe is not None:
            probes = {q.name: q.depth for q in ref.probes}
            out.append(probes.get(p.probe, p.base))
        else:
            v = getattr(ref.layers[p.layers[0]], p.property)
            out.append(float(v) if v is not None else np.nan)
    return np.array(out, dtype=float)

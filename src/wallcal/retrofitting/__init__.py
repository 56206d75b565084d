"""Retrofit design from the (calibrated) wall: a weather year, condensation risk, and uncertainty.

Pipeline: the study's ``[retrofit]`` table (:mod:`.config`) -> the variants' walls -> a weather year
(:mod:`wallcal.weather`) turned into the engine's boundary inputs (:mod:`.boundary`: the sol-air temperature) ->
periodic year runs through the batch engine (:mod:`.run`) -> ISO 13788 (:mod:`.glaser`) -> outputs,
figures and the report. Public entry point: :func:`retrofit` (also ``wallcal.retrofit``).

Importing this package is cheap; pvlib and the engine are imported when a run starts.
"""

from __future__ import annotations


def retrofit(study, *, wall=None, from_dir=None, out=None, samples=None, progress=False, wall_source=None):
    """Run every retrofit variant of a study over its weather year.

    See :func:`wallcal.retrofitting.run.retrofit` (this is the same function, imported lazily).
    """
    from .run import retrofit as _retrofit

    return _retrofit(
        study, wall=wall, from_dir=from_dir, out=out, samples=samples, progress=progress, wall_source=wall_source
    )


__all__ = ["retrofit"]

"""Engines by name: ``fd-cn``, ``fd-implicit``, ``fd-exact``, ``fd-reference`` (built in), ``energyplus`` (an extra).

Every engine implements the contract of :mod:`wallcal.engines.base`. :func:`engine_for` is the one
place where a task that needs a capability (calibration: batches) gets an engine that has it, with
the message saying which engine ran instead and why.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from ..errors import EngineError, StudyError, closest
from .base import (
    CAPABILITY_WORDS,
    BatchOutput,
    BoundaryInput,
    Capabilities,
    Engine,
    EngineOptions,
    EngineOutput,
    SimulationInput,
    WallBatch,
)

ENGINE_NAMES = ("fd-cn", "fd-implicit", "fd-exact", "fd-reference", "energyplus")


def _registered(name: str) -> tuple[type[Engine], dict]:
    """The class of engine ``name`` and its constructor arguments (the one list of engines)."""
    if name in ("fd-cn", "fd-implicit", "fd-exact"):
        from .fd import FDEngine

        return FDEngine, {"scheme": scheme_of(name)}
    if name == "fd-reference":
        from .reference import ReferenceEngine

        return ReferenceEngine, {}
    if name == "energyplus":
        from .energyplus import EnergyPlusEngine

        return EnergyPlusEngine, {}
    raise StudyError([f"engine: unknown engine {name!r}; {closest(name, ENGINE_NAMES)}"])


def get_engine(name: str) -> Engine:
    """Return the engine called ``name``."""
    cls, kwargs = _registered(name)
    return cls(**kwargs)


def engine_class(name: str) -> type[Engine]:
    """The class of engine ``name`` (its capabilities without building it)."""
    return _registered(name)[0]


def scheme_of(name: str) -> str:
    """Time scheme implied by an engine name ("cn" unless the name says implicit)."""
    if name.endswith("exact"):
        return "exact"
    return "implicit" if name.endswith("implicit") else "cn"


@dataclass(frozen=True)
class EngineChoice:
    """The engine a task runs and, when it is not the one asked for, why (:attr:`note`)."""

    name: str
    requested: str
    note: str = ""


def engine_for(
    requested: str, needs: Sequence[str] = (), *, purpose: str, time_steps: Sequence[float] = ()
) -> EngineChoice:
    """The engine that runs ``purpose``: ``requested`` when it has every capability in ``needs``
    (attribute names of :class:`Capabilities`) and accepts every time step in ``time_steps``,
    else the substitute it declares (verified against it), with a note saying so.

    Raises
    ------
    EngineError
        Neither ``requested`` nor its substitute can run ``purpose``.
    """
    cls = engine_class(requested)
    lacking = _lacking(requested, needs, time_steps)
    if not lacking:
        return EngineChoice(requested, requested)
    sub = cls.capabilities.substitute
    if sub is not None and not _lacking(sub, needs, time_steps):
        verified = f" ({cls.capabilities.substitute_verified})" if cls.capabilities.substitute_verified else ""
        return EngineChoice(sub, requested, f"{requested} {'; '.join(lacking)}: {purpose} uses {sub}{verified}")
    raise EngineError(f"{purpose} needs an engine with {', '.join(lacking)}; {requested} has not")


def _lacking(name: str, needs: Sequence[str], time_steps: Sequence[float]) -> list[str]:
    cls = engine_class(name)
    out = [f"runs no {CAPABILITY_WORDS.get(n, n)}" for n in cls.capabilities.lacks(needs)]
    if time_steps and not cls.capabilities.any_time_step:
        eng = get_engine(name)
        out += [why for why in dict.fromkeys(eng.check_time_step(float(dt)) for dt in time_steps) if why]
    return out


__all__ = [
    "ENGINE_NAMES",
    "BatchOutput",
    "BoundaryInput",
    "Capabilities",
    "Engine",
    "EngineChoice",
    "EngineOptions",
    "EngineOutput",
    "SimulationInput",
    "WallBatch",
    "engine_class",
    "engine_for",
    "get_engine",
    "scheme_of",
]

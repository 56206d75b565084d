"""Engines by name: ``fd-cn``, ``fd-implicit``, ``fd-reference`` (built in) and ``energyplus`` (optional extra)."""

from __future__ import annotations

from ..errors import StudyError, closest
from .base import BoundaryInput, Engine, EngineOutput, SimulationInput

ENGINE_NAMES = ("fd-cn", "fd-implicit", "fd-reference", "energyplus")


def get_engine(name: str) -> Engine:
    """Return the engine called ``name``."""
    if name in ("fd-cn", "fd-implicit"):
        from .fd import FDEngine

        return FDEngine("cn" if name == "fd-cn" else "implicit")
    if name == "fd-reference":
        from .reference import ReferenceEngine

        return ReferenceEngine()
    if name == "energyplus":
        from .energyplus import EnergyPlusEngine

        return EnergyPlusEngine()
    raise StudyError([f"engine: unknown engine {name!r}; {closest(name, ENGINE_NAMES)}"])


def scheme_of(name: str) -> str:
    """Time scheme implied by an engine name ("cn" unless the name says implicit)."""
    return "implicit" if name.endswith("implicit") else "cn"


__all__ = ["ENGINE_NAMES", "BoundaryInput", "Engine", "EngineOutput", "SimulationInput", "get_engine", "scheme_of"]

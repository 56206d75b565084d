"""The engine registry: the one place that knows engines by name.

Built in: ``fd-cn``, ``fd-implicit``, ``fd-exact`` (exact in time for linear walls), ``fd-reference``, ``ham``
(coupled heat and moisture, :mod:`wallcal.engines.ham`) and
``energyplus`` (optional extra), plus the comparison names ``energyplus-cn`` / ``energyplus-implicit``
(EnergyPlus with its CondFD scheme chosen).
Every engine implements the contract of :mod:`wallcal.engines.base` and is registered here by one line of
:data:`BUILT_IN` (or, from outside, one :func:`register` call). Its :class:`EngineEntry` says what callers
outside ``engines/`` need to know, so none of them tests a name:

- what the engine can do and which time steps it takes: its class's ``capabilities`` and
  ``check_time_step`` (:func:`engine_class`); what a study must provide for it: ``Engine.problems(inp)``;
- its time scheme (:func:`scheme_of`), whether a study may name it (``simulation.engine``), whether the
  run's base-case stage runs it, and how a second-engine comparison treats it: which engine object runs
  it (aliases share one, and an engine's runs in a comparison go to it at once through ``run_inputs``),
  the node rule it always uses, and whether a calibration refines its optimum with it.

:func:`engine_for` is the one place where a task that needs a capability (calibration: batches) gets an
engine that has it, with the message saying which engine ran instead and why.
"""

from __future__ import annotations

import importlib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

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

#: The time schemes an engine may declare.
SCHEMES = ("cn", "implicit", "exact")

#: The engine a study runs when it names none.
DEFAULT_ENGINE = "fd-cn"


@dataclass(frozen=True)
class EngineEntry:
    """One registered engine.

    Attributes
    ----------
    name : str
        The name studies, commands and tables use.
    factory : type or str
        The engine class (an :class:`~wallcal.engines.base.Engine`), or ``"module:Class"`` imported when
        first needed (a module name starting with ``.`` is relative to :mod:`wallcal.engines`).
    kwargs : mapping
        Constructor arguments.
    scheme : str
        Time scheme of the runs: ``"cn"`` (Crank-Nicolson), ``"implicit"`` or ``"exact"`` (the exact
        exponential solution for inputs linear between samples; see :mod:`wallcal.engines.exact`).
    in_studies : bool
        A study's ``simulation.engine`` (and ``wallcal simulate --engine``) may name it; False for names
        that only exist in comparisons.
    base_case : bool
        ``wallcal run``'s base-case stage runs it (when it is installed and can run the study).
    runs_as : str or None
        The registered engine whose object runs it (an alias: ``energyplus-cn`` runs as ``energyplus``);
        None: itself.
    node_rule : str or None
        The node rule it always uses, in words, whatever the input's (None: the input's ``node_rule``).
    refines_calibration : bool
        A calibration of a study naming this engine searches with its substitute, then refines the
        optimum with this engine (:mod:`wallcal.calibration.refine`).
    """

    name: str
    factory: type | str
    kwargs: Mapping = field(default_factory=dict)
    scheme: str = "cn"
    in_studies: bool = True
    base_case: bool = True
    runs_as: str | None = None
    node_rule: str | None = None
    refines_calibration: bool = False

    def engine_class(self) -> type[Engine]:
        f = self.factory
        if isinstance(f, str):
            module, _, attr = f.partition(":")
            f = getattr(importlib.import_module(module, __name__), attr)
        return f

    def build(self) -> Engine:
        return self.engine_class()(**dict(self.kwargs))

    @property
    def runner(self) -> str:
        """The registered name whose engine object runs this entry."""
        return self.runs_as or self.name


#: The built-in engines, one line each.
BUILT_IN = (
    EngineEntry("fd-cn", ".fd:FDEngine", {"scheme": "cn"}),
    EngineEntry("fd-implicit", ".fd:FDEngine", {"scheme": "implicit"}, scheme="implicit"),
    EngineEntry("fd-exact", ".fd:FDEngine", {"scheme": "exact"}, scheme="exact"),
    EngineEntry("fd-reference", ".reference:ReferenceEngine"),
    EngineEntry(
        "energyplus", ".energyplus:EnergyPlusEngine", node_rule="energyplus (EnergyPlus' own)", refines_calibration=True
    ),
    EngineEntry(
        "energyplus-cn",
        ".energyplus:EnergyPlusEngine",
        in_studies=False,
        base_case=False,
        runs_as="energyplus",
        node_rule="energyplus (EnergyPlus' own)",
    ),  # fmt: skip
    EngineEntry(
        "energyplus-implicit",
        ".energyplus:EnergyPlusEngine",
        scheme="implicit",
        in_studies=False,
        base_case=False,
        runs_as="energyplus",
        node_rule="energyplus (EnergyPlus' own)",
    ),  # fmt: skip
    EngineEntry("ham", ".ham:HamEngine", scheme="implicit", base_case=False),
)

_REGISTRY: dict[str, EngineEntry] = {e.name: e for e in BUILT_IN}


def register(name: str, factory: type | str, **facts) -> EngineEntry:
    """Register an engine: ``factory`` its class (or ``"module:Class"``), ``facts`` the other fields of
    :class:`EngineEntry`. A name already registered is an error (see :func:`unregister`)."""
    if name in _REGISTRY:
        raise EngineError(f"engine {name!r} is already registered")
    entry = EngineEntry(name, factory, **facts)
    if entry.scheme not in SCHEMES:
        raise EngineError(f"engine {name!r}: scheme must be one of {', '.join(SCHEMES)}, got {entry.scheme!r}")
    _REGISTRY[name] = entry
    return entry


def unregister(name: str) -> None:
    """Forget engine ``name`` (tests; a built-in engine cannot be removed)."""
    if any(e.name == name for e in BUILT_IN):
        raise EngineError(f"engine {name!r} is built in")
    _REGISTRY.pop(name, None)


def engine_names(*, in_studies: bool | None = None, base_case: bool | None = None) -> tuple[str, ...]:
    """Registered engine names in registration order, optionally only those a study may name
    (``in_studies=True``) or the base-case stage runs (``base_case=True``)."""
    return tuple(
        e.name
        for e in _REGISTRY.values()
        if (in_studies is None or e.in_studies == in_studies) and (base_case is None or e.base_case == base_case)
    )


def entry(name: str) -> EngineEntry:
    """The :class:`EngineEntry` of ``name``.

    Raises
    ------
    StudyError
        ``name`` is not registered (with the closest registered name).
    """
    try:
        return _REGISTRY[name]
    except (KeyError, TypeError):
        raise StudyError([f"engine: unknown engine {name!r}; {closest(str(name), list(_REGISTRY))}"]) from None


def get_engine(name: str) -> Engine:
    """Return the engine called ``name``."""
    return entry(name).build()


def engine_class(name: str) -> type[Engine]:
    """The class of engine ``name`` (its capabilities without building it)."""
    return entry(name).engine_class()


def scheme_of(name: str) -> str:
    """Time scheme of engine ``name``: one of :data:`SCHEMES`."""
    return entry(name).scheme


def __getattr__(attr: str):
    if attr == "ENGINE_NAMES":  # the engines a study may name, as registered now
        return engine_names(in_studies=True)
    raise AttributeError(f"module {__name__!r} has no attribute {attr!r}")


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


def available(names: Sequence[str], inp: SimulationInput) -> tuple[list[str], dict[str, str]]:
    """Which of ``names`` can run ``inp`` on this machine, and why each other cannot (not installed, or
    its own :meth:`~wallcal.engines.base.Engine.problems` with the input)."""
    ok, why = [], {}
    for name in names:
        eng = get_engine(name)
        reason = eng.unavailable() or "; ".join(eng.problems(inp))
        if reason:
            why[name] = reason
        else:
            ok.append(name)
    return ok, why


__all__ = [
    "BUILT_IN",
    "DEFAULT_ENGINE",
    "ENGINE_NAMES",
    "BatchOutput",
    "BoundaryInput",
    "Capabilities",
    "Engine",
    "EngineChoice",
    "EngineEntry",
    "EngineOptions",
    "EngineOutput",
    "SimulationInput",
    "WallBatch",
    "available",
    "engine_class",
    "engine_for",
    "engine_names",
    "entry",
    "get_engine",
    "register",
    "scheme_of",
    "unregister",
]

"""The study file's feature tables: ``[calibration]``, ``[retrofit]``, ``[building]``...

Each feature package owns its table (keys, checks, spec object); this module lists them, one
:class:`FeatureTable` line each, and :func:`wallcal.study.parse_study` reads the list: the study core
imports no feature package. A parser is imported only when a study has its table. A new feature is its
package plus one line of :data:`FEATURES` (or one :func:`register_feature` call).

A parser is called as ``parse(raw, problems, ctx)``: ``raw`` the table as read from TOML, ``problems`` the
study's :class:`~wallcal.schema.Problems` (every problem is added there, with its key path, so a study's
problems are reported in one pass), ``ctx`` a :class:`StudyContext` (what the rest of the study says). It
returns the feature's spec; None only when the study has a problem (a table that cannot be read is an error at load,
never a silent None: :func:`parse_features` adds one otherwise).
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .schema import Problems


@dataclass(frozen=True)
class StudyContext:
    """What a feature table's parser may use of the rest of the study.

    Attributes
    ----------
    wall : Wall or None
        The study's wall (None when ``[wall]`` is missing or unreadable).
    wall_clean : bool
        ``[wall]`` was read without a problem (parameters may be checked against it).
    sensors : tuple of SensorSpec
        The sensors read so far.
    sensor_names : set of str
        Every sensor name given, readable or not.
    base_dir : Path or None
        The study file's folder (relative files are relative to it).
    """

    wall: Any
    wall_clean: bool
    sensors: tuple
    sensor_names: frozenset
    base_dir: Path | None


@dataclass(frozen=True)
class FeatureTable:
    """One feature table: its top-level key and its parser (a callable or ``"module:function"``)."""

    key: str
    parser: Callable | str

    def parse(self, raw: Any, problems: Problems, ctx: StudyContext):
        f = self.parser
        if isinstance(f, str):
            module, _, attr = f.partition(":")
            f = getattr(importlib.import_module(module, __package__), attr)
        return f(raw, problems, ctx)


def _calibration(raw, problems: Problems, ctx: StudyContext):
    from .calibration.space import CALIBRATION_KEYS, parse_calibration
    from .schema import Table

    return parse_calibration(
        Table(raw, "calibration", problems, CALIBRATION_KEYS),
        problems,
        ctx.wall if ctx.wall_clean else None,
        list(ctx.sensors),
        sensor_names=set(ctx.sensor_names),
        base_dir=ctx.base_dir,
    )


def _retrofit(raw, problems: Problems, ctx: StudyContext):
    from .retrofitting.config import parse_retrofit

    return parse_retrofit(raw, problems, ctx.base_dir, ctx.wall)


def _building(raw, problems: Problems, ctx: StudyContext):
    from .building.config import parse_building

    return parse_building(raw, problems, ctx.base_dir)


#: The feature tables, in the order they are read.
FEATURES: list[FeatureTable] = [
    FeatureTable("calibration", _calibration),
    FeatureTable("retrofit", _retrofit),
    FeatureTable("building", _building),
]


def register_feature(key: str, parser: Callable | str) -> FeatureTable:
    """Add a feature table read by every later :func:`~wallcal.study.load_study` (``key`` not yet taken)."""
    if any(f.key == key for f in FEATURES):
        raise ValueError(f"the feature table [{key}] is already registered")
    entry = FeatureTable(key, parser)
    FEATURES.append(entry)
    return entry


def unregister_feature(key: str) -> None:
    """Forget feature table ``key`` (tests)."""
    FEATURES[:] = [f for f in FEATURES if f.key != key]


def feature_keys() -> tuple[str, ...]:
    """The top-level keys of the registered feature tables."""
    return tuple(f.key for f in FEATURES)


def parse_features(raw: dict, problems: Problems, ctx: StudyContext) -> dict[str, Any]:
    """Each registered feature table present in ``raw`` (the whole study) -> its spec; problems added."""
    out = {}
    for feature in FEATURES:
        if feature.key not in raw:
            continue
        out[feature.key] = feature.parse(raw[feature.key], problems, ctx)
    if not problems:  # a parser may give None because of a problem elsewhere (the wall); never silently
        for key, spec in out.items():
            if spec is None:
                problems.add(key, "the table could not be read (its parser gave nothing and said nothing)")
    return out

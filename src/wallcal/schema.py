"""Reading and checking TOML tables: the helpers every file format of wallcal shares.

A :class:`Table` reads one TOML table, records every problem with its key path in
:class:`Problems` (``wall.layers[2].conductivity: must be > 0, got -0.035``) and rejects
unknown keys with the closest valid name. The study parser (:mod:`wallcal.study`), the wall
reader (:mod:`wallcal.wallfile`) and the calibration table (:mod:`wallcal.calibration.space`)
build on them, so that every problem of a file is reported at once.
"""

from __future__ import annotations

import datetime as _dt
import math
import os
import stat
import tomllib
from pathlib import Path
from typing import Any

from .errors import StudyError, clip, closest, show

#: the default of a required key
MISSING = object()

#: largest TOML file read (a study or wall file is a few kB) [bytes]
MAX_TOML_BYTES = 4_000_000
#: deepest nesting of tables and arrays in a TOML file (a study nests 5: ``wall.layers[0].conductivity_table[0]``)
MAX_TOML_DEPTH = 16


class Problems(list):
    """Every problem found in a file, each ``"key.path: what is wrong"``."""

    def add(self, path: str, msg: str) -> None:
        self.append(f"{path}: {msg}")


def describe(value: Any) -> str:
    """How a wrong value is named in a message (``'abc'``, ``a table``, ``a list``, ``1.5``)."""
    if isinstance(value, dict):
        return "a table"
    if isinstance(value, list):
        return "a list"
    return show(value)


class Table:
    """Reads one TOML table, recording problems and unknown keys."""

    def __init__(self, data: Any, path: str, problems: Problems, allowed: tuple[str, ...]):
        self.path = path
        self.problems = problems
        self.allowed = allowed
        self.ok = isinstance(data, dict)
        if not self.ok:
            problems.add(path, f"must be a table, got {describe(data)}")
            data = {}
        self.data = data
        for key in data:
            if key not in allowed:
                problems.add(self.at(clip(key)), f"unknown key; {closest(key, allowed)}")

    def at(self, key: str) -> str:
        """The key path of ``key`` in this table (``wall.layers[2].conductivity``)."""
        return f"{self.path}.{key}" if self.path else key

    def has(self, key: str) -> bool:
        return key in self.data

    def raw(self, key: str, default=None):
        return self.data.get(key, default)

    def str(self, key: str, default=MISSING, choices: tuple[str, ...] | None = None):
        v = self.data.get(key, MISSING)
        if v is MISSING:
            if default is MISSING:
                self.problems.add(self.at(key), "required, missing")
                return None
            return default
        if not isinstance(v, str):
            self.problems.add(self.at(key), f"must be a string, got {describe(v)}")
            return None if default is MISSING else default
        if choices is not None and v not in choices:
            hint = closest(v, choices)
            self.problems.add(self.at(key), f"must be one of {', '.join(choices)}; got {show(v)}; {hint}")
            return None if default is MISSING else default
        return v

    def num(self, key: str, default=MISSING, *, gt=None, ge=None, le=None, lt=None, integer=False):
        v = self.data.get(key, MISSING)
        if v is MISSING:
            if default is MISSING:
                self.problems.add(self.at(key), "required, missing")
            return None if default is MISSING else default
        return check_number(v, self.at(key), self.problems, gt=gt, ge=ge, le=le, lt=lt, integer=integer)

    def bool(self, key: str, default: bool) -> bool:
        v = self.data.get(key, MISSING)
        if v is MISSING:
            return default
        if not isinstance(v, bool):
            self.problems.add(self.at(key), f"must be true or false, got {describe(v)}")
            return default
        return v

    def datetime(self, key: str, default=MISSING):
        v = self.data.get(key, MISSING)
        if v is MISSING:
            if default is MISSING:
                self.problems.add(self.at(key), "required, missing")
                return None
            return default
        return to_datetime(v, self.at(key), self.problems)

    def table(self, key: str, allowed: tuple[str, ...], required=True) -> Table | None:
        v = self.data.get(key, MISSING)
        if v is MISSING:
            if required:
                self.problems.add(self.at(key), "required table, missing")
            return None
        return Table(v, self.at(key), self.problems, allowed)

    def tables(self, key: str, allowed: tuple[str, ...], required=True) -> list[Table]:
        v = self.data.get(key, MISSING)
        if v is MISSING:
            if required:
                self.problems.add(self.at(key), "required, missing (an array of tables [[...]])")
            return []
        if not isinstance(v, list):
            self.problems.add(self.at(key), f"must be an array of tables [[{self.at(key)}]], got {describe(v)}")
            return []
        return [Table(item, f"{self.at(key)}[{i}]", self.problems, allowed) for i, item in enumerate(v)]


def check_number(v, path, problems, *, gt=None, ge=None, le=None, lt=None, integer=False):
    """``v`` as a float within the limits, or None after recording why not at ``path``."""
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        problems.add(path, f"must be a number, got {describe(v)}")
        return None
    if isinstance(v, float) and not math.isfinite(v):
        problems.add(path, f"must be a finite number, got {v}")
        return None
    if isinstance(v, int) and abs(v) > 10**15:  # float(v) would overflow for TOML's unbounded integers
        problems.add(path, "is out of any physical range, got an integer beyond 1e15")
        return None
    if integer and not float(v).is_integer():
        problems.add(path, f"must be a whole number, got {v}")
        return None
    v = float(v)
    if abs(v) > 1e15:
        problems.add(path, f"is out of any physical range, got {v:g}")
        return None
    if gt is not None and not v > gt:
        problems.add(path, f"must be > {gt:g}, got {v:g}")
        return None
    if ge is not None and not v >= ge:
        problems.add(path, f"must be >= {ge:g}, got {v:g}")
        return None
    if lt is not None and not v < lt:
        problems.add(path, f"must be < {lt:g}, got {v:g}")
        return None
    if le is not None and not v <= le:
        problems.add(path, f"must be <= {le:g}, got {v:g}")
        return None
    return v


def to_datetime(v, path, problems):
    """``v`` as a naive date-time (local standard time), or None after recording why not at ``path``."""
    if isinstance(v, _dt.datetime):
        if v.tzinfo is not None:
            problems.add(path, "give a local date-time without a time-zone offset (local standard time)")
            return None
        return v
    if isinstance(v, _dt.date):
        return _dt.datetime(v.year, v.month, v.day)
    if isinstance(v, str):
        try:
            out = _dt.datetime.fromisoformat(v)
        except ValueError:
            problems.add(path, f"must be a date-time like 2025-05-30T00:00:00, got {show(v)}")
            return None
        if out.tzinfo is not None:
            problems.add(path, "give a local date-time without a time-zone offset (local standard time)")
            return None
        return out
    problems.add(path, f"must be a date-time like 2025-05-30T00:00:00, got {describe(v)}")
    return None


def regular_file(path: Path, what: str, limit: int) -> int:
    """The size [bytes] of ``path`` after checking, without opening it, that it is a regular file of at most
    ``limit`` bytes (a FIFO, a device such as ``/dev/zero`` or a directory would block or never end).

    Raises
    ------
    OSError
        From ``os.stat`` (FileNotFoundError for a missing file).
    ValueError
        With the problem in words (the caller adds the file and raises its own error type).
    """
    st = os.stat(path)
    if not stat.S_ISREG(st.st_mode):
        kind = "a directory" if stat.S_ISDIR(st.st_mode) else "a FIFO, socket or device"
        raise ValueError(f"is not a regular file ({kind}); give a {what} file")
    if st.st_size > limit:
        raise ValueError(
            f"is {st.st_size / 1e6:,.0f} MB, larger than wallcal reads as a {what} file ({limit / 1e6:,.0f} MB)"
        )
    return st.st_size


def toml_depth(data) -> int:
    """Deepest nesting of tables and arrays in parsed TOML (walked without recursion)."""
    deepest = 0
    stack = [(data, 0)]
    while stack:
        node, depth = stack.pop()
        deepest = max(deepest, depth)
        if isinstance(node, dict):
            stack.extend((v, depth + 1) for v in node.values() if isinstance(v, dict | list))
        elif isinstance(node, list):
            stack.extend((v, depth + 1) for v in node if isinstance(v, dict | list))
    return deepest


def read_toml(path: Path) -> dict:
    """The parsed TOML file; a :class:`StudyError` naming the file when it cannot be read, is not a regular file,
    is larger than :data:`MAX_TOML_BYTES`, is not UTF-8 TOML, or nests deeper than :data:`MAX_TOML_DEPTH`."""
    try:
        regular_file(path, "TOML", MAX_TOML_BYTES)
    except FileNotFoundError as exc:
        raise StudyError([f"file not found: {path}"], source=str(path)) from exc
    except OSError as exc:
        raise StudyError([f"cannot read the file: {exc.strerror}"], source=str(path)) from exc
    except ValueError as exc:
        raise StudyError([str(exc)], source=str(path)) from exc
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise StudyError([f"cannot read the file: {exc.strerror}"], source=str(path)) from exc
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise StudyError(
            [f"not valid UTF-8 text (byte {exc.start}): save the file as UTF-8"], source=str(path)
        ) from exc
    too_deep = f"tables or arrays nested deeper than {MAX_TOML_DEPTH} levels; a study nests 5 at most"
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise StudyError([f"not valid TOML: {clip(str(exc), 200)}"], source=str(path)) from exc
    except RecursionError as exc:  # tomllib parses nested arrays and inline tables recursively
        raise StudyError([too_deep], source=str(path)) from exc
    except ValueError as exc:  # e.g. an integer beyond Python's digit limit
        raise StudyError([f"not valid TOML: {clip(str(exc), 200)}"], source=str(path)) from exc
    if toml_depth(raw) > MAX_TOML_DEPTH:
        raise StudyError([too_deep], source=str(path))
    return raw

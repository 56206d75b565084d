"""wallcal's own exceptions.

Every error a user can cause (a bad study file, a bad data file, an impossible
setting) is raised as a :class:`WallcalError` subclass whose message names the
file, key path or column and says what to do. The CLI prints that message on
one line and exits non-zero; ``--debug`` shows the traceback.

Echoed values are cut (:func:`show`, :func:`clip`) so that a hostile input never turns into a huge
message; :func:`format_message` is the last resort the CLI applies to every message (at most
:data:`MAX_LINES` lines of at most :data:`MAX_LINE` characters, control characters escaped).
"""

from __future__ import annotations

import difflib
from collections.abc import Iterable

#: longest line of an error message as the CLI prints it [characters]
MAX_LINE = 300
#: most lines of an error message as the CLI prints it
MAX_LINES = 25
#: most problems a :class:`StudyError` lists (the rest are counted)
MAX_PROBLEMS = 20
#: longest echo of a value in a message [characters]
MAX_ECHO = 60


def clip(text: str, limit: int = MAX_ECHO) -> str:
    """``text`` cut to at most ``limit`` characters (ending in ``...`` when cut)."""
    if len(text) <= limit:
        return text
    return text[: max(limit - 3, 0)] + "..."


def show(value, limit: int = MAX_ECHO) -> str:
    """How a value read from a file is echoed in a message: its ``repr``, at most ``limit`` characters."""
    if isinstance(value, str | bytes):
        return clip(repr(value[: limit + 1]), limit)
    if isinstance(value, int) and not isinstance(value, bool) and value.bit_length() > 128:
        return f"an integer of about {int(value.bit_length() * 0.30103)} digits"
    return clip(repr(value), limit)


def format_message(msg: str, prefix: str = "") -> str:
    """``prefix + msg`` as printed: at most :data:`MAX_LINES` lines of at most :data:`MAX_LINE` characters (a
    longer line keeps its start and its end, the file and key path and what to do, cut in the middle with
    `` ... ``), control characters (NUL, escape sequences, carriage returns) shown escaped (``\\x00``)."""
    most = MAX_LINE * (MAX_LINES + 1)
    if len(msg) > most:  # never split or escape a huge message whole
        msg = msg[:most] + msg[-MAX_LINE:]
    lines = msg.split("\n")
    out = []
    for i, line in enumerate(lines[:MAX_LINES]):
        line = (prefix if i == 0 else "") + line
        if len(line) > 2 * MAX_LINE:
            line = line[:MAX_LINE] + line[-MAX_LINE:]
        line = "".join(c if c.isprintable() else c.encode("unicode_escape").decode() for c in line)
        if len(line) > MAX_LINE:
            keep = MAX_LINE * 3 // 5
            line = line[:keep] + " ... " + line[-(MAX_LINE - keep - 5) :]
        out.append(line)
    if len(lines) > MAX_LINES:
        out.append("  ... (message cut)")
    return "\n".join(out)


class WallcalError(Exception):
    """Base class of every error wallcal raises on purpose."""


class StudyError(WallcalError):
    """A study or wall file is invalid.

    Parameters
    ----------
    problems : list of str
        Every problem found, each starting with its key path
        (``wall.layers[2].conductivity: must be > 0, got -0.035``).
    source : str, optional
        The file the problems were found in.
    """

    def __init__(self, problems: list[str], source: str | None = None):
        self.problems = list(problems)
        self.source = source
        where = f"{source}: " if source else ""
        if len(self.problems) == 1:
            msg = f"{where}{self.problems[0]}"
        else:
            shown = self.problems[:MAX_PROBLEMS]
            body = "\n".join(f"  - {p}" for p in shown)
            if len(self.problems) > len(shown):
                body += f"\n  ... and {len(self.problems) - len(shown)} more"
            msg = f"{where}{len(self.problems)} problems:\n{body}"
        super().__init__(msg)


class DataError(WallcalError):
    """Monitoring data cannot be read or do not fit the study."""


class EngineError(WallcalError):
    """An engine cannot run the requested case (or an external engine failed)."""


class OptionalDependencyError(WallcalError):
    """An optional extra is needed but not installed."""


def check_finite(series: dict, engine: str, cause: str) -> None:
    """Raise :class:`EngineError` naming the first series (sensor, probe or face) of ``series`` (name -> array)
    that holds NaN or inf, and ``cause`` (the likely cause, e.g. :meth:`wallcal.wall.Wall.nonfinite_cause`):
    a simulation never ends in NaN silently."""
    import numpy as np

    for name, values in series.items():
        v = np.asarray(values, dtype=float)
        bad = ~np.isfinite(v)
        if bad.any():
            k = int(np.flatnonzero(bad.ravel())[0])
            raise EngineError(
                f"{engine}: the simulated {name!s:.40} is not finite (NaN or inf) from output {k + 1} of {v.size} on; "
                f"{cause}"
            )


def closest(name: str, valid: Iterable[str], n: int = 3) -> str:
    """Return a hint naming the valid names closest to ``name``.

    Returns an empty string when nothing is close.
    """
    valid = list(valid)
    if len(name) > 200 or len(valid) > 1000:  # a hostile name or header: no fuzzy search
        return "valid names: " + clip(", ".join(show(v) for v in valid[:20]), 200)
    matches = difflib.get_close_matches(name, valid, n=n, cutoff=0.5)
    if matches:
        return "did you mean " + " or ".join(show(m) for m in matches) + "?"
    return "valid names: " + clip(", ".join(show(v) for v in valid[:20]), 200)


def require(module: str, extra: str):
    """Import an optional dependency or raise with the install command."""
    import importlib

    try:
        return importlib.import_module(module)
    except ImportError as exc:  # pragma: no cover - depends on environment
        raise OptionalDependencyError(
            f"this needs the optional package {module!r}: pip install 'wallcal[{extra}]'"
        ) from exc


def interrupted(exc: BaseException | None) -> bool:
    """Whether ``exc`` comes from a Ctrl-C: a ``KeyboardInterrupt``, or one that arrived while a numba kernel ran
    and surfaces as a ``SystemError`` ("returned a result with an exception set") caused by it."""
    seen = set()
    while exc is not None and id(exc) not in seen:
        if isinstance(exc, KeyboardInterrupt):
            return True
        seen.add(id(exc))
        exc = exc.__cause__ or exc.__context__
    return False

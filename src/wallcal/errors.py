"""wallcal's own exceptions.

Every error a user can cause (a bad study file, a bad data file, an impossible
setting) is raised as a :class:`WallcalError` subclass whose message names the
file, key path or column and says what to do. The CLI prints that message on
one line and exits non-zero; ``--debug`` shows the traceback.
"""

from __future__ import annotations

import difflib
from collections.abc import Iterable


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
            body = "\n".join(f"  - {p}" for p in self.problems)
            msg = f"{where}{len(self.problems)} problems:\n{body}"
        super().__init__(msg)


class DataError(WallcalError):
    """Monitoring data cannot be read or do not fit the study."""


class EngineError(WallcalError):
    """An engine cannot run the requested case (or an external engine failed)."""


class OptionalDependencyError(WallcalError):
    """An optional extra is needed but not installed."""


def closest(name: str, valid: Iterable[str], n: int = 3) -> str:
    """Return a hint naming the valid names closest to ``name``.

    Returns an empty string when nothing is close.
    """
    valid = list(valid)
    matches = difflib.get_close_matches(name, valid, n=n, cutoff=0.5)
    if matches:
        return "did you mean " + " or ".join(repr(m) for m in matches) + "?"
    return "valid names: " + ", ".join(repr(v) for v in valid)


def require(module: str, extra: str):
    """Import an optional dependency or raise with the install command."""
    import importlib

    try:
        return importlib.import_module(module)
    except ImportError as exc:  # pragma: no cover - depends on environment
        raise OptionalDependencyError(
            f"this needs the optional package {module!r}: pip install 'wallcal[{extra}]'"
        ) from exc

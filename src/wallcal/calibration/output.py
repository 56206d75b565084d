"""A ``wallcal calibrate`` output folder, read back (its writer: :meth:`.run.CalibrationResult.write_into`).

One study: ``calibrated_wall.toml`` in the folder; several studies at once: one sub-folder per study, each
with its ``calibrated_wall.toml``. The folder's ``manifest.json`` carries its format version
(:mod:`wallcal.outputs`), which :func:`read_calibrated_walls` checks.
"""

from __future__ import annotations

from pathlib import Path

from ..errors import StudyError
from ..outputs import check_format
from ..wall import Wall

#: The command whose output this module reads.
COMMAND = "calibrate"
#: The calibrated wall's file in the folder (or in each study's sub-folder).
WALL_FILE = "calibrated_wall.toml"


def is_calibrate_output(directory: str | Path) -> bool:
    """True when ``directory`` holds a calibrated wall, at its top or in sub-folders."""
    d = Path(directory)
    return (d / WALL_FILE).exists() or any((p / WALL_FILE).exists() for p in d.iterdir() if p.is_dir())


def read_calibrated_walls(directory: str | Path) -> dict[str, Wall]:
    """The calibrated walls of a calibrate output: ``{folder name: wall}`` (one study), or ``{sub-folder name:
    wall}`` for each study (several studies at once).

    Raises
    ------
    OutputFormatError
        A folder of another format version, or without one (:func:`wallcal.outputs.check_format`).
    StudyError
        No calibrated wall in the folder, or one that does not parse.
    """
    from ..wallfile import load_wall

    d = Path(directory)
    check_format(d, COMMAND)
    if (d / WALL_FILE).exists():
        return {d.name: load_wall(d / WALL_FILE)}
    subs = sorted(p for p in d.iterdir() if (p / WALL_FILE).exists())
    if not subs:
        raise StudyError([f"{d}: a calibrate output without {WALL_FILE}"])
    return {p.name: load_wall(p / WALL_FILE) for p in subs}


__all__ = ["WALL_FILE", "is_calibrate_output", "read_calibrated_walls"]

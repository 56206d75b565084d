"""The cross-check: every wall in every engine, RMSE per target (the paper's Table VIII), and its output folder.

One implementation for ``wallcal crosscheck`` and the ``crosscheck`` stage of ``wallcal run``. The output
folder (format :data:`FORMAT_VERSION` in ``manifest.json``, see :mod:`wallcal.outputs`):

- ``crosscheck.csv``: one row per wall and engine, columns ``wall``, ``engine`` and ``rmse_<target>`` [K for
  temperatures, W/m2 for heat fluxes] for each target;
- ``walls/<wall>.toml``: the walls checked (the probes they were run with), which ``wallcal building --from``
  reads back through :func:`read_crosscheck`.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from .errors import StudyError
from .outputs import FORMATS
from .wall import Wall

#: The command whose output this module writes and reads.
COMMAND = "crosscheck"
#: Format version of the output folder (kept in :data:`wallcal.outputs.FORMATS`).
FORMAT_VERSION = FORMATS[COMMAND].version
#: The table's file and the walls' folder in the output.
CSV, WALLS = "crosscheck.csv", "walls"
#: Column of a target's RMSE.
RMSE_COLUMN = "rmse_{}"


@dataclass
class Crosscheck:
    """The walls checked (name -> wall, in order) and the table (``wall``, ``engine``, ``rmse_<target>``)."""

    walls: dict[str, Wall]
    table: pd.DataFrame

    def write_into(self, d: Path) -> list[str]:
        """Write ``crosscheck.csv`` and ``walls/<name>.toml`` into ``d``; returns the names written."""
        from .wallfile import dump_wall

        d = Path(d)
        self.table.to_csv(d / CSV, index=False, float_format="%.6g")
        (d / WALLS).mkdir(exist_ok=True)
        files = [CSV]
        for name, wall in self.walls.items():
            (d / WALLS / f"{name}.toml").write_text(dump_wall(wall, f"wall {name!r} of a wallcal crosscheck"))
            files.append(f"{WALLS}/{name}.toml")
        return files


def default_targets(study) -> list[str]:
    """The study's calibration targets, else its temperature sensors."""
    if study.calibration:
        return list(study.calibration.targets)
    return [s.name for s in study.sensors if s.quantity == "temperature"]


def with_study_probes(study, wall: Wall, source: str) -> Wall:
    """``wall`` with the study's probes when it has none; checked to have every probe the study's temperature
    sensors need.

    Raises
    ------
    StudyError
        Naming ``source`` and the missing probes.
    """
    if not wall.probes:
        wall = wall.replace(probes=study.wall.probes)
    have = {p.name for p in wall.probes}
    missing = [s.name for s in study.sensors if s.quantity == "temperature" and s.name not in have]
    if missing:
        raise StudyError([f"{source}: the wall has no probe {', '.join(missing)} that the study's sensors need"])
    return wall


def crosscheck(study, walls: dict[str, Wall], engines, *, targets=None, known: dict | None = None) -> Crosscheck:
    """Run every wall of ``walls`` (name -> wall) in every engine of ``engines`` over the study's data.

    Parameters
    ----------
    study : Study
    walls : dict of str to Wall
        The walls, each with the probes the study needs (:func:`with_study_probes`); names become the
        ``wall`` column and the file names in ``walls/``.
    engines : sequence of str
    targets : sequence of str, optional
        The RMSE columns; default :func:`default_targets`.
    known : dict of str to Comparison, optional
        Comparisons already run for some walls (by name), reused as they are.

    Returns
    -------
    Crosscheck

    Raises
    ------
    StudyError
        An unknown engine, a name used twice.
    """
    from .comparison import compare_many

    targets = list(targets) if targets is not None else default_targets(study)
    known = dict(known or {})
    todo = [name for name in walls if name not in known]
    comps = dict(zip(todo, compare_many([study.replace(wall=walls[n]) for n in todo], engines), strict=True))
    comps.update(known)
    rows = []
    for name in walls:
        for eng, r in comps[name].results.items():
            met = r.metrics.set_index("signal")
            rows.append({"wall": name, "engine": eng, **{RMSE_COLUMN.format(t): met.loc[t, "rmse"] for t in targets}})
    return Crosscheck(walls=dict(walls), table=pd.DataFrame(rows))


def read_crosscheck(directory: str | Path) -> Crosscheck:
    """A crosscheck output folder (the format this wallcal writes): its table and its walls.

    Raises
    ------
    OutputFormatError
        A folder of another format version, or without one (:func:`wallcal.outputs.check_format`).
    StudyError
        The folder has no ``walls/`` or a wall file that does not parse.
    """
    from .outputs import check_format
    from .wallfile import load_wall

    d = Path(directory)
    check_format(d, COMMAND)
    files = sorted((d / WALLS).glob("*.toml"))
    if not files:
        raise StudyError([f"{d}: a crosscheck output without walls in {WALLS}/; run 'wallcal crosscheck' again"])
    try:
        table = pd.read_csv(d / CSV)
    except (OSError, ValueError) as exc:
        raise StudyError([f"{d / CSV}: not readable ({exc})"]) from exc
    return Crosscheck(walls={f.stem: load_wall(f) for f in files}, table=table)


__all__ = [
    "CSV",
    "FORMAT_VERSION",
    "WALLS",
    "Crosscheck",
    "crosscheck",
    "default_targets",
    "read_crosscheck",
    "with_study_probes",
]

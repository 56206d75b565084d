"""The walls a building is run with: wall files, and the walls in other commands' outputs (``--from``).

- a ``wallcal calibrate`` output: ``calibrated_wall.toml`` (one optimal wall), or one sub-folder per study
  each with its ``calibrated_wall.toml`` (calibrating several studies at once);
- a ``wallcal crosscheck`` output: the walls it checked, ``walls/<name>.toml``;
- a ``wallcal posterior`` output (``chain.npz``): ``samples`` draws, spread evenly over the chain after its
  burn-in (:func:`wallcal.analysis.posterior.load_samples`), applied to the study's wall;
- a ``wallcal retrofit`` output: its variants' walls, ``variant_<k>.toml`` named in ``retrofit.json``.

Each folder is read by the reader beside its writer, which checks its format version (:mod:`wallcal.outputs`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from ..errors import StudyError
from ..wall import Wall

#: Kinds of wall entries.
KINDS = ("file", "study", "optimal", "draw", "variant")


@dataclass(frozen=True)
class WallEntry:
    """One wall to run: its name in ``building.csv``, the wall, its kind (:data:`KINDS`) and its source."""

    name: str
    wall: Wall
    kind: str
    source: str


def from_output(study, directory: str | Path, samples: int) -> list[WallEntry]:
    """The walls in another command's output folder (see the module text).

    Raises
    ------
    StudyError
        A folder that is none of these outputs, or whose walls do not parse.
    """
    from ..calibration.output import is_calibrate_output, read_calibrated_walls
    from ..crosscheck import CSV, read_crosscheck

    d = Path(directory)
    if not d.is_dir():
        raise StudyError([f"--from {d}: no such folder"])
    if (d / "chain.npz").exists():
        from ..analysis.posterior import load_samples

        smp = load_samples(d, study.wall, samples)
        return [WallEntry(f"draw_{k:03d}", w, "draw", f"posterior draw {k} of {d}") for k, w in enumerate(smp.walls, 1)]
    if (d / CSV).exists():
        return [
            WallEntry(n, w, "optimal", f"crosscheck wall {d / 'walls' / n}.toml")
            for n, w in read_crosscheck(d).walls.items()
        ]
    if (d / "retrofit.json").exists():
        from ..retrofitting.run import read_variant_walls

        return [WallEntry(n, w, "variant", f"retrofit variant {n!r} of {d}") for n, w in read_variant_walls(d).items()]
    if is_calibrate_output(d):
        return [
            WallEntry(n, w, "optimal", f"calibrated wall of {d if n == d.name else d / n}")
            for n, w in read_calibrated_walls(d).items()
        ]
    raise StudyError(
        [
            f"--from {d}: not a calibrate (calibrated_wall.toml), crosscheck (crosscheck.csv and walls/), "
            "posterior (chain.npz) or retrofit (retrofit.json) output"
        ]
    )


def collect_walls(study, wall_files=(), from_dirs=(), samples: int = 20) -> list[WallEntry]:
    """Every wall to run, in the order given: the wall files, then each ``--from`` folder's walls; the study's
    wall alone when neither is given. Names are made unique (``name``, ``name-2``, ...).

    Raises
    ------
    StudyError
        A wall file that does not parse (its file and key path), or a bad ``--from`` folder.
    """
    from ..study import load_wall

    entries: list[WallEntry] = []
    for f in wall_files:
        p = Path(f)
        if not p.is_file():
            raise StudyError([f"--walls {p}: no such file"])
        entries.append(WallEntry(p.stem, load_wall(p), "file", str(p)))
    for d in from_dirs:
        entries += from_output(study, d, samples)
    if not entries:
        entries.append(WallEntry("study wall", study.wall, "study", "the study's wall"))
    seen: dict[str, int] = {}
    out = []
    for e in entries:
        n = seen.get(e.name, 0) + 1
        seen[e.name] = n
        out.append(e if n == 1 else WallEntry(f"{e.name}-{n}", e.wall, e.kind, e.source))
    return out

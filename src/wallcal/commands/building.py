"""``wallcal building STUDY [--walls A.toml ...] [--from DIR ...] [--building MODEL] [--surfaces NAMES]
[--weather EPW] [--measured ZONE.csv --zone-column NAME] --out OUT``: the walls in a whole building."""

from __future__ import annotations

import shutil
from pathlib import Path

from ..formatting import table


def register(sub) -> None:
    p = sub.add_parser(
        "building",
        help="the walls in a whole building (EnergyPlus): heating, cooling, peaks, whole-envelope check",
        description="Put each wall on the outdoor walls of the bundled reference building (or of --building) and "
        "run EnergyPlus over the weather file. Writes building.csv (heating_kWh, cooling_kWh, per m2 of "
        "conditioned floor, peaks, difference to the first wall), spread.csv with posterior draws, "
        "envelope_check.csv with --measured, building.json. See docs/building.md.",
    )
    p.add_argument("study", help="study file (TOML)")
    p.add_argument("--walls", nargs="+", default=[], metavar="WALL.toml", help="wall files (default: the study's)")
    p.add_argument(
        "--from",
        dest="from_dirs",
        action="append",
        default=[],
        metavar="DIR",
        help="a calibrate, crosscheck, posterior or retrofit output (its walls); may be repeated",
    )
    p.add_argument("--samples", type=int, metavar="N", help="posterior draws (default: building.samples, 20)")
    p.add_argument("--building", metavar="MODEL", help="your EnergyPlus 25.2 model (.epJSON or .idf)")
    p.add_argument(
        "--surfaces", metavar="NAMES", help="comma-separated surfaces that get the wall (default: every outdoor wall)"
    )
    p.add_argument(
        "--weather", metavar="EPW", help="EPW file or shipped weather name (default: [building] or [retrofit] weather)"
    )
    p.add_argument("--period", metavar="MM-DD:MM-DD", help="run period (default: building.start/end, else the year)")
    p.add_argument("--measured", metavar="ZONE.csv", help="measured zone air temperatures (first column: time)")
    p.add_argument("--zone-column", metavar="NAME", help="the column of --measured to compare with")
    p.add_argument(
        "--zone", metavar="ZONE", help="the zone compared with --measured (default: the only conditioned one)"
    )
    p.add_argument("--out", metavar="DIR", required=True, help="output directory")
    p.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help="dask scheduler for the EnergyPlus runs (default: WALLCAL_SCHEDULER, else a local cluster)",
    )
    p.add_argument(
        "--resume",
        action="store_true",
        help="reuse the runs an interrupted command finished (kept in .OUT.building-cache next to --out)",
    )
    p.add_argument("--quiet", action="store_true", help="no progress line")
    p.set_defaults(func=run)


def run(args) -> int:
    from ..building import BuildingSpec, building, collect_walls
    from ..building.config import parse_day
    from ..errors import StudyError
    from ..schema import Problems
    from ..simulation import manifest_of
    from ..study import load_study

    study = load_study(args.study)
    spec = study.building or BuildingSpec()
    if args.samples is not None:
        if args.samples < 1:
            raise StudyError([f"--samples: must be >= 1, got {args.samples}"])
        spec = _replace(spec, samples=args.samples)
    if args.period:
        problems = Problems()
        a, _, b = args.period.partition(":")
        start, end = parse_day(a, "--period (start)", problems), parse_day(b, "--period (end)", problems)
        if start and end and end < start:
            problems.add("--period", f"the end {b} is before the start {a}; a run period must not wrap the year")
        if problems:
            raise StudyError(problems)
        spec = _replace(spec, start=start, end=end)
    if args.measured and not args.zone_column:
        raise StudyError(["--measured needs --zone-column NAME"])
    walls = collect_walls(study, args.walls, args.from_dirs, spec.samples)
    out = Path(args.out).resolve()
    cache = out.parent / f".{out.name}.building-cache"
    surfaces = [s.strip() for s in args.surfaces.split(",") if s.strip()] if args.surfaces else None
    res = building(
        study,
        walls,
        spec=spec,
        model=args.building,
        surfaces=surfaces,
        weather=args.weather,
        measured=args.measured,
        zone_column=args.zone_column,
        zone=args.zone,
        scheduler=args.scheduler,
        cache_dir=cache,
        resume=args.resume,
        progress=not args.quiet,
    )
    manifest = manifest_of(study, "building")
    manifest["weather"] = str(res.weather)
    res.write(args.out, manifest=manifest)
    shutil.rmtree(cache, ignore_errors=True)  # the runs are in the output now
    print(f"{study.name or Path(args.study).name}: {len(walls)} wall(s) in the building, {res.seconds:.1f} s")
    print()
    print(table(res.table().set_index("wall"), "Heating and cooling (kWh, kWh/m2 of conditioned floor; peaks W)"))
    sp = res.spread()
    if not sp.empty:
        print()
        print(table(sp, "Spread over the posterior draws"))
    if res.check is not None:
        print()
        print(table(res.check.set_index("wall"), "Whole-envelope check: free-floating zone air vs measured (K)"))
    print()
    for note in res.notes():
        print(f"- {note}")
    print(f"\nwrote {args.out}/building.csv and building.json")
    return 0


def _replace(spec, **changes):
    import dataclasses

    return dataclasses.replace(spec, **changes)

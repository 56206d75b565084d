"""``wallcal run STUDY``: the whole study, with an HTML report."""

from __future__ import annotations

from pathlib import Path

from ..workflow import STAGES
from .clusteropts import add_scheduler, executor_for


def register(sub) -> None:
    names = ", ".join(st.name for st in STAGES)
    p = sub.add_parser(
        "run",
        help=f"the whole study ({names}) and an HTML report",
        description="Run every stage of the study and write DIR/index.html (self-contained) with "
        "each stage's machine-readable results in DIR/<stage>/. A failing optional "
        "stage is reported, not fatal.",
    )
    p.add_argument("study")
    p.add_argument("--out", metavar="DIR", help="default: report/ next to the study")
    p.add_argument(
        "--skip",
        default="",
        help=f"comma-separated stages to leave out ({names})",
    )
    p.add_argument("--engines", help="comma-separated engines (default: every available one)")
    p.add_argument("--quick", action="store_true", help="smaller grid study and swarm (a preview)")
    p.add_argument("--quiet", action="store_true")
    add_scheduler(p)
    p.set_defaults(func=run)


def run(args) -> int:
    from ..study import load_study
    from ..workflow import run_study

    study = load_study(args.study)
    out = Path(args.out) if args.out else Path(args.study).resolve().parent / "report"
    skip = tuple(s.strip() for s in args.skip.split(",") if s.strip())
    engines = [e.strip() for e in args.engines.split(",")] if args.engines else None
    with executor_for(args, out, progress=not args.quiet):  # every EnergyPlus run of every stage
        outputs = run_study(study, out, skip=skip, quick=args.quick, engines=engines, progress=not args.quiet)
    print(f"{study.name}: report {out / 'index.html'}")
    for o in outputs:
        print(f"  {o.name:16s} {o.status:8s} {o.seconds:6.1f} s  {o.message}")
    return 0

"""``wallcal retrofit STUDY [--wall WALL.toml | --from DIR] --out OUT``: the study's retrofit variants over a
weather year (U, annual loss and peak, ISO 13788, intervals from posterior draws)."""

from __future__ import annotations

from pathlib import Path

from ..errors import interrupted
from ..formatting import table


def register(sub) -> None:
    p = sub.add_parser(
        "retrofit",
        help="retrofit variants over a weather year: U, annual loss, peak, condensation, intervals",
        description="Run every [[retrofit.variants]] of the study over the [retrofit] weather year from a "
        "periodic state. Writes variants.csv (U, annual loss with its 5-95 %% interval over posterior draws, "
        "saving, peak loss, minimum interior surface temperature, f_Rsi, ISO 13788 condensation), per-variant "
        "hourly_<k>.csv and glaser_<k>.csv, retrofit.json and figures. With posterior draws the draws done are "
        "saved beside --out as they finish: after an interruption --resume continues. See docs/retrofit.md.",
    )
    p.add_argument("study", help="study file (TOML) with a [retrofit] table")
    src = p.add_mutually_exclusive_group()
    src.add_argument("--wall", metavar="WALL.toml", help="start the variants from this wall instead of the study's")
    src.add_argument(
        "--from",
        dest="from_dir",
        metavar="DIR",
        help="a 'wallcal calibrate' output (its calibrated wall) or a 'wallcal posterior' output (its draws)",
    )
    p.add_argument("--out", metavar="DIR", help="output directory (default: retrofit/ next to the study)")
    p.add_argument("--samples", type=int, metavar="N", help="posterior draws used (default: retrofit.samples)")
    p.add_argument(
        "--resume",
        action="store_true",
        help="continue an interrupted run: take the posterior draws already done from the checkpoint beside --out",
    )
    p.add_argument("--quiet", action="store_true", help="no progress lines")
    p.set_defaults(func=run)


def run(args) -> int:
    import sys

    from ..calibration.checkpoint import present
    from ..errors import StudyError
    from ..outputs import clean_stale
    from ..retrofitting.run import checkpoint_path, retrofit
    from ..study import load_study, load_wall

    study = load_study(args.study)
    if args.samples is not None and args.samples < 1:
        raise StudyError([f"--samples: must be >= 1, got {args.samples}"])
    wall = load_wall(args.wall) if args.wall else None
    out = Path(args.out) if args.out else Path(args.study).resolve().parent / "retrofit"
    clean_stale(out)  # what a killed run left next to --out (temporary directories)
    ckpt = checkpoint_path(out)
    resume = args.resume
    if resume and not present(ckpt):
        if _complete_output(out, study):
            print(f"nothing to resume: {out} holds the complete retrofit run; run without --resume to run it again")
            return 0
        print(f"no checkpoint of {out} (the run stopped before its first): running from the start", file=sys.stderr)
        resume = False
    before = _stamp(ckpt)
    try:
        res = retrofit(
            study,
            wall=wall,
            from_dir=args.from_dir,
            out=out,
            samples=args.samples,
            progress=not args.quiet,
            resume=resume,
        )
    except Exception as exc:
        saved = _stamp(ckpt) not in (None, before)  # the run wrote the draws' checkpoint or took it up
        if interrupted(exc) and not getattr(args, "debug", False):
            if not saved:
                raise KeyboardInterrupt from None
            print(f"wallcal: interrupted; nothing was written to {out}. {_saved(args, ckpt)}", file=sys.stderr)
            return 130
        if saved and not getattr(args, "debug", False):  # a lost cluster, a killed worker ...: the draws are kept
            print(_saved(args, ckpt), file=sys.stderr)
        raise
    except KeyboardInterrupt:
        if _stamp(ckpt) in (None, before):
            raise
        print(f"wallcal: interrupted; nothing was written to {out}. {_saved(args, ckpt)}", file=sys.stderr)
        return 130
    tab = res.table().set_index("variant")
    print(f"{study.name or Path(args.study).name}: {len(res.variants)} variant(s), {res.seconds:.1f} s")
    print()
    print(
        table(
            tab[["U", "annual_loss_kWh_m2", "annual_loss_p05", "annual_loss_p95", "saving_vs_first_kWh_m2"]],
            "Annual heat loss through the wall (kWh/m2, net; U in W/(m2K))",
        )
    )
    print()
    print(
        table(
            tab[
                [
                    "peak_loss_W_m2",
                    "min_interior_surface_temperature",
                    "frsi",
                    "condensation_max_kg_m2",
                    "condensation_verdict",
                ]
            ],
            "Peak loss (W/m2), interior surface (degC), ISO 13788",
        )
    )
    print()
    if (tab["moisture_verdict"] != "").any():  # the hygrothermal run (EN 15026) and the mould index
        cols = ["moisture_years", "water_content_trend_kg_m2_per_year", "max_relative_humidity_critical"]
        cols += ["critical_interface", "mould_index_max", "moisture_verdict"]
        print(table(tab[cols], "Moisture (EN 15026 year runs): water trend (kg/m2 a year), critical interface"))
        print()
    for note in res.notes():
        print(f"- {note}")
    print(f"\nwrote {out}/variants.csv and the per-variant series and figures")
    return 0


def _saved(args, ckpt) -> str:
    """Where the draws done so far are and the command that continues."""
    import shlex

    cmd = ["wallcal", "retrofit", args.study]
    if args.wall:
        cmd += ["--wall", args.wall]
    if args.from_dir:
        cmd += ["--from", args.from_dir]
    if args.out:
        cmd += ["--out", args.out]
    if args.samples is not None:
        cmd += ["--samples", str(args.samples)]
    cmd.append("--resume")
    return f"The posterior draws done so far are saved in {ckpt}; continue with: {shlex.join(cmd)}"


def _stamp(path):
    """The checkpoint file's identity (inode, modification time), None without one: it changes when the run writes
    it (atomically: a new file each time)."""
    import os

    try:
        st = os.stat(path)
    except (OSError, TypeError):
        return None
    return st.st_ino, st.st_mtime_ns


def _complete_output(out: Path, study) -> bool:
    """Whether ``out`` holds a complete retrofit output of this study file (its manifest says so)."""
    import json

    try:
        man = json.loads((out / "manifest.json").read_text())
    except (OSError, ValueError):
        return False
    return (
        isinstance(man, dict)
        and man.get("command") == "retrofit"
        and man.get("study_sha256") == study.sha256
        and (out / "variants.csv").is_file()
    )

"""``wallcal compare STUDY --engines ...`` and ``wallcal export-idf WALL_OR_STUDY``."""

from __future__ import annotations

import sys
from pathlib import Path

from .clusteropts import add_cluster_options, executor_for

_PERCENT = ("rn_rmse", "cv_rmse_eff", "nmbe", "cv_rmse_g14")
_LABELS = {
    "rmse": "RMSE",
    "rn_rmse": "RN_RMSE %",
    "cv_rmse_eff": "CV_RMSE %",
    "mbe": "MBE (G14)",
    "nmbe": "NMBE % (G14)",
    "cv_rmse_g14": "CV(RMSE) % (G14)",
}


def register(sub) -> None:
    from ..comparison import COMPARE_ENGINES

    p = sub.add_parser(
        "compare",
        help="run a study with several engines: Table IV and engine-to-engine differences",
        description="Simulate the study with each engine (same time step, grid constant and node rule), print "
        "the error metrics per engine and sensor (Table IV) and the RMS differences between engines, "
        "and optionally write comparison.csv, differences.csv and comparison.png. "
        f"Engines: {', '.join(COMPARE_ENGINES)} ('energyplus' is Crank-Nicolson). The node rule "
        "applies to the fd engines; EnergyPlus always uses its own (int) rule.",
    )
    p.add_argument("study", help="study file (TOML)")
    p.add_argument(
        "--engines",
        default="fd-cn,fd-implicit,energyplus",
        metavar="LIST",
        help="comma-separated engine names (default: fd-cn,fd-implicit,energyplus)",
    )
    p.add_argument("--time-step", type=float, metavar="S", help="time step [s] for every engine; default: the study's")
    p.add_argument(
        "--grid-constant", type=float, metavar="C", help="C = dx^2/(alpha dt) for every engine; default: the study's"
    )
    p.add_argument(
        "--node-rule",
        choices=("wallcal", "energyplus"),
        help="nodes per layer rule of the fd engines; default: the study's",
    )
    p.add_argument("--out", metavar="DIR", help="write comparison.csv, differences.csv, comparison.png here")
    add_cluster_options(p)
    p.set_defaults(func=run_compare)

    q = sub.add_parser(
        "export-idf",
        help="write a wall as EnergyPlus 25.2 objects (materials, construction, CondFD settings)",
        description="Write Material / Material:NoMass, MaterialProperty:VariableThermalConductivity (lambda(T) "
        "layers), Construction and HeatBalanceSettings:ConductionFiniteDifference objects for "
        "EnergyPlus 25.2. Contact resistances become thin Material:NoMass (or Material:AirGap) layers.",
    )
    q.add_argument("wall", metavar="WALL_OR_STUDY", help="wall file or study file (TOML with a [wall] table)")
    q.add_argument("--out", metavar="FILE", help="output .idf file (default: standard output)")
    q.add_argument("--name", help="construction name (default: the wall's name)")
    q.add_argument(
        "--grid-constant",
        type=float,
        metavar="C",
        help="CondFD Space Discretization Constant; default: the study's, 3 for a wall file",
    )
    q.add_argument(
        "--scheme",
        choices=("cn", "implicit"),
        help="CondFD difference scheme; default: from the study's engine, cn for a wall file",
    )
    q.add_argument(
        "--temperature-range",
        type=float,
        nargs=2,
        metavar=("LO", "HI"),
        help="range [degC] over which exponential lambda(T) laws are tabulated (default -20 70)",
    )
    q.add_argument(
        "--inside-convergence",
        type=float,
        metavar="K",
        help="CondFD inside-face convergence criterion [K] (default: EnergyPlus' 0.002)",
    )
    q.add_argument(
        "--no-settings", action="store_true", help="leave out HeatBalanceSettings:ConductionFiniteDifference"
    )
    q.set_defaults(func=run_export)


def _g(v, digits: int) -> str:
    """``v`` with ``digits`` significant digits (trailing zeros kept), '-' for NaN."""
    v = float(v)
    return "-" if v != v else f"{v:#.{digits}g}".rstrip(".")


def _metric_rows(comp) -> tuple:
    t4 = comp.table_iv()
    rows = []
    for (sig, metric), r in t4.iterrows():
        unit = comp.table.loc[comp.table["signal"] == sig, "unit"].iloc[0]
        label = _LABELS.get(metric, metric)
        if metric in ("rmse", "mbe"):
            label = f"{label} [{unit}]"
        cells = [sig, label]
        for e in comp.engines:
            v = r[e]
            cells.append("-" if v != v else (f"{100 * v:.2f}" if metric in _PERCENT else _g(v, 4)))
        rows.append(cells)
    return ["signal", "metric", *comp.engines], rows


def _text_table(head, rows, title=None) -> str:
    widths = [max(len(h), *(len(r[i]) for r in rows)) for i, h in enumerate(head)]
    lines = [title] if title else []
    lines.append(
        "  ".join(h.rjust(w) if i > 1 else h.ljust(w) for i, (h, w) in enumerate(zip(head, widths, strict=True)))
    )
    lines.append("  ".join("-" * w for w in widths))
    prev = None
    for r in rows:
        cells = list(r)
        if cells[0] == prev:
            cells[0] = ""
        else:
            prev = cells[0]
        lines.append(
            "  ".join(c.rjust(w) if i > 1 else c.ljust(w) for i, (c, w) in enumerate(zip(cells, widths, strict=True)))
        )
    return "\n".join(lines)


def run_compare(args) -> int:
    with executor_for(args, args.out):
        return compare_command(args)


def compare_command(args) -> int:
    from ..comparison import compare_engines
    from ..outputs import output_dir
    from ..simulation import manifest_of
    from ..study import load_study

    study = load_study(args.study)
    engines = [e.strip() for e in args.engines.split(",") if e.strip()]
    comp = compare_engines(
        study, engines, node_rule=args.node_rule, grid_constant=args.grid_constant, time_step=args.time_step
    )
    for name, why in comp.skipped.items():
        print(f"wallcal: warning: engine {name} skipped: {why}", file=sys.stderr)
    s = comp.settings
    print(
        f"{study.name or Path(args.study).name}: dt = {s['time_step_s']:g} s, C = {s['grid_constant']:g}, "
        f"fd node rule {s['node_rule_fd']} (EnergyPlus: its own int rule)"
    )
    for name in comp.engines:
        print(f"  {name}: {s['nodes'].get(name, '?')} nodes, {s['seconds'][name]:.1f} s")
    for name in comp.skipped:
        print(f"  {name}: skipped (not installed: pip install 'wallcal[energyplus]')")
    print()
    head, rows = _metric_rows(comp)
    print(
        _text_table(
            head,
            rows,
            "Simulated vs measured per engine (Table IV; Guideline-14 figures: MBE, NMBE, "
            "CV(RMSE), measured minus simulated)",
        )
    )
    if len(comp.engines) > 1:
        units = comp.differences.drop_duplicates("signal").set_index("signal")["unit"]
        for value, title in (
            ("rms_difference", "RMS difference between engines (a - b) over the comparison period"),
            ("max_abs_difference", "Maximum absolute difference between engines"),
        ):
            m = comp.difference_matrix(value)
            head = ["signal", "unit", *m.columns]
            rows = [[sig, str(units[sig]), *(_g(v, 3) for v in r)] for sig, r in m.iterrows()]
            print()
            print(_text_table(head, rows, title))
    if args.out:
        man = manifest_of(study, "compare")
        man.update(
            {
                "engines": list(comp.engines),
                "skipped": comp.skipped,
                "time_step_s": s["time_step_s"],
                "grid_constant": s["grid_constant"],
                "node_rule_fd": s["node_rule_fd"],
            }
        )
        with output_dir(args.out, manifest=man) as tmp:
            files = comp.write_into(tmp)
        print(f"\nwrote {args.out}/" + ", ".join(files))
    return 0


def _is_study(path: Path) -> bool:
    import tomllib

    try:
        raw = tomllib.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError):
        return False  # load_wall reports it
    return any(k in raw for k in ("data", "sensors", "boundary", "period", "study"))


def run_export(args) -> int:
    from ..engines import scheme_of
    from ..idf import DEFAULT_TEMPERATURE_RANGE, wall_to_idf_objects
    from ..study import load_study, load_wall

    path = Path(args.wall)
    if _is_study(path):
        study = load_study(path)
        wall = study.wall
        c_default = study.simulation.grid_constant
        scheme_default = scheme_of(study.simulation.engine)
    else:
        wall = load_wall(path)
        c_default, scheme_default = 3.0, "cn"
    text = wall_to_idf_objects(
        wall,
        grid_constant=args.grid_constant or c_default,
        scheme=args.scheme or scheme_default,
        name=args.name,
        temperature_range=tuple(args.temperature_range or DEFAULT_TEMPERATURE_RANGE),
        inside_convergence=args.inside_convergence,
        settings=not args.no_settings,
    )
    header = (
        f"! EnergyPlus 25.2 objects for {wall.name or 'the wall'} from {path.name}, written by wallcal export-idf\n"
    )
    if args.out:
        out = Path(args.out)
        out.parent.mkdir(parents=True, exist_ok=True)
        tmp = out.with_name(f".{out.name}.tmp")
        tmp.write_text(header + text, encoding="utf-8")
        tmp.replace(out)
        print(f"wrote {out}")
    else:
        sys.stdout.write(header + text)
    return 0

"""``wallcal wall`` and ``wallcal iso9869``: the standards toolbox on the command line.

- ``wallcal wall WALL_OR_STUDY``: layer table, R and U (ISO 6946), areal heat
  capacity and the ISO 13786 dynamic characteristics.
- ``wallcal iso9869 STUDY``: the ISO 9869-1 average method on the study's measured
  heat flux and surface temperatures, with its acceptance criteria.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd

from ..errors import StudyError
from ..formatting import table

DIRECTIONS = ("horizontal", "upward", "downward")


# ============================================================================ registration
def register(sub) -> None:
    p = sub.add_parser(
        "wall",
        help="layers, R, U and ISO 13786 dynamic characteristics of a wall",
        description="Print the layers of a wall (a wall file or a study file), its thermal resistance and "
        "U-value (ISO 6946, with the conventional surface resistances), its areal heat capacity "
        "and its ISO 13786 dynamic thermal characteristics.",
    )
    p.add_argument("wall", metavar="WALL_OR_STUDY", help="wall file or study file (TOML with a [wall] table)")
    p.add_argument(
        "--direction",
        choices=DIRECTIONS,
        default="horizontal",
        help="direction of heat flow, for the surface and air-layer resistances (default: horizontal)",
    )
    p.add_argument(
        "--period-hours",
        type=float,
        default=24.0,
        metavar="H",
        help="period of the ISO 13786 characteristics [h] (default: 24)",
    )
    p.add_argument(
        "--air-layer",
        action="append",
        default=None,
        metavar="ID=VENTILATION",
        help="treat layer ID as an ISO 6946 air layer: unventilated, slightly_ventilated or "
        "well_ventilated (repeatable). When given, only these layers are air layers; "
        "by default layers whose material mentions 'air' and its ventilation are",
    )
    p.set_defaults(func=run_wall)

    q = sub.add_parser(
        "iso9869",
        help="ISO 9869-1 average method on the study's measured heat flux",
        description="Estimate the surface-to-surface thermal resistance with the ISO 9869-1 average method "
        "from the study's measured heat flux at one face and its measured surface temperatures, "
        "and check the standard's acceptance criteria.",
    )
    q.add_argument("study", help="study file (TOML)")
    q.add_argument(
        "--face",
        choices=("interior", "exterior"),
        default="interior",
        help="face of the heat flux meter (default: interior)",
    )
    q.add_argument("--sensor", metavar="NAME", help="heat-flux sensor to use when the study has several at that face")
    q.add_argument(
        "--whole-record", action="store_true", help="use the whole data record instead of the study's comparison period"
    )
    q.add_argument("--out", metavar="DIR", help="write iso9869.csv, iso9869.json and iso9869.png here")
    q.set_defaults(func=run_iso9869)


# ============================================================================ wallcal wall
def _parse_air_layers(items) -> dict[str, str] | None:
    if not items:
        return None
    out: dict[str, str] = {}
    for item in items:
        key, sep, vent = item.partition("=")
        if not sep or not key.strip() or not vent.strip():
            raise StudyError([f"--air-layer: expected ID=VENTILATION (e.g. 2=slightly_ventilated), got {item!r}"])
        out[key.strip()] = vent.strip()
    return out


def run_wall(args) -> int:
    from ..standards import iso6946, iso13786
    from ..study import load_wall

    if not (math.isfinite(args.period_hours) and args.period_hours > 0):
        raise StudyError([f"--period-hours: must be a number of hours > 0, got {args.period_hours:g}"])
    wall = load_wall(args.wall)
    air = _parse_air_layers(args.air_layer)
    res = iso6946.thermal_resistance(wall, air_layers=air, direction=args.direction)
    dc = iso13786.dynamic_characteristics(wall, args.period_hours * 3600.0, air_layers=air, direction=args.direction)
    print(table(_layer_table(wall, res), f"{wall.name or Path(args.wall).name}: layers, exterior first"))
    print()
    kappa = wall.areal_heat_capacity
    lines = [
        ("R (surface to surface)", f"{res.resistance:.4f} m2K/W"),
        ("Rsi, Rse", f"{res.rsi:g}, {res.rse:g} m2K/W (ISO 6946, heat flow {args.direction})"),
        ("R_T = Rsi + R + Rse", f"{res.total_resistance:.4f} m2K/W"),
        ("U (ISO 6946)", f"{res.u_value:.4f} W/(m2K)"),
        (
            "areal heat capacity",
            f"{kappa / 1000:.2f} kJ/(m2K) ({'heavy' if kappa > 20e3 else 'light'} element for ISO 9869-1: limit 20)",
        ),
    ]
    lines += [("note", n) for n in res.notes]
    _print_pairs("Steady state (ISO 6946)", lines)
    print()
    t_h = dc.period_s / 3600.0
    dyn = [
        ("|Y12| periodic transmittance", f"{abs(dc.Y12):.5f} W/(m2K)"),
        ("decrement factor f", f"{dc.decrement_factor:.4f}"),
        ("time shift of Y12", f"{dc.time_shift_h:.2f} h (interior heat flow lags the exterior temperature)"),
        (
            "|Y11| interior admittance",
            f"{abs(dc.Y11):.4f} W/(m2K), time shift {dc.admittance_time_lead_interior_h:.2f} h (lead)",
        ),
        (
            "|Y22| exterior admittance",
            f"{abs(dc.Y22):.4f} W/(m2K), time shift {dc.admittance_time_lead_exterior_h:.2f} h (lead)",
        ),
        ("kappa1 interior", f"{dc.kappa1 / 1000:.2f} kJ/(m2K)"),
        ("kappa2 exterior", f"{dc.kappa2 / 1000:.2f} kJ/(m2K)"),
    ]
    _print_pairs(f"Dynamic characteristics (ISO 13786, period {t_h:g} h, with Rsi and Rse)", dyn)
    return 0


def _layer_table(wall, res) -> pd.DataFrame:
    by_id = {lr.id: lr for lr in res.layers}
    rows = []
    for layer in wall.layers:
        lr = by_id.get(layer.id)
        mass = not layer.is_massless
        rows.append(
            {
                "id": layer.id,
                "material": layer.material or "-",
                "d mm": 1000.0 * layer.thickness,
                "lambda W/(m K)": float(layer.conductivity_at(layer.reference_temperature)) if mass else float("nan"),
                "rho kg/m3": float(layer.density) if mass else float("nan"),
                "c J/(kg K)": float(layer.specific_heat) if mass else float("nan"),
                "R m2K/W": f"{lr.resistance if lr is not None else layer.resistance:.4f}",
                "rho c d kJ/(m2K)": layer.areal_heat_capacity / 1000.0,
                "counted as": lr.kind if lr is not None else "material",
            }
        )
        contact = by_id.get(f"{layer.id}/contact")
        if contact is not None:
            rows.append(
                {
                    "id": f"{layer.id}/contact",
                    "material": "contact resistance",
                    "d mm": 0.0,
                    "lambda W/(m K)": float("nan"),
                    "rho kg/m3": float("nan"),
                    "c J/(kg K)": float("nan"),
                    "R m2K/W": f"{contact.resistance:.4f}",
                    "rho c d kJ/(m2K)": 0.0,
                    "counted as": contact.kind,
                }
            )
    df = pd.DataFrame(rows).set_index("id")
    if (df["counted as"] == "material").all():
        df = df.drop(columns="counted as")
    return df


def _print_pairs(title: str, pairs) -> None:
    print(title)
    w = max(len(k) for k, _ in pairs)
    for k, v in pairs:
        print(f"  {k.ljust(w)}  {v}")


# ============================================================================ wallcal iso9869
def run_iso9869(args) -> int:
    from ..standards.insitu import iso9869_for_study
    from ..study import load_study

    study = load_study(args.study)
    ins = iso9869_for_study(study, face=args.face, sensor=args.sensor, whole_record=args.whole_record)
    res, t = ins.res, ins.times_s
    dt = float(np.median(np.diff(t)))
    print(
        f"{study.name or Path(args.study).name}: ISO 9869-1 average method, heat flux {ins.sensor!r} "
        f"at the {args.face} face"
    )
    print(
        f"window {ins.start} .. {ins.end} ({'whole record' if args.whole_record else 'study period'}, "
        f"end excluded): {len(t)} readings x {dt:g} s = {res.duration_h:g} h"
    )
    if ins.n_filled:
        print(f"{ins.n_filled} missing value(s) filled by linear interpolation in time.")
    print()
    df = ins.criteria_table()
    print(table(df[["result", "value", "limit"]], "Acceptance criteria (ISO 9869-1, average method)"))
    print()
    for c in res.verdict.criteria:
        print(f"  {c.name}: {c.description}; {c.detail}")
    print()
    heavy = "heavy" if res.heavy else "light"
    kappa = res.areal_heat_capacity
    print(f"element: {heavy} (areal heat capacity {kappa / 1000:.1f} kJ/(m2K), limit 20)")
    print(f"verdict: {res.verdict.statement}")
    print()
    pairs = [
        ("R (average method)", f"{res.r_value:.3f} m2K/W"),
        (
            "R storage-corrected",
            f"{res.r_storage_corrected:.3f} m2K/W (wallcal's quasi-steady estimate)"
            if res.r_storage_corrected is not None
            else "-",
        ),
        ("U with Rsi, Rse", f"{ins.u:.4f} W/(m2K) (Rsi = {ins.rsi:g}, Rse = {ins.rse:g} m2K/W)"),
        ("R of the study's wall", f"{study.wall.resistance:.3f} m2K/W (layers, for comparison)"),
    ]
    caveat = "" if res.verdict.applicable else " (the ISO 9869-1 criteria are not met: see the verdict)"
    _print_pairs("Estimate" + caveat, pairs)

    if args.out:
        from ..outputs import output_dir
        from ..simulation import manifest_of

        with output_dir(args.out, manifest=manifest_of(study, "iso9869")) as tmp:
            ins.write_into(tmp)
        print(f"\nwrote {args.out}/iso9869.csv, iso9869.json, iso9869.png")
    return 0

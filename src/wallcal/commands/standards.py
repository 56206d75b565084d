"""``wallcal wall`` and ``wallcal iso9869``: the standards toolbox on the command line.

- ``wallcal wall WALL_OR_STUDY``: layer table, R and U (ISO 6946), areal heat
  capacity and the ISO 13786 dynamic characteristics.
- ``wallcal iso9869 STUDY``: the ISO 9869-1 average method on the study's measured
  heat flux and surface temperatures, with its acceptance criteria.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pandas as pd

from ..errors import DataError, StudyError
from ._format import fmt, table

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
    p.add_argument("--direction", choices=DIRECTIONS, default="horizontal",
                   help="direction of heat flow, for the surface and air-layer resistances (default: horizontal)")
    p.add_argument("--period-hours", type=float, default=24.0, metavar="H",
                   help="period of the ISO 13786 characteristics [h] (default: 24)")
    p.add_argument("--air-layer", action="append", default=None, metavar="ID=VENTILATION",
                   help="treat layer ID as an ISO 6946 air layer: unventilated, slightly_ventilated or "
                        "well_ventilated (repeatable). When given, only these layers are air layers; "
                        "by default layers whose material mentions 'air' and its ventilation are")
    p.set_defaults(func=run_wall)

    q = sub.add_parser(
        "iso9869",
        help="ISO 9869-1 average method on the study's measured heat flux",
        description="Estimate the surface-to-surface thermal resistance with the ISO 9869-1 average method "
                    "from the study's measured heat flux at one face and its measured surface temperatures, "
                    "and check the standard's acceptance criteria.",
    )
    q.add_argument("study", help="study file (TOML)")
    q.add_argument("--face", choices=("interior", "exterior"), default="interior",
                   help="face of the heat flux meter (default: interior)")
    q.add_argument("--sensor", metavar="NAME",
                   help="heat-flux sensor to use when the study has several at that face")
    q.add_argument("--whole-record", action="store_true",
                   help="use the whole data record instead of the study's comparison period")
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
    dc = iso13786.dynamic_characteristics(wall, args.period_hours * 3600.0, air_layers=air,
                                          direction=args.direction)
    print(table(_layer_table(wall, res), f"{wall.name or Path(args.wall).name}: layers, exterior first"))
    print()
    kappa = wall.areal_heat_capacity
    lines = [
        ("R (surface to surface)", f"{res.resistance:.4f} m2K/W"),
        ("Rsi, Rse", f"{res.rsi:g}, {res.rse:g} m2K/W (ISO 6946, heat flow {args.direction})"),
        ("R_T = Rsi + R + Rse", f"{res.total_resistance:.4f} m2K/W"),
        ("U (ISO 6946)", f"{res.u_value:.4f} W/(m2K)"),
        ("areal heat capacity", f"{kappa / 1000:.2f} kJ/(m2K) "
                                f"({'heavy' if kappa > 20e3 else 'light'} element for ISO 9869-1: limit 20)"),
    ]
    lines += [("note", n) for n in res.notes]
    _print_pairs("Steady state (ISO 6946)", lines)
    print()
    t_h = dc.period_s / 3600.0
    dyn = [
        ("|Y12| periodic transmittance", f"{abs(dc.Y12):.5f} W/(m2K)"),
        ("decrement factor f", f"{dc.decrement_factor:.4f}"),
        ("time shift of Y12", f"{dc.time_shift_h:.2f} h (interior heat flow lags the exterior temperature)"),
        ("|Y11| interior admittance",
         f"{abs(dc.Y11):.4f} W/(m2K), time shift {dc.admittance_time_lead_interior_h:.2f} h (lead)"),
        ("|Y22| exterior admittance",
         f"{abs(dc.Y22):.4f} W/(m2K), time shift {dc.admittance_time_lead_exterior_h:.2f} h (lead)"),
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
        rows.append({
            "id": layer.id,
            "material": layer.material or "-",
            "d mm": 1000.0 * layer.thickness,
            "lambda W/(m K)": float(layer.conductivity_at(layer.reference_temperature)) if mass else float("nan"),
            "rho kg/m3": float(layer.density) if mass else float("nan"),
            "c J/(kg K)": float(layer.specific_heat) if mass else float("nan"),
            "R m2K/W": f"{lr.resistance if lr is not None else layer.resistance:.4f}",
            "rho c d kJ/(m2K)": layer.areal_heat_capacity / 1000.0,
            "counted as": lr.kind if lr is not None else "material",
        })
        contact = by_id.get(f"{layer.id}/contact")
        if contact is not None:
            rows.append({"id": f"{layer.id}/contact", "material": "contact resistance", "d mm": 0.0,
                         "lambda W/(m K)": float("nan"), "rho kg/m3": float("nan"), "c J/(kg K)": float("nan"),
                         "R m2K/W": f"{contact.resistance:.4f}", "rho c d kJ/(m2K)": 0.0, "counted as": contact.kind})
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
def _heat_flux_sensor(study, face: str, name: str | None):
    from ..errors import closest

    cands = [s for s in study.sensors if s.quantity == "heat_flux" and s.face == face]
    if name is not None:
        for s in cands:
            if s.name == name:
                return s
        valid = [s.name for s in cands]
        raise StudyError([f"--sensor: {name!r} is not a heat_flux sensor at the {face} face; "
                          + (closest(name, valid) if valid else "the study has none there")],
                         source=str(study.path) if study.path else None)
    if not cands:
        others = [f"{s.name} ({s.face})" for s in study.sensors if s.quantity == "heat_flux"]
        hint = (f"; heat_flux sensors in the study: {', '.join(others)} (use --face)" if others
                else "; add a [[sensors]] entry with quantity = \"heat_flux\" and face = \"" + face + "\"")
        raise StudyError([f"sensors: no heat_flux sensor at the {face} face{hint}"],
                         source=str(study.path) if study.path else None)
    if len(cands) > 1:
        raise StudyError([f"sensors: {len(cands)} heat_flux sensors at the {face} face "
                          f"({', '.join(s.name for s in cands)}); choose one with --sensor"],
                         source=str(study.path) if study.path else None)
    return cands[0]


def _check_surface_boundaries(study) -> None:
    bad = [f"boundary.{face}.type is {b.type!r}" for face, b in (("exterior", study.exterior),
                                                                   ("interior", study.interior))
           if b.type != "surface_temperature"]
    if bad:
        raise StudyError([f"ISO 9869 needs measured surface temperatures on both faces, but {' and '.join(bad)}"
                          " (not \"surface_temperature\")"], source=str(study.path) if study.path else None)


def _select(frame: pd.DataFrame, cols: list[str], start, end, max_gap: float) -> tuple[pd.DataFrame, int]:
    """Readings in [start, end) with short gaps filled by linear interpolation in time.

    Each reading stands for one interval (ISO 9869-1 sums), so the half-open window makes
    the analysed duration exactly end - start. Returns the frame and the number of filled values.
    """
    sel = frame.loc[(frame.index >= start) & (frame.index < end), cols]
    if len(sel) < 2:
        raise DataError(f"the analysis window {start} .. {end} holds {len(sel)} reading(s); need at least 2")
    missing = sel.isna()
    n_filled = int(missing.to_numpy().sum())
    if n_filled:
        secs = sel.index.to_series().diff().dt.total_seconds().median()
        for c in cols:
            m = missing[c].to_numpy()
            if not m.any():
                continue
            runs = np.diff(np.concatenate([[0], m.astype(int), [0]]))
            starts, ends = np.flatnonzero(runs == 1), np.flatnonzero(runs == -1)
            longest = int((ends - starts).max())
            if m[0] or m[-1] or (longest + 1) * secs > max_gap:
                i = int(starts[np.argmax(ends - starts)])
                raise DataError(
                    f"column {c!r} is missing {longest} reading(s) from {sel.index[i]} "
                    f"({'at an end of the window' if m[0] or m[-1] else f'longer than data.max_gap = {max_gap:g} s'})"
                    "; the average method needs a complete series: move the period or fill the data"
                )
        sel = sel.interpolate(method="time", limit_area="inside")
    return sel, n_filled


def run_iso9869(args) -> int:
    from ..data import load_measurements
    from ..standards import iso6946, iso9869
    from ..study import load_study

    study = load_study(args.study)
    sensor = _heat_flux_sensor(study, args.face, args.sensor)
    _check_surface_boundaries(study)
    meas = load_measurements(study)
    frame = meas.frame
    if args.whole_record:
        start, end = frame.index[0], frame.index[-1]
    else:
        start, end = pd.Timestamp(study.period.start), pd.Timestamp(study.period.end)
    sel, n_filled = _select(frame, [sensor.name, "interior", "exterior"], start, end, study.data.max_gap)
    t = (sel.index - sel.index[0]).total_seconds().to_numpy(dtype=float)
    res = iso9869.average_method(t, sel[sensor.name].to_numpy(), sel["interior"].to_numpy(),
                                 sel["exterior"].to_numpy(), wall=study.wall, q_side=args.face)
    rsi, rse = iso6946.surface_resistances("horizontal")
    u = 1.0 / (rsi + res.r_value + rse) if res.r_value > 0 else float("nan")
    r_design = study.wall.resistance

    dt = float(np.median(np.diff(t)))
    print(f"{study.name or Path(args.study).name}: ISO 9869-1 average method, heat flux {sensor.name!r} "
          f"at the {args.face} face")
    print(f"window {start} .. {end} ({'whole record' if args.whole_record else 'study period'}, end excluded): "
          f"{len(t)} readings x {dt:g} s = {res.duration_h:g} h")
    if n_filled:
        print(f"{n_filled} missing value(s) filled by linear interpolation in time.")
    print()
    crit_rows = []
    for c in res.verdict.criteria:
        status = ("not required" if not c.required and c.passed is None else
                  "not evaluated" if c.passed is None else "pass" if c.passed else "FAIL")
        if not c.required and c.passed is not None:
            status += " (not required)"
        crit_rows.append({"criterion": c.name, "result": status, "value": _crit_value(c),
                          "limit": _crit_value(c, limit=True), "detail": c.detail})
    df = pd.DataFrame(crit_rows).set_index("criterion")
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
        ("R storage-corrected", f"{res.r_storage_corrected:.3f} m2K/W (wallcal's quasi-steady estimate)"
         if res.r_storage_corrected is not None else "-"),
        ("U with Rsi, Rse", f"{u:.4f} W/(m2K) (Rsi = {rsi:g}, Rse = {rse:g} m2K/W)"),
        ("R of the study's wall", f"{r_design:.3f} m2K/W (layers, for comparison)"),
    ]
    caveat = "" if res.verdict.applicable else " (the ISO 9869-1 criteria are not met: see the verdict)"
    _print_pairs("Estimate" + caveat, pairs)

    if args.out:
        from ..outputs import output_dir
        from ..simulation import manifest_of

        running = pd.DataFrame({
            "elapsed_h": t / 3600.0,
            "q_W_m2": sel[sensor.name].to_numpy(),
            "t_si_C": sel["interior"].to_numpy(),
            "t_se_C": sel["exterior"].to_numpy(),
            "r_running_m2K_W": res.r_running,
        }, index=sel.index.strftime("%Y-%m-%dT%H:%M:%S"))
        running.index.name = "timestamp"
        verdict = {
            "study": study.name,
            "face": args.face,
            "sensor": sensor.name,
            "window_start": str(start),
            "window_end": str(end),
            "window": "whole record" if args.whole_record else "study period",
            "readings": int(len(t)),
            "time_step_s": dt,
            "duration_h": res.duration_h,
            "filled_values": n_filled,
            "r_value_m2K_W": res.r_value,
            "r_storage_corrected_m2K_W": res.r_storage_corrected,
            "u_value_W_m2K": u,
            "rsi_m2K_W": rsi,
            "rse_m2K_W": rse,
            "areal_heat_capacity_J_m2K": kappa,
            "heavy": res.heavy,
            "stored_heat_change_J_m2": res.stored_heat_change_J_m2,
            "heat_through_J_m2": res.heat_through_J_m2,
            "applicable": res.verdict.applicable,
            "statement": res.verdict.statement,
            "failing": res.verdict.failing,
            "criteria": [
                {"name": c.name, "description": c.description, "required": c.required, "passed": c.passed,
                 "value": _json_num(c.value), "limit": _json_num(c.limit), "detail": c.detail}
                for c in res.verdict.criteria
            ],
        }
        with output_dir(args.out, manifest=manifest_of(study, "iso9869")) as tmp:
            tmp = Path(tmp)
            running.to_csv(tmp / "iso9869.csv", float_format="%.6g")
            (tmp / "iso9869.json").write_text(json.dumps(verdict, indent=2, allow_nan=False))
            _figure(tmp / "iso9869.png", t / 3600.0, res, sensor.name, args.face, study.name)
        print(f"\nwrote {args.out}/iso9869.csv, iso9869.json, iso9869.png")
    return 0


def _crit_value(c, limit: bool = False):
    v = c.limit if limit else c.value
    if v is None:
        return float("nan")
    if c.name in ("last_24h", "first_last_two_thirds", "storage"):
        return f"{100 * v:.1f} %" if np.isfinite(v) else "inf"
    return f"{fmt(float(v))} h"


def _json_num(v):
    if v is None:
        return None
    v = float(v)
    return v if math.isfinite(v) else None


def _figure(path: Path, hours: np.ndarray, res, sensor: str, face: str, title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 4.5))
    try:
        r_end = res.r_value
        ax.axhspan(0.95 * r_end, 1.05 * r_end, color="tab:green", alpha=0.2,
                   label=f"final R = {r_end:.2f} m2K/W ± 5 %")
        ax.plot(hours, res.r_running, color="tab:blue", lw=1.2, label="running estimate")
        if res.duration_h > 24:
            ax.axvline(res.duration_h - 24, color="0.5", ls=":", lw=1, label="24 h before the end")
        ax.set_xlabel("elapsed time [h]")
        ax.set_ylabel("R (surface to surface) [m2K/W]")
        # the first day can be wild (sum of q near 0): scale the axis on the rest of the record
        late = res.r_running[hours >= min(24.0, 0.25 * res.duration_h)]
        finite = late[np.isfinite(late)]
        if finite.size:
            lo, hi = float(finite.min()), float(finite.max())
            lo, hi = min(lo, 0.9 * r_end), max(hi, 1.1 * r_end)
            ax.set_ylim(lo - 0.05 * (hi - lo), hi + 0.05 * (hi - lo))
        ax.set_title(f"{title + ': ' if title else ''}ISO 9869-1 average method ({sensor}, {face} face)\n"
                     f"{res.verdict.statement}", fontsize=9)
        ax.grid(True, alpha=0.3)
        ax.legend(loc="best", fontsize=8)
        fig.tight_layout()
        fig.savefig(path, dpi=120)
    finally:
        plt.close(fig)

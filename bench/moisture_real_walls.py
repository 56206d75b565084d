"""Issue 37's real-wall protocols for the heat-and-moisture engine: PASSYS and TRH-1, held-out scoring.

Run: ``PYTHONPATH=src python bench/moisture_real_walls.py [--out DIR] [--quick]``. Prints the tables of
docs/moisture.md ("Real walls: held-out scores").

PASSYS (``examples/passys/study_moisture.toml``, data read in place from ``../shared/data/real/``), the study's
calibration plus each in-wall sensor's offset within its accuracy (0.5 K, 0.03 RH; ``in_wall_offsets``):
``wallcal calibrate`` on the first 10 days (the study's ``[period] end`` moved to 2014-01-10 23:55, its own window
dropped), then ``wallcal simulate`` of the whole record with a study whose ``[wall] file`` is the
``calibrated_wall.toml`` the calibration wrote (its calibrated sensor offsets, read from ``calibration.json``, added
to the sensors' ``offset``); the last 4 days (2014-01-11 .. 14) are scored. The heat-only study
``examples/passys/study.toml`` goes through the same protocol (its +0.9 K face offset removed, the in-wall offsets
calibrated instead; T_4, T_8, T_12 on the same days), for the side-by-side table; and the moisture study once more
with its own calibration, no offsets (what the material alone explains). A second table gives the mean errors
(measured - model). ``wallcal diagnose`` of the study itself (its window held out) is in bench/validation_arms.py.

TRH-1 (``src/wallcal/examples/trh/study_moisture.toml``, bundled): the interface T and RH over the second half
of the record (2021-01-26 .. 02-15), first with the catalogue's properties, then calibrated on the first half
(2021-01-05 .. 25) and simulated over the whole record from its ``calibrated_wall.toml``.

Everything goes through the CLI (``wallcal.cli.main``); the variant study files are written into
``--out`` (default a temporary directory) with absolute data paths. ``--quick`` runs each protocol on a few days
with one least-squares iteration (the machinery check of tests/test_moisture_real_walls.py).
"""

from __future__ import annotations

import argparse
import contextlib
import datetime as dt
import io
import json
import tempfile
import time
import tomllib
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
import tomli_w

ROOT = Path(__file__).resolve().parents[1]
PASSYS_MOISTURE = ROOT / "examples" / "passys" / "study_moisture.toml"
PASSYS_THERMAL = ROOT / "examples" / "passys" / "study.toml"
TRH_MOISTURE = ROOT / "src" / "wallcal" / "examples" / "trh" / "study_moisture.toml"


@dataclass(frozen=True)
class Protocol:
    """Calibrate up to ``cal_end``; simulate up to ``end`` (None: the study's own end); score ``test``."""

    cal_end: dt.datetime
    test: tuple[dt.datetime, dt.datetime]
    end: dt.datetime | None = None
    max_nfev: int | None = None  # None: the study's own least-squares budget


PASSYS = Protocol(dt.datetime(2014, 1, 10, 23, 55), (dt.datetime(2014, 1, 11, 0, 0), dt.datetime(2014, 1, 14, 23, 55)))
TRH = Protocol(dt.datetime(2021, 1, 25, 23, 55), (dt.datetime(2021, 1, 26, 0, 5), dt.datetime(2021, 2, 15, 23, 55)))
#: --quick (tests/test_moisture_real_walls.py): the machinery on a few days, one least-squares iteration
PASSYS_QUICK = Protocol(
    dt.datetime(2014, 1, 3, 23, 55),
    (dt.datetime(2014, 1, 4, 0, 0), dt.datetime(2014, 1, 4, 23, 55)),
    dt.datetime(2014, 1, 4, 23, 55),
    1,
)
TRH_QUICK = Protocol(
    dt.datetime(2021, 1, 6, 23, 55),
    (dt.datetime(2021, 1, 7, 0, 5), dt.datetime(2021, 1, 7, 23, 55)),
    dt.datetime(2021, 1, 7, 23, 55),
    1,
)


def wallcal(*args: str) -> None:
    """Run one wallcal command (the CLI's ``main``, in this process); raise with its output when it fails."""
    from wallcal.cli import main

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        rc = main(list(args))
    if rc != 0:
        raise RuntimeError(f"wallcal {' '.join(args)} failed ({rc}):\n{out.getvalue()}\n{err.getvalue()}")


def absolute_paths(raw: dict, base: Path) -> dict:
    """The study's data file names made absolute, so that the variant can live anywhere (the two studies name
    no other file)."""
    data = raw["data"]
    if "file" in data:
        data["file"] = str((base / data["file"]).resolve())
    for f in data.get("files", []):
        f["file"] = str((base / f["file"]).resolve())
    return raw


def in_wall_offsets(raw: dict, sensors=("T_4", "T_8", "T_12", "HR_4", "HR_8", "HR_12")) -> dict:
    """The protocol's calibration: the study's parameters plus each in-wall sensor's offset within its accuracy
    (0.5 K, 0.03 RH), no window of the study's own (the protocol holds out its own days, scored here)."""
    for key in ("validation_start", "validation_end"):
        raw["period"].pop(key, None)
    names = {s["name"] for s in raw["sensors"]}
    raw["calibration"]["parameters"] += [
        {"sensor": name, "property": "offset", "bounds": [-0.03, 0.03] if name.startswith("HR") else [-0.5, 0.5]}
        for name in sensors
        if name in names
    ]
    return raw


def heat_only_as_moisture(raw: dict) -> dict:
    """The thermal PASSYS study calibrated as the moisture study is: no face offset declared by hand (the
    study's +0.9 K set to 0), the in-wall temperature sensors' offsets calibrated within their accuracy."""
    for b in raw["boundary"].values():
        b.pop("offset", None)
    return in_wall_offsets(raw)


def variant(src: Path, dest: Path, *, end=None, wall_file=None, offsets=None, max_nfev=None, edit=None) -> Path:
    """Write a variant of the study ``src`` to ``dest``: another ``[period] end``, a ``[wall] file``, sensor
    offsets added to the sensors' ``offset``, a least-squares budget, ``edit(raw)`` applied first."""
    raw = absolute_paths(tomllib.loads(src.read_text()), src.parent)
    if edit is not None:
        raw = edit(raw)
    if end is not None:
        raw["period"]["end"] = end
    if wall_file is not None:
        raw["wall"] = {"file": str(wall_file)}
    for s in raw.get("sensors", []):
        if offsets and s["name"] in offsets:
            s["offset"] = s.get("offset", 0.0) + offsets[s["name"]]
    if max_nfev is not None and "calibration" in raw:
        raw["calibration"]["algorithm"] = "least-squares"
        raw["calibration"]["settings"] = {"max_nfev": max_nfev}
    dest.parent.mkdir(parents=True, exist_ok=True)
    dest.write_text(tomli_w.dumps(raw))
    return dest


def scores(sim_dir: Path, signals, start, end, stat: str = "rmse") -> dict[str, float]:
    """RMSE (``stat="rmse"``) or mean error measured - model (``"mbe"``) of each signal between ``start`` and
    ``end`` (inclusive) from a ``wallcal simulate --out`` directory (measured.csv holds the corrected measured
    signals, RH as fractions)."""
    sim = pd.read_csv(sim_dir / "simulated.csv", index_col=0, parse_dates=True)
    meas = pd.read_csv(sim_dir / "measured.csv", index_col=0, parse_dates=True)
    out = {}
    for s in signals:
        d = (meas[s] - sim[s]).loc[start:end].dropna().to_numpy()
        out[s] = float(np.sqrt(np.mean(d**2)) if stat == "rmse" else np.mean(d))
    return out


def without_offsets(raw: dict) -> dict:
    """The moisture study's own calibration, no sensor offsets (what the material alone explains)."""
    for key in ("validation_start", "validation_end"):
        raw["period"].pop(key, None)
    return raw


def calibrate_then_simulate(study: Path, work: Path, proto: Protocol, edit=None) -> tuple[Path, dict]:
    """``wallcal calibrate`` the study up to ``proto.cal_end``; ``wallcal simulate`` the whole record (up to
    ``proto.end``) from the ``calibrated_wall.toml`` it wrote. Returns the simulate directory and the
    calibration's json."""
    cal_study = variant(study, work / "calibrate.toml", end=proto.cal_end, max_nfev=proto.max_nfev, edit=edit)
    t0 = time.perf_counter()
    wallcal("calibrate", str(cal_study), "--out", str(work / "calibration"), "--quiet")
    seconds = time.perf_counter() - t0
    cal = json.loads((work / "calibration" / "calibration.json").read_text())
    cal["wall_seconds"] = seconds
    offsets = {p["name"][len("offset[") : -1]: p["optimum"] for p in cal["parameters"] if p["property"] == "offset"}
    wall = work / "calibration" / "calibrated_wall.toml"
    sim_study = variant(study, work / "simulate.toml", end=proto.end, wall_file=wall, offsets=offsets, edit=edit)
    wallcal("simulate", str(sim_study), "--out", str(work / "simulate"))
    return work / "simulate", cal


def passys(out: Path, proto: Protocol = PASSYS, variants: bool = True) -> tuple[pd.DataFrame, pd.DataFrame]:
    """PASSYS: held-out RMSE and mean error of the moisture and the heat-only studies, calibrated on the first
    10 days; with ``variants`` also the moisture study calibrated without sensor offsets."""
    rows, bias = {}, {}
    hr = ["HR_4", "HR_8", "HR_12"]
    cases = [
        ("heat and moisture (ham)", "passys_moisture", PASSYS_MOISTURE, hr, in_wall_offsets),
        ("heat only (fd-cn)", "passys_thermal", PASSYS_THERMAL, [], heat_only_as_moisture),
    ]
    if variants:
        cases.append(("ham, no offset parameters", "passys_moisture_no_offsets", PASSYS_MOISTURE, hr, without_offsets))
    for label, name, study, extra, edit in cases:
        signals = ["T_4", "T_8", "T_12", *extra]
        sim_dir, cal = calibrate_then_simulate(study, out / name, proto, edit)
        rows[label] = {
            **scores(sim_dir, signals, *proto.test),
            "runs": cal["evaluations"],
            "calibration s": round(cal["wall_seconds"], 1),
        }
        bias[label] = scores(sim_dir, signals, *proto.test, stat="mbe")
    return pd.DataFrame(rows).T, pd.DataFrame(bias).T


def trh(out: Path, proto: Protocol = TRH) -> pd.DataFrame:
    """TRH-1: interface T and RH over the second half, catalogue properties and calibrated on the first half."""
    signals = ["interface", "interface_rh"]
    work = out / "trh"
    base = variant(TRH_MOISTURE, work / "catalogue.toml", end=proto.end)
    wallcal("simulate", str(base), "--out", str(work / "catalogue"))
    rows = {"catalogue": scores(work / "catalogue", signals, *proto.test)}
    sim_dir, cal = calibrate_then_simulate(TRH_MOISTURE, work, proto)
    rows["calibrated on the first half"] = {
        **scores(sim_dir, signals, *proto.test),
        "runs": cal["evaluations"],
        "calibration s": round(cal["wall_seconds"], 1),
    }
    return pd.DataFrame(rows).T


def markdown(t: pd.DataFrame) -> str:
    """The table as markdown (RMSE with 3 decimals, the run count as an integer), as docs/moisture.md shows it."""
    cols = list(t.columns)
    lines = ["| | " + " | ".join(cols) + " |", "|---" * (len(cols) + 1) + "|"]
    for label, row in t.iterrows():
        cells = []
        for c in cols:
            v = row[c]
            cells.append(
                "-" if pd.isna(v) else f"{int(v)}" if c == "runs" else f"{v:.1f}" if c.endswith(" s") else f"{v:.3f}"
            )
        lines.append(f"| {label} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, help="working directory (default: a temporary one)")
    ap.add_argument("--quick", action="store_true", help="a few days and one least-squares iteration (the tests)")
    ap.add_argument("--wall", choices=("passys", "trh", "both"), default="both")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        out = args.out or Path(tmp)
        if args.wall in ("passys", "both"):
            if not (ROOT.parent / "shared" / "data" / "real").is_dir():
                print("PASSYS: ../shared/data/real/ not found beside the repository: skipped")
            else:
                proto = PASSYS_QUICK if args.quick else PASSYS
                t, bias = passys(out, proto, variants=not args.quick)
                print(f"PASSYS, held-out RMSE {proto.test[0]:%Y-%m-%d} .. {proto.test[1]:%Y-%m-%d} (K; RH fraction)")
                print(markdown(t))
                print("\nPASSYS, held-out mean error, measured - model")
                print(markdown(bias))
                print()
        if args.wall in ("trh", "both"):
            proto = TRH_QUICK if args.quick else TRH
            t = trh(out, proto)
            print(f"TRH-1, held-out RMSE {proto.test[0]:%Y-%m-%d} .. {proto.test[1]:%Y-%m-%d} (K; RH fraction)")
            print(markdown(t))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

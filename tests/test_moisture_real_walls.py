"""Issue 37's real-wall protocols (bench/moisture_real_walls.py) on a few days: calibrate, write
calibrated_wall.toml with its hygric keys, simulate from it, score the held-out days; the documented figures
come from the script."""

from __future__ import annotations

import importlib.util
import json
import re
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

REPO = Path(__file__).resolve().parents[1]
PASSYS_DATA = REPO.parent / "shared" / "data" / "real" / "srouchier__buildingenergygeeks" / "PASSYS_01.txt"


def _bench():
    spec = importlib.util.spec_from_file_location("moisture_real_walls", REPO / "bench" / "moisture_real_walls.py")
    mod = importlib.util.module_from_spec(spec)
    sys.modules["moisture_real_walls"] = mod
    spec.loader.exec_module(mod)
    return mod


@pytest.fixture(scope="module")
def bench():
    return _bench()


def _check_round_trip(work: Path, layer_id: str, hygric: tuple[str, ...]):
    """calibrated_wall.toml carries every calibrated property, hygric ones included, and the simulate study
    that points at it runs that wall."""
    from wallcal.study import load_study
    from wallcal.wallfile import load_wall

    cal = json.loads((work / "calibration" / "calibration.json").read_text())
    wall = load_wall(work / "calibration" / "calibrated_wall.toml")
    layer = next(lay for lay in wall.layers if lay.id == layer_id)
    for p in cal["parameters"]:
        if p["property"] == "offset" or layer_id not in p["layers"]:
            continue
        assert getattr(layer, p["property"]) == pytest.approx(p["optimum"], rel=1e-6), p["name"]
    keys = layer.hygric_keys()
    for k in hygric:
        assert k in keys, k
    sim = load_study(work / "simulate.toml")
    assert sim.wall.layers == wall.layers
    # the calibrated offsets went onto the sensors of the simulate study
    offsets = {p["name"][7:-1]: p["optimum"] for p in cal["parameters"] if p["property"] == "offset"}
    for s in sim.sensors:
        if s.name in offsets:
            assert s.offset == pytest.approx(offsets[s.name])


def _check_held_out(bench, sim_dir: Path, proto, signals):
    """The held-out score is the RMSE over the test days only, from the files simulate wrote."""
    got = bench.scores(sim_dir, signals, *proto.test)
    sim = pd.read_csv(sim_dir / "simulated.csv", index_col=0, parse_dates=True)
    meas = pd.read_csv(sim_dir / "measured.csv", index_col=0, parse_dates=True)
    assert sim.index[0] < pd.Timestamp(proto.test[0])  # the whole record was simulated, not only the test days
    for s in signals:
        d = (meas[s] - sim[s])[(sim.index >= proto.test[0]) & (sim.index <= proto.test[1])].dropna()
        assert len(d) > 10
        assert got[s] == pytest.approx(float(np.sqrt(np.mean(d**2))))
        assert np.isfinite(got[s])


@pytest.mark.slow
def test_trh_protocol_machinery(bench, tmp_path):
    t = bench.trh(tmp_path, bench.TRH_QUICK)
    assert list(t.index) == ["catalogue", "calibrated on the first half"]
    assert t.loc["calibrated on the first half", "runs"] >= 2
    work = tmp_path / "trh"
    for f in ("calibrated_wall.toml", "calibration.json", "metrics.csv"):
        assert (work / "calibration" / f).exists()
    _check_round_trip(work, "vapour_barrier", ("vapour_resistance_factor", "moisture_storage"))
    _check_held_out(bench, work / "simulate", bench.TRH_QUICK, ["interface", "interface_rh"])
    # the calibration saw only the days before the test days
    from wallcal.study import load_study

    assert pd.Timestamp(load_study(work / "calibrate.toml").period.end) < pd.Timestamp(bench.TRH_QUICK.test[0])


@pytest.mark.slow
@pytest.mark.skipif(not PASSYS_DATA.exists(), reason=f"PASSYS data absent ({PASSYS_DATA}); read in place only")
def test_passys_protocol_machinery(bench, tmp_path):
    t, bias = bench.passys(tmp_path, bench.PASSYS_QUICK, variants=False)
    assert list(t.index) == list(bias.index) == ["heat and moisture (ham)", "heat only (fd-cn)"]
    assert ((bias.abs() <= t[bias.columns]) | bias.isna()).all().all()  # |mean error| <= RMSE
    assert t.loc["heat only (fd-cn)", ["HR_4", "HR_8", "HR_12"]].isna().all()
    work = tmp_path / "passys_moisture"
    _check_round_trip(
        work,
        "wood_fibre",
        ("vapour_resistance_factor", "moisture_storage", "liquid_transport", "moisture_conductivity_coefficient"),
    )
    _check_held_out(bench, work / "simulate", bench.PASSYS_QUICK, ["T_4", "HR_4", "HR_12"])
    # the heat-only study lost its hand-declared face offset and calibrates the in-wall offsets instead
    from wallcal.study import load_study

    thermal = load_study(tmp_path / "passys_thermal" / "calibrate.toml")
    assert thermal.exterior.offset == 0 and thermal.interior.offset == 0
    assert {"offset[T_4]", "offset[T_8]", "offset[T_12]"} <= set(thermal.calibration.names)
    moisture = load_study(REPO / "examples" / "passys" / "study_moisture.toml")
    assert moisture.exterior.offset == 0 and moisture.interior.offset == 0


def test_calibrated_wall_carries_every_hygric_parameter(tmp_path):
    """The calibrated wall as calibrate writes it (ParameterSpace.wall_at, dump_wall) keeps every hygric
    parameter's value through the file."""
    from wallcal.study import load_study
    from wallcal.wallfile import dump_wall, load_wall

    study = load_study(REPO / "examples" / "passys" / "study_moisture.toml")
    space = study.calibration
    x = space.base.copy()
    values = {
        "conductivity": 0.037,
        "specific_heat": 1500.0,
        "sorption_scale": 0.31,
        "vapour_resistance_factor": 1.7,
    }
    for j, p in enumerate(space.parameters):
        if p.property in values:
            x[j] = values[p.property]
    path = tmp_path / "calibrated_wall.toml"
    path.write_text(dump_wall(space.wall_at(study.wall, x), "test"))
    layer = load_wall(path).layers[0]
    for k, v in values.items():
        assert getattr(layer, k) == pytest.approx(v), k
    keys = layer.hygric_keys()
    assert keys["sorption_scale"] == pytest.approx(0.31) and keys["vapour_resistance_factor"] == pytest.approx(1.7)
    assert {"moisture_storage", "liquid_transport", "moisture_conductivity_coefficient"} <= set(keys)


def test_documented_tables_are_the_bench_scripts(bench):
    """docs/moisture.md's held-out tables have the rows and columns the script prints, and the script holds no
    result figure of them (it computes them)."""
    doc = (REPO / "docs" / "moisture.md").read_text()
    src = (REPO / "bench" / "moisture_real_walls.py").read_text()
    block = doc[doc.index("## Real walls: held-out scores") :]
    rows = [line for line in block.splitlines() if line.startswith("| ") and re.search(r"\d\.\d{3}", line)]
    labels = {line.split("|")[1].strip() for line in rows}
    assert {"heat and moisture (ham)", "heat only (fd-cn)", "catalogue", "calibrated on the first half"} <= labels
    figures = {v for line in rows for v in re.findall(r"\d+\.\d{3}", line)}
    assert figures and not any(v in src for v in figures)
    table = bench.markdown(
        pd.DataFrame({"T_4": [0.1], "runs": [3.0], "calibration s": [1.25]}, index=["heat only (fd-cn)"])
    )
    assert table.splitlines()[2] == "| heat only (fd-cn) | 0.100 | 3 | 1.2 |"


def test_diagnose_proposes_lambda_w_for_a_moisture_study():
    from wallcal.analysis.diagnose_candidates import propose
    from wallcal.study import load_study

    study = load_study(REPO / "src" / "wallcal" / "examples" / "trh" / "study_moisture.toml")
    exts = [e for e in propose(study, study.calibration) if e.kind == "moisture_conductivity_coefficient"]
    # the two insulation layers (glass wool, wind barrier); not the gypsum board nor the vapour barrier film
    assert [e.table["layers"] for e in exts] == [["wind_barrier"], ["glass_wool"]]
    gw = exts[1].table
    assert gw["property"] == "moisture_conductivity_coefficient" and gw["bounds"][0] == 0.0
    assert gw["bounds"][1] > (study.wall.layers[1].moisture_conductivity_coefficient or 0.0)
    thermal = load_study(REPO / "src" / "wallcal" / "examples" / "trh" / "study.toml")
    assert not [e for e in propose(thermal, thermal.calibration) if e.kind == "moisture_conductivity_coefficient"]


@pytest.mark.slow
def test_run_report_stage_shows_the_moisture_figures(bench, tmp_path):
    """wallcal run's base-case stage hands the moisture figures to the report for a moisture study."""
    from wallcal.study import load_study
    from wallcal.workflow import RunContext, StageOutput, _stage_data, _stage_engines

    path = bench.variant(bench.TRH_MOISTURE, tmp_path / "s.toml", end=bench.TRH_QUICK.end)
    ctx = RunContext(study=load_study(path), out=tmp_path, progress=False)
    _stage_data(ctx, tmp_path, StageOutput("data", ""))
    so = StageOutput("engines", "")
    _stage_engines(ctx, tmp_path, so)
    names = [p.name for _, p in so.figures]
    assert "moisture_rh.png" in names and "moisture_profiles.png" in names
    for _, p in so.figures:
        if p.name.startswith("moisture_"):
            assert p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and p.stat().st_size > 10_000


def _short_moisture_study(parameters):
    """The bundled TRH-1 moisture study on its first two days, calibrating ``parameters``."""
    import copy
    import datetime as dt

    from wallcal.study import load_study, parse_study

    path = REPO / "src" / "wallcal" / "examples" / "trh" / "study_moisture.toml"
    raw = copy.deepcopy(load_study(path).raw)
    raw["period"] = {"start": dt.datetime(2021, 1, 1, 0, 5), "end": dt.datetime(2021, 1, 2, 23, 55)}
    raw["calibration"]["parameters"] = parameters
    return parse_study(raw, base_dir=path.parent, source=str(path)).replace(path=path)


@pytest.mark.parametrize(
    "parameter, what",
    [
        (
            {
                "layers": ["glass_wool"],
                "property": "conductivity_temperature_coefficient",
                "bounds": [0.0, 0.02],
                "bounds_kind": "absolute",
            },
            "lambda(T)",
        ),
        (
            {
                "layers": ["wind_barrier"],
                "property": "contact_resistance",
                "bounds": [0.0, 0.2],
                "bounds_kind": "absolute",
            },
            "contact resistance",
        ),
    ],
)
def test_ham_engine_refuses_a_batch_parameter_it_cannot_represent(parameter, what):
    """A calibration parameter the ham engine has no law for is refused when the batch is prepared: the batch walls
    are not checked again, and the engine once ran them with the parameter silently ignored (every value gave the
    same series)."""
    from wallcal.calibration.objective import Evaluator
    from wallcal.calibration.space import space_of
    from wallcal.errors import EngineError
    from wallcal.simulation import BATCH_NEEDS, prepare

    study = _short_moisture_study([parameter])
    with pytest.raises(EngineError, match=f"ham engine has no {re.escape(what)}"):
        Evaluator(prepare(study, needs=BATCH_NEEDS), space_of(study))


def test_diagnose_proposes_no_candidate_the_engine_cannot_represent():
    from wallcal.analysis.diagnose_candidates import propose
    from wallcal.engines import engine_class

    study = _short_moisture_study([{"layers": ["glass_wool"], "property": "conductivity", "bounds": [-0.2, 0.2]}])
    everything = {e.kind for e in propose(study, study.calibration)}
    assert {"contact_resistance", "conductivity_temperature_coefficient"} <= everything
    kinds = {e.kind for e in propose(study, study.calibration, capabilities=engine_class("ham").capabilities)}
    assert kinds & {"contact_resistance", "conductivity_temperature_coefficient"} == set()
    assert {"moisture_conductivity_coefficient", "offset", "depth"} <= kinds


def test_identifiability_stencil_stays_inside_the_box_at_a_bound():
    """At an optimum on a bound the central differences turn one-sided: a vapour resistance factor of 1 (its
    physical floor and the box's lower bound) was stepped to 0.999, which the material refuses."""
    from wallcal.analysis.identifiability import identifiability
    from wallcal.calibration.space import space_of

    study = _short_moisture_study(
        [
            {
                "layers": ["glass_wool"],
                "property": "vapour_resistance_factor",
                "bounds": [1.0, 3.0],
                "bounds_kind": "absolute",
            }
        ]
    )
    space = space_of(study)
    res = identifiability(study, x0=space.lower.copy(), add_fluxes=False)
    assert res is not None

"""``wallcal building``: the walls in the reference building through EnergyPlus (on the dask executor), the
contract columns, posterior spread, the whole-envelope check, ``--from`` sources and bad input."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from conftest import EXAMPLE, assert_clean_error
from wallcal import dump_wall, load_study
from wallcal.building import COLUMNS, collect_walls, reference_building
from wallcal.building.model import select_surfaces, with_wall
from wallcal.building.run import run_building
from wallcal.cli import main
from wallcal.errors import StudyError
from wallcal.outputs import format_entries
from wallcal.weather import resolve_weather

CHICAGO = "USA_IL_Chicago-OHare.Intl.AP.725300_TMY3.epw"
pytestmark = pytest.mark.energyplus  # EnergyPlus runs, and the weather files shipped with it


def _study(tmp_path, building: str = "") -> str:
    """The bundled example (data and reference wall by absolute path) with ``building`` as its [building] table."""
    text = (
        EXAMPLE.read_text()
        .replace('file = "measured.csv"', f'file = "{EXAMPLE.parent / "measured.csv"}"')
        .replace('reference_wall = "true_wall.toml"', f'reference_wall = "{EXAMPLE.parent / "true_wall.toml"}"')
    )
    text = text.split("\n[building]")[0]  # the example's own [building] table is replaced by ``building``
    path = tmp_path / "study.toml"
    path.write_text(text + "\n" + building)
    return str(path)


def _manifest(d, command):
    """The manifest.json ``wallcal <command>`` writes: its format version (wallcal.outputs)."""
    (d / "manifest.json").write_text(json.dumps({"command": command, **format_entries(command)}))


@pytest.fixture(scope="module")
def big_run(tmp_path_factory):
    """One command over a week of January: the study wall, an identical copy, a wall with layer 3's
    conductivity doubled, four posterior draws, and the free-floating check against a synthetic record
    made by EnergyPlus from the study wall itself."""
    tmp = tmp_path_factory.mktemp("building")
    study_file = _study(tmp, '[building]\nweather = "' + CHICAGO + '"\nstart = "01-08"\nend = "01-14"\n')
    study = load_study(study_file)
    (tmp / "base.toml").write_text(dump_wall(study.wall))
    (tmp / "same.toml").write_text(dump_wall(study.wall))
    (tmp / "kplus.toml").write_text(dump_wall(study.wall.replace_layer("3", conductivity=0.08)))
    # a posterior output: 4 draws of conductivity[3] between 0.03 and 0.05 W/(mK)
    post = tmp / "post"
    post.mkdir()
    chain = np.linspace(0.0, 1.0, 8).reshape(4, 2, 1)
    np.savez(post / "chain.npz", chain=chain, names=np.array(["conductivity[3]"]), lower=[0.03], upper=[0.05])
    (post / "posterior.json").write_text(json.dumps({"burn": 0, "thin": 1}))
    _manifest(post, "posterior")
    # the measured zone air: the study wall's free-floating run over 10-14 January, hourly
    model = reference_building()
    mdl = with_wall(
        model,
        study.wall,
        select_surfaces(model, None),
        period=((1, 10), (1, 14)),
        steps_per_hour=6,
        free_floating=True,
        zone_temperatures=True,
    )
    sim = run_building(
        {
            "model": mdl,
            "weather": str(resolve_weather(CHICAGO)),
            "steps_per_hour": 6,
            "zones": ["ZONE"],
            "temperature_zone": "ZONE",
        }
    )
    times = [
        pd.Timestamp(f"2021-{t.split()[0].replace('/', '-')}") + pd.Timedelta(hours=int(t.split()[1][:2]))
        for t in sim["zone_temperature"]["time"]
    ]
    pd.DataFrame({"time": times, "T_zone": sim["zone_temperature"]["value"]}).to_csv(tmp / "zone.csv", index=False)
    out = tmp / "out"
    code = main(
        [
            "building",
            study_file,
            "--walls",
            str(tmp / "base.toml"),
            str(tmp / "same.toml"),
            str(tmp / "kplus.toml"),
            "--from",
            str(post),
            "--samples",
            "4",
            "--measured",
            str(tmp / "zone.csv"),
            "--zone-column",
            "T_zone",
            "--out",
            str(out),
            "--quiet",
            "--scheduler",
            "local",
        ]
    )
    assert code == 0
    return out


@pytest.mark.slow
def test_contract_columns_and_per_floor_area(big_run):
    tab = pd.read_csv(big_run / "building.csv")
    assert tuple(tab.columns) == COLUMNS
    assert list(tab["wall"]) == ["base", "same", "kplus", "draw_001", "draw_002", "draw_003", "draw_004"]
    info = json.loads((big_run / "building.json").read_text())
    assert info["conditioned_floor_area_m2"] == pytest.approx(80.0)  # 10 m x 8 m
    np.testing.assert_allclose(tab["heating_kWh_m2"], tab["heating_kWh"] / 80.0, rtol=1e-5)
    np.testing.assert_allclose(tab["cooling_kWh_m2"], tab["cooling_kWh"] / 80.0, rtol=1e-5)
    np.testing.assert_allclose(
        tab["difference_vs_first_heating_kWh"], tab["heating_kWh"] - tab["heating_kWh"][0], atol=1e-3
    )
    # a January week in Chicago: heating, no cooling; peaks of a 80 m2 well-insulated box (kW scale)
    assert (tab["heating_kWh"] > 50).all() and (tab["cooling_kWh"] == 0).all()
    assert (tab["peak_heating_W"] > 500).all() and (tab["peak_heating_W"] < 10000).all()


@pytest.mark.slow
def test_bigger_conductivity_gives_more_heating_and_identical_walls_identical_rows(big_run):
    tab = pd.read_csv(big_run / "building.csv").set_index("wall")
    assert tab.loc["kplus", "heating_kWh"] > tab.loc["base", "heating_kWh"] + 1.0
    assert tab.loc["kplus", "peak_heating_W"] > tab.loc["base", "peak_heating_W"]
    cols = [c for c in COLUMNS[1:] if c != "difference_vs_first_heating_kWh"]
    assert tab.loc["same", cols].tolist() == tab.loc["base", cols].tolist()
    assert tab.loc["same", "difference_vs_first_heating_kWh"] == 0.0
    # the draws' conductivity[3] rises from 0.03 to 0.05 W/(mK): heating rises with it
    draws = tab.loc[[f"draw_00{k}" for k in range(1, 5)], "heating_kWh"].to_numpy()
    assert np.all(np.diff(draws) > 0)


@pytest.mark.slow
def test_the_heating_difference_is_the_walls_ua_difference_times_the_degree_hours(big_run):
    """A check of area and units: the extra heating of the leakier wall against Delta(U A) x sum(20 - T_air) dt
    over the week (U by ISO 6946 with Rsi 0.13, Rse 0.04; A = 86.4 m2 of net wall). It is an upper estimate:
    sun on the walls, EnergyPlus' own surface coefficients and the hours in which gains cover the losses (no
    heating then) make the simulated difference smaller; measured ratio 0.80."""
    from wallcal.weather import read_weather

    study = load_study(EXAMPLE)
    d_u = study.wall.replace_layer("3", conductivity=0.08).u_value() - study.wall.u_value()
    area = 2 * (24.0 + 19.2)
    w = read_weather(resolve_weather(CHICAGO)).data
    week = w[(w.index.month == 1) & (w.index.day >= 8) & (w.index.day <= 14)]["temp_air"].to_numpy()
    expected_kwh = d_u * area * np.maximum(20.0 - week, 0.0).sum() / 1000.0
    tab = pd.read_csv(big_run / "building.csv").set_index("wall")
    got = tab.loc["kplus", "heating_kWh"] - tab.loc["base", "heating_kWh"]
    assert 0.6 < got / expected_kwh < 1.0, (got, expected_kwh)


@pytest.mark.slow
def test_posterior_spread_and_the_plain_sentence(big_run):
    sp = pd.read_csv(big_run / "spread.csv", index_col="figure")
    tab = pd.read_csv(big_run / "building.csv").set_index("wall")
    draws = tab.loc[[w for w in tab.index if w.startswith("draw_")], "heating_kWh"]
    assert sp.loc["heating_kWh", "p05"] == pytest.approx(np.percentile(draws, 5), rel=1e-5)
    assert sp.loc["heating_kWh", "p95"] == pytest.approx(np.percentile(draws, 95), rel=1e-5)
    notes = json.loads((big_run / "building.json").read_text())["notes"]
    width = sp.loc["heating_kWh", "p95"] - sp.loc["heating_kWh", "p05"]
    others = tab.loc[["base", "same", "kplus"], "heating_kWh"]
    verdict = "more" if others.max() - others.min() > width else "less"
    assert any(f"{verdict} than the posterior spread" in n for n in notes), notes


@pytest.mark.slow
def test_whole_envelope_check_finds_the_wall_that_made_the_record(big_run):
    chk = pd.read_csv(big_run / "envelope_check.csv").set_index("wall")
    # the record is the study wall's own free-floating run over the same days: the same EnergyPlus run
    assert chk.loc["base", "rmse_K"] < 1e-4 and abs(chk.loc["base", "mbe_K"]) < 1e-4
    assert chk.loc["kplus", "rmse_K"] > 0.1  # a leakier wall: a colder free-floating zone
    assert chk.loc["kplus", "mbe_K"] < 0
    assert chk.loc["base", "hours"] >= 5 * 24 - 1
    z = pd.read_csv(big_run / "zone_temperatures.csv")
    assert {"time", "measured", "base", "kplus"} <= set(z.columns)


def test_from_retrofit_crosscheck_and_many_calibrate_outputs(tmp_path):
    study = load_study(EXAMPLE)
    ret = tmp_path / "ret"
    ret.mkdir()
    (ret / "retrofit.json").write_text(
        json.dumps({"variants": [{"index": 1, "name": "as built"}, {"index": 2, "name": "EPS"}]})
    )
    (ret / "variant_1.toml").write_text(dump_wall(study.wall))
    (ret / "variant_2.toml").write_text(dump_wall(study.wall.replace_layer("3", conductivity=0.02)))
    _manifest(ret, "retrofit")
    cc = tmp_path / "cc"
    (cc / "walls").mkdir(parents=True)
    (cc / "crosscheck.csv").write_text("wall,engine\n")
    (cc / "walls" / "opt1.toml").write_text(dump_wall(study.wall))
    _manifest(cc, "crosscheck")
    many = tmp_path / "many"
    for name in ("s1", "s2"):
        (many / name).mkdir(parents=True)
        (many / name / "calibrated_wall.toml").write_text(dump_wall(study.wall))
    _manifest(many, "calibrate")
    walls = collect_walls(study, (), [ret, cc, many], 5)
    assert [(w.name, w.kind) for w in walls] == [
        ("as built", "variant"),
        ("EPS", "variant"),
        ("opt1", "optimal"),
        ("s1", "optimal"),
        ("s2", "optimal"),
    ]
    assert walls[1].wall.layers[0].conductivity == 0.02
    assert collect_walls(study)[0].kind == "study"
    with pytest.raises(StudyError, match="not a calibrate"):
        collect_walls(study, (), [tmp_path])


def test_crosscheck_and_retrofit_outputs_keep_their_walls(tmp_path, capsys):
    """crosscheck writes walls/<stem>.toml beside crosscheck.csv, which --from reads back."""
    study = load_study(EXAMPLE)
    (tmp_path / "w1.toml").write_text(dump_wall(study.wall))
    out = tmp_path / "cc"
    assert main(["crosscheck", str(EXAMPLE), str(tmp_path / "w1.toml"), "--engines", "fd-cn", "--out", str(out)]) == 0
    walls = collect_walls(study, (), [out])
    assert [w.name for w in walls] == ["w1"] and walls[0].wall.layers == study.wall.layers


# ---------------------------------------------------------------------------- bad input
def test_a_model_with_no_outdoor_wall(tmp_path, capsys):
    model = reference_building()
    for s in model["BuildingSurface:Detailed"].values():
        if s["surface_type"] == "Wall":
            s["outside_boundary_condition"] = "Adiabatic"
    model.pop("FenestrationSurface:Detailed")
    (tmp_path / "m.epJSON").write_text(json.dumps(model))
    out = tmp_path / "out"
    code = main(
        [
            "building",
            _study(tmp_path),
            "--building",
            str(tmp_path / "m.epJSON"),
            "--weather",
            CHICAGO,
            "--out",
            str(out),
            "--quiet",
        ]
    )
    assert_clean_error(code, capsys.readouterr(), out, "m.epJSON has no outdoor wall")


def test_an_unknown_surface_gets_did_you_mean(tmp_path, capsys):
    out = tmp_path / "out"
    code = main(
        [
            "building",
            _study(tmp_path),
            "--surfaces",
            "WALL_SOUTH,WALL_NROTH",
            "--weather",
            CHICAGO,
            "--out",
            str(out),
            "--quiet",
        ]
    )
    assert_clean_error(code, capsys.readouterr(), out, "'WALL_NROTH' is not a surface", "did you mean 'WALL_NORTH'")


def test_a_wall_file_that_does_not_parse(tmp_path, capsys):
    (tmp_path / "bad.toml").write_text("[wall\nlayers = \n")  # not TOML
    out = tmp_path / "out"
    code = main(
        [
            "building",
            _study(tmp_path),
            "--walls",
            str(tmp_path / "bad.toml"),
            "--weather",
            CHICAGO,
            "--out",
            str(out),
            "--quiet",
        ]
    )
    assert_clean_error(code, capsys.readouterr(), out, "bad.toml")


def test_a_weather_name_that_does_not_exist(tmp_path, capsys):
    out = tmp_path / "out"
    code = main(["building", _study(tmp_path), "--weather", "USA_IL_Chicago.epw", "--out", str(out), "--quiet"])
    assert_clean_error(code, capsys.readouterr(), out, "--weather: 'USA_IL_Chicago.epw'", "shipped:")


def test_a_measured_column_that_does_not_exist(tmp_path, capsys):
    (tmp_path / "zone.csv").write_text("time,T_zone\n2021-01-10 01:00,20.0\n2021-01-10 02:00,20.1\n")
    out = tmp_path / "out"
    code = main(
        [
            "building",
            _study(tmp_path),
            "--weather",
            CHICAGO,
            "--measured",
            str(tmp_path / "zone.csv"),
            "--zone-column",
            "T_zon",
            "--out",
            str(out),
            "--quiet",
        ]
    )
    assert_clean_error(code, capsys.readouterr(), out, "--zone-column 'T_zon'", "did you mean 'T_zone'")


def test_the_building_table_is_validated_with_key_paths(tmp_path):
    path = _study(tmp_path, '[building]\nstart = "13-01"\nend = "01-01"\nsurfacs = ["A"]\ntimesteps_per_hour = 7\n')
    with pytest.raises(StudyError) as exc:
        load_study(path)
    msg = str(exc.value)
    assert "building.start: must be a day" in msg
    assert "building.surfacs: unknown key; did you mean 'surfaces'" in msg
    assert "building.timesteps_per_hour: must divide 60" in msg


@pytest.mark.slow
def test_an_idf_model_converted_by_energyplus_with_one_surface(tmp_path, capsys):
    """--building model.idf (converted with energyplus --convert-only) and --surfaces: only the south wall
    gets the wall under test; the other walls keep their own construction."""
    import subprocess

    from wallcal.engines.energyplus.runner import energyplus_binary

    model = reference_building()
    for name, s in model["BuildingSurface:Detailed"].items():
        if s["surface_type"] == "Wall" and name != "WALL_SOUTH":
            s["construction_name"] = "WALLCAL_ROOF"
    model["Construction"]["WALLCAL_WALL"] = {"outside_layer": "WALLCAL_ROOF_INSULATION"}  # replaced by wallcal
    (tmp_path / "m.epJSON").write_text(json.dumps(model))
    subprocess.run(
        [str(energyplus_binary()), "--convert-only", "-d", str(tmp_path), str(tmp_path / "m.epJSON")],
        capture_output=True,
        check=True,
    )
    assert (tmp_path / "m.idf").exists()
    study = load_study(EXAMPLE)
    (tmp_path / "base.toml").write_text(dump_wall(study.wall))
    (tmp_path / "kplus.toml").write_text(dump_wall(study.wall.replace_layer("3", conductivity=0.08)))
    out = tmp_path / "out"
    args = ["building", _study(tmp_path), "--walls", str(tmp_path / "base.toml"), str(tmp_path / "kplus.toml")]
    args += ["--building", str(tmp_path / "m.idf"), "--surfaces", "wall_south", "--weather", CHICAGO]
    args += ["--period", "01-08:01-10", "--out", str(out), "--quiet"]
    assert main(args) == 0, capsys.readouterr().err
    tab = pd.read_csv(out / "building.csv").set_index("wall")
    assert tab.loc["kplus", "heating_kWh"] > tab.loc["base", "heating_kWh"]
    info = json.loads((out / "building.json").read_text())
    assert info["surfaces"] == ["WALL_SOUTH"] and info["model"] == "model m.idf"
    assert info["run_period"] == ["01-08", "01-10"]


def test_an_unreachable_scheduler_is_named_within_15_s(tmp_path, capsys):
    import time

    out = tmp_path / "out"
    t = time.perf_counter()
    code = main(
        [
            "building",
            _study(tmp_path),
            "--weather",
            CHICAGO,
            "--period",
            "01-08:01-09",
            "--scheduler",
            "tcp://127.0.0.1:9",
            "--out",
            str(out),
            "--quiet",
        ]
    )
    assert time.perf_counter() - t < 15
    assert_clean_error(code, capsys.readouterr(), out, "tcp://127.0.0.1:9")


@pytest.mark.slow
def test_an_interrupted_command_resumes_from_its_finished_runs(tmp_path, capsys, monkeypatch):
    from wallcal.building.study import BuildingResult

    out = tmp_path / "out"
    args = ["building", _study(tmp_path), "--weather", CHICAGO, "--period", "01-08:01-09", "--out", str(out)]

    def interrupted(self, *a, **k):
        raise KeyboardInterrupt

    with monkeypatch.context() as m:
        m.setattr(BuildingResult, "write", interrupted)
        assert main([*args, "--quiet"]) == 130
    capsys.readouterr()
    cache = tmp_path / ".out.building-cache"
    assert not out.exists() and len(list(cache.glob("*.pkl"))) == 1  # the run finished before the interruption
    assert main([*args, "--resume"]) == 0
    err = capsys.readouterr().err
    assert "1/1, 1 from the cache" in err, err
    assert pd.read_csv(out / "building.csv")["heating_kWh"].iloc[0] > 0
    assert not cache.exists()  # the runs are in the output now


def test_inside_a_commands_executor_the_runs_go_to_it(tmp_path, monkeypatch):
    """`wallcal run` holds one executor (its --scheduler, its store of finished runs) for every stage: the
    building's runs go to it, no second cluster is started."""
    import wallcal.cluster
    from wallcal.building import building
    from wallcal.cluster import Executor

    study = load_study(_study(tmp_path, '[building]\nweather = "' + CHICAGO + '"\nstart = "01-08"\nend = "01-08"\n'))

    def no_second_cluster(*a, **k):
        raise AssertionError("a second executor was started")

    sent = []

    def in_process(fn, tasks, **kw):
        sent.append(len(tasks))
        return [fn(t) for t in tasks]

    monkeypatch.setattr(wallcal.cluster, "executor_from", no_second_cluster)
    with Executor("local", workers=1, progress=False) as ex:  # started lazily: never, here
        monkeypatch.setattr(ex, "map", in_process)
        res = building(study, collect_walls(study))
    assert sent == [1]
    assert res.table()["heating_kWh"].iloc[0] > 0

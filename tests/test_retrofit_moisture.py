"""The hygrothermal columns of ``wallcal retrofit``: driving rain, the periodic EN 15026 year, the mould index at the
layer interfaces, the verdicts, and bad input (one line, exit 2)."""

from __future__ import annotations

import math
import tomllib
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import tomli_w

from conftest import assert_clean_error
from retrofit_helpers import study_with_retrofit, write_epw
from wallcal import load_study
from wallcal.cli import main
from wallcal.retrofitting import moisture_risk as mr
from wallcal.retrofitting.run import VARIANT_COLUMNS, retrofit
from wallcal.wallfile import load_wall
from wallcal.weather import Weather

#: issue 38's classic case, shipped as an example (also run whole by bench/retrofit_classic.py)
CLASSIC = Path(__file__).resolve().parents[1] / "examples" / "retrofit_classic"
BRICK_WALL = (CLASSIC / "brick_wall.toml").read_text()

#: a capillary-active wall (aerated concrete, lime plaster); the test's variant seals it outside with a film
SEALED_WALL = """
[wall]
name = "aerated concrete"

[[wall.layers]]
id = "aac"
material = "aerated concrete"
thickness = 0.2

[[wall.layers]]
id = "plaster"
material = "lime plaster"
thickness = 0.015
"""


def _weather(n=48, depth=None, quantity=None, speed=None, direction=None, rh=None) -> Weather:
    idx = pd.date_range("2021-01-01", periods=n, freq="h", tz="Etc/GMT+6")
    d = pd.DataFrame(
        {
            "temp_air": np.full(n, 5.0),
            "relative_humidity": np.full(n, 80.0) if rh is None else rh,
            "liquid_precipitation_depth": np.full(n, 999.0) if depth is None else depth,
            "liquid_precipitation_quantity": np.full(n, 99.0) if quantity is None else quantity,
            "wind_speed": np.full(n, 4.0) if speed is None else speed,
            "wind_direction": np.full(n, 180.0) if direction is None else direction,
        },
        index=idx,
    )
    return Weather(data=d, latitude=45.0, longitude=7.0, altitude=100.0, name="synthetic.epw")


# ============================================================================ driving rain
def test_driving_rain_follows_en_iso_15927_3_by_hand():
    """r_bv = R_1 R_2 v cos(D - theta) r_h^0.88 [mm/h]; R_2 = 2/9 s/m.

    Hour 0: 2 mm in one hour, wind 5 m/s from the south onto a south wall (cos 0 = 1), R_1 = 0.4:
        0.4 x 2/9 x 5 x 1 x 2^0.88 = 0.444444 x 1.840375 = 0.817944 mm/h.
    Hour 1: 2 mm, wind from 240 deg on the south wall: cos 60 deg = 0.5 -> 0.408972 mm/h.
    Hour 2: 2 mm, wind from the north: nothing on the south wall.
    Hours 5..7: 6 mm over a 3-hour quantity ending at hour 7 -> 2 mm/h each, wind 5 m/s from the south.
    Hour 8: depth missing (999): dry.
    """
    n = 10
    depth = np.array([2, 2, 2, 0, 0, 0, 0, 6, 999, 0], dtype=float)
    qty = np.array([1, 1, 1, 1, 1, 1, 1, 3, 99, 1], dtype=float)
    direction = np.array([180, 240, 0, 180, 180, 180, 180, 180, 180, 180], dtype=float)
    w = _weather(n, depth=depth, quantity=qty, speed=np.full(n, 5.0), direction=direction)
    rain, info = mr.driving_rain(w, azimuth=180.0, factor=0.4)
    mm_h = rain * 3600.0
    one = 0.4 * 2 / 9 * 5 * 2**0.88
    assert one == pytest.approx(0.817944, abs=1e-6)
    assert mm_h[0] == pytest.approx(one)
    assert mm_h[1] == pytest.approx(0.5 * one)
    assert mm_h[2] == 0.0
    assert list(mm_h[5:8]) == pytest.approx([one, one, one])
    assert mm_h[8] == 0.0 and mm_h[3] == 0.0
    assert info.hours_with_data == 9 and info.precipitation_mm == pytest.approx(12.0)
    assert "underestimated" in info.note()


def test_no_precipitation_is_said():
    rain, info = mr.driving_rain(_weather(), azimuth=180.0)
    assert not rain.any()
    assert "no precipitation" in info.note()


# ============================================================================ verdicts
@pytest.mark.parametrize(
    ("periodic", "trend", "mould", "rh", "expected"),
    [
        (False, 0.5, 0.0, 0.7, "accumulating"),
        (False, -0.5, 2.0, 0.99, "mould_risk"),
        (True, 0.0, 1.0, 0.99, "mould_risk"),
        (True, 0.0, 0.99, 0.95, "acceptable"),
        (True, 0.0, 0.0, 0.80, "acceptable"),
        (True, 0.0, 0.0, 0.7999, "dry"),
    ],
)
def test_verdict_thresholds(periodic, trend, mould, rh, expected):
    assert mr.verdict(periodic, trend, mould, rh) == expected


# ============================================================================ runs
def _cold_epw(path, hours=8760, mean=-4.0):
    h = np.arange(hours)
    t = mean - 9.0 * np.cos(2 * np.pi * h / 8760.0) + 3.0 * np.sin(2 * np.pi * (h - 9) / 24.0)
    return write_epw(path, t, rh=np.full(hours, 85.0))


def _study(tmp_path, body, epw="cold.epw"):
    return load_study(study_with_retrofit(tmp_path, f'[retrofit]\nweather = "{epw}"\n' + body))


@pytest.mark.slow
def test_vapour_tight_outside_accumulates_in_a_cold_climate(tmp_path):
    """Interior vapour condenses behind an exterior film in a cold climate and cannot dry out: the wall's water
    rises year after year (no periodic state), and more years do not make the rise vanish."""
    _cold_epw(tmp_path / "cold.epw")
    (tmp_path / "sealed.toml").write_text(SEALED_WALL)
    wall = load_wall(tmp_path / "sealed.toml")
    body = (
        "interior_relative_humidity = 0.6\ncondensation_check = false\n"
        '[[retrofit.variants]]\nname = "sealed"\n'
        'add_exterior = [{ material = "vapour control layer", thickness = 0.0002 }]\n'
    )
    trends = {}
    for years in (3, 5):
        st = _study(tmp_path, f"moisture_max_years = {years}\n" + body)
        res = retrofit(st, wall=wall)
        v = res.variants[0]
        tab = res.table()
        assert v.hygro.years == years and not v.hygro.periodic
        assert tab["moisture_verdict"][0] == "accumulating"
        trends[years] = tab["water_content_trend_kg_m2_per_year"][0]
        total = v.hygro.layer_water.sum(axis=1)
        assert np.all(np.diff(total)[1:] > 0)  # every year after the first adds water
    # the condensation zone moves inwards and slows down (1.98 then 0.71 kg/m2 in the 3rd and 5th year), but two more
    # years leave it well above the periodic tolerance: still accumulating, not a periodic state
    assert trends[3] > 0.5 and trends[5] > 0.2


def test_columns_are_empty_with_a_note_without_hygric_data(tmp_path):
    write_epw(tmp_path / "w.epw", np.full(48, 5.0))
    body = '[retrofit]\nweather = "w.epw"\ncondensation_check = false\n[[retrofit.variants]]\nname = "as built"\n'
    st = load_study(study_with_retrofit(tmp_path, body, wall_mu=False))  # the example's layers without mu
    res = retrofit(st)
    tab = res.table()
    assert list(tab.columns) == list(VARIANT_COLUMNS)
    assert math.isnan(tab["mould_index_max"][0]) and tab["moisture_verdict"][0] == ""
    assert any("no hygric properties" in n for n in res.notes())


def test_brick_wall_short_period_outputs(tmp_path):
    """A two-week period: every new column filled, verdict consistent with the RH and mould columns, the files."""
    h = np.arange(24 * 14)
    write_epw(tmp_path / "w.epw", 2.0 + 4.0 * np.sin(2 * np.pi * h / 24), rh=np.full(h.size, 80.0))
    (tmp_path / "brick.toml").write_text(BRICK_WALL)
    body = (
        '[[retrofit.variants]]\nname = "as built"\n'
        '[[retrofit.variants]]\nname = "EPS"\nadd_exterior = [{ material = "EPS", thickness = 0.1 }]\n'
    )
    st = _study(tmp_path, body, epw="w.epw")
    out = tmp_path / "out"
    res = retrofit(st, wall=load_wall(tmp_path / "brick.toml"), out=out)
    tab = pd.read_csv(out / "variants.csv", keep_default_na=False)
    for col in ("moisture_years", "water_content_trend_kg_m2_per_year", "max_relative_humidity_critical"):
        assert tab[col].notna().all()
    assert list(tab["critical_interface"])[0] == "brick|plaster"
    for _, row in tab.iterrows():
        expected = mr.verdict(
            int(row["moisture_years"]) < st.retrofit.moisture_max_years,
            float(row["water_content_trend_kg_m2_per_year"]),
            float(row["mould_index_max"]),
            float(row["max_relative_humidity_critical"]),
        )
        assert row["moisture_verdict"] == expected
    assert (out / "moisture_2.csv").exists() and (out / "water_2.csv").exists()
    water = pd.read_csv(out / "water_1.csv")
    assert list(water.columns) == ["year", "layer brick", "layer plaster", "total"]
    assert any("no precipitation" in n or "driving rain" in n for n in res.notes())
    # the report's items: the verdict table beside Glaser, the two figures
    tables, figures = res.report_items(out)
    vt = tables[0][1]
    assert list(vt.index) == ["as built", "EPS"] and "Glaser (ISO 13788)" in vt.columns
    assert [f.name for _, f in figures] == ["moisture_critical.png", "water_by_year.png"]
    assert all(f.exists() for _, f in figures)


# ============================================================================ bad input
def _cli(tmp_path, capsys, body, *, epw_rh=None, wall=BRICK_WALL):
    h = np.arange(48)
    write_epw(tmp_path / "w.epw", np.full(h.size, 5.0), rh=epw_rh)
    (tmp_path / "wall.toml").write_text(wall)
    study = study_with_retrofit(tmp_path, '[retrofit]\nweather = "w.epw"\n' + body)
    out = tmp_path / "out"
    code = main(["retrofit", str(study), "--wall", str(tmp_path / "wall.toml"), "--out", str(out), "--quiet"])
    return code, capsys.readouterr(), out


def test_missing_hygric_property_of_an_added_material(tmp_path, capsys):
    body = '[[retrofit.variants]]\nname = "pir"\nadd_interior = [{ material = "PIR", thickness = 0.05 }]\n'
    assert_clean_error(
        *_cli(tmp_path, capsys, body), "retrofit.variants[0].add_interior[0]", "PIR", "no hygric properties"
    )


def test_unknown_mould_sensitivity_class(tmp_path, capsys):
    body = 'mould_sensitivity = { brick = "very resistant" }\n[[retrofit.variants]]\nname = "as built"\n'
    assert_clean_error(
        *_cli(tmp_path, capsys, body), "retrofit.mould_sensitivity.brick", "unknown mould sensitivity class"
    )


def test_weather_file_without_relative_humidity(tmp_path, capsys):
    body = '[[retrofit.variants]]\nname = "as built"\n'
    assert_clean_error(*_cli(tmp_path, capsys, body, epw_rh=np.full(48, 999.0)), "relative_humidity", "missing")


# ============================================================================ the classic case
#: the classic case's variants the suite runs; the vapour control layer and calcium silicate variants (about 100 s of
#: solver time for the first) are run by bench/retrofit_classic.py, and their verdicts are not yet the expected
#: ones (docs/retrofit.md, "The classic case")
CLASSIC_VARIANTS = tomli_w.dumps(
    {
        "retrofit": {
            "variants": [
                v
                for v in tomllib.loads((CLASSIC / "variants.toml").read_text())["retrofit"]["variants"]
                if v["name"] in ("as built", "wool 80 + board", "EPS 100 outside")
            ]
        }
    }
)  # the [[retrofit.variants]] tables, appended to a [retrofit] table


@pytest.fixture(scope="module")
def classic(tmp_path_factory):
    """The solid brick wall (--wall), the bundled example's [retrofit] settings and the shipped Chicago weather."""
    from conftest import EXAMPLE
    from wallcal.weather import shipped_weather_files

    if "USA_IL_Chicago-OHare.Intl.AP.725300_TMY3.epw" not in shipped_weather_files():
        pytest.skip("the shipped weather files come with the energyplus extra")
    tmp = tmp_path_factory.mktemp("classic")
    text = EXAMPLE.read_text()
    settings = text.partition("\n[retrofit]\n")[2].partition("[[retrofit.variants]]")[0]
    study = study_with_retrofit(tmp, "[retrofit]\n" + settings + CLASSIC_VARIANTS)
    (tmp / "brick.toml").write_text(BRICK_WALL)
    out = tmp / "out"
    code = main(["retrofit", str(study), "--wall", str(tmp / "brick.toml"), "--out", str(out), "--quiet"])
    assert code == 0
    return pd.read_csv(out / "variants.csv", keep_default_na=False).set_index("variant"), load_study(study)


@pytest.mark.slow
def test_classic_case_verdicts_agree_with_their_columns(classic):
    tab, study = classic
    for name, row in tab.iterrows():
        assert row["moisture_verdict"] == mr.verdict(
            int(row["moisture_years"]) < study.retrofit.moisture_max_years,
            float(row["water_content_trend_kg_m2_per_year"]),
            float(row["mould_index_max"]),
            float(row["max_relative_humidity_critical"]),
        ), name
    assert tab.loc["as built", "moisture_verdict"] in ("dry", "acceptable")


@pytest.mark.slow
def test_classic_case_interior_wool_without_vapour_control_is_a_risk(classic):
    """Interior vapour wets the old plaster behind the wool in winter, and the plaster sucks it in: RH
    0.965 at most in the cells either side of the contact (1.0 for months while the kernel let no condensate
    cross the contact), mould index 4.1."""
    tab, _ = classic
    row = tab.loc["wool 80 + board"]
    assert row["moisture_verdict"] in ("mould_risk", "accumulating")
    assert row["critical_interface"] == "plaster|int1"
    assert float(row["max_relative_humidity_critical"]) > 0.95 and float(row["mould_index_max"]) >= 1.0


@pytest.mark.slow
def test_classic_case_exterior_eps_is_dry(classic):
    tab, _ = classic
    row = tab.loc["EPS 100 outside"]
    assert row["moisture_verdict"] == "dry"
    assert float(row["max_relative_humidity_critical"]) < 0.8 and float(row["mould_index_max"]) == 0.0


# ============================================================================ intervals over posterior draws
def test_mould_index_and_trend_intervals_over_draws(tmp_path):
    """With --from a posterior output the mould index and the trend get p05/p95 over the draws (each draw's wall
    from its variant's periodic end state); the example's layers carry hygric data."""
    import json

    from wallcal.calibration import parse_space
    from wallcal.outputs import format_entries

    h = np.arange(24 * 4)
    write_epw(tmp_path / "w.epw", 0.0 + 6.0 * np.sin(2 * np.pi * h / 24), rh=np.full(h.size, 85.0))
    study = load_study(
        study_with_retrofit(tmp_path, '[retrofit]\nweather = "w.epw"\n[[retrofit.variants]]\nname = "as built"\n')
    )
    sp = parse_space(study)
    d = tmp_path / "post"
    d.mkdir()
    chain = np.random.default_rng(3).random((6, 4, sp.n))
    np.savez_compressed(
        d / "chain.npz",
        chain=chain,
        log_prob=np.zeros(chain.shape[:2]),
        names=np.array(sp.names),
        lower=sp.lower,
        upper=sp.upper,
    )
    (d / "posterior.json").write_text(json.dumps({"burn": 2, "thin": 1}))
    (d / "manifest.json").write_text(json.dumps({"command": "posterior", **format_entries("posterior")}))
    res = retrofit(study, from_dir=d, samples=6)
    v = res.variants[0]
    assert v.sample_moisture.shape == (6, 4)
    row = res.table().iloc[0]
    assert row["mould_index_max_p05"] <= row["mould_index_max_p95"]
    assert row["water_content_trend_p05"] <= row["water_content_trend_p95"]
    assert np.isfinite([row["mould_index_max_p05"], row["water_content_trend_p95"]]).all()
    assert np.all(v.sample_moisture[:, 2] >= 1)

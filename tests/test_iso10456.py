"""Tests of wallcal.standards.iso10456 against independent hand calculations.

Reference: ISO 10456:2007 eq. (3)-(4), F_T = exp(f_T (T2 - T1)); the worked figures
below are computed by hand with math.exp, independently of numpy.
"""

import math

import numpy as np
import pytest

from wallcal.standards.iso10456 import convert_conductivity, temperature_factor


def test_mineral_wool_to_measured_mean_temperature():
    # 0.035 W/(m K) declared at 10 degC, f_T = 0.0046 1/K (ISO 10456 Table 4, mineral wool),
    # to 23.65 degC (mean of the 23.5-23.8 degC range in the calibration paper, Table III):
    # 0.035 * exp(0.0046 * 13.65) = 0.035 * 1.06478... = 0.037267 W/(m K)
    expected = 0.035 * math.exp(0.0046 * 13.65)
    got = convert_conductivity(0.035, 10.0, 23.65, 0.0046)
    assert got == pytest.approx(expected, rel=1e-12)
    assert got == pytest.approx(0.03727, abs=5e-6)
    assert isinstance(got, float)  # a scalar in, a Python float out (not a 0-d array)
    # The paper states 0.0375 for its LD wool: within 0.7 % of this conversion (the paper's
    # figure is rounded and its exact f_T / mean temperature are not given).
    assert abs(got - 0.0375) / 0.0375 < 0.007


def test_high_density_wool_figure_of_the_paper_is_not_this_conversion():
    # The paper raises the HD wool from 0.040 to 0.0435 (+8.75 %); with f_T = 0.0046 the
    # conversion to 23.65 degC gives +6.5 % only, so 0.0435 includes a calibration choice.
    got = convert_conductivity(0.040, 10.0, 23.65, 0.0046)
    assert got == pytest.approx(0.040 * math.exp(0.0046 * 13.65), rel=1e-12)
    assert got < 0.0435


def test_temperature_factor_identities():
    assert temperature_factor(0.0046, 0.0) == 1.0
    # round trip and composition: F(a) F(b) = F(a + b)
    assert temperature_factor(0.0046, 7.0) * temperature_factor(0.0046, 5.0) == pytest.approx(
        temperature_factor(0.0046, 12.0), rel=1e-14
    )
    lam = convert_conductivity(convert_conductivity(0.04, 10, 30, 0.003), 30, 10, 0.003)
    assert lam == pytest.approx(0.04, rel=1e-14)


def test_vectorised():
    temps = np.array([0.0, 10.0, 20.0])
    out = convert_conductivity(0.035, 10.0, temps, 0.0046)
    assert out.shape == (3,)
    np.testing.assert_allclose(out, [0.035 * math.exp(0.0046 * (t - 10.0)) for t in temps], rtol=1e-14)
    assert isinstance(convert_conductivity(0.035, 10.0, 20.0, 0.0046), float)

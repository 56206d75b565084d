"""The VTT mould model against its published equations, with hand-computed values.

References: Hukka & Viitanen, Wood Sci. Technol. 33 (1999) 475-485; Ojanen, Viitanen, Peuhkuri, Lahdesmaki,
Vinha, Salminen, "Mold growth modeling of building structures using sensitivity classes of materials",
Thermal Performance of the Exterior Envelopes of Whole Buildings XI (2010).

Equations (T [degC], RH [%], W = 0, SQ = 0)::

    growth, t in days:  dM/dt = k1 k2 / (7 exp(-0.68 ln T - 13.9 ln RH + 66.02))
                        k2 = max(1 - exp(2.3 (M - M_max)), 0)
                        M_max = A + B x - C x^2,  x = (RH_crit - RH) / (RH_crit - 100)
                        RH_crit = max(-0.00267 T^3 + 0.160 T^2 - 3.13 T + 100, RH_min) (T <= 20), RH_min (T > 20)
    decline, t in hours since the dry period began:
                        dM/dt = C_mat (-0.00133 (<= 6 h); 0 (6-24 h); -0.000667 (> 24 h))

    class             k1(M<1)  k1(M>=1)  A    B   C    RH_min
    very sensitive    1        2         1    7   2    80
    sensitive         0.578    0.386     0.3  6   1    80
    medium resistant  0.072    0.097     0    5   1.5  85
    resistant         0.033    0.014     0    3   1    85

Hand computation at T = 20 degC, RH = 97 %:
    0.68 ln 20 = 2.037098, 13.9 ln 97 = 63.588489, exponent 66.02 - 65.625587 = 0.394413,
    7 exp(0.394413) = 10.384717 days -> 0.0962959 per day at k1 = k2 = 1.
    RH_crit = -21.36 + 64 - 62.6 + 100 = 80.04 (very sensitive, sensitive); 85 (medium resistant).
    very sensitive: x = 16.96 / 19.96 = 0.849699, M_max = 1 + 5.947896 - 1.443977 = 5.503919;
        k2(M=0) = 1 - exp(-12.659) = 0.999997 -> one day from M = 0: 0.0962956
        from M = 2: k1 = 2, k2 = 1 - exp(2.3 (2 - 5.503919)) = 1 - exp(-8.059014) = 0.999684
        -> one day: 2 x 0.999684 x 0.0962959 = 0.192530
    sensitive: M_max = 0.3 + 5.098196 - 0.721989 = 4.676207, k2(0) = 0.999979
        -> one day from 0: 0.578 x 0.999979 x 0.0962959 = 0.0556576
    medium resistant: x = 0.8, M_max = 4 - 0.96 = 3.04, k2(0) = 1 - exp(-6.992) = 0.999081
        -> one day from 0: 0.072 x 0.999081 x 0.0962959 = 0.00692699
Decline from M = 2 at RH 50 % over 48 h with C_mat = 1: 6 x 0.00133 + 18 x 0 + 24 x 0.000667 = 0.023988.
"""

import math

import numpy as np
import pytest

from wallcal.errors import StudyError
from wallcal.moisture import mould
from wallcal.moisture.mould import CLASSES, critical_rh, decline_rate, growth_rate, mould_index


def series(hours, t, rh):
    return np.full(hours, float(t)), np.full(hours, float(rh))


def test_growth_at_constant_conditions_very_sensitive():
    t, rh = series(24, 20.0, 0.97)
    m = mould_index(t, rh, "very sensitive", decline=1.0)
    assert m[-1] == pytest.approx(0.0962956, abs=2e-6)
    assert np.all(np.diff(m) > 0)
    m2 = mould_index(t, rh, "very sensitive", initial=2.0)
    assert m2[-1] - 2.0 == pytest.approx(0.192530, abs=2e-5)  # k1 = 2 once M >= 1


def test_growth_at_constant_conditions_other_classes():
    t, rh = series(24, 20.0, 0.97)
    assert mould_index(t, rh, "sensitive")[-1] == pytest.approx(0.0556576, abs=2e-6)
    assert mould_index(t, rh, "medium resistant")[-1] == pytest.approx(0.00692699, abs=2e-7)
    # resistant: RH_crit 85, M_max = 3 x 0.8 - 0.64 = 1.76, k2(0) = 1 - exp(-4.048) = 0.982538
    # (k2 falls slightly as M rises over the day)
    assert mould_index(t, rh, "resistant")[-1] == pytest.approx(0.033 * 0.982538 * 0.0962959, rel=1e-4)


def test_point_functions_match_the_series():
    cls = CLASSES["sensitive"]
    assert critical_rh(20.0, cls) == pytest.approx(80.04)
    assert critical_rh(10.0, cls) == pytest.approx(-2.67 + 16.0 - 31.3 + 100.0)
    assert critical_rh(25.0, CLASSES["medium resistant"]) == 85.0
    assert critical_rh(17.0, cls) == 80.0  # the polynomial dips below RH_min there
    assert growth_rate(20.0, 97.0, 0.0, cls) * 24 == pytest.approx(0.0556576, abs=2e-6)
    assert growth_rate(-1.0, 99.0, 0.0, cls) == 0.0
    assert decline_rate(3.0, 1.0) == -0.00133
    assert decline_rate(12.0, 1.0) == 0.0
    assert decline_rate(30.0, 0.5) == pytest.approx(-0.0003335)


def test_critical_humidity_switches_growth_on():
    """At 10 degC RH_crit = 82.03 %: just below it M declines (stays 0), just above it M grows."""
    t = np.full(100, 10.0)
    assert mould_index(t, np.full(100, 0.820), "very sensitive")[-1] == 0.0
    assert mould_index(t, np.full(100, 0.821), "very sensitive")[-1] > 0.0


def test_decline_periods():
    t, rh = series(48, 20.0, 0.50)
    m = mould_index(t, rh, "very sensitive", decline=1.0, initial=2.0)
    assert 2.0 - m[-1] == pytest.approx(0.023988, abs=1e-9)
    assert m[5] == pytest.approx(2.0 - 6 * 0.00133)
    assert m[23] == m[5]  # no decline from 6 h to 24 h
    m = mould_index(t, rh, "sensitive", decline=0.25, initial=2.0)
    assert 2.0 - m[-1] == pytest.approx(0.25 * 0.023988, abs=1e-9)
    # a wet hour restarts the clock of the dry period; M never falls below zero
    m = mould_index(np.full(1000, 20.0), np.full(1000, 0.5), "very sensitive", initial=0.1, decline=1.0)
    assert m.min() == 0.0


def test_growth_stops_at_the_maximum_index():
    """At 20 degC and 85 %: M_max = 1 + 7 x 0.248497 - 2 x 0.061751 = 2.615978 (very sensitive)."""
    t, rh = series(5 * 8760, 20.0, 0.85)
    m = mould_index(t, rh, "very sensitive")
    m_max = 1 + 7 * (4.96 / 19.96) - 2 * (4.96 / 19.96) ** 2
    assert m[-1] < m_max
    assert m[-1] > m_max - 0.05


def test_periodic_mould_index_converges_and_batches():
    hours = np.arange(8760)
    t = 10 + 8 * np.sin(2 * np.pi * hours / 8760)
    rh = 0.80 + 0.15 * np.cos(2 * np.pi * hours / 8760)
    m, years = mould.periodic_mould_index(np.vstack([t, t]), np.vstack([rh, np.full(8760, 0.6)]), "sensitive")
    assert m.shape == (2, 8760)
    assert 1 <= years <= mould.MOULD_CYCLES
    assert m[1].max() == 0.0 and m[0].max() > 0.0
    # the same row alone gives the same values (rows are independent)
    single = mould_index(t, rh, "sensitive")
    assert np.all(m[0] >= single - 1e-12)


@pytest.mark.parametrize("bad", ["very resistant", "", 3, None])
def test_unknown_class_is_one_clear_line(bad):
    with pytest.raises(StudyError) as e:
        mould.mould_class(bad, "retrofit.mould_sensitivity")
    msg = str(e.value)
    assert "\n" not in msg.strip()
    assert "retrofit.mould_sensitivity" in msg and "medium resistant" in msg


def test_class_names_are_forgiving():
    assert mould.mould_class("Medium_Resistant") is CLASSES["medium resistant"]
    assert mould.mould_class("very-sensitive") is CLASSES["very sensitive"]


def test_hand_exponent():
    """The docstring's hand numbers (guards against a typo in the constants above)."""
    e = 66.02 - 0.68 * math.log(20) - 13.9 * math.log(97)
    assert 1 / (7 * math.exp(e)) == pytest.approx(0.0962959, abs=1e-7)

"""``interior_humidity_class`` in ``[retrofit]``: read at load, run, and checked against ISO 13788 Annex A."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from retrofit_helpers import study_with_retrofit, write_epw, year_temperature
from wallcal import load_study
from wallcal.errors import StudyError
from wallcal.retrofitting import glaser, run

#: ISO 13788:2012 Annex A (Table A.1, Figure A.1): indoor vapour excess of the humidity classes 1..5 at an
#: exterior temperature <= 0 degC, as a vapour pressure Delta p [Pa] and a vapour content Delta v [kg/m3];
#: both fall linearly to 0 at 20 degC and above.
ANNEX_A_DP = {1: 270.0, 2: 540.0, 3: 810.0, 4: 1080.0, 5: 1350.0}
ANNEX_A_DV = {1: 0.002, 2: 0.004, 3: 0.006, 4: 0.008, 5: 0.010}
R_VAPOUR = 461.5  # J/(kg K)


@pytest.mark.parametrize("cls", [1, 2, 3, 4, 5])
def test_humidity_class_excess_is_annex_a(cls):
    th = np.array([-15.0, -5.0, 0.0, 5.0, 10.0, 15.0, 20.0, 25.0])
    expected = ANNEX_A_DP[cls] * np.array([1, 1, 1, 0.75, 0.5, 0.25, 0, 0])
    assert glaser.humidity_class_excess(th, cls) == pytest.approx(expected)
    # Delta p = Delta v R_v T at the 20 degC interior of the annex: the two tables agree within 0.5 %
    assert glaser.humidity_class_excess(-5.0, cls) == pytest.approx(ANNEX_A_DV[cls] * R_VAPOUR * 293.15, rel=5e-3)
    p_e = np.array([400.0, 600.0])
    p_i = glaser.interior_vapour_pressure(np.array([0.0, 10.0]), p_e, 20.0, humidity_class=cls)
    assert p_i == pytest.approx(p_e + 1.10 * ANNEX_A_DP[cls] * np.array([1.0, 0.5]))  # with the safety factor


def _weather(tmp_path):
    t = year_temperature(24 * 6)
    write_epw(tmp_path / "w.epw", t)


def test_interior_humidity_class_loads_and_runs(tmp_path):
    _weather(tmp_path)
    st = load_study(study_with_retrofit(tmp_path, '[retrofit]\nweather = "w.epw"\ninterior_humidity_class = 3\n'))
    assert st.retrofit is not None and st.features["retrofit"] is st.retrofit
    assert st.retrofit.interior_humidity_class == 3 and st.retrofit.interior_relative_humidity is None
    res = run.retrofit(st, out=tmp_path / "out")
    g = pd.read_csv(tmp_path / "out" / "glaser_1.csv")
    expected = g["p_e"] + 1.10 * glaser.humidity_class_excess(g["theta_e"].to_numpy(), 3)
    assert g["p_i"].to_numpy() == pytest.approx(expected.to_numpy(), rel=1e-5)
    assert res.variants[0].glaser is not None


def test_both_humidity_keys_or_a_bad_class_are_errors_at_load(tmp_path):
    _weather(tmp_path)
    for body, fragment in (
        ("interior_humidity_class = 3\ninterior_relative_humidity = 0.5\n", "not both"),
        ("interior_humidity_class = 6\n", "retrofit.interior_humidity_class"),
    ):
        with pytest.raises(StudyError, match=fragment):
            load_study(study_with_retrofit(tmp_path, '[retrofit]\nweather = "w.epw"\n' + body))

"""An explicit 0 (time step, grid constant) is checked and refused, not replaced by the study's value."""

from __future__ import annotations

import numpy as np
import pytest

from retrofit_helpers import study_with_retrofit, write_epw
from wallcal import load_study
from wallcal.errors import StudyError
from wallcal.simulation import prepare, simulate
from wallcal.weather import read_weather


@pytest.mark.parametrize(
    ("kw", "key"),
    [
        ({"time_step": 0.0}, "simulation.time_step: must be > 0, got 0"),
        ({"time_step": -60.0}, "simulation.time_step: must be > 0, got -60"),
        ({"grid_constant": 0.0}, "simulation.grid_constant: must be > 0, got 0"),
    ],
)
def test_explicit_zero_is_refused(example_study, kw, key):
    with pytest.raises(StudyError, match=key):
        prepare(example_study, **kw)
    with pytest.raises(StudyError, match=key):
        simulate(example_study, **kw)


def test_none_takes_the_study_value(example_study):
    prep = prepare(example_study, time_step=None, grid_constant=None)
    assert prep.inp.time_step == example_study.simulation.time_step
    assert prep.inp.grid_constant == example_study.simulation.grid_constant


def test_year_boundaries_refuse_an_explicit_zero_step(tmp_path):
    from wallcal.retrofitting.boundary import year_boundaries

    write_epw(tmp_path / "w.epw", np.full(48, 5.0))
    spec = load_study(study_with_retrofit(tmp_path, '[retrofit]\nweather = "w.epw"\n')).retrofit
    wx = read_weather(tmp_path / "w.epw")
    assert year_boundaries(wx, spec, time_step=None).time_step == spec.time_step
    for bad in (0.0, 7.0):
        with pytest.raises(StudyError, match="retrofit.time_step: must be a positive divisor of 3600 s"):
            year_boundaries(wx, spec, time_step=bad)

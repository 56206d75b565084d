"""Sensitivity: one-at-a-time, Morris and Sobol over the calibration space, through the batched engine."""

import dataclasses

import numpy as np
import pytest

from wallcal.analysis.sensitivity import sensitivity
from wallcal.calibration import parse_space


def test_oat_ranks_the_insulation_first(example_study):
    r = sensitivity(example_study, "oat", progress=False)
    assert r.evaluations == 2 * 18 + 1
    assert r.ranking.index[0] == "conductivity[3]"
    ins = r.by_layer[r.by_layer["insulation"]]
    assert ins["share"].sum() > 0.5
    assert {"dRMSE_T3A_lower", "dRMSE_T1A_upper"} <= set(r.ranking.columns)
    # density and specific heat of one layer act through their product: same effect at +-20 %
    assert np.isclose(
        r.ranking.loc["density[3]", "d_objective_upper"], r.ranking.loc["specific_heat[3]", "d_objective_upper"]
    )


def test_sobol_and_morris_small(example_study, tmp_path):
    space = parse_space(example_study)
    sub = dataclasses.replace(space, parameters=space.parameters[:6])
    s = sensitivity(example_study, "sobol", space=sub, n=32, progress=False)
    assert s.evaluations == 32 * (6 + 2)
    assert {"ST", "ST_conf", "S1", "S1_conf"} <= set(s.ranking.columns)
    assert s.ranking.index[0] == "conductivity[3]"
    s.write_into(tmp_path)
    assert (tmp_path / "sensitivity_sobol.png").exists()
    m = sensitivity(example_study, "morris", space=sub, n=4, progress=False)
    assert m.evaluations == 4 * 7
    assert "mu_star" in m.ranking.columns


def test_bad_method_and_sample(example_study):
    from wallcal.errors import StudyError

    with pytest.raises(StudyError):
        sensitivity(example_study, "fast", progress=False)
    with pytest.raises(StudyError, match="power of 2"):
        sensitivity(example_study, "sobol", n=100, progress=False)


def test_cli_sensitivity_oat(tmp_path, capsys):
    from conftest import EXAMPLE
    from wallcal.cli import main

    assert main(["sensitivity", str(EXAMPLE), "--method", "oat", "--out", str(tmp_path / "s"), "--quiet"]) == 0
    out = capsys.readouterr().out
    assert "conductivity[3]" in out and "insulation" in out
    assert (tmp_path / "s" / "sensitivity_oat.png").exists()

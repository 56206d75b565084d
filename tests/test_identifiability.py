"""Identifiability: the structural flat directions of the example are found and named; a heat flux fixes the scale."""

import numpy as np
import pytest

from wallcal.analysis.identifiability import identifiability, structural_directions
from wallcal.calibration import parse_space


@pytest.fixture(scope="module")
def ident(example_study):
    return identifiability(example_study)


def test_known_directions_of_the_example(example_study):
    space = parse_space(example_study)
    keys = [k for k, _, _ in structural_directions(space, example_study.wall)]
    assert keys == ["rho_c[3]", "rho_c[4]", "rho_c[5,8]", "rho_c[6]", "rho_c[7]", "rho_c[9]", "common_scale"]
    keys_flux = [k for k, _, _ in structural_directions(space, example_study.wall, with_flux=True)]
    assert "common_scale" not in keys_flux


def test_temperatures_only_names_the_flat_directions(ident):
    a = ident.main
    assert a.targets == ("T3A", "T2A", "T1A")
    assert a.rank == 11 and a.n == 18  # 18 - 6 (rho*c products) - 1 (common scale)
    assert "common_scale" in a.flat.index
    assert sum(k.startswith("rho_c[") for k in a.flat.index) == 6
    assert "common factor" in a.flat.loc["common_scale", "in words"]
    # every absolute conductivity is structurally unidentifiable from temperatures alone
    lam = a.parameters[a.parameters.index.str.startswith("conductivity")]
    assert (lam["verdict"] == "not identifiable (structural)").all()
    # ratios and diffusivities are structurally identifiable, resistances are not
    assert not a.combos.loc["lambda[7]/lambda[3]", "verdict"].startswith("not identifiable")
    assert not a.combos.loc["alpha[3] = lambda/(rho c)", "verdict"].startswith("not identifiable")
    assert a.combos.loc["R_total (all layers)", "verdict"].startswith("not identifiable")


def test_heat_flux_fixes_the_common_scale(ident):
    comp = ident.comparison()
    assert comp.loc["T3A+T2A+T1A", "rank"] == "11 of 18"
    assert comp.loc["T3A+T2A+T1A+qe", "rank"] == "12 of 18"
    assert comp.loc["T3A+T2A+T1A+qi", "rank"] == "12 of 18"
    assert ident.main.scale_gain == 0.0
    assert ident.analyses[1].scale_gain > 10.0
    qe = ident.analyses[1]
    assert "common_scale" not in qe.flat.index
    assert not qe.combos.loc["R_total (all layers)", "verdict"].startswith("not identifiable")


def test_common_scale_leaves_temperatures_unchanged(ident):
    d = ident.demo
    for t in ("T3A", "T2A", "T1A"):
        assert np.ptp(d[f"RMSE {t}"]) < 1e-6
    assert np.ptp(d["RMSE qe"]) > 0.05  # the flux is not invariant


def test_cli_identifiability(tmp_path, capsys):
    from conftest import EXAMPLE
    from wallcal.cli import main

    assert main(["identifiability", str(EXAMPLE), "--out", str(tmp_path / "id")]) == 0
    out = capsys.readouterr().out
    assert "11 of 18" in out and "common_scale" in out and "12 of 18" in out
    assert (tmp_path / "id" / "singular_values.png").exists()

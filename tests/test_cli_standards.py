"""CLI tests of ``wallcal wall`` and ``wallcal iso9869`` (wallcal.commands.standards)."""

from __future__ import annotations

import json
import re
import shutil

import pytest

from conftest import EXAMPLE
from wallcal.cli import main


def _number_after(label: str, text: str) -> float:
    m = re.search(re.escape(label) + r"\s+([-+0-9.eE]+)", text)
    assert m, f"{label!r} not found in:\n{text}"
    return float(m.group(1))


# --------------------------------------------------------------------------- wallcal wall


def test_wall_on_example_study(capsys):
    assert main(["wall", str(EXAMPLE)]) == 0
    out = capsys.readouterr().out
    # every layer of the study wall is listed (ids 3..9)
    for lid in "3456789":
        assert re.search(rf"^\s*{lid}\s", out, re.M), out
    # ISO 6946: 1 / (0.13 + 8.1726 + 0.04) = 0.1199 W/(m2K), the design value 0.12 (docs/standards.md)
    assert _number_after("U (ISO 6946)", out) == pytest.approx(0.12, abs=0.002)
    assert _number_after("R (surface to surface)", out) == pytest.approx(8.1726, abs=1e-3)
    assert _number_after("areal heat capacity", out) == pytest.approx(65.43, abs=0.01)
    # ISO 13786 figures of this wall at 24 h (docs/standards.md, cross-checked in test_iso13786.py)
    assert _number_after("|Y12| periodic transmittance", out) == pytest.approx(0.0254, abs=2e-4)
    assert _number_after("decrement factor f", out) == pytest.approx(0.212, abs=1e-3)
    assert _number_after("time shift of Y12", out) == pytest.approx(10.9, abs=0.05)
    assert _number_after("|Y11| interior admittance", out) == pytest.approx(1.67, abs=0.01)
    assert _number_after("|Y22| exterior admittance", out) == pytest.approx(0.61, abs=0.01)
    assert _number_after("kappa1 interior", out) == pytest.approx(24.9, abs=0.1)
    assert _number_after("kappa2 exterior", out) == pytest.approx(9.0, abs=0.1)


def test_wall_options_change_the_figures(capsys, tmp_path):
    wall_file = tmp_path / "wall.toml"
    wall_file.write_text(
        '[wall]\nname = "with gap"\n'
        '[[wall.layers]]\nid = "1"\nmaterial = "brick"\nthickness = 0.1\nconductivity = 0.8\n'
        "density = 1800\nspecific_heat = 840\n"
        '[[wall.layers]]\nid = "2"\nmaterial = "gap"\nthickness = 0.05\nconductivity = 0.3\n'
        "density = 1.2\nspecific_heat = 1000\n"
        '[[wall.layers]]\nid = "3"\nmaterial = "wool"\nthickness = 0.1\nconductivity = 0.04\n'
        "density = 60\nspecific_heat = 1030\n"
    )
    assert main(["wall", str(wall_file), "--air-layer", "2=unventilated", "--period-hours", "12"]) == 0
    out = capsys.readouterr().out
    # 0.13 + 0.1/0.8 + 0.18 (Table 8, 50 mm, horizontal) + 0.1/0.04 + 0.04 = 2.975
    assert _number_after("R_T = Rsi + R + Rse", out) == pytest.approx(2.975, abs=1e-4)
    assert "air:unventilated" in out
    assert "period 12 h" in out
    assert main(["wall", str(wall_file), "--air-layer", "2"]) == 2
    err = capsys.readouterr().err
    assert "--air-layer" in err and "ID=VENTILATION" in err


def test_wall_missing_file_exits_2_with_one_line(capsys, tmp_path):
    missing = tmp_path / "nope.toml"
    assert main(["wall", str(missing)]) == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1
    assert lines[0].startswith("wallcal: error:") and "file not found" in lines[0] and "nope.toml" in lines[0]


# --------------------------------------------------------------------------- wallcal iso9869


def test_iso9869_example_names_the_failing_criteria(capsys):
    assert main(["iso9869", str(EXAMPLE)]) == 0
    out = capsys.readouterr().out
    # Campaign A is free-floating late-spring/summer data: over the 8-day period the exterior surface
    # (10..58 degC, sunlit) is on average 4.6 K *warmer* than the interior surface (22..25 degC), and
    # T_si - T_se changes sign about half of the time. The net heat flux is small against daily swings
    # of +-12 K, so the running R does not settle (last_24h and first_last_two_thirds fail), and the
    # exterior surface warms by about 4 K between the first and the last day, so the heat stored in
    # this heavy (65 kJ/(m2K) > 20) wall changes by a third of the heat that crossed it (storage fails).
    # ISO 9869-1 asks for a steady, mostly one-signed temperature difference (heating season).
    assert "verdict: not applicable: fails last_24h, first_last_two_thirds, storage" in out
    for name, result in (
        ("duration", "pass"),
        ("last_24h", "FAIL"),
        ("first_last_two_thirds", "FAIL"),
        ("storage", "FAIL"),
        ("whole_days", "pass"),
    ):
        assert re.search(rf"^\s*{name}\s+{result}\b", out, re.M), (name, out)
    assert "element: heavy" in out
    # the period 2025-05-30 .. 2025-06-07, end excluded: 8 days of 5-min readings
    assert "2304 readings x 300 s = 192 h" in out
    r = _number_after("R (average method)", out)
    assert 5.0 < r < 12.0
    assert _number_after("U with Rsi, Rse", out) == pytest.approx(1 / (0.13 + r + 0.04), abs=1e-4)


def test_iso9869_exterior_face_and_whole_record(capsys):
    assert main(["iso9869", str(EXAMPLE), "--face", "exterior", "--whole-record"]) == 0
    out = capsys.readouterr().out
    assert "heat flux 'qe' at the exterior face" in out
    assert "whole record" in out
    assert "verdict:" in out


def test_iso9869_out_writes_three_files(capsys, tmp_path):
    out_dir = tmp_path / "res"
    assert main(["iso9869", str(EXAMPLE), "--out", str(out_dir)]) == 0
    capsys.readouterr()
    for name in ("iso9869.csv", "iso9869.json", "iso9869.png", "manifest.json"):
        assert (out_dir / name).is_file(), name
    verdict = json.loads((out_dir / "iso9869.json").read_text())
    assert verdict["applicable"] is False
    assert verdict["failing"] == ["last_24h", "first_last_two_thirds", "storage"]
    assert {c["name"] for c in verdict["criteria"]} == {
        "duration",
        "last_24h",
        "first_last_two_thirds",
        "storage",
        "whole_days",
    }
    csv = (out_dir / "iso9869.csv").read_text().splitlines()
    assert csv[0].split(",") == ["timestamp", "elapsed_h", "q_W_m2", "t_si_C", "t_se_C", "r_running_m2K_W"]
    assert len(csv) == 1 + 2304
    assert float(csv[-1].split(",")[-1]) == pytest.approx(verdict["r_value_m2K_W"], rel=1e-5)
    assert (out_dir / "iso9869.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert not list(tmp_path.glob(".res*"))  # no temporary directory or lock left


def test_iso9869_without_out_writes_nothing(capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(["iso9869", str(EXAMPLE)]) == 0
    assert list(tmp_path.iterdir()) == []


def _study_copy(tmp_path, edit):
    src = EXAMPLE.parent
    shutil.copy(src / "measured.csv", tmp_path / "measured.csv")
    shutil.copy(src / "true_wall.toml", tmp_path / "true_wall.toml")
    text = edit((src / "study.toml").read_text())
    path = tmp_path / "study.toml"
    path.write_text(text)
    return path


def test_iso9869_no_flux_sensor_at_face(capsys, tmp_path):
    # drop the interior heat-flux sensor (the last [[sensors]] table)
    path = _study_copy(tmp_path, lambda t: t[: t.rindex("[[sensors]]")] + t[t.index("[period]") :])
    assert main(["iso9869", str(path), "--face", "interior"]) == 2
    err = capsys.readouterr().err.strip()
    assert "no heat_flux sensor at the interior face" in err and "qe (exterior)" in err


def test_iso9869_needs_surface_temperatures(capsys, tmp_path):
    path = _study_copy(
        tmp_path,
        lambda t: t.replace(
            '[boundary.interior]\ntype = "surface_temperature"',
            '[boundary.interior]\ntype = "air_temperature"\nsurface_coefficient = 7.7',
        ),
    )
    assert main(["iso9869", str(path)]) == 2
    err = capsys.readouterr().err
    assert "surface temperatures" in err and "boundary.interior.type is 'air_temperature'" in err

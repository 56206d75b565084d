"""The study file: contract keys, validation with key paths, closest-name hints."""

from __future__ import annotations

import copy
import tomllib

import pytest

from conftest import EXAMPLE
from wallcal import StudyError
from wallcal.study import load_study, load_wall, parse_study


@pytest.fixture()
def raw():
    return tomllib.loads(EXAMPLE.read_text())


def problems_of(raw, base=EXAMPLE.parent):
    with pytest.raises(StudyError) as exc:
        parse_study(raw, base_dir=base)
    return exc.value.problems


def test_example_loads(example_study):
    s = example_study
    assert s.name == "Campaign A, base case"
    assert [layer.id for layer in s.wall.layers] == ["3", "4", "5", "6", "7", "8", "9"]
    assert s.wall.probe("T2A").depth == pytest.approx(0.1525)
    assert s.simulation.engine == "fd-cn" and s.simulation.grid_constant == 2.0
    assert s.sensor("qe").quantity == "heat_flux" and s.sensor("qe").face == "exterior"
    assert s.sensor("qe").accuracy_relative == 0.03
    assert len(s.sha256) == 64


def test_negative_conductivity_reports_key_path(raw):
    raw["wall"]["layers"][2]["conductivity"] = -0.035
    assert problems_of(raw) == ["wall.layers[2].conductivity: must be > 0, got -0.035"]


def test_all_problems_reported_at_once(raw):
    raw["wall"]["layers"][0]["density"] = "heavy"
    raw["wall"]["layers"][1]["thikness"] = 0.01
    raw["simulation"]["engine"] = "fd-cnn"
    raw["sensors"][0]["accuracy"] = float("nan")
    del raw["period"]["end"]
    probs = problems_of(raw)
    text = "\n".join(probs)
    assert "wall.layers[0].density: must be a number, got 'heavy'" in text
    assert "wall.layers[1].thikness: unknown key; did you mean 'thickness'?" in text
    assert "simulation.engine: must be one of" in text and "did you mean 'fd-cn'" in text
    assert "sensors[0].accuracy: must be a finite number" in text
    assert "period.end: required, missing" in text
    assert len(probs) >= 5


def test_unknown_top_level_key(raw):
    raw["simulaton"] = {}
    assert any(p.startswith("simulaton: unknown key; did you mean 'simulation'") for p in problems_of(raw))


def test_sensor_must_name_a_probe(raw):
    raw["sensors"][0]["name"] = "T3B"
    assert any(p.startswith("sensors[0].name: 'T3B' is not a probe") and "T3A" in p for p in problems_of(raw))


def test_duplicate_layer_and_sensor(raw):
    raw["wall"]["layers"][1]["id"] = "3"
    raw["sensors"][1]["name"] = "T3A"
    probs = "\n".join(problems_of(raw))
    assert "layer id '3' is used twice" in probs
    assert "sensor 'T3A' is defined twice" in probs


def test_period_order_and_types(raw):
    raw["period"]["end"] = raw["period"]["start"]
    raw["period"]["warmup_start"] = "yesterday"
    probs = "\n".join(problems_of(raw))
    assert "period.end: must be after period.start" in probs
    assert "period.warmup_start: must be a date-time" in probs


def test_probe_beyond_wall_and_depth_from_interior(raw):
    raw["wall"]["probes"][0]["depth"] = 0.5
    assert any("beyond the wall's thickness" in p for p in problems_of(raw))
    raw2 = tomllib.loads(EXAMPLE.read_text())
    raw2["wall"]["probes"][0]["depth"] = 0.24
    raw2["wall"]["probes"][0]["depth_from"] = "interior"
    s = parse_study(raw2, base_dir=EXAMPLE.parent)
    assert s.wall.probe("T3A").depth == pytest.approx(0.34 - 0.24)


def test_optional_layer_keys(raw):
    layer = raw["wall"]["layers"][0]
    layer["conductivity_temperature_coefficient"] = 0.0046
    layer["reference_temperature"] = 10.0
    layer["contact_resistance"] = 0.01
    raw["wall"]["layers"][1]["conductivity_table"] = [[0.0, 0.19], [40.0, 0.21]]
    raw["wall"]["layers"][1].pop("conductivity")
    raw["wall"]["layers"].insert(1, {"id": "gap", "thickness": 0.0, "thermal_resistance": 0.17})
    raw.pop("calibration")  # its relative bounds need layer 4's conductivity
    s = parse_study(raw, base_dir=EXAMPLE.parent)
    assert s.wall.layers[0].conductivity_at(20.0) == pytest.approx(0.04 * 2.718281828 ** (0.046), rel=1e-6)
    assert s.wall.layers[1].is_massless
    assert s.wall.layers[2].conductivity_at(20.0) == pytest.approx(0.20)
    assert not s.wall.is_linear


def test_massless_layer_rejects_conductivity(raw):
    raw["wall"]["layers"][0]["thermal_resistance"] = 0.2
    assert any("takes no conductivity" in p for p in problems_of(raw))


def test_boundary_validation(raw):
    raw["boundary"]["exterior"]["type"] = "air_temperature"
    probs = problems_of(raw)
    assert probs == ["boundary.exterior.surface_coefficient: required, missing"]
    raw["boundary"]["exterior"]["surface_coefficient"] = 25.0
    parse_study(raw, base_dir=EXAMPLE.parent)


def test_both_flux_boundaries_rejected(raw):
    raw["boundary"]["exterior"] = {"type": "heat_flux", "column": "qe"}
    raw["boundary"]["interior"] = {"type": "heat_flux", "column": "qi"}
    assert any("heat-flux boundaries on both faces" in p for p in problems_of(raw))


def test_wall_file_and_wall_from_study(tmp_path, raw):
    w = load_wall(EXAMPLE)
    assert len(w.layers) == 7
    wall_toml = tmp_path / "wall.toml"
    wall_toml.write_text(
        '[wall]\nname = "w"\n[[wall.layers]]\nid = "a"\nthickness = 0.1\nconductivity = 0.04\n'
        'density = 30\nspecific_heat = 1000\n[[wall.probes]]\nname = "T3A"\ndepth = 0.05\n'
    )
    raw2 = copy.deepcopy(raw)
    raw2["wall"] = {"file": str(wall_toml)}
    raw2["sensors"] = [raw["sensors"][0]]
    raw2.pop("calibration")  # its parameters name the example's layers
    s = parse_study(raw2, base_dir=EXAMPLE.parent)
    assert s.wall.layers[0].id == "a"


def test_not_utf8_and_bad_toml(tmp_path):
    p = tmp_path / "s.toml"
    p.write_bytes(b'[study]\nname = "\xff\xfe"\n')
    with pytest.raises(StudyError, match="not valid UTF-8"):
        load_study(p)
    p.write_text("[study\nname=1")
    with pytest.raises(StudyError, match="not valid TOML"):
        load_study(p)
    with pytest.raises(StudyError, match="file not found"):
        load_study(tmp_path / "missing.toml")


# ---------------------------------------------------------------------------- [calibration], validated at load
def test_calibration_is_parsed_at_load(example_study, raw):
    from wallcal.calibration import ParameterSpace

    sp = example_study.calibration
    assert isinstance(sp, ParameterSpace) and sp.n == 18 and sp.targets == ("T3A", "T2A", "T1A")
    assert sp.reference_wall == EXAMPLE.parent / "true_wall.toml"
    with pytest.raises(AttributeError):
        sp.seed = 2  # frozen
    raw.pop("calibration")
    assert parse_study(raw, base_dir=EXAMPLE.parent).calibration is None


def test_broken_calibration_fails_at_load_with_every_problem(raw):
    raw["calibration"]["parameters"][2]["bounds"] = [0.2, -0.2]
    raw["calibration"]["parameters"][4]["layers"] = ["44"]
    raw["calibration"]["objective"] = "rmse"
    raw["simulation"]["engine"] = "fd-cnn"  # a problem elsewhere: reported in the same error
    probs = problems_of(raw)
    assert "calibration.parameters[2].bounds: upper bound must exceed lower bound, got [0.2, -0.2]" in probs
    assert any(p.startswith("calibration.parameters[4].layers[0]: '44' is not a layer id") for p in probs)
    assert any(p.startswith("calibration.objective: must be one of cse") for p in probs)
    assert any(p.startswith("simulation.engine:") for p in probs)
    assert len(probs) == 4, probs


def test_calibration_settings_checked_at_load(raw):
    raw["calibration"]["settings"] = {"particle": 3, "generations": 2.5, "polish": "yes", "topology": "ring"}
    probs = problems_of(raw)
    assert any(p.startswith("calibration.settings.particle: unknown setting for pso-hj; did you mean") for p in probs)
    assert "calibration.settings.generations: must be a whole number, got 2.5" in probs
    assert "calibration.settings.polish: must be true or false, got 'yes'" in probs
    assert any(p.startswith("calibration.settings.topology: must be one of vonneumann, gbest") for p in probs)
    assert len(probs) == 4, probs
    raw["calibration"]["algorithm"] = "nelder-mead"
    raw["calibration"]["settings"] = {"maxfev": 100}
    s = parse_study(raw, base_dir=EXAMPLE.parent)
    assert dict(s.calibration.settings) == {"maxfev": 100}


def test_calibration_reference_wall_checked_at_load(raw, tmp_path):
    raw["calibration"]["reference_wall"] = "no_such_wall.toml"
    (probs,) = problems_of(raw)
    assert probs.startswith("calibration.reference_wall (") and "file not found" in probs


def test_calibration_gives_no_follow_up_problems_of_a_broken_wall(raw):
    raw["wall"]["layers"][2]["density"] = -40.0  # layer 5 is dropped; the parameters naming it are not flagged
    assert problems_of(raw) == ["wall.layers[2].density: must be > 0, got -40"]
    raw["calibration"]["parameters"][0]["bounds"] = [0.3]  # a problem that does not depend on the wall
    assert problems_of(raw)[1] == "calibration.parameters[0].bounds: must be a pair [lower, upper]"

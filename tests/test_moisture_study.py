"""Moisture in studies and wall files: catalogue layers, hygric keys, DELPHIN files, the ham engine, bad input."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from wallcal import materials
from wallcal.errors import StudyError
from wallcal.moisture.delphin import read_m6
from wallcal.wallfile import dump_wall, load_wall

DATA = Path(__file__).parent / "data"

WALL = """[wall]
[[wall.layers]]
id = "1"
material = "solid brick"
thickness = 0.2
[[wall.layers]]
id = "2"
material = "wood fibre board"
thickness = 0.1
conductivity = 0.045
[[wall.layers]]
id = "3"
hygric_file = "b.m6"
thickness = 0.05
[[wall.layers]]
id = "4"
material = "vapour control layer"
thickness = 0.0005
"""


def _wall(tmp_path, text=WALL):
    shutil.copy(DATA / "test_material.m6", tmp_path / "b.m6")
    (tmp_path / "w.toml").write_text(text)
    return load_wall(tmp_path / "w.toml")


def test_catalogue_material_gives_every_property_and_explicit_keys_win(tmp_path):
    w = _wall(tmp_path)
    brick, wood, m6, vcl = w.layers
    cat = materials.find("solid brick")
    assert (brick.conductivity, brick.density, brick.specific_heat) == (
        cat.conductivity,
        cat.density,
        cat.specific_heat,
    )
    assert brick.hygric_keys()["moisture_storage"]["form"] == "van_genuchten"
    assert wood.conductivity == 0.045 and wood.density == materials.find("wood fibre board").density
    assert vcl.vapour_resistance_factor == pytest.approx(10.0 / 0.0005)
    for layer in w.layers:
        layer.hygric_material()  # every layer can run in the ham engine


def test_delphin_file_is_read(tmp_path):
    keys = read_m6(DATA / "test_material.m6")
    assert keys["density"] == 1800 and keys["conductivity"] == 0.7 and keys["vapour_resistance_factor"] == 12
    assert keys["moisture_storage"]["form"] == "suction_table" and keys["moisture_storage"]["w"][0] == 250.0
    assert keys["liquid_transport"]["form"] == "conductivity_table"
    layer = _wall(tmp_path).layers[2]
    assert layer.density == 1800 and layer.specific_heat == 850
    h = layer.hygric_material()
    assert h.water_content_from_rh(0.99) > h.water_content_from_rh(0.5) > 0


def test_calibrated_wall_file_carries_the_hygric_properties(tmp_path):
    w = _wall(tmp_path)
    (tmp_path / "back.toml").write_text(dump_wall(w))
    (tmp_path / "b.m6").unlink()  # read back without the catalogue's or the file's help
    back = load_wall(tmp_path / "back.toml")
    assert back == w
    assert back.layers[2].hygric_keys() == w.layers[2].hygric_keys()


def test_non_monotone_storage_table_is_one_line(tmp_path):
    text = WALL + "moisture_storage = { phi = [0.3, 0.8, 0.9], w = [1.0, 5.0, 4.0] }\n"
    with pytest.raises(StudyError) as exc:
        _wall(tmp_path, text)
    msg = str(exc.value)
    assert "wall.layers[3].moisture_storage" in msg and "not monotone" in msg and "\n" not in msg.strip()


def test_bad_delphin_file_names_it(tmp_path):
    (tmp_path / "bad.m6").write_text("[PARAMETERS]\n  RHO = 1000 kg/m3\n")
    text = (
        '[wall]\n[[wall.layers]]\nid = "1"\nthickness = 0.1\nconductivity = 1.0\ndensity = 1000\n'
        'specific_heat = 1000\nhygric_file = "bad.m6"\n'
    )
    (tmp_path / "w.toml").write_text(text)
    with pytest.raises(StudyError, match="hygric_file.*Theta_l"):
        load_wall(tmp_path / "w.toml")


def test_sorption_scale_scales_the_storage(tmp_path):
    w = _wall(tmp_path)
    layer = w.layers[1]
    base = layer.hygric_material().water_content_from_rh(0.8)
    scaled = layer.replace(sorption_scale=2.0).hygric_material().water_content_from_rh(0.8)
    assert scaled == pytest.approx(2 * base, rel=1e-9)
    assert np.isfinite(base)

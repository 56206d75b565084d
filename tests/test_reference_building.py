"""The reference building is data (``building/reference_building.epJSON``): the model it gives is the one the
Python code of earlier versions built, field for field."""

from __future__ import annotations

import json

from conftest import REPO
from wallcal.building.model import REFERENCE_BUILDING_FILE, reference_building

#: The base commit's ``reference_building(heating_setpoint=19.0, cooling_setpoint=27.5)``, dumped once.
SNAPSHOT = REPO / "tests" / "data" / "reference_building_base.epJSON"


def test_the_shipped_reference_building_equals_the_one_the_code_built():
    expected = json.loads(SNAPSHOT.read_text())
    got = reference_building(heating_setpoint=19.0, cooling_setpoint=27.5)
    assert got == expected
    # the same text to EnergyPlus: same keys in the same order, same types (0 stays an int, 0.0 a float)
    assert json.dumps(got) == json.dumps(expected)


def test_the_default_set_points_and_a_fresh_copy_each_call():
    a = reference_building()
    sched = a["Schedule:Constant"]
    assert sched["WALLCAL_HEATING_SETPOINT"]["hourly_value"] == 20.0
    assert sched["WALLCAL_COOLING_SETPOINT"]["hourly_value"] == 26.0
    sched["WALLCAL_HEATING_SETPOINT"]["hourly_value"] = -99.0
    assert reference_building()["Schedule:Constant"]["WALLCAL_HEATING_SETPOINT"]["hourly_value"] == 20.0


def test_the_data_file_ships_with_the_package():
    pyproject = (REPO / "pyproject.toml").read_text()
    assert "building/*.epJSON" in pyproject
    assert REFERENCE_BUILDING_FILE.parent.name == "building" and REFERENCE_BUILDING_FILE.is_file()

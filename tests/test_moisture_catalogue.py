"""The hygric catalogue: every required material has thermal and hygric data with sources, and runs."""

import numpy as np
import pytest

from wallcal import materials
from wallcal.errors import StudyError
from wallcal.moisture.materials import hygric_material
from wallcal.moisture.solver import Boundary, Layer, make_grid, solve

REQUIRED = (
    "solid brick",
    "lime plaster",
    "gypsum plasterboard",
    "calcium silicate board",
    "mineral wool",
    "wood fibre board",
    "EPS",
    "XPS",
    "cellulose",
    "aerated concrete",
    "vapour control layer",
    "glass wool",
    "wind barrier",
)


@pytest.mark.parametrize("name", REQUIRED)
def test_required_material_has_sourced_thermal_and_hygric_data(name):
    m = materials.find(name)
    assert m is not None and m.has_hygric
    assert m.source and m.hygric_source
    assert m.density > 0 and m.conductivity > 0 and m.specific_heat > 0
    h = m.hygric_material(0.05)
    w = h.water_content_from_rh(np.array([0.3, 0.8, 0.99]))
    assert np.all(np.diff(w) > 0)


def test_retrofit_catalogue_is_the_same_object():
    from wallcal.retrofitting import materials as rm

    assert rm.catalogue() is materials.catalogue() and rm.find("EPS") is materials.find("eps")


def test_vapour_control_layer_mu_is_sd_over_thickness():
    vcl = materials.find("vapour control layer")
    assert vcl.resistance_factor(0.0002) == pytest.approx(50000.0)
    assert vcl.resistance_factor(0.001) == pytest.approx(10000.0)
    assert vcl.layer_keys(0.0005)["vapour_resistance_factor"] == pytest.approx(20000.0)


def test_every_catalogue_material_runs_in_the_solver():
    """Two days of a board of each material behind a thin layer of the vapour control layer."""
    vcl = materials.find("vapour control layer")
    for name in REQUIRED:
        m = materials.find(name)
        layers = [Layer(m.hygric_material(0.03), 0.03), Layer(vcl.hygric_material(0.0002), 0.0002)]
        grid = make_grid(layers, first=2e-4, ratio=1.3, max_cell=0.005)
        res = solve(
            grid,
            Boundary("air", 0.0, 0.9, h=25.0, beta=2e-7),
            Boundary("air", 20.0, 0.5, h=8.0, beta=3e-8),
            10.0,
            0.6,
            [86400.0, 2 * 86400.0],
            dt_max=3600.0,
        )
        assert np.all(res.mass_balance_error < 1e-6) and np.all(res.energy_balance_error < 1e-6), name
        assert np.all((res.relative_humidity >= 0) & (res.relative_humidity <= 1)), name


def test_hygric_keys_bad_input_is_one_line():
    with pytest.raises(StudyError, match="missing hygric key 'moisture_storage'"):
        hygric_material("x", {"vapour_resistance_factor": 5}, conductivity=1, density=1000, specific_heat=1000)
    with pytest.raises(StudyError, match="vapour_resistance_factor: must be >= 1"):
        hygric_material(
            "x",
            {"vapour_resistance_factor": 0.5, "moisture_storage": {"form": "kuenzel", "w_80": 1, "w_f": 10}},
            conductivity=1,
            density=1000,
            specific_heat=1000,
        )
    with pytest.raises(StudyError, match="not monotone"):
        hygric_material(
            "x",
            {"vapour_resistance_factor": 5, "moisture_storage": {"phi": [0.5, 0.8, 0.9], "w": [1, 3, 2]}},
            conductivity=1,
            density=1000,
            specific_heat=1000,
        )


@pytest.mark.parametrize("value", [10**400, float("nan"), float("inf")])
def test_hygric_table_entry_that_is_no_finite_number_names_its_key(value):
    """An absorption coefficient too large for a float (or nan, inf) is refused under its own key path, not as
    a malformed table."""
    hygric = {
        "vapour_resistance_factor": 5,
        "moisture_storage": {"form": "kuenzel", "w_80": 1, "w_f": 10},
        "liquid_transport": {"form": "kuenzel", "absorption": value},
    }
    with pytest.raises(StudyError) as exc:
        hygric_material("x", hygric, conductivity=1, density=1000, specific_heat=1000)
    assert any(".liquid_transport.absorption: must be finite" in p for p in exc.value.problems), exc.value.problems

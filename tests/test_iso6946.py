"""Tests of wallcal.standards.iso6946.

References: ISO 6946:2017 Table 7 (surface resistances), Table 8 (unventilated air
layers), eq. (6)-(8); the study wall of the calibration paper
(../shared/reference/wall_calibration_paper.md relative to the repository, Tables I and II, design U 0.12).
Expected totals are written out by hand (sums of d / lambda) in each test.
"""

import math

import numpy as np
import pytest

from wallcal.errors import StudyError
from wallcal.standards import iso6946
from wallcal.wall import Layer, Wall


def study_wall(air_material="Air gap, slightly ventilated"):
    """The paper's nine-layer wall: Table I thicknesses, Table II base case for #3..#9."""
    return Wall(
        (
            Layer("1", 0.015, 0.13, 500, 1600, "Wood panel"),
            Layer("2", 0.035, material=air_material),
            Layer("3", 0.10, 0.04, 135, 1030, "High density mineral wool"),
            Layer("4", 0.0125, 0.2, 530, 1600, "LVL panel"),
            Layer("5", 0.04, 0.035, 40, 1030, "Low density mineral wool"),
            Layer("6", 0.0125, 0.2, 530, 1600, "LVL panel"),
            Layer("7", 0.095, 0.035, 40, 1030, "Low density mineral wool"),
            Layer("8", 0.055, 0.035, 40, 1030, "Low density mineral wool"),
            Layer("9", 0.025, 0.21, 900, 1000, "Plasterboard"),
        )
    )


# sum of d / lambda of layers #3..#9 by hand
R_3_TO_9 = 0.10 / 0.04 + 0.0125 / 0.2 + 0.04 / 0.035 + 0.0125 / 0.2 + 0.095 / 0.035 + 0.055 / 0.035 + 0.025 / 0.21
R_WOOD = 0.015 / 0.13


def test_surface_resistances_table_7():
    assert iso6946.surface_resistances("horizontal") == (0.13, 0.04)
    assert iso6946.surface_resistances("upward") == (0.10, 0.04)
    assert iso6946.surface_resistances("downward") == (0.17, 0.04)
    with pytest.raises(StudyError, match="direction"):
        iso6946.surface_resistances("sideways")


@pytest.mark.parametrize(
    ("d_mm", "up", "hor", "down"),
    [  # ISO 6946:2017 Table 8 rows
        (0, 0.00, 0.00, 0.00),
        (5, 0.11, 0.11, 0.11),
        (7, 0.13, 0.13, 0.13),
        (10, 0.15, 0.15, 0.15),
        (15, 0.16, 0.17, 0.17),
        (25, 0.16, 0.18, 0.19),
        (50, 0.16, 0.18, 0.21),
        (100, 0.16, 0.18, 0.22),
        (300, 0.16, 0.18, 0.23),
    ],
)
def test_table_8_nodes(d_mm, up, hor, down):
    d = d_mm / 1000
    assert iso6946.unventilated_air_layer_resistance(d, "upward") == pytest.approx(up)
    assert iso6946.unventilated_air_layer_resistance(d, "horizontal") == pytest.approx(hor)
    assert iso6946.unventilated_air_layer_resistance(d, "downward") == pytest.approx(down)


def test_table_8_interpolation_and_limits():
    # linear interpolation between rows (allowed by the standard)
    assert iso6946.unventilated_air_layer_resistance(0.0125, "horizontal") == pytest.approx(0.16)
    assert iso6946.unventilated_air_layer_resistance(0.075, "downward") == pytest.approx(0.215)
    assert iso6946.unventilated_air_layer_resistance(0.035, "horizontal") == pytest.approx(0.18)
    with pytest.raises(StudyError, match="thickness_m"):
        iso6946.unventilated_air_layer_resistance(0.35)
    assert iso6946.air_layer_resistance(0.035, "slightly") == pytest.approx(0.09)
    assert iso6946.air_layer_resistance(0.035, "well_ventilated") == 0.0
    with pytest.raises(StudyError, match="ventilation"):
        iso6946.air_layer_resistance(0.035, "breezy")


def test_single_layer_hand_calculation():
    wall = Wall((Layer("a", 0.2, 0.04, 30, 1000),))
    res = iso6946.thermal_resistance(wall)
    assert res.resistance == pytest.approx(5.0)
    assert res.u_value == pytest.approx(1 / (0.13 + 5.0 + 0.04))
    assert iso6946.u_value(wall, direction="upward") == pytest.approx(1 / (0.10 + 5.0 + 0.04))


def test_study_wall_is_about_the_design_u_value():
    res = iso6946.thermal_resistance(study_wall())
    # half of 0.18 for the air gap; wood panel + Rse = 0.1554 > 0.15 capped to 0.15
    expected_rt = 0.13 + R_3_TO_9 + 0.09 + 0.15
    assert res.total_resistance == pytest.approx(expected_rt, rel=1e-12)
    assert res.u_value == pytest.approx(0.1171, abs=1e-4)
    assert abs(res.u_value - 0.12) < 0.005  # the paper's design U is 0.12 W/(m2K)
    assert any("capped" in n for n in res.notes)


def test_study_wall_explicit_argument_equals_material_detection():
    by_text = iso6946.thermal_resistance(study_wall())
    by_arg = iso6946.thermal_resistance(study_wall("Air gap"), air_layers={"2": "slightly_ventilated"})
    assert by_arg.u_value == pytest.approx(by_text.u_value, rel=1e-14)


def test_air_layer_without_ventilation_needs_the_argument():
    with pytest.raises(StudyError, match=r"air_layers=\{'2'"):
        iso6946.thermal_resistance(study_wall("Air gap"))
    with pytest.raises(StudyError, match="no layer with this id"):
        iso6946.thermal_resistance(study_wall(), air_layers={"12": "slightly"})


def test_unventilated_and_well_ventilated():
    un = iso6946.thermal_resistance(study_wall(), air_layers={"2": "unventilated"})
    assert un.total_resistance == pytest.approx(0.13 + R_3_TO_9 + 0.18 + R_WOOD + 0.04, rel=1e-12)
    well = iso6946.thermal_resistance(study_wall(), air_layers={"2": "well"})
    # layers 1, 2 ignored, Rse = Rsi = 0.13
    assert well.total_resistance == pytest.approx(0.13 + R_3_TO_9 + 0.13, rel=1e-12)
    assert well.rse == 0.13
    assert [b.kind for b in well.layers[:2]] == ["ignored", "ignored"]


def test_opening_area_interpolation_iso6946_2017():
    un = iso6946.thermal_resistance(study_wall(), air_layers={"2": "unventilated"}).total_resistance
    well = iso6946.thermal_resistance(study_wall(), air_layers={"2": "well"}).total_resistance
    for av, expected in (
        (500, un),
        (1000, 0.5 * un + 0.5 * well),
        (1500, well),
        (1200, 0.3 * un + 0.7 * well),
    ):
        got = iso6946.thermal_resistance(study_wall(), opening_area_mm2_per_m=av).total_resistance
        assert got == pytest.approx(expected, rel=1e-12), av
    assert iso6946.thermal_resistance(study_wall(), opening_area_mm2_per_m=1000).u_value == pytest.approx(
        0.1172, abs=1e-4
    )


def test_air_layers_empty_dict_disables_detection():
    wall = Wall((Layer("a", 0.1, 0.04, 30, 1000), Layer("gap", 0.02, thermal_resistance=0.3, material="air")))
    res = iso6946.thermal_resistance(wall, air_layers={})
    assert res.resistance == pytest.approx(2.5 + 0.3)


def test_contact_resistance_and_temperature():
    wall = Wall(
        (
            Layer("a", 0.1, 0.04, 30, 1000, contact_resistance=0.05, conductivity_temperature_coefficient=0.0046),
            Layer("b", 0.02, 0.2, 500, 1600),
        )
    )
    res = iso6946.thermal_resistance(wall)
    assert res.resistance == pytest.approx(2.5 + 0.05 + 0.1)
    import math

    hot = iso6946.thermal_resistance(wall, mean_temperature_C=23.65)
    assert hot.resistance == pytest.approx(0.1 / (0.04 * math.exp(0.0046 * 13.65)) + 0.05 + 0.1)


def test_resolve_layers_for_iso13786():
    layers, cut = iso6946.resolve_layers(study_wall())
    assert not cut and len(layers) == 9
    assert layers[1].is_massless and layers[1].thermal_resistance == pytest.approx(0.09)
    layers, cut = iso6946.resolve_layers(study_wall(), air_layers={"2": "well"})
    assert cut and [layer.id for layer in layers] == ["3", "4", "5", "6", "7", "8", "9"]


# ---------------------------------------------------------------------------- air-layer detection and breakdown
@pytest.mark.parametrize(
    "material,expected",
    [
        ("Air gap, well-ventilated", "well_ventilated"),
        ("air gap, well_ventilated", "well_ventilated"),
        ("AIR LAYER (Slightly-Ventilated)", "slightly_ventilated"),
        ("air cavity, slightly_ventilated", "slightly_ventilated"),
        ("unventilated air space", "unventilated"),
        ("air space, not ventilated", "unventilated"),
        ("still air", "unventilated"),
    ],
)
def test_ventilation_read_from_the_material_text(material, expected):
    wall = Wall((Layer("a", 0.1, 0.04, 30, 1000, "wool"), Layer("gap", 0.03, material=material)))
    assert iso6946.find_air_layers(wall) == {"gap": expected}


def test_air_layer_problems_are_all_reported():
    wall = Wall(
        (
            Layer("a", 0.1, 0.04, 30, 1000, "wool"),
            Layer("gap", 0.4, material="air, unventilated"),  # too thick for Table 8
            Layer("b", 0.02, 0.2, 500, 1600, "panel"),
        )
    )
    with pytest.raises(StudyError) as exc:
        iso6946.find_air_layers(wall)
    assert exc.value.problems == [
        "air_layers['gap']: an ISO 6946 air layer must be > 0 and <= 0.3 m thick, got thickness 0.4 m"
    ]
    with pytest.raises(StudyError) as exc:
        iso6946.find_air_layers(wall, {"gp": "slightly", "b": "sometimes"})
    text = "\n".join(exc.value.problems)
    assert "air_layers['gp']: no layer with this id; did you mean 'gap'" in text
    assert "air_layers['b']: unknown ventilation 'sometimes'" in text


@pytest.mark.parametrize(
    "alias,canonical",
    [
        ("un", "unventilated"),
        ("none", "unventilated"),
        ("Slightly", "slightly_ventilated"),
        ("well-ventilated", "well_ventilated"),
        ("well ventilated", "well_ventilated"),
    ],
)
def test_ventilation_aliases(alias, canonical):
    assert iso6946.normalize_ventilation(alias) == canonical


def test_air_layer_resistance_by_direction_table_8():
    # 50 mm: 0.16 upward, 0.18 horizontal, 0.21 downward (ISO 6946:2017 Table 8); slightly ventilated: half
    assert iso6946.air_layer_resistance(0.05, "unventilated", "upward") == pytest.approx(0.16)
    assert iso6946.air_layer_resistance(0.05, "unventilated", "downward") == pytest.approx(0.21)
    assert iso6946.air_layer_resistance(0.05) == pytest.approx(0.18)
    assert iso6946.air_layer_resistance(0.05, "slightly", "downward") == pytest.approx(0.105)
    assert iso6946.air_layer_resistance(0.05, "well", "downward") == 0.0
    with pytest.raises(StudyError, match="unknown heat-flow direction 'sideways'"):
        iso6946.surface_resistances("sideways")


def test_breakdown_kinds_and_direction():
    wall = Wall(
        (
            Layer("a", 0.1, 0.04, 30, 1000, "wool", contact_resistance=0.05),
            Layer("gap", 0.05, material="air, unventilated"),
            Layer("m", 0.0, thermal_resistance=0.2, material="membrane"),
            Layer("b", 0.02, 0.2, 500, 1600, "panel"),
        )
    )
    res = iso6946.thermal_resistance(wall, direction="downward")
    assert [(b.id, b.kind) for b in res.layers] == [
        ("a", "material"),
        ("a/contact", "contact"),
        ("gap", "air:unventilated"),
        ("m", "no-mass"),
        ("b", "material"),
    ]
    assert [b.resistance for b in res.layers] == pytest.approx([2.5, 0.05, 0.21, 0.2, 0.1])
    assert (res.rsi, res.rse) == (0.17, 0.04)  # downward heat flow: Rsi 0.17
    assert res.total_resistance == pytest.approx(0.17 + 2.5 + 0.05 + 0.21 + 0.2 + 0.1 + 0.04)
    assert res.u_value == pytest.approx(1 / res.total_resistance)
    hot = iso6946.thermal_resistance(wall, mean_temperature_C=10.0)
    assert [b.kind for b in hot.layers][0] == "material" and hot.layers[3].kind == "no-mass"
    # explicit surface resistances override the table
    res2 = iso6946.thermal_resistance(wall, rsi=0.2, rse=0.1)
    assert (res2.rsi, res2.rse) == (0.2, 0.1)
    assert iso6946.u_value(wall, rsi=0.2, rse=0.1) == pytest.approx(res2.u_value)


def _slight_wall(panel=0.015, contact=0.0):
    return Wall(
        (
            Layer("p", panel, 0.13, 500, 1600, "panel", contact_resistance=contact),
            Layer("gap", 0.035, material="air, slightly ventilated"),
            Layer("w", 0.1, 0.04, 135, 1030, "wool"),
        )
    )


def test_slightly_ventilated_half_rule_and_cap_by_hand():
    # panel 0.015 / 0.13 = 0.11538; with Rse 0.04 that is 0.15538 > 0.15: scaled to 0.15 - 0.04 = 0.11
    # gap 35 mm: Table 8 horizontal 0.18 (25..50 mm), half = 0.09; wool 2.5 -> R = 2.7, R_T = 2.87
    res = iso6946.thermal_resistance(_slight_wall())
    assert [(b.id, b.kind) for b in res.layers] == [
        ("p", "material(capped)"),
        ("gap", "air:slightly_ventilated"),
        ("w", "material"),
    ]
    assert [b.resistance for b in res.layers] == pytest.approx([0.11, 0.09, 2.5], rel=1e-12)
    assert res.total_resistance == pytest.approx(2.87, rel=1e-12)
    assert any("capped at 0.15" in n for n in res.notes) and any("half the Table 8" in n for n in res.notes)
    # a thinner panel (0.0769 + 0.04 < 0.15) is not capped
    thin = iso6946.thermal_resistance(_slight_wall(panel=0.01))
    assert thin.layers[0].kind == "material" and thin.layers[0].resistance == pytest.approx(0.01 / 0.13)
    assert not any("capped" in n for n in thin.notes)
    # a contact resistance outside the air layer is capped with the panel: 0.11538 + 0.02 -> scaled to 0.11
    c = iso6946.thermal_resistance(_slight_wall(contact=0.02))
    assert c.layers[0].resistance + c.layers[1].resistance == pytest.approx(0.11, rel=1e-12)
    assert c.layers[1].kind == "contact(capped)"
    with pytest.raises(StudyError, match="exceeds the 0.15 m2K/W cap"):
        iso6946.thermal_resistance(_slight_wall(), rse=0.2)


def test_opening_area_limits_and_errors():
    un = iso6946.thermal_resistance(_slight_wall(), air_layers={"gap": "unventilated"})
    well = iso6946.thermal_resistance(_slight_wall(), air_layers={"gap": "well"})
    assert iso6946.thermal_resistance(_slight_wall(), opening_area_mm2_per_m=400).total_resistance == pytest.approx(
        un.total_resistance
    )
    assert iso6946.thermal_resistance(_slight_wall(), opening_area_mm2_per_m=1600).total_resistance == pytest.approx(
        well.total_resistance
    )
    mid = iso6946.thermal_resistance(_slight_wall(), opening_area_mm2_per_m=750)
    assert mid.total_resistance == pytest.approx(0.75 * un.total_resistance + 0.25 * well.total_resistance)
    assert mid.resistance == pytest.approx(mid.total_resistance - 0.13 - 0.04)
    assert "A_v = 750 mm2/m" in mid.notes[0]
    with pytest.raises(StudyError, match="exactly one slightly ventilated air layer, found 0"):
        iso6946.thermal_resistance(_slight_wall(), air_layers={"gap": "unventilated"}, opening_area_mm2_per_m=900)
    with pytest.raises(StudyError, match="surface resistances must be >= 0"):
        iso6946.thermal_resistance(_slight_wall(), rsi=-0.1)


def test_resolve_layers_direction_and_slight_ventilation():
    layers, cut = iso6946.resolve_layers(_slight_wall(), direction="downward")
    assert not cut and layers[1].is_massless
    # 35 mm downward: Table 8 interpolated between 25 mm (0.19) and 50 mm (0.21) = 0.198, halved = 0.099
    assert layers[1].thermal_resistance == pytest.approx(0.099, rel=1e-12)
    assert layers[1].conductivity is None and layers[1].density is None and layers[1].specific_heat is None
    assert layers[0] == _slight_wall().layers[0] and layers[2] == _slight_wall().layers[2]


def test_opening_area_interpolation_passes_every_option_on():
    wall = _slight_wall().replace_layer("w", conductivity_temperature_coefficient=0.004)
    kw = {"direction": "downward", "rsi": 0.2, "rse": 0.06, "mean_temperature_C": 25.0}
    un = iso6946.thermal_resistance(wall, air_layers={"gap": "unventilated"}, **kw)
    well = iso6946.thermal_resistance(wall, air_layers={"gap": "well"}, **kw)
    # by hand: wool at 25 degC: 0.1 / (0.04 exp(0.004 x 15)); the gap downward 0.198; Rsi 0.2, Rse 0.06
    r_wool = 0.1 / (0.04 * math.exp(0.004 * 15.0))
    assert un.total_resistance == pytest.approx(0.2 + 0.015 / 0.13 + 0.198 + r_wool + 0.06, rel=1e-12)
    assert well.total_resistance == pytest.approx(0.2 + r_wool + 0.2, rel=1e-12)
    mid = iso6946.thermal_resistance(wall, opening_area_mm2_per_m=1000, **kw)
    assert mid.total_resistance == pytest.approx(0.5 * (un.total_resistance + well.total_resistance), rel=1e-12)
    assert (mid.rsi, mid.rse) == (0.2, 0.06) and mid.layers == un.layers
    assert mid.u_value == pytest.approx(1 / mid.total_resistance)
    # the limits of the interpolation, with the same options
    at500 = iso6946.thermal_resistance(wall, opening_area_mm2_per_m=500, **kw).total_resistance
    assert at500 == pytest.approx(un.total_resistance, rel=1e-12)
    just_above = iso6946.thermal_resistance(wall, opening_area_mm2_per_m=500.5, **kw).total_resistance
    assert just_above == pytest.approx(0.9995 * un.total_resistance + 0.0005 * well.total_resistance, rel=1e-12)
    assert just_above != at500
    at1500 = iso6946.thermal_resistance(wall, opening_area_mm2_per_m=1500, **kw).total_resistance
    beyond = iso6946.thermal_resistance(wall, opening_area_mm2_per_m=1600, **kw)
    assert at1500 == pytest.approx(well.total_resistance, rel=1e-12)
    assert beyond.total_resistance == pytest.approx(well.total_resistance, rel=1e-12) and beyond.rse == 0.2


def test_two_slightly_ventilated_layers_are_refused():
    wall = Wall(
        (
            Layer("g1", 0.02, material="air, slightly ventilated"),
            Layer("a", 0.1, 0.04, 30, 1000, "wool"),
            Layer("g2", 0.02, material="air, slightly ventilated"),
            Layer("b", 0.02, 0.2, 500, 1600, "panel"),
        )
    )
    with pytest.raises(StudyError, match="air_layers: 2 slightly ventilated air layers; ISO 6946 treats one"):
        iso6946.thermal_resistance(wall)
    # zero surface resistances are allowed (a surface-to-surface figure), negative ones are not
    res = iso6946.thermal_resistance(_slight_wall(panel=0.01), rsi=0.0, rse=0.0)
    assert res.total_resistance == pytest.approx(res.resistance)


# ---------------------------------------------------------------------------- each rule at its documented edge
def test_table_8_function_takes_0_to_0_3_m_and_refuses_the_rest_naming_the_value():
    assert iso6946.unventilated_air_layer_resistance(0.3) == pytest.approx(0.18)  # the table's last row
    assert iso6946.unventilated_air_layer_resistance(0.0) == 0.0
    for bad in (0.3005, -0.001, float("nan")):  # just over 300 mm, negative, not a number
        with pytest.raises(StudyError) as exc:
            iso6946.unventilated_air_layer_resistance(bad)
        assert exc.value.problems == [f"thickness_m: an ISO 6946 air layer must be 0 to 0.3 m thick, got {bad!r}"]


def test_table_8_function_returns_a_float_for_a_number_and_an_array_for_an_array():
    r = iso6946.unventilated_air_layer_resistance(0.05)
    assert type(r) is float and r == pytest.approx(0.18)  # a plain float prints as 0.18 in reports
    arr = iso6946.unventilated_air_layer_resistance([0.005, 0.05], "downward")
    assert isinstance(arr, np.ndarray) and arr == pytest.approx([0.11, 0.21])
    one = iso6946.unventilated_air_layer_resistance([0.05])
    assert isinstance(one, np.ndarray) and one.shape == (1,) and one[0] == pytest.approx(0.18)


def test_default_arguments_are_the_documented_ones():
    assert iso6946.surface_resistances() == (0.13, 0.04)  # horizontal heat flow: a wall
    assert iso6946.air_layer_resistance(0.05) == pytest.approx(0.18)  # unventilated, horizontal
    with pytest.raises(StudyError) as exc:
        iso6946.normalize_ventilation("wel")
    assert exc.value.problems == ["ventilation: unknown ventilation 'wel'; did you mean 'well'?"]


def _gap_wall(d):
    return Wall((Layer("a", 0.1, 0.04, 30, 1000, "wool"), Layer("gap", d, material="air, unventilated")))


def test_air_layer_of_a_wall_is_more_than_0_and_at_most_0_3_m_thick():
    assert iso6946.find_air_layers(_gap_wall(0.3)) == {"gap": "unventilated"}
    assert iso6946.thermal_resistance(_gap_wall(0.3)).layers[1].resistance == pytest.approx(0.18)
    with pytest.raises(StudyError) as exc:
        iso6946.find_air_layers(_gap_wall(0.0))
    assert exc.value.problems == [
        "air_layers['gap']: an ISO 6946 air layer must be > 0 and <= 0.3 m thick, got thickness 0.0 m"
    ]


def test_air_layer_without_ventilation_message_names_every_way_out():
    with pytest.raises(StudyError) as exc:
        iso6946.find_air_layers(study_wall("Air gap"))
    assert exc.value.problems == [
        "wall.layers['2']: material 'Air gap' looks like an air layer but does not say its ventilation; pass "
        "air_layers={'2': 'unventilated' | 'slightly_ventilated' | 'well_ventilated'} "
        "(or air_layers={} to treat it as an ordinary layer)"
    ]


def test_a_contact_resistance_on_the_last_layer_is_outside_the_wall():
    wall = Wall((Layer("a", 0.1, 0.04, 30, 1000), Layer("b", 0.02, 0.2, 500, 1600, contact_resistance=0.3)))
    res = iso6946.thermal_resistance(wall)
    assert [b.id for b in res.layers] == ["a", "b"]
    assert res.resistance == pytest.approx(2.5 + 0.1)


def test_notes_and_ignored_layers_name_the_air_layer():
    well = iso6946.thermal_resistance(study_wall(), air_layers={"2": "well"})
    assert [(b.id, b.kind, b.resistance) for b in well.layers[:2]] == [("1", "ignored", 0.0), ("2", "ignored", 0.0)]
    assert well.notes == (
        "well ventilated air layer '2': it and the layers outside it ignored, Rse = Rsi = 0.13 m2K/W",
    )
    thin = iso6946.thermal_resistance(_slight_wall(panel=0.01))
    assert thin.notes == ("slightly ventilated air layer 'gap': half the Table 8 value (ISO 6946:1996 5.3.3 rule)",)


def _membrane_slight_wall(r_membrane):
    return Wall(
        (
            Layer("m", 0.0, thermal_resistance=r_membrane, material="membrane"),
            Layer("gap", 0.035, material="air, slightly ventilated"),
            Layer("w", 0.1, 0.04, 135, 1030, "wool"),
        )
    )


def test_slightly_ventilated_cap_applies_above_0_15_only():
    # layers outside + Rse = 0.15 + 0 exactly: at the cap, nothing is scaled
    at = iso6946.thermal_resistance(_membrane_slight_wall(0.15), rse=0.0)
    assert [b.kind for b in at.layers] == ["no-mass", "air:slightly_ventilated", "material"]
    assert at.layers[0].resistance == 0.15 and not any("capped" in n for n in at.notes)
    # Rse = 0.15 itself is allowed: the layers outside are scaled to nothing
    full = iso6946.thermal_resistance(_slight_wall(), rse=0.15)
    assert (full.layers[0].kind, full.layers[0].resistance) == ("material(capped)", 0.0)
    assert full.total_resistance == pytest.approx(0.13 + 0.09 + 2.5 + 0.15, rel=1e-12)
    # an air layer with nothing outside it and an Rse over the cap
    bare = Wall((Layer("gap", 0.035, material="air, slightly ventilated"), Layer("w", 0.1, 0.04, 135, 1030, "wool")))
    with pytest.raises(StudyError, match=r"rse: 0.2 m2K/W exceeds the 0.15 m2K/W cap"):
        iso6946.thermal_resistance(bare, rse=0.2)


def test_opening_area_bounds_follow_iso_6946_2017():
    # A_v <= 500: unventilated (no interpolation); 500 < A_v <= 1500: interpolated; > 1500: well ventilated
    at500 = iso6946.thermal_resistance(_slight_wall(), opening_area_mm2_per_m=500)
    assert at500.notes == () and at500.layers[1].kind == "air:unventilated"
    at1500 = iso6946.thermal_resistance(_slight_wall(), opening_area_mm2_per_m=1500)
    assert "interpolation with A_v = 1500 mm2/m" in at1500.notes[0] and at1500.rse == 0.04
    well = iso6946.thermal_resistance(_slight_wall(), air_layers={"gap": "well"})
    over = iso6946.thermal_resistance(_slight_wall(), opening_area_mm2_per_m=1500.5)
    assert over.total_resistance == pytest.approx(well.total_resistance, rel=1e-12)
    assert over.notes[0].startswith("well ventilated air layer 'gap'")


def test_opening_area_interpolation_keeps_the_direction_for_another_air_layer():
    wall = Wall(
        (
            Layer("p", 0.015, 0.13, 500, 1600, "panel"),
            Layer("g1", 0.035, material="air, slightly ventilated"),
            Layer("w", 0.1, 0.04, 135, 1030, "wool"),
            Layer("g2", 0.05, material="air, unventilated"),
            Layer("b", 0.0125, 0.2, 530, 1600, "board"),
        )
    )
    # by hand, downward heat flow: Rsi 0.17, Table 8 at 35 mm 0.198 and at 50 mm 0.21
    r_u = 0.17 + 0.015 / 0.13 + 0.198 + 2.5 + 0.21 + 0.0625 + 0.04
    r_v = 0.17 + 2.5 + 0.21 + 0.0625 + 0.17  # outside g1 ignored, Rse = Rsi
    mid = iso6946.thermal_resistance(wall, opening_area_mm2_per_m=1000, direction="downward")
    assert mid.total_resistance == pytest.approx(0.5 * (r_u + r_v), rel=1e-12)


def test_resolve_layers_drops_the_declared_properties_of_an_air_layer():
    wall = Wall((Layer("gap", 0.035, 0.025, 1.2, 1000, "air, unventilated"), Layer("w", 0.1, 0.04, 135, 1030)))
    layers, cut = iso6946.resolve_layers(wall)
    assert cut is False
    gap = layers[0]
    assert gap.is_massless and gap.thermal_resistance == pytest.approx(0.18)
    assert (gap.conductivity, gap.density, gap.specific_heat) == (None, None, None)

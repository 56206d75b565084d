"""Calibration objectives (wallcal.calibration.objective) against hand computations.

First on small arrays written out by hand (the same functions the Evaluator calls), then through the Evaluator on
the example study, against sums formed here from `wallcal.simulate` (the user's path, not the batch engine).
"""

from __future__ import annotations

import copy
import dataclasses
import math
import types

import numpy as np
import pytest

from wallcal.calibration import parse_space
from wallcal.calibration.objective import Evaluator, accuracy_scale, objective_value, residual_weights

# two candidates, two targets: CSE [unit^2], valid samples, weights, accuracies
CSE = np.array([[2.0, 16.0], [8.0, 0.0]])
N_VALID = np.array([2, 4])
WEIGHTS = [1.0, 3.0]
SCALE = [0.5, 2.0]
# RMSE = sqrt(CSE / n): candidate 0: [1, 2]; candidate 1: [2, 0]


@pytest.mark.parametrize(
    "kind,expected",
    [
        ("cse", [2 + 16, 8 + 0]),
        ("weighted_cse", [1 * 2 + 3 * 16, 1 * 8 + 3 * 0]),  # 50, 8
        ("weighted_rmse", [1 * 1 + 3 * 2, 1 * 2 + 3 * 0]),  # 7, 2
        ("rmse_accuracy", [1 / 0.5 + 2 / 2.0, 2 / 0.5 + 0 / 2.0]),  # 3, 4
    ],
)
def test_objective_by_hand(kind, expected):
    got = objective_value(kind, CSE, N_VALID, WEIGHTS, SCALE)
    assert got.shape == (2,)
    np.testing.assert_allclose(got, expected, rtol=1e-15)


@pytest.mark.parametrize(
    "kind,expected",
    [
        ("cse", [1.0, 1.0]),
        ("weighted_cse", [1.0, 3.0]),
        ("weighted_rmse", [1.0 / 2, 3.0 / 4]),  # w / n: sum w e^2 / n = sum w RMSE^2
        ("rmse_accuracy", [1.0 / (0.25 * 2), 1.0 / (4.0 * 4)]),  # 1 / (acc^2 n): sum (RMSE / acc)^2
    ],
)
def test_residual_weights_by_hand(kind, expected):
    w = residual_weights(kind, N_VALID, WEIGHTS, SCALE)
    np.testing.assert_allclose(w, expected, rtol=1e-15)
    # and the sum of squared residuals they give, for candidate 0 (RMSE 1 and 2)
    ssr = float((w * CSE[0]).sum())
    by_hand = {"cse": 18.0, "weighted_cse": 50.0, "weighted_rmse": 1 + 3 * 4, "rmse_accuracy": 4 + 1}[kind]
    assert ssr == pytest.approx(by_hand, rel=1e-15)


def test_accuracy_scale_by_hand():
    assert accuracy_scale(0.5, None, np.array([1.0, 2.0])) == 0.5
    assert accuracy_scale(0.5, 0.1, np.array([1.0, 2.0])) == 0.5  # the absolute accuracy wins
    # relative: 0.03 x sqrt((3^2 + 4^2) / 2) = 0.03 x 3.5355
    assert accuracy_scale(None, 0.03, np.array([3.0, -4.0])) == pytest.approx(0.03 * math.sqrt(12.5), rel=1e-15)


# ---------------------------------------------------------------------------- through the Evaluator
TARGETS = ["T3A", "T1A", "qi"]
WEIGHT = {"T3A": 2.0, "T1A": 0.5, "qi": 1.5}


@pytest.fixture(scope="module")
def weighted_study(example_study):
    sensors = tuple(dataclasses.replace(s, weight=WEIGHT.get(s.name, 1.0)) for s in example_study.sensors)
    study = dataclasses.replace(example_study, sensors=sensors)
    from wallcal import simulate

    res = simulate(study)
    return study, res


@pytest.mark.parametrize("kind", ["cse", "weighted_cse", "weighted_rmse", "rmse_accuracy"])
def test_evaluator_objective_matches_a_hand_sum_over_the_simulated_series(weighted_study, kind):
    study, res = weighted_study
    cal = copy.deepcopy(study.raw["calibration"])
    cal["targets"] = TARGETS
    cal["objective"] = kind
    space = parse_space(study, cal)
    from wallcal.simulation import prepare

    ev = Evaluator(prepare(study), space)
    got = float(ev.objective(space.base[None])[0])
    terms = []
    for t in TARGETS:
        y, s = res.measured[t].to_numpy(), res.simulated[t].to_numpy()
        ok = np.isfinite(y)
        e = s[ok] - y[ok]
        cse, rmse = float(np.sum(e**2)), float(np.sqrt(np.mean(e**2)))
        sensor = study.sensor(t)
        acc = (
            sensor.accuracy if sensor.accuracy is not None else sensor.accuracy_relative * np.sqrt(np.mean(y[ok] ** 2))
        )
        terms.append(
            {
                "cse": cse,
                "weighted_cse": WEIGHT[t] * cse,
                "weighted_rmse": WEIGHT[t] * rmse,
                "rmse_accuracy": rmse / acc,
            }[kind]
        )
    # the batch engine and the user's simulate() agree to round-off on the same grid
    assert got == pytest.approx(sum(terms), rel=1e-8)
    # per target: CSE and RMSE (what the sensitivity analysis ranks)
    cse_t, rmse_t = ev.per_target(space.base[None])
    for k, t in enumerate(TARGETS):
        e = (res.simulated[t] - res.measured[t]).dropna().to_numpy()
        assert cse_t[0, k] == pytest.approx(np.sum(e**2), rel=1e-8)
        assert rmse_t[0, k] == pytest.approx(np.sqrt(np.mean(e**2)), rel=1e-8)
    # the least-squares residuals: sum(r^2) is the objective (squared-error kinds) or its smooth surrogate
    r = ev.residuals(space.base[None])
    ssr = float((r**2).sum())
    if kind in ("cse", "weighted_cse"):
        assert ssr == pytest.approx(got, rel=1e-9)
    else:
        rm = [np.sqrt(np.mean((res.simulated[t] - res.measured[t]).dropna() ** 2)) for t in TARGETS]
        w = [WEIGHT[t] * rm[i] ** 2 if kind == "weighted_rmse" else (terms[i]) ** 2 for i, t in enumerate(TARGETS)]
        assert ssr == pytest.approx(sum(w), rel=1e-8)


def test_objective_and_residuals_from_one_run(weighted_study):
    study, _ = weighted_study
    cal = copy.deepcopy(study.raw["calibration"])
    cal["targets"], cal["objective"] = TARGETS, "weighted_rmse"
    space = parse_space(study, cal)
    from wallcal.simulation import prepare

    ev = Evaluator(prepare(study), space)
    X = np.stack([space.base, space.base * 1.05])
    f, R = ev.objective_and_residuals(X)
    np.testing.assert_allclose(f, ev.objective(X), rtol=1e-12)
    np.testing.assert_allclose(R, ev.residuals(X), rtol=1e-12)
    assert f.shape == (2,) and R.shape == (2, len(TARGETS) * ev.y.shape[1])
    assert ev.evaluations == 2 * 3 and ev.seconds > 0  # candidates simulated so far, and their time


def test_evaluator_probe_depth_parameter_equals_simulate(example_study):
    from wallcal import simulate
    from wallcal.simulation import prepare

    cal = copy.deepcopy(example_study.raw["calibration"])
    cal["parameters"] = [{"probe": "T3A", "property": "depth", "bounds": [0.095, 0.105], "bounds_kind": "absolute"}]
    space = parse_space(example_study, cal)
    ev = Evaluator(prepare(example_study), space)
    x = np.array([0.098])
    got = float(ev.objective(x[None])[0])
    res = simulate(example_study.replace(wall=space.wall_at(example_study.wall, x)))
    cse = sum(float(((res.simulated[t] - res.measured[t]) ** 2).sum()) for t in space.targets)
    assert got == pytest.approx(cse, rel=1e-6)
    assert abs(got - float(ev.objective(np.array([[0.1]]))[0])) > 1e-3 * got


def test_evaluator_candidates_with_lambda_t_and_contact_parameters_equal_simulate(example_study):
    """Parameters that change the grid or the conductivity law (a lambda(T) coefficient, a contact resistance
    whose base value is 0): the Evaluator's candidate equals `simulate` of the candidate wall."""
    from wallcal import simulate
    from wallcal.simulation import prepare

    cal = copy.deepcopy(example_study.raw["calibration"])
    cal["parameters"] = [
        {
            "layers": ["3"],
            "property": "conductivity_temperature_coefficient",
            "bounds": [0.0, 0.01],
            "bounds_kind": "absolute",
        },
        {"layers": ["4"], "property": "contact_resistance", "bounds": [0.0, 0.2], "bounds_kind": "absolute"},
    ]
    space = parse_space(example_study, cal)
    ev = Evaluator(prepare(example_study), space)
    x = np.array([0.006, 0.1])
    got = float(ev.objective(x[None])[0])
    res = simulate(example_study.replace(wall=space.wall_at(example_study.wall, x)))
    cse = sum(float(((res.simulated[t] - res.measured[t]) ** 2).sum()) for t in space.targets)
    assert got == pytest.approx(cse, rel=1e-6)
    # and the candidate really differs from the base case
    assert abs(got - float(ev.objective(np.zeros((1, 2)))[0])) > 1e-3 * got


def test_evaluator_sensor_offset_is_added_to_the_measured_signal(example_study):
    """An ``offset`` parameter (sensor = NAME) corrects that target's measured signal: error = simulated -
    (measured + offset), on that target only; by hand from `simulate` and the measured series."""
    from wallcal import simulate
    from wallcal.simulation import prepare

    cal = copy.deepcopy(example_study.raw["calibration"])
    target = cal["targets"][1]  # not the first: the offset must land on its own target's row
    cal["parameters"] = [{"sensor": target, "property": "offset", "bounds": [-1.0, 1.0]}]
    space = parse_space(example_study, cal)
    ev = Evaluator(prepare(example_study), space)
    X = np.array([[0.0], [0.3], [-0.2]])  # offset [K]
    got = ev.objective(X)
    np.testing.assert_array_equal(space.offsets(X)[:, space.targets.index(target)], X[:, 0])
    assert np.count_nonzero(space.offsets(X)) == 2
    res = simulate(example_study)
    for (x,), g in zip(X, got, strict=True):
        cse = 0.0
        for t in space.targets:
            shift = x if t == target else 0.0
            cse += float(((res.simulated[t] - (res.measured[t] + shift)) ** 2).sum())
        assert g == pytest.approx(cse, rel=1e-9)
    assert abs(got[1] - got[0]) > 1e-3 * got[0]  # the offset moves the objective
    assert ev.objective(np.array([[-0.3]]))[0] != pytest.approx(got[1], rel=1e-6)  # and not as its negative


def test_missing_samples_are_left_out_of_every_sum(weighted_study):
    """Samples missing in the data (NaN) count in no sum: the CSE and RMSE over the valid samples only."""
    study, res = weighted_study
    from wallcal.simulation import prepare

    cal = copy.deepcopy(study.raw["calibration"])
    cal["targets"], cal["objective"] = TARGETS, "cse"
    space = parse_space(study, cal)
    base = prepare(study)
    measured = base.measured.copy()
    gaps = {"T3A": slice(100, 400), "qi": slice(0, 50)}
    for t, sl in gaps.items():
        measured.iloc[sl, measured.columns.get_loc(t)] = np.nan
    ev = Evaluator(dataclasses.replace(base, measured=measured), space)
    cse_t, rmse_t = ev.per_target(space.base[None])
    for k, t in enumerate(TARGETS):
        y = measured[t].to_numpy()
        ok = np.isfinite(y)
        assert ok.sum() < len(y) or t not in gaps
        e = res.simulated[t].to_numpy()[ok] - y[ok]
        assert cse_t[0, k] == pytest.approx(np.sum(e**2), rel=1e-8)
        assert rmse_t[0, k] == pytest.approx(np.sqrt(np.mean(e**2)), rel=1e-8)
    assert list(ev.n_valid) == [int(np.isfinite(measured[t]).sum()) for t in TARGETS]
    r = ev.residuals(space.base[None])
    assert float((r**2).sum()) == pytest.approx(float(cse_t.sum()), rel=1e-9)


def test_evaluator_asks_the_engine_for_its_targets_only(example_study):
    """The engine input of a calibration carries the target probes and faces only (no work for the others)."""
    from wallcal.simulation import prepare

    cal = copy.deepcopy(example_study.raw["calibration"])
    cal["targets"] = ["T2A", "qi"]
    ev = Evaluator(prepare(example_study), parse_space(example_study, cal))
    assert ev.inp.probes == ("T2A",)
    assert ev.inp.flux_faces == ("interior",)
    assert ev.inp.flux_depths == ()
    assert ev.keys == [("temperatures", "T2A"), ("fluxes", "interior")]


def test_evaluator_time_is_the_sum_over_calls(example_study, monkeypatch):
    """``seconds`` adds up the time of every simulate() call (a clock that ticks 1 s per reading)."""
    from wallcal.calibration import objective
    from wallcal.simulation import prepare

    space = parse_space(example_study)
    ev = Evaluator(prepare(example_study), space)
    assert ev.seconds == 0.0 and ev.evaluations == 0
    ticks = iter(range(100, 200, 3))  # each call reads the clock twice, 3 s apart
    monkeypatch.setattr(objective, "time", types.SimpleNamespace(perf_counter=lambda: float(next(ticks))))
    ev.simulate(space.base[None])
    ev.simulate(np.stack([space.base, space.base]))
    assert ev.seconds == 6.0 and ev.evaluations == 3


def test_evaluator_refuses_an_engine_without_batches(example_study):
    from wallcal.errors import EngineError
    from wallcal.simulation import prepare

    prepared = prepare(example_study, "energyplus")
    with pytest.raises(EngineError, match=r"the energyplus engine runs no batches: prepare the data with needs="):
        Evaluator(prepared, parse_space(example_study))

"""Automatic calibration: parameter space validation, objective, algorithms, outputs, resume."""

from __future__ import annotations

import copy
import json
import tomllib

import numpy as np
import pandas as pd
import pytest

from conftest import EXAMPLE
from wallcal import StudyError, load_study, load_wall
from wallcal.calibration import calibrate, parse_space
from wallcal.calibration.objective import Evaluator
from wallcal.cli import main
from wallcal.simulation import prepare
from wallcal.study import parse_study

QUICK = {"particles": 6, "generations": 3, "step_reductions": 1, "polish": False}


@pytest.fixture(scope="module")
def raw():
    return tomllib.loads(EXAMPLE.read_text())


def space_problems(raw, calibration):
    """The problems of a study whose [calibration] table is ``calibration``: found when it is loaded."""
    r = copy.deepcopy(raw)
    r["calibration"] = calibration
    with pytest.raises(StudyError) as exc:
        parse_study(r, base_dir=EXAMPLE.parent)
    return exc.value.problems


def test_example_space(example_study):
    sp = parse_space(example_study)
    assert sp.n == 18
    assert sp.names[6] == "conductivity[5,8]"
    p7 = sp.parameters[12]
    assert p7.name == "conductivity[7]" and p7.lower == pytest.approx(0.0175) and p7.upper == pytest.approx(0.105)
    assert sp.targets == ("T3A", "T2A", "T1A")


def test_bound_sides_names_the_bound_within_its_band(example_study):
    sp = parse_space(example_study)
    x = sp.base.copy()
    x[0], x[1], x[2] = sp.lower[0], sp.upper[1], sp.lower[2] + 1e-3 * (sp.upper[2] - sp.lower[2])
    sides = sp.bound_sides(x)
    assert sides[:3] == ["lower", "upper", ""]
    assert sp.bound_sides(x, band=2e-3)[2] == "lower"
    assert sides[3:] == [""] * (sp.n - 3)  # the base case lies inside the box


def test_space_validation_reports_every_problem(raw):
    probs = space_problems(
        raw,
        {
            "targets": ["T3A", "T4A"],
            "parameters": [
                {"layers": ["3"], "property": "conductivity", "bounds": [0.1, 0.2], "bounds_kind": "absolute"},
                {"layers": ["3x"], "property": "density", "bounds": [-0.2, 0.2]},  # unknown layer
                {"layers": ["4"], "property": "conductivity", "bounds": [-0.1, 0.3], "bounds_kind": "absolute"},
                {"layers": ["5", "5"], "property": "density", "bounds": [-0.2, 0.2]},  # named twice
                {"layers": ["4", "5"], "property": "specific_heat", "bounds": [-0.2, 0.2]},  # tied, different base
                {"probe": "T9A", "property": "depth", "bounds": [0.09, 0.11]},  # unknown probe
                {"layers": ["3"], "property": "contact_resistance", "bounds": [-0.5, 0.5]},  # relative of 0
                {"layers": ["9"], "property": "contact_resistance", "bounds": [0, 0.1], "bounds_kind": "absolute"},
                {"layers": ["6"], "property": "conductivty", "bounds": [-0.2, 0.2]},
            ],
        },
    )
    text = "\n".join(probs)
    assert "calibration.targets[1]: 'T4A' is not a sensor" in text
    assert "the base value 0.04 of conductivity[3] is outside the bounds [0.1, 0.2]" in text
    assert "'3x' is not a layer id; did you mean '3'" in text
    assert "conductivity[4] must stay > 0 over the whole box; lower bound is -0.1" in text
    assert "layer '5' density is already a parameter" in text
    assert "tied layers must share a base specific_heat" in text
    assert "'T9A' is not a probe of the wall" in text
    assert "relative bounds need a non-zero base value" in text
    assert "the innermost layer has no next layer" in text
    assert "did you mean 'conductivity'" in text


def test_parameters_map_to_properties(example_study):
    r = copy.deepcopy(example_study.raw["calibration"])
    r["parameters"] = r["parameters"] + [
        {"probe": "T3A", "property": "depth", "bounds": [-0.005, 0.005], "bounds_kind": "absolute"}
    ]
    with pytest.raises(StudyError, match="base value 0.1 of depth"):
        parse_space(example_study, r)
    r["parameters"][-1]["bounds"] = [0.095, 0.105]
    sp = parse_space(example_study, r)
    x = sp.base.copy()
    x[6] = 0.04  # conductivity[5,8]
    x[8] = 1200  # specific_heat[5,8]
    x[-1] = 0.098
    props, depths = sp.properties(example_study.wall, x[None])
    assert props.conductivity[0, 2] == props.conductivity[0, 5] == 0.04
    assert props.volumetric_heat_capacity[0, 5] == pytest.approx(40 * 1200)
    assert depths["T3A"][0] == pytest.approx(0.098)
    w = sp.wall_at(example_study.wall, x)
    assert w.layers[5].conductivity == 0.04 and w.probe("T3A").depth == pytest.approx(0.098)


def test_objective_is_cse(example_study):
    sp = parse_space(example_study)
    prep = prepare(example_study)
    ev = Evaluator(prep, sp)
    f = ev.objective(sp.base[None])[0]
    res = wallcal_simulate(example_study, prep)
    cse = sum(((res.simulated[t] - res.measured[t]) ** 2).sum() for t in sp.targets)
    assert f == pytest.approx(cse, rel=1e-9)
    r = ev.residuals(sp.base[None])
    assert (r**2).sum() == pytest.approx(f, rel=1e-9)


def wallcal_simulate(study, prep):
    from wallcal import simulate

    return simulate(study, prepared=prep)


@pytest.mark.slow
def test_default_calibration_of_the_example(tmp_path, capsys):
    """Acceptance: within 0.01 % of the best attainable; each target below the base case and within
    its noise floor + 0.1 degC; T1A falls below its floor and the output says so."""
    out = tmp_path / "cal"
    assert main(["calibrate", str(EXAMPLE), "--out", str(out), "--quiet"]) == 0
    text = capsys.readouterr().out
    info = json.loads((out / "calibration.json").read_text())
    assert info["status"] == "complete" and info["algorithm"] == "pso-hj"
    # best attainable: a least-squares run from the base case (an independent start)
    study = load_study(EXAMPLE)
    ls = calibrate(study, algorithm="least-squares", settings={"max_nfev": 200}, progress=False)
    best = min(ls.f_opt, info["objective_optimum"])
    assert info["objective_optimum"] <= best * (1 + 1e-4)
    rm = info["rmse"]
    floors = info["noise_floors"]
    for t in ("T3A", "T2A", "T1A"):
        assert rm["calibrated"][t] < rm["base"][t]
        assert rm["calibrated"][t] <= floors[t] + 0.1
    assert floors["T3A"] == pytest.approx(0.15, abs=0.01) and floors["T1A"] == pytest.approx(0.35, abs=0.01)
    assert "T1A: calibrated RMSE" in text and "well below its noise floor" in text
    # the calibrated wall drops into a study
    wall = load_wall(out / "calibrated_wall.toml")
    assert wall.layers[0].conductivity == pytest.approx(info["parameters"][0]["optimum"])
    met = pd.read_csv(out / "metrics.csv")
    assert set(met["case"]) == {"base", "calibrated"}
    assert (out / "convergence.png").stat().st_size > 1000 and (out / "fit.png").stat().st_size > 1000


@pytest.mark.slow
def test_recovers_a_known_wall_without_noise(tmp_path):
    """A campaign generated by wallcal from a known wall (no noise): the optimiser reaches an objective
    within 1e-6 of the known wall's (which is 0 up to round-off); parameters need not match."""
    study = load_study(EXAMPLE)
    truth = load_wall(EXAMPLE.parent / "true_wall.toml")
    space = parse_space(study)
    x_true = np.array([_value(truth, p) for p in space.parameters])
    ev = Evaluator(prepare(study), space)
    sim = ev.simulate(x_true[None])[0]  # the calibration's own grid: the known wall scores 0
    data = pd.read_csv(EXAMPLE.parent / "measured.csv").set_index("timestamp")
    stamps = ev.prepared.times.strftime("%Y-%m-%dT%H:%M:%S")
    for k, t in enumerate(space.targets):
        data.loc[stamps, t] = sim[k]
    data.to_csv(tmp_path / "measured.csv", float_format="%.12g")
    text = EXAMPLE.read_text().replace('reference_wall = "true_wall.toml"', "")
    (tmp_path / "study.toml").write_text(text)
    s2 = load_study(tmp_path / "study.toml")
    known = float(Evaluator(prepare(s2), parse_space(s2)).objective(x_true[None])[0])
    assert known < 1e-12
    cal = calibrate(s2, progress=False)
    assert cal.f_opt <= known + 1e-6


def _value(wall, p):
    if p.probe:
        return wall.probe(p.probe).depth
    return getattr(wall.layers[p.layers[0]], p.property)


def test_same_seed_same_result(example_study):
    a = calibrate(example_study, settings=QUICK, progress=False)
    b = calibrate(example_study, settings=QUICK, progress=False)
    np.testing.assert_array_equal(a.x_opt, b.x_opt)
    assert a.f_opt == b.f_opt and a.evaluations == b.evaluations
    c = calibrate(example_study, settings=QUICK, seed=7, progress=False)
    assert not np.array_equal(a.x_opt, c.x_opt)


def test_interrupt_keeps_best_and_resume_continues(example_study, tmp_path, monkeypatch):
    out = tmp_path / "cal"
    full = calibrate(example_study, settings=QUICK, progress=False)
    calls = {"n": 0}
    orig = Evaluator.objective

    def flaky(self, X):
        calls["n"] += 1
        if calls["n"] == 20:
            raise KeyboardInterrupt
        return orig(self, X)

    monkeypatch.setattr(Evaluator, "objective", flaky)
    part = calibrate(example_study, settings=QUICK, progress=False, out_dir=out)
    assert part.status == "interrupted"
    assert part.f_opt < part.f_base
    ckpt = tmp_path / ".cal.checkpoint.json"
    assert ckpt.exists()
    part.write(out)
    assert json.loads((out / "calibration.json").read_text())["status"] == "interrupted"
    monkeypatch.setattr(Evaluator, "objective", orig)
    done = calibrate(example_study, settings=QUICK, progress=False, out_dir=out, resume=True)
    assert done.status == "complete" and ckpt.exists()  # kept until the outputs are in place
    done.write(out)
    assert not ckpt.exists()
    np.testing.assert_allclose(done.x_opt, full.x_opt, rtol=0, atol=1e-12)
    assert done.f_opt == pytest.approx(full.f_opt, rel=1e-12)


def test_resume_without_checkpoint_is_a_clear_error(example_study, tmp_path):
    from wallcal import WallcalError

    with pytest.raises(WallcalError, match="nothing to resume"):
        calibrate(example_study, settings=QUICK, progress=False, out_dir=tmp_path / "x", resume=True)


@pytest.mark.parametrize(
    "algorithm,settings",
    [
        ("nelder-mead", {"maxfev": 150}),
        ("differential-evolution", {"maxiter": 3, "popsize": 2}),
        ("least-squares", {"max_nfev": 5}),
    ],
)
def test_library_algorithms_improve_the_base_case(example_study, algorithm, settings):
    res = calibrate(example_study, algorithm=algorithm, settings=settings, progress=False)
    assert res.f_opt < res.f_base
    assert res.algorithm == algorithm


def test_cma_es(example_study):
    pytest.importorskip("cma")
    res = calibrate(example_study, algorithm="cma-es", settings={"maxfevals": 60}, progress=False)
    assert res.f_opt < res.f_base


def test_unknown_setting_is_rejected(example_study):
    with pytest.raises(StudyError, match="calibration.settings.particle: unknown setting for pso-hj; did you mean"):
        calibrate(example_study, settings={"particle": 3}, progress=False)


def test_convert_conductivity_manual_route(tmp_path, capsys):
    out = tmp_path / "wall.toml"
    assert (
        main(
            [
                "convert-conductivity",
                str(EXAMPLE),
                "--coefficient",
                "3=0.0046",
                "--coefficient",
                "5=0.0046",
                "--coefficient",
                "7=0.0046",
                "--coefficient",
                "8=0.0046",
                "--layers",
                "3,5,7,8",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    w = load_wall(out)
    # the layers' mean measured temperatures are about 24-26 degC: ISO 10456 gives +6..7 % from 10 degC
    for lid, lam0 in (("3", 0.040), ("5", 0.035)):
        layer = w.layers[[x.id for x in w.layers].index(lid)]
        assert 23.0 < layer.reference_temperature < 27.5
        assert layer.conductivity == pytest.approx(lam0 * np.exp(0.0046 * (layer.reference_temperature - 10)))
    assert w.layers[1].conductivity == 0.2  # LVL untouched


def test_crosscheck(tmp_path, capsys):
    assert (
        main(
            [
                "crosscheck",
                str(EXAMPLE),
                str(EXAMPLE.parent / "true_wall.toml"),
                str(EXAMPLE),
                "--engines",
                "fd-cn,fd-implicit",
                "--out",
                str(tmp_path / "cc"),
            ]
        )
        == 0
    )
    df = pd.read_csv(tmp_path / "cc" / "crosscheck.csv")
    assert len(df) == 4 and {"rmse_T3A", "rmse_T2A", "rmse_T1A"} <= set(df.columns)
    t = df[(df.wall == "true_wall") & (df.engine == "fd-cn")].iloc[0]
    assert t["rmse_T1A"] == pytest.approx(0.35, abs=0.01)

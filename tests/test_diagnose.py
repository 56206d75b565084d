"""``wallcal diagnose``: the sensor-offset parameter kind, the AR(1) criterion, and the structure the data choose
on synthetic campaigns with a known wall (a probe offset: its depth is adopted; no structure error: nothing)."""

from __future__ import annotations

import copy
import json
import math
import tomllib

import numpy as np
import pandas as pd
import pytest

from conftest import EXAMPLE
from synthetic_campaign import make_campaign
from wallcal import StudyError, load_study
from wallcal.analysis.diagnose import ADOPT_DELTA, ar1_loglike, diagnose, propose, refine
from wallcal.calibration import calibrate
from wallcal.calibration.objective import Evaluator
from wallcal.cli import main
from wallcal.simulation import BATCH_NEEDS, prepare
from wallcal.study import parse_study

TRUE_LAMBDA = {"3": 0.043, "5": 0.037, "8": 0.037, "7": 0.045}


# ============================================================================ the offset parameter kind
def _with_params(raw, *params):
    r = copy.deepcopy(raw)
    r["calibration"]["parameters"] = list(r["calibration"]["parameters"]) + list(params)
    return r


@pytest.fixture(scope="module")
def raw():
    return tomllib.loads(EXAMPLE.read_text())


def test_offset_parameter_parsed(raw):
    st = parse_study(_with_params(raw, {"sensor": "T1A", "property": "offset", "bounds": [-1.0, 0.5]}), EXAMPLE.parent)
    p = st.calibration.parameters[-1]
    assert (p.name, p.property, p.sensor, p.probe, p.layers) == ("offset[T1A]", "offset", "T1A", None, ())
    assert (p.base, p.lower, p.upper) == (0.0, -1.0, 0.5)
    assert st.calibration.offset_values(np.r_[st.calibration.base[:-1], 0.25]) == {"T1A": 0.25}
    # the wall does not change with an offset
    assert st.calibration.wall_at(st.wall, np.r_[st.calibration.base[:-1], 0.25]) == st.wall


@pytest.mark.parametrize(
    ("param", "message"),
    [
        ({"sensor": "qe", "property": "offset", "bounds": [-1, 1]}, "'qe' is not a target of the calibration"),
        ({"sensor": "T1A", "property": "offset", "bounds": [0.1, 1]}, "must hold 0"),
        ({"sensor": "T1A", "property": "depth", "bounds": [-1, 1]}, "property"),
        ({"sensor": "T1A", "property": "offset", "bounds": [-1, 1], "bounds_kind": "relative"}, "bounds_kind"),
        ({"sensor": "T1A", "probe": "T1A", "property": "offset", "bounds": [-1, 1]}, "give one of layers"),
    ],
)
def test_offset_parameter_problems(raw, param, message):
    with pytest.raises(StudyError) as exc:
        parse_study(_with_params(raw, param), EXAMPLE.parent)
    assert any(message in p and "calibration.parameters[18]" in p for p in exc.value.problems), exc.value.problems


def test_offset_twice_is_a_problem(raw):
    p = {"sensor": "T1A", "property": "offset", "bounds": [-1, 1]}
    with pytest.raises(StudyError, match="sensor 'T1A' offset is already a parameter"):
        parse_study(_with_params(raw, p, p), EXAMPLE.parent)


def test_offset_shifts_the_measured_signal(raw):
    """errors(x) = simulated - (measured + offset) for the offset's target only; other targets unchanged."""
    st = parse_study(_with_params(raw, {"sensor": "T2A", "property": "offset", "bounds": [-1, 1]}), EXAMPLE.parent)
    st = st.replace(path=EXAMPLE)
    prep = prepare(st, needs=BATCH_NEEDS)
    ev = Evaluator(prep, st.calibration)
    x0 = st.calibration.base
    x1 = x0.copy()
    x1[-1] = 0.3
    e0, e1 = ev.errors(np.array([x0, x1]))
    m = ev.mask
    assert np.allclose(e1[1][m[1]], e0[1][m[1]] - 0.3, atol=1e-12)
    assert np.array_equal(e1[[0, 2]], e0[[0, 2]])


# ============================================================================ the criterion and the optimiser
def test_ar1_loglike_by_hand():
    e = np.array([0.3, 0.1, -0.2, 0.05, 0.4, np.nan, 0.2, 0.1])
    mask = np.isfinite(e)
    pairs = [(0.1, 0.3), (-0.2, 0.1), (0.05, -0.2), (0.4, 0.05), (0.1, 0.2)]  # the gap breaks (0.4) -> (0.2)
    a = np.array([p[0] for p in pairs])
    b = np.array([p[1] for p in pairs])
    phi = (a @ b) / (b @ b)
    s2 = np.mean((a - phi * b) ** 2)
    ll, m, ph = ar1_loglike(np.nan_to_num(e), mask)
    assert m == 5 and ph == pytest.approx(phi)
    assert ll == pytest.approx(-0.5 * 5 * (math.log(2 * math.pi * s2) + 1))


def test_refine_finds_a_bounded_least_squares_optimum():
    """A linear model with its optimum outside the box on one parameter: that parameter ends at its bound, the
    other at the constrained optimum."""
    t = np.linspace(0, 1, 200)
    y = 1.4 * t + 0.3 * t**2

    def residuals(U):
        return U[:, :1] * t[None] + U[:, 1:2] * t[None] ** 2 - y[None]

    u, runs = refine(residuals, np.array([0.5, 0.5]), max_jacobians=20, ftol=1e-12)
    assert u[0] == 1.0
    # with a = 1: minimise ||(t + b t^2) - y|| over b: b = <t^2, y - t> / <t^2, t^2>
    b = (t**2 @ (y - t)) / (t**2 @ t**2)
    assert u[1] == pytest.approx(b, abs=1e-6)
    assert runs > 3


# ============================================================================ synthetic campaigns
@pytest.fixture(scope="module")
def probe_campaign(tmp_path_factory):
    return make_campaign(tmp_path_factory.mktemp("probe"), probe_depths={"T3A": 0.094}, conductivity=TRUE_LAMBDA)


@pytest.fixture(scope="module")
def null_campaign(tmp_path_factory):
    return make_campaign(tmp_path_factory.mktemp("null"), conductivity=TRUE_LAMBDA)


def test_candidates_proposed(null_campaign):
    st = load_study(null_campaign)
    names = [e.name for e in propose(st, st.calibration)]
    assert names == [
        "depth[T3A]",
        "depth[T2A]",
        "depth[T1A]",
        "contact_resistance[3]",  # T3A sits at 3|4, T2A at 5|6, T1A at 7|8
        "contact_resistance[5]",
        "contact_resistance[7]",
        "conductivity_temperature_coefficient[3]",  # insulation groups as the space ties them
        "conductivity_temperature_coefficient[5,8]",
        "conductivity_temperature_coefficient[7]",
        "conductivity_temperature_coefficient[3,5,7,8]",  # and all of them sharing one coefficient
        "offset[T3A]",
        "offset[T2A]",
        "offset[T1A]",
        "response_time[T3A]",  # a first-order lag of each probe's reading
        "response_time[T2A]",
        "response_time[T1A]",
        "offset[faces]",  # both boundary sensors together: every temperature moves by it
    ]


def test_candidates_of_a_probe_inside_a_layer_and_of_a_flux(raw):
    """A probe inside layer 5 (0.1125..0.1525 m): contact resistances at both its faces (4|5 and 5|6); a flux
    target's offset spans a quarter of the signal's sd when 2 x its relative accuracy is less."""
    r = copy.deepcopy(raw)
    r["wall"]["probes"][1]["depth"] = 0.13
    r["calibration"]["targets"] = ["T2A", "qi"]
    st = parse_study(r, EXAMPLE.parent).replace(path=EXAMPLE)
    prep = prepare(st, needs=BATCH_NEEDS)
    ev = Evaluator(prep, st.calibration)
    y = {t: ev.y[k][ev.mask[k]] for k, t in enumerate(st.calibration.targets)}
    ext = {e.name: e for e in propose(st, st.calibration, y=y)}
    assert [n for n in ext if n.startswith("contact")] == ["contact_resistance[4]", "contact_resistance[5]"]
    assert ext["depth[T2A]"].table["bounds"] == [pytest.approx(0.12), pytest.approx(0.14)]
    assert ext["offset[T2A]"].table["bounds"] == [-1.0, 1.0]  # 2 x 0.5 K
    half = ext["offset[qi]"].table["bounds"][1]
    assert half == pytest.approx(0.25 * np.std(y["qi"]), rel=1e-2) and half > 2 * 0.03 * np.sqrt(np.mean(y["qi"] ** 2))
    # lambda(T): insulation layers only (3, 5+8 tied, 7), never the LVL panels or the plasterboard
    assert sorted(n for n in ext if n.startswith("conductivity_temperature")) == [
        "conductivity_temperature_coefficient[3,5,7,8]",
        "conductivity_temperature_coefficient[3]",
        "conductivity_temperature_coefficient[5,8]",
        "conductivity_temperature_coefficient[7]",
    ]
    assert ext["conductivity_temperature_coefficient[3]"].table["bounds"] == [0.0, 0.02]


def test_probe_offset_gets_the_depth_adopted(probe_campaign, tmp_path):
    st = load_study(probe_campaign)
    d = diagnose(st)
    assert d.adopted == ["depth[T3A]"]
    assert d.x["depth[T3A]"] == pytest.approx(0.094, abs=5e-4)
    c = d.candidates
    assert list(c.columns) == [
        "extension",
        "delta_bic",
        "RMSE T3A",
        "RMSE T2A",
        "RMSE T1A",
        "validation RMSE T3A",  # NaN: the campaign has no validation window
        "validation RMSE T2A",
        "validation RMSE T1A",
        "plausible",
        "adopted",
        "held_at_bounds",
    ]
    assert c["validation RMSE T3A"].isna().all()
    row = c[c["adopted"]]
    assert list(row["extension"]) == ["depth[T3A]"] and float(row["delta_bic"].iloc[0]) < -ADOPT_DELTA
    assert float(row["RMSE T3A"].iloc[0]) < 0.06  # the noise (0.05 K), from 0.39 K without the depth
    assert d.rmse_base["T3A"] > 0.2
    assert d.residuals.loc["T3A", "daily_share"] > 0.5  # the probe error shows as a daily pattern
    # the extended study: the depth is a calibration parameter, and it calibrates
    assert "depth[T3A]" in d.study.calibration.names
    out = tmp_path / "out"
    d.write(out)
    assert sorted(p.name for p in out.iterdir()) == [
        "candidates.csv",
        "diagnose.json",
        "manifest.json",
        "residuals.csv",
        "study.toml",
    ]
    back = pd.read_csv(out / "candidates.csv")
    assert list(back.columns) == list(c.columns) and len(back) == len(c)
    ext = load_study(out / "study.toml")
    assert ext.calibration.names == d.study.calibration.names
    assert ext.data.file.resolve() == st.data.file.resolve()
    res = calibrate(ext, progress=False, settings={"particles": 6, "generations": 3})
    assert res.space.names[-1] == "depth[T3A]"
    assert res.metrics.set_index(["case", "signal"]).loc[("calibrated", "T3A"), "rmse"] < 0.1
    assert "depth[T3A]" in d.summary() and "support" in d.summary()


def test_contact_resistance_gets_adopted(tmp_path):
    """A 0.15 m2K/W contact resistance between layers 3 and 4 (where T3A sits): the contact is adopted, not the
    probe's depth (which fits T3A almost as well but not the other probes), and its value recovered."""
    st = load_study(make_campaign(tmp_path / "contact", contact={"3": 0.15}, conductivity=TRUE_LAMBDA))
    d = diagnose(st, kinds=("depth", "contact_resistance"))
    assert d.adopted == ["contact_resistance[3]"]
    assert d.x["contact_resistance[3]"] == pytest.approx(0.15, rel=0.05)
    c = d.candidates.set_index("extension")
    assert c.loc["contact_resistance[3]", "delta_bic"] < c.loc["depth[T3A]", "delta_bic"] < -ADOPT_DELTA


def test_no_structure_error_adopts_nothing(null_campaign, tmp_path):
    st = load_study(null_campaign)
    msgs = []
    d = diagnose(st, progress=msgs.append)
    assert d.adopted == []
    assert not d.candidates["adopted"].any()
    assert len(d.candidates) == 17  # the single candidates (with the response times and the face offset); none useful
    assert (d.candidates["delta_bic"] > -ADOPT_DELTA).all()
    assert d.study.calibration.names == st.calibration.names
    assert "support the study's structure" in d.summary()
    assert any("scoring" in m for m in msgs)
    # from a calibration output directory: the same answer
    cal = tmp_path / "cal"
    calibrate(st, progress=False).write(cal)
    d2 = diagnose(st, start=cal, kinds=("offset",))
    assert d2.adopted == [] and len(d2.candidates) == 3


# ============================================================================ the command
def test_cli_diagnose(probe_campaign, tmp_path, capsys):
    out = tmp_path / "diag"
    assert main(["diagnose", str(probe_campaign), "--out", str(out), "--quiet"]) == 0
    text = capsys.readouterr().out
    assert "depth[T3A]" in text and "The data support extending the calibration with depth[T3A]" in text
    cand = pd.read_csv(out / "candidates.csv")
    assert cand.loc[cand["adopted"], "extension"].tolist() == ["depth[T3A]"]
    info = json.loads((out / "diagnose.json").read_text())
    assert info["adopted"] == ["depth[T3A]"]


def test_cli_bad_input(tmp_path, probe_campaign, capsys):
    out = tmp_path / "out"
    # a --from that does not exist
    assert main(["diagnose", str(probe_campaign), "--from", str(tmp_path / "nope"), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--from" in err[0] and "nope" in err[0]
    # a calibration output of another parameter space
    other = tmp_path / "cal"
    other.mkdir()
    (other / "calibration.json").write_text(json.dumps({"parameters": [{"name": "density[3]", "optimum": 1.0}]}))
    assert main(["diagnose", str(probe_campaign), "--from", str(other), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "another parameter space" in err[0]
    # a study without [calibration]
    raw = tomllib.loads(probe_campaign.read_text())
    del raw["calibration"]
    import tomli_w

    bad = probe_campaign.parent / "no_calibration.toml"
    bad.write_text(tomli_w.dumps(raw))
    assert main(["diagnose", str(bad), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "[calibration]" in err[0]
    # a missing study
    assert main(["diagnose", str(tmp_path / "missing.toml"), "--out", str(out)]) == 2
    assert len(capsys.readouterr().err.strip().splitlines()) == 1
    assert not out.exists() and not any(p.name.startswith(".out") for p in tmp_path.iterdir())


def test_unknown_kind(null_campaign):
    with pytest.raises(StudyError, match="unknown extension kind"):
        diagnose(load_study(null_campaign), kinds=("depth", "gap"))


def test_extended_study_paths_resolve_from_elsewhere(probe_campaign, tmp_path):
    """OUT/study.toml in another folder: data file and every relative path still resolve."""
    st = load_study(probe_campaign)
    d = diagnose(st, start=st.wall, kinds=("depth",))
    out = tmp_path / "deep" / "er" / "out"
    d.write(out)
    text = (out / "study.toml").read_text()
    assert 'file = "../../../' in text
    ext = load_study(out / "study.toml")
    assert ext.data.file.resolve() == st.data.file.resolve()


def test_calibrated_offset_cancels_a_sensor_bias(null_campaign, tmp_path):
    """A +0.3 K bias put on T1A (its declared offset) is found by an offset parameter (-0.3 K), and the calibrated
    metrics use the corrected signal."""
    raw = tomllib.loads(null_campaign.read_text())
    raw["sensors"][2]["offset"] = 0.3
    raw["calibration"]["parameters"].append({"sensor": "T1A", "property": "offset", "bounds": [-1.0, 1.0]})
    import tomli_w

    path = null_campaign.parent / "biased.toml"
    path.write_text(tomli_w.dumps(raw))
    st = load_study(path)
    res = calibrate(st, progress=False, algorithm="least-squares")
    assert res.x_opt[-1] == pytest.approx(-0.3, abs=0.01)
    rm = res.metrics.set_index(["case", "signal"])["rmse"]
    assert rm[("base", "T1A")] > 0.25
    assert rm[("calibrated", "T1A")] < 0.06
    assert any("calibrated sensor offsets" in n and "T1A -0." in n for n in res.notes)


# ============================================================================ sensor biases and shared lambda(T)
def test_ar1_loglike_integrates_the_bias_out():
    """With a bias prior the criterion is the AR(1) likelihood with the bias integrated out, maximised over phi and
    s: checked against a numerical integral over b and a general-purpose maximiser."""
    from scipy import integrate, optimize

    rng = np.random.default_rng(3)
    n, tau = 400, 0.25
    u = np.zeros(n)
    for t in range(1, n):
        u[t] = 0.4 * u[t - 1] + 0.1 * rng.standard_normal()
    e = u + 0.3
    mask = np.ones(n, bool)
    mask[200] = False  # a gap restarts the process
    pair = mask[1:] & mask[:-1]
    a, p = e[1:][pair], e[:-1][pair]
    m = len(a)

    def loglike(phi, log_s):
        s2 = math.exp(2 * log_s)
        r = a - phi * p

        def dens(b):
            q = np.sum((r - (1 - phi) * b) ** 2)
            return (
                math.exp(-q / (2 * s2) + q0 / (2 * s2))
                * math.exp(-(b**2) / (2 * tau**2))
                / math.sqrt(2 * math.pi * tau**2)
            )

        q0 = np.sum((r - np.mean(r)) ** 2)
        val, _ = integrate.quad(dens, -3, 3, points=[np.mean(r) / (1 - phi)], limit=200)
        return -0.5 * m * math.log(2 * math.pi * s2) - q0 / (2 * s2) + math.log(val)

    best = optimize.minimize(
        lambda v: -loglike(*v),
        [0.4, math.log(0.1)],
        method="Nelder-Mead",
        options={"xatol": 1e-8, "fatol": 1e-9, "maxiter": 4000},
    )
    ll, mm, phi = ar1_loglike(e, mask, bias_sd=tau)
    assert mm == m
    # the closed-form updates maximise the joint density of (phi, s, b); the marginal's log-determinant term is
    # left out of that maximisation, which costs a few thousandths
    assert -best.fun - 0.01 < ll <= -best.fun + 1e-6
    assert phi == pytest.approx(best.x[0], abs=0.01)
    # the bias is explained by the error model: far better than without it, and bias_sd=0 is the plain AR(1)
    assert ll > ar1_loglike(e, mask)[0] + 10
    assert ar1_loglike(e, mask, bias_sd=0.0) == ar1_loglike(e, mask)


def test_a_sensor_bias_does_not_hide_the_contact(tmp_path):
    """Biases within the thermocouples' accuracy (T1A +0.25 K, T2A -0.2 K) next to a contact resistance between
    layers 3 and 4: the criterion integrates each sensor's bias out (the posterior's error model) and the fit
    profiles it, so the wall's properties do not absorb the biases and no offset stands in for the contact."""
    st = load_study(
        make_campaign(
            tmp_path / "biased", contact={"3": 0.15}, conductivity=TRUE_LAMBDA, bias={"T1A": 0.25, "T2A": -0.2}
        )
    )
    d = diagnose(st, kinds=("contact_resistance", "offset"))
    assert d.adopted == ["contact_resistance[3]"]
    assert d.x["contact_resistance[3]"] == pytest.approx(0.15, rel=0.1)
    c = d.candidates.set_index("extension")
    assert (c.loc[[n for n in c.index if n.startswith("offset")], "delta_bic"] > -ADOPT_DELTA).all()


def test_shared_lambda_t_adopted(tmp_path):
    """The same lambda(T) coefficient in every mineral-wool layer: the shared coefficient (one parameter) is
    adopted, not the separate groups, and the value recovered."""
    st = load_study(
        make_campaign(
            tmp_path / "lambdaT",
            conductivity=TRUE_LAMBDA,
            coefficient={lid: 0.005 for lid in ("3", "5", "7", "8")},
        )
    )
    d = diagnose(st, kinds=("conductivity_temperature_coefficient",))
    assert d.adopted == ["conductivity_temperature_coefficient[3,5,7,8]"]
    assert d.x["conductivity_temperature_coefficient[3,5,7,8]"] == pytest.approx(0.005, rel=0.2)


def test_forward_selection_polishes_close_contenders_and_adopts_ties():
    """Selection on scripted criterion values: a contender within POLISH_MARGIN is polished before the comparison
    (here it overtakes the leader); candidates ending within TIE_DELTA of the best are adopted together; a
    distant second is not."""
    from types import SimpleNamespace as F

    from wallcal.analysis.diagnose import POLISH_MARGIN, TIE_DELTA, forward_select

    def run(values, polished, combos):
        calls = {"polish": [], "score": []}

        def score(names, warm):
            calls["score"].append(tuple(sorted(names)))
            return F(names=tuple(names), bic=combos[tuple(sorted(names))])

        def polish(f):
            calls["polish"].append(f.names)
            return F(names=f.names, bic=polished.get(f.names, f.bic))

        singles = {n: F(names=(n,), bic=v) for n, v in values.items()}
        fit, adopted, tied, _ = forward_select(F(names=(), bic=0.0), singles, score, polish, lambda names: True)
        return fit, adopted, tied, calls

    # A leads B by less than the margin, but B polished ends as good as A: both adopted; C (far) never polished
    far = -(POLISH_MARGIN + 30.0)
    combos = {("A", "B"): -91.0, ("A", "C"): -95.0, ("B", "C"): -95.0, ("A", "B", "C"): -85.0}
    fit, adopted, tied, calls = run(
        {"A": -100.0, "B": -100.0 + POLISH_MARGIN - 1, "C": far}, {("B",): -100.0 + TIE_DELTA / 2}, combos
    )
    assert set(adopted) == {"A", "B"} and fit.bic == -91.0
    assert ("C",) not in calls["polish"] and ("B",) in calls["polish"]
    assert tied and set(tied[0][0]) == {"A", "B"} and tied[0][1] == pytest.approx(9.0)
    # B polished but still 3 behind: not tied; the next step tries A + B and A + C and adopts neither (no gain of
    # ADOPT_DELTA over A)
    combos = {("A", "B"): -95.0, ("A", "C"): -100.0}
    fit, adopted, tied, calls = run({"A": -100.0, "B": -90.0, "C": far}, {("B",): -97.0}, combos)
    assert adopted == ("A",) and not tied and fit.bic == -100.0
    assert ("A", "B") in calls["score"] and ("A", "C") in calls["score"]


def test_a_depth_starting_on_a_contact_node_leaves_it(probe_campaign):
    """T3A sits 6 mm inside layer 3 but is declared at the 3|4 interface, which carries a contact link (the
    contact resistance is a parameter): the depth starts on the contact's double node, where the probe reads the
    mean of both sides and a finite-difference fit cannot move. Fitted also from just off the node on each side
    (node_starts), the depth reaches the truth and the contact goes to about zero."""
    from wallcal.analysis.diagnose import NODE_STEP, node_starts
    from wallcal.grid import contact_node_depths

    raw = tomllib.loads(probe_campaign.read_text())
    contact = {"layers": ["3"], "property": "contact_resistance", "bounds": [0.0, 0.5], "bounds_kind": "absolute"}
    st = parse_study(_with_params(raw, contact), probe_campaign.parent).replace(path=probe_campaign)
    wall = st.wall
    for lid, lam in TRUE_LAMBDA.items():
        wall = wall.replace_layer(lid, conductivity=lam)
    # the node: exactly the grid's double node, only with the contact link
    i3 = st.wall.layer_index("3")
    node = contact_node_depths(st.wall, {i3})[i3]
    assert node == pytest.approx(st.wall.probe("T3A").depth, abs=1e-12) and contact_node_depths(st.wall) == {}
    d = diagnose(st, start=wall, kinds=("depth",))
    # the fit leaves the node for the true depth; the contact is no longer needed
    assert d.adopted == ["depth[T3A]"]
    assert d.x["depth[T3A]"] == pytest.approx(0.094, abs=5e-4)
    assert d.x["contact_resistance[3]"] < 0.01
    sp = d.study.calibration
    x = np.array([d.x.get(n, p.base) for n, p in zip(sp.names, sp.parameters, strict=True)])
    j = sp.names.index("depth[T3A]")
    x[j] = node  # the starts: on the node and 1 mm to each side for the depth; the other parameters unchanged
    starts = node_starts(sp, st.wall, sp.contact_layers, x)
    assert [s[j] - node for s in starts] == pytest.approx([0.0, -NODE_STEP, NODE_STEP], abs=1e-12)
    assert all(np.array_equal(np.delete(s, j), np.delete(x, j)) for s in starts)
    assert len(node_starts(sp, st.wall, frozenset(), x)) == 1  # no contact link: no jump, one start


def test_a_structure_holding_parameters_at_bounds_needs_only_positive_evidence():
    """Selection on scripted criterion values and bound sets: once the adopted structure holds a study parameter at
    a bound of its prior box (it fails its own check), a candidate that frees it is adopted on positive evidence
    (WEAK_DELTA); not when the structure holds nothing (the strong threshold protects a plausible one), nor when
    the candidate does not free it, nor when its gain falls short of WEAK_DELTA."""
    from types import SimpleNamespace as F

    from wallcal.analysis.diagnose import WEAK_DELTA, forward_select

    gain = (ADOPT_DELTA + WEAK_DELTA) / 2  # between the two thresholds

    def run(held, combos, held_combos, singles=None):
        def score(names, warm):
            key = tuple(sorted(names))
            return F(names=tuple(names), bic=combos.get(key, 0.0), held=frozenset(held_combos.get(key, ())))

        singles = singles or {"A": (-100.0, held), "B": (-50.0, held)}
        fits = {n: F(names=(n,), bic=b, held=frozenset(h)) for n, (b, h) in singles.items()}
        base = F(names=(), bic=0.0, held=frozenset({"lambda[3]"}))
        return forward_select(base, fits, score, lambda f: f, lambda names: True, held=lambda f: f.held)

    both = {("A", "B"): -100.0 - gain}
    # A holds lambda[3] at its bound; A + B frees it with a gain below ADOPT_DELTA: adopted on the weaker threshold
    fit, adopted, tied, weak = run({"lambda[3]"}, both, {})
    assert adopted == ("A", "B") and fit.bic == -100.0 - gain and not tied
    assert weak == [(["B"], pytest.approx(-gain), frozenset({"lambda[3]"}), frozenset())]
    # A holds nothing: the strong threshold stands
    fit, adopted, _, weak = run(set(), both, {})
    assert adopted == ("A",) and not weak
    # A + B still holds lambda[3]: it does not remove the rejection, not adopted
    fit, adopted, _, weak = run({"lambda[3]"}, both, {("A", "B"): {"lambda[3]"}})
    assert adopted == ("A",) and not weak
    # A + B frees it but gains less than WEAK_DELTA: not adopted
    fit, adopted, _, weak = run({"lambda[3]"}, {("A", "B"): -100.0 - WEAK_DELTA / 2}, {})
    assert adopted == ("A",) and not weak
    # at the first step too: no candidate reaches ADOPT_DELTA against a base that holds lambda[3]; of the two that
    # gain WEAK_DELTA, the better one does not free it, the other does and is adopted
    fit, adopted, _, weak = run(
        set(), {}, {}, singles={"A": (-gain - 1.0, {"lambda[3]"}), "B": (-gain, ()), "C": (-WEAK_DELTA / 2, ())}
    )
    assert adopted == ("B",) and weak == [(["B"], pytest.approx(-gain), frozenset({"lambda[3]"}), frozenset())]
    # without a bound check (held=None, the default) only the strong threshold applies
    fits = {"A": F(names=("A",), bic=-gain)}
    fit, adopted, _, weak = forward_select(F(names=(), bic=0.0), fits, None, lambda f: f, lambda names: True)
    assert adopted == () and not weak


def test_a_combination_is_fitted_from_each_parent(probe_campaign, monkeypatch):
    """A structure of two extensions is recalibrated from the optimum it was reached from and from the optimum of
    its other one-extension parent: when it is first scored, starts from two different points (one parent's
    optimum can hold the combination in a valley the other's is outside of)."""
    import wallcal.analysis.diagnose as dg

    calls: list = []
    real = dg.node_starts

    def spy(space, wall, contact_layers, x):
        calls.append((tuple(space.names), np.array(x, dtype=float)))
        return real(space, wall, contact_layers, x)

    monkeypatch.setattr(dg, "node_starts", spy)
    d = diagnose(load_study(probe_campaign))
    assert d.adopted == ["depth[T3A]"]
    n_own = len(d.base_study.calibration.names)
    first: dict[tuple, list] = {}  # the starts of each structure's first fit: its first run of consecutive calls
    done: set = set()
    for i, (names, x) in enumerate(calls):
        if i and calls[i - 1][0] != names and calls[i - 1][0] in first:
            done.add(calls[i - 1][0])
        if names not in done:
            first.setdefault(names, []).append(x)
    pairs = {k: v for k, v in first.items() if len(k) == n_own + 2}
    assert pairs, "no combination of two extensions was scored"
    for names, starts in pairs.items():
        # (node_starts itself varies only probe depths: compare the other parameters)
        other = np.array([not n.startswith("depth[") for n in names])
        assert len({tuple(np.round(s[other], 12)) for s in starts}) >= 2, names


def test_largest_step_finds_an_event_beside_a_daily_pattern():
    """residuals.csv's ``step``/``step_at``: the change of the residual's daily mean where it is largest. A level
    change of 1 K at a known time, under a daily pattern of 0.3 K and noise, is found at that time within an hour
    and sized within 0.05 K; the daily pattern alone gives no step above 0.05 K; a record under a day gives none."""
    from wallcal.analysis.diagnose_candidates import largest_step

    rng = np.random.default_rng(3)
    t = pd.date_range("2014-01-01", periods=6 * 288, freq="5min")
    daily = 0.3 * np.sin(2 * np.pi * np.arange(len(t)) / 288)
    noise = 0.02 * rng.standard_normal(len(t))
    event = np.where(t >= pd.Timestamp("2014-01-04T09:10"), -1.0, 0.0)
    step, at = largest_step(t, daily + noise + event)
    assert step == pytest.approx(-1.0, abs=0.05)
    assert abs(pd.Timestamp(at) - pd.Timestamp("2014-01-04T09:10")) <= pd.Timedelta("1h")
    step, _ = largest_step(t, daily + noise)
    assert abs(step) < 0.05
    assert np.isnan(largest_step(t[:100], noise[:100])[0])


def test_common_step_names_an_event_only_when_probes_step_together():
    """Two or more temperature targets whose largest daily-mean steps fall within 6 h of each other, each beyond
    half the sensor's accuracy, make one event; one probe alone, steps inside the accuracy or far apart do not."""
    from types import SimpleNamespace

    from wallcal.analysis.diagnose_candidates import common_step

    sensors = {
        "A": SimpleNamespace(quantity="temperature", accuracy=0.5),
        "B": SimpleNamespace(quantity="temperature", accuracy=0.5),
        "F": SimpleNamespace(quantity="heat_flux", accuracy=None),
    }
    study = SimpleNamespace(sensor=lambda t: sensors[t])

    def res(rows):
        return pd.DataFrame(rows, columns=["target", "step", "step_at"]).set_index("target")

    together = res([("A", -1.4, "2014-01-08T09:00"), ("B", -1.1, "2014-01-08T11:00"), ("F", 0.5, "2014-01-08T09:20")])
    text = common_step(study, together)
    assert "A -1.40 K, B -1.10 K" in text and "2014-01-08 09:00" in text and "F" not in text.split("(")[0]
    assert common_step(study, res([("A", -1.4, "2014-01-08T09:00"), ("B", -1.1, "2014-01-09T09:00")])) == ""
    assert common_step(study, res([("A", -1.4, "2014-01-08T09:00"), ("B", -0.2, "2014-01-08T10:00")])) == ""
    assert common_step(study, res([("A", -1.4, "2014-01-08T09:00"), ("B", float("nan"), "")])) == ""

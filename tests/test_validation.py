"""Held-out validation ([period] validation_start/validation_end): no fit sees the window; calibrate and diagnose
score it (validation.csv); diagnose adopts only plausible extensions that lower the held-out RMSE of every
temperature target. Real walls: PASSYS (data read in place, skipped when absent) and the bundled TRH-1 example.
"""

from __future__ import annotations

import copy

import numpy as np
import pandas as pd
import pytest

from conftest import REPO
from wallcal import StudyError, load_study
from wallcal.analysis.diagnose import diagnose
from wallcal.analysis.diagnose_candidates import plausibility
from wallcal.calibration import calibrate
from wallcal.calibration.space import parse_space
from wallcal.metrics import VALIDATION_COLUMNS, validation_table
from wallcal.simulation import prepare
from wallcal.study import parse_study
from wallcal.validation import score_wall, validation_study

TRH = REPO / "src" / "wallcal" / "examples" / "trh" / "study.toml"
PASSYS = REPO / "examples" / "passys" / "study.toml"
PASSYS_MOISTURE = REPO / "examples" / "passys" / "study_moisture.toml"
PASSYS_DATA = REPO.parent / "shared" / "data" / "real" / "srouchier__buildingenergygeeks" / "PASSYS_01.txt"
needs_passys = pytest.mark.skipif(not PASSYS_DATA.exists(), reason=f"PASSYS data absent ({PASSYS_DATA})")


def _passys_as_measured():
    """The PASSYS study with its face sensors' declared offset set to 0 (the data as measured)."""
    raw = copy.deepcopy(load_study(PASSYS).raw)
    for face in ("exterior", "interior"):
        raw["boundary"][face]["offset"] = 0.0
    return parse_study(raw, base_dir=PASSYS.parent.resolve(), source=str(PASSYS)).replace(path=PASSYS.resolve())


@pytest.fixture(scope="module")
def trh():
    return load_study(TRH)


def _with_period(study, path, **period):
    raw = copy.deepcopy(study.raw)
    raw["period"].update(period)
    for k, v in list(raw["period"].items()):
        if v is None:
            del raw["period"][k]
    return parse_study(raw, base_dir=path.parent.resolve(), source=str(path)).replace(path=path.resolve())


def test_period_keys_parsed_and_checked(trh):
    p = trh.period
    assert p.validation == (pd.Timestamp("2021-02-02T00:05").to_pydatetime(), pd.Timestamp("2021-02-15T23:55"))
    with pytest.raises(StudyError, match=r"period.validation_end: give both validation_start and validation_end"):
        _with_period(trh, TRH, validation_end=None)
    with pytest.raises(StudyError, match=r"period.validation_end: must be after validation_start"):
        _with_period(trh, TRH, validation_end=pd.Timestamp("2021-02-01").to_pydatetime())
    with pytest.raises(StudyError, match=r"period.validation_start: must be after period.start"):
        _with_period(trh, TRH, validation_start=pd.Timestamp("2021-01-05T00:05").to_pydatetime())


def test_window_never_fitted(trh):
    """Inside [start, end] the window's measured values are left out of the prepared data (every fit, every
    objective and criterion reads them there); the validation study compares exactly there."""
    prep = prepare(trh)
    vs, ve = (pd.Timestamp(t) for t in trh.period.validation)
    inside = (prep.times >= vs) & (prep.times <= ve)
    assert inside.sum() == 2016  # 14 days of 10-min data
    assert prep.measured.loc[inside].isna().all().all()
    assert prep.measured.loc[~inside, "interface"].notna().mean() > 0.99
    v = validation_study(trh)
    assert v.period.validation is None and (v.period.start, v.period.end) == trh.period.validation
    assert v.period.warmup_start == trh.period.warmup_start
    # no window: the prepared data are the whole period, as before
    full = _with_period(trh, TRH, validation_start=None, validation_end=None)
    assert prepare(full).measured["interface"].notna().sum() > prep.measured["interface"].notna().sum() + 2000
    assert validation_study(full) is None and score_wall(full) is None


def test_validation_table():
    y = np.array([[1.0, 2.0, np.nan, 4.0]])
    s = np.array([[1.5, 2.5, 0.0, 4.5]])
    t = validation_table(["a"], y, s)
    assert list(t.columns) == list(VALIDATION_COLUMNS)
    assert t.loc[0, "rmse"] == pytest.approx(0.5) and t.loc[0, "mbe"] == pytest.approx(-0.5) and t.loc[0, "n"] == 3


def test_plausibility_ranges(trh):
    raw = copy.deepcopy(trh.raw)
    raw["calibration"]["parameters"] += [
        {"sensor": "interface", "property": "offset", "bounds": [-1.0, 1.0]},
        {"sensor": "faces", "property": "offset", "bounds": [-0.3, 0.3]},
    ]
    sp = parse_space(trh, raw["calibration"])
    names = {"offset[interface]", "offset[faces]"}
    x = sp.base.copy()
    x[2], x[3] = 0.15, 0.1
    assert plausibility(trh, sp, x, names, 0.005) == []
    x[2] = -0.8  # beyond 2 x the 0.1 K accuracy
    assert plausibility(trh, sp, x, names, 0.005) == [
        "offset[interface] = -0.8 outside its plausible range -0.2 .. 0.2"
    ]
    x[2], x[3] = 0.0, 0.3  # at the bound of its box: never adopted silently
    assert plausibility(trh, sp, x, names, 0.005) == ["offset[faces] = 0.3 at the upper bound of its box"]
    # the face offset moves every temperature target's measured signal by its opposite, no flux
    assert sp.offsets(x[None])[0].tolist() == [-0.3]
    assert sp.offset_values(x) == {"interface": -0.3}


@pytest.mark.slow
def test_trh_held_out(trh, tmp_path):
    """TRH-1, the last third held out: the calibration predicts it within 0.25 K at the interface; diagnose
    decides the offset on held-out evidence (the -0.8 K offset it would need is beyond the sensor's accuracy)."""
    res = calibrate(trh, progress=False)
    res.write(tmp_path / "cal")
    v = pd.read_csv(tmp_path / "cal" / "validation.csv")
    assert list(v.columns) == list(VALIDATION_COLUMNS)
    row = v.set_index("sensor").loc["interface"]
    assert row["rmse"] <= 0.25 and row["n"] == 2016
    d = diagnose(trh, start=res, progress=False)
    c = d.candidates.set_index("extension")
    assert "validation RMSE interface" in c.columns and "plausible" in c.columns
    assert not c.loc["offset[interface]", "plausible"]
    assert "offset[interface]" not in d.adopted
    d.write(tmp_path / "diag")
    assert (tmp_path / "diag" / "validation.csv").exists()


def test_diagnose_keeps_a_window_given_in_code(trh, tmp_path):
    """A study given another held-out window in code (``study.replace(period=...)``): the diagnosed study and the
    study.toml diagnose writes hold that window, not the file's (they held the file's: a posterior of the
    diagnosed study then predicted another window than the one diagnose had scored)."""
    import dataclasses

    p = trh.period
    window = (pd.Timestamp("2021-01-19T00:05").to_pydatetime(), pd.Timestamp("2021-01-28T23:55").to_pydatetime())
    study = trh.replace(
        period=dataclasses.replace(p, end=p.validation_end, validation_start=window[0], validation_end=window[1])
    )
    d = diagnose(study, progress=False)
    assert d.study.period == study.period and d.study.period.validation == window
    d.write(tmp_path / "diag")
    assert load_study(tmp_path / "diag" / "study.toml").period == study.period
    assert d.validation.set_index("sensor").loc["interface", "n"] == 10 * 144  # the window's 10 days, not the file's 14


@needs_passys
@pytest.mark.slow
def test_passys_as_measured_adopts_only_what_the_window_confirms(tmp_path):
    """PASSYS with the face offset set to 0, the last 4 days held out: every adopted extension lowers the held-out
    RMSE of every temperature target against the base structure and lies inside its plausible range, off its
    bounds; the implausible in-sample favourites (lambda(T) at 0.02 1/K, probes moved by 1 cm) are refused."""
    s = _passys_as_measured()
    d = diagnose(s, progress=False)
    c = d.candidates.set_index("extension")
    temps = ("T_4", "T_8", "T_12")
    if d.adopted:
        row = c[c["adopted"]].iloc[0]
        assert bool(row["plausible"])
        for t in temps:
            assert row[f"validation RMSE {t}"] < d.validation_base[t]
    lam = "conductivity_temperature_coefficient[outer,mid_outer,mid_inner,inner]"
    assert lam not in d.adopted and not c.loc[lam, "plausible"]
    assert not any(n.startswith("depth[") for n in d.adopted)
    # the interior humidity step of 2014-01-08, which a conduction model cannot follow, is named as an event
    assert any("step together" in n and "2014-01-08" in n for n in d.notes), d.notes
    assert d.adopted == ["offset[faces]"]  # the offset found by hand, now a candidate
    assert 0.3 < d.x["offset[faces]"] < 1.0
    v = d.validation.set_index("sensor")
    assert (v.loc[list(temps), "rmse"] < 0.7).all()
    d.write(tmp_path / "diag")
    assert set(pd.read_csv(tmp_path / "diag" / "validation.csv").columns) == set(VALIDATION_COLUMNS)


@pytest.fixture(scope="module")
def passys_moisture_diagnosis():
    """``wallcal diagnose`` of the PASSYS heat-and-moisture study (the data as measured: no offset declared; the
    last 4 days held out), about 20 s."""
    return diagnose(load_study(PASSYS_MOISTURE), progress=False)


@needs_passys
@pytest.mark.slow
def test_passys_heat_and_moisture_meets_the_held_out_goal(passys_moisture_diagnosis, tmp_path):
    """The coupled model of the same wall and data, as measured: every adopted extension is plausible, off its
    bounds, and lowers the held-out RMSE of every temperature target; the held-out RMSE is below 0.5 K on T_4, T_8
    and T_12 (measured 0.09, 0.14, 0.20 K with offset[faces] +0.51 K and depth[T_4] 0.9 mm off;
    docs/identifiability.md), where the heat-only structure stops at 0.44, 0.58, 0.64 K."""
    d = passys_moisture_diagnosis
    assert d.adopted and "offset[faces]" in d.adopted
    c = d.candidates
    row = c[c["adopted"]].iloc[0]
    assert bool(row["plausible"])
    temps = ("T_4", "T_8", "T_12")
    for t in temps:
        assert row[f"validation RMSE {t}"] < d.validation_base[t]
    for n in d.adopted:  # inside the plausible range (2 x the 0.5 K accuracy; a probe within 10 mm)
        if n == "offset[faces]":
            assert 0.2 < d.x[n] < 1.0
        else:
            assert n.startswith("depth[") and abs(d.x[n] - d.study.wall.probe(n[6:-1]).depth) < 0.01
    v = d.validation.set_index("sensor")
    assert (v.loc[list(temps), "rmse"] < 0.5).all(), v
    assert (v.loc[["HR_4", "HR_8", "HR_12"], "rmse"] < 0.03).all(), v
    # the heat-only candidates the ham engine cannot represent are not proposed
    assert not c["extension"].str.contains("conductivity_temperature_coefficient|contact_resistance").any()
    assert "RH" in d.summary() and "HR_4 0.006 -> 0.006 K" not in d.summary()
    assert not any("step together" in n for n in d.notes)  # the coupled model follows the humidity step


# ---------------------------------------------------------------------------- posterior predictive bands
@pytest.mark.slow
def test_posterior_predictive_trh(trh, tmp_path):
    """The posterior predicts the held-out window from its draws plus their out-of-sample errors over the fitted
    period: validation.csv with the band's coverage and width, predictive.csv per timestamp and sensor; --predict
    any other period (modest chain settings: the bands, not the chain, are under test)."""
    from wallcal.analysis.posterior import posterior
    from wallcal.cli import main

    res = calibrate(trh, progress=False)
    res.write(tmp_path / "cal")
    p = posterior(
        trh, x_start=res.x_opt, walkers=16, steps=40, progress=False, nonunique_candidates=16, predictive_draws=60
    )
    p.write_into(tmp_path)
    v = pd.read_csv(tmp_path / "validation.csv").set_index("sensor")
    assert list(v.columns) == ["rmse", "mbe", "n", "coverage_95", "band_width_95"]
    row = v.loc["interface"]
    assert row["n"] == 2016 and row["rmse"] <= 0.25
    # measured figures (docs/identifiability.md, default chain): coverage 1.000 with a 1.17 K band (0.999, 0.83 K
    # from the in-sample errors alone) - this third is predicted better than the rest of the record (RMSE 0.15 K
    # against 0.21-0.35 K for the other thirds held out, bench/coverage_folds.py), so the upper limit of 99 % is not
    # met here and not asserted
    assert 0.85 <= row["coverage_95"] and 0.9 < row["band_width_95"] < 1.4, row
    b = pd.read_csv(tmp_path / "predictive.csv")
    assert list(b.columns) == ["timestamp", "sensor", "measured", "median", "p2.5", "p97.5"]
    assert len(b) == 2016 and (b["p2.5"] <= b["median"]).all() and (b["median"] <= b["p97.5"]).all()
    out = tmp_path / "post"
    argv = ["posterior", str(TRH), "--from", str(tmp_path / "cal"), "--walkers", "16", "--steps", "30"]
    assert main(argv + ["--predict", "2021-01-20", "2021-01-21T23:50", "--out", str(out), "--quiet"]) == 0
    s = pd.read_csv(out / "predictive_summary.csv").set_index("sensor")
    assert 280 < s.loc["interface", "n"] <= 288 and not (out / "validation.csv").exists()
    assert main(argv + ["--predict", "2021-01-20", "yesterday-ish", "--out", str(out), "--quiet"]) == 2


@needs_passys
@pytest.mark.slow
def test_posterior_predictive_passys_heat_and_moisture(passys_moisture_diagnosis):
    """The coupled model's bands on the held-out days (modest chain: T_4 0.997, T_8 0.959, T_12 0.848 with bands of
    0.69-0.76 K; default chain in docs/identifiability.md), four times narrower than the heat-only structure's: every
    temperature sensor covered at 80 % or more, T_8 inside 85-99 %; the self-check rejects the structure (the vapour
    resistance factor held at its floor of 1), so the report does not present these intervals as trustworthy."""
    from wallcal.analysis.posterior import posterior

    d = passys_moisture_diagnosis
    x0 = np.array([d.x[n] for n in d.study.calibration.names])
    p = posterior(
        d.study, x_start=x0, walkers=16, steps=40, progress=False, nonunique_candidates=16, predictive_draws=60
    )
    v = p.predictive.table.set_index("sensor")
    temps = ["T_4", "T_8", "T_12"]
    assert (v.loc[temps, "coverage_95"] >= 0.8).all() and (v.loc[temps, "band_width_95"] < 0.9).all(), v
    assert 0.85 <= v.loc["T_8", "coverage_95"] <= 0.99 and (v.loc[temps, "rmse"] < 0.3).all(), v
    assert p.structure["rejected"] and "vapour_resistance_factor[wood_fibre]" in p.structure["statement"]


@needs_passys
@pytest.mark.slow
def test_posterior_predictive_passys_as_measured():
    """PASSYS with the face offset at 0, the structure diagnose adopts (offset[faces]): the 95 % bands cover at least
    85 % of the held-out points of every temperature sensor. They are too wide on this window (default chain: 1.00
    each with bands of 2.9-3.6 K; docs/identifiability.md), which the model predicts better than the rest of the
    record (bench/coverage_folds.py: 0.69-0.77 and 0.89-1.00 on the first two thirds held out), so the upper limit
    of 99 % is not met here and not asserted."""
    from wallcal.analysis.posterior import posterior

    s = _passys_as_measured()
    d = diagnose(s, progress=False)
    x0 = np.array([d.x[n] for n in d.study.calibration.names])
    p = posterior(
        d.study, x_start=x0, walkers=16, steps=40, progress=False, nonunique_candidates=16, predictive_draws=60
    )
    v = p.predictive.table.set_index("sensor")
    for t in ("T_4", "T_8", "T_12"):
        assert 0.85 <= v.loc[t, "coverage_95"] and v.loc[t, "band_width_95"] < 4.0, v
        assert v.loc[t, "rmse"] < 0.7


def test_report_shows_the_held_out_window_beside_the_fitted_period(trh, tmp_path):
    from wallcal.report import HELD_OUT_TITLE, held_out_table, write_report
    from wallcal.workflow import StageOutput

    m = pd.DataFrame({"base": [0.55], "calibrated": [0.2]}, index=pd.Index(["interface"], name="signal"))
    v = pd.DataFrame({"sensor": ["interface"], "rmse": [0.116], "mbe": [0.064], "n": [2016]})
    t = held_out_table(m["calibrated"], v)
    assert list(t.columns) == ["fitted RMSE", "held-out RMSE", "held-out MBE", "held-out n"]
    so = StageOutput("calibration", "Automatic calibration", text=["least-squares"])
    so.tables += [("Calibrated properties", pd.DataFrame({"x": [1.0]}), ()), ("RMSE", m, ()), (HELD_OUT_TITLE, t, ())]
    data = StageOutput("data", "Data")
    data.tables.append(("Measured", pd.DataFrame({"min": [-5.0], "max": [5.0]}, index=["interface"]), ()))
    page = write_report(trh, [data, so], tmp_path / "index.html").read_text()
    assert "of which 2021-02-02 00:05:00 to 2021-02-15 23:55:00 held out for validation" in page
    assert "RMSE fitted period -&gt; held-out window: interface 0.200 -&gt; 0.116" in page
    assert HELD_OUT_TITLE in page


def test_response_time_is_a_first_order_lag(trh):
    """A probe's response time tau filters its simulated series: m_t = m_(t-1) + (1 - exp(-step/tau)) (x_t -
    m_(t-1)); tau 0 leaves it alone. The candidate is proposed for every temperature target."""
    from wallcal.analysis.diagnose_candidates import propose
    from wallcal.calibration.objective import Evaluator, first_order_lag

    x = np.zeros((2, 50))
    x[:, 10:] = 1.0
    y = first_order_lag(x, 600.0, np.array([0.0, 1200.0]))
    assert np.array_equal(y[0], x[0])
    assert y[1][10] == pytest.approx(1 - np.exp(-0.5)) and y[1][12] == pytest.approx(1 - np.exp(-1.5))
    raw = copy.deepcopy(trh.raw)
    raw["calibration"]["parameters"].append({"sensor": "interface", "property": "response_time", "bounds": [0, 3600]})
    sp = parse_space(trh, raw["calibration"])
    assert sp.names[-1] == "response_time[interface]" and sp.offsets(sp.base[None]).tolist() == [[0.0]]
    ev = Evaluator(prepare(trh), sp)
    x0 = sp.base.copy()
    x1 = x0.copy()
    x1[-1] = 1800.0
    s0, s1 = ev.simulate(np.array([x0, x1]))[:, 0]
    assert np.allclose(s1, first_order_lag(s0[None], 600.0, np.array([1800.0]))[0])
    assert not np.allclose(s0, s1)
    bad = copy.deepcopy(trh.raw)
    bad["calibration"]["parameters"].append({"sensor": "interface", "property": "response_time", "bounds": [-5, 60]})
    with pytest.raises(StudyError, match="a response time is >= 0 s"):
        parse_study(bad, base_dir=TRH.parent)
    assert "response_time[interface]" in [e.name for e in propose(trh, trh.calibration)]


def test_simulate_scores_the_held_out_window(trh, tmp_path, capsys):
    """``wallcal simulate`` of a study with a window: the window is left out of metrics.csv and scored on its own
    in validation.csv (the same figures as :func:`score_wall`), and the table is printed."""
    from wallcal.cli import main

    out = tmp_path / "sim"
    assert main(["simulate", str(TRH), "--out", str(out)]) == 0
    assert "Held-out window" in capsys.readouterr().out
    got = pd.read_csv(out / "validation.csv")
    assert list(got.columns) == list(VALIDATION_COLUMNS)
    want = score_wall(trh)
    np.testing.assert_allclose(got["rmse"], want["rmse"], rtol=1e-5)
    assert (got["n"] == want["n"]).all() and (got["n"] > 2000).all()

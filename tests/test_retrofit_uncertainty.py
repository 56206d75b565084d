"""Retrofit intervals from posterior draws (``--from`` a posterior output)."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from retrofit_helpers import study_with_retrofit, write_epw, year_temperature
from wallcal import load_study, weather
from wallcal.analysis.posterior_outputs import write_samples
from wallcal.calibration.space import parse_space
from wallcal.cli import main
from wallcal.outputs import format_entries
from wallcal.retrofitting import boundary, run

BODY = """
[retrofit]
weather = "w.epw"
samples = 24
[[retrofit.variants]]
name = "as built"
[[retrofit.variants]]
name = "EPS 100"
add_exterior = [{ material = "EPS", thickness = 0.1 }]
"""


def _posterior_dir(study, d, seed=0):
    """A posterior output as ``wallcal posterior`` writes it (chain.npz in unit coordinates, posterior.json)."""
    sp = parse_space(study)
    chain = np.random.default_rng(seed).random((30, 8, sp.n))
    write_samples(d, sp, chain, burn=10, thin=2)
    return sp, chain


@pytest.fixture(scope="module")
def posterior_run(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("post")
    t = year_temperature(24 * 5)
    ghi = np.clip(400 * np.sin(2 * np.pi * (np.arange(len(t)) % 24 - 6) / 24), 0, None)
    write_epw(tmp / "w.epw", t, ghi=ghi, dni=ghi, dhi=0.3 * ghi)
    study = load_study(study_with_retrofit(tmp, BODY))
    sp, chain = _posterior_dir(study, tmp / "post")
    res = run.retrofit(study, from_dir=tmp / "post", out=tmp / "out")
    return study, sp, chain, res, tmp


def test_draws_are_the_thinned_chain_after_burn_in(posterior_run):
    study, sp, chain, res, _ = posterior_run
    flat = chain[10::2].reshape(-1, sp.n)  # 10 steps x 8 walkers = 80 draws; 24 of them, evenly spread
    S = res.samples
    assert len(S.walls) == 24 and S.values.shape == (24, sp.n)
    pick = np.unique(np.linspace(0, len(flat) - 1, 24).round().astype(int))
    np.testing.assert_allclose(S.values, sp.lower + flat[pick] * (sp.upper - sp.lower))
    j = sp.names.index("conductivity[5,8]")
    w = S.walls[3]
    assert w.layers[w.layer_index("5")].conductivity == w.layers[w.layer_index("8")].conductivity == S.values[3, j]
    med = np.median(sp.lower + flat * (sp.upper - sp.lower), axis=0)
    assert S.point.layers[S.point.layer_index("7")].conductivity == pytest.approx(
        med[sp.names.index("conductivity[7]")]
    )


def test_intervals_hold_the_point_and_the_batch_equals_single_runs(posterior_run):
    study, sp, chain, res, tmp = posterior_run
    tab = pd.read_csv(tmp / "out" / "variants.csv")
    assert (tab["annual_loss_p05"] <= tab["annual_loss_kWh_m2"]).all()
    assert (tab["annual_loss_kWh_m2"] <= tab["annual_loss_p95"]).all()
    assert (tab["annual_loss_p95"] - tab["annual_loss_p05"] > 0).all()
    # the EPS variant's known added resistance narrows the interval
    width = tab["annual_loss_p95"] - tab["annual_loss_p05"]
    assert width[1] < width[0]
    # one draw run alone (on the same grid, the point wall's) gives the loss the batch gave it
    v = res.variants[0]
    wx = weather.read_weather(tmp / "w.epw")
    yb = boundary.year_boundaries(wx, study.retrofit)
    alone = run.periodic_year([v.wall, res.samples.walls[5]], yb, all_rows=False).annual_loss_kWh_m2
    assert v.sample_losses[5] == pytest.approx(alone[1], rel=1e-9)
    assert v.annual_loss == pytest.approx(alone[0], rel=1e-9)


def test_report_names_the_dominant_properties_and_the_flux_sensor(posterior_run):
    study, sp, chain, res, tmp = posterior_run
    spread = pd.read_csv(tmp / "out" / "spread.csv", index_col=0)
    assert set(sp.names) | {"R total of the sampled wall"} == set(spread.index)
    top = spread.drop(index="R total of the sampled wall")["as built"].abs().idxmax()
    assert top.startswith("conductivity[")  # heat capacities hardly move an annual sum
    assert spread.loc["R total of the sampled wall", "as built"] < -0.8
    text = " ".join(res.notes())
    assert "heat-flux sensor" in text and "common scale" in text and top in text
    assert (tmp / "out" / "sample_losses.csv").exists()


def test_cli_from_posterior_with_samples_option(posterior_run, capsys):
    study, sp, chain, res, tmp = posterior_run
    code = main(
        [
            "retrofit",
            str(study.path),
            "--from",
            str(tmp / "post"),
            "--samples",
            "5",
            "--out",
            str(tmp / "o5"),
            "--quiet",
        ]
    )
    assert code == 0, capsys.readouterr().err
    assert len(pd.read_csv(tmp / "o5" / "sample_losses.csv")) == 5


def test_wallcal_run_finds_the_study_s_own_posterior_output(tmp_path):
    write_epw(tmp_path / "w.epw", year_temperature(48))
    study = load_study(study_with_retrofit(tmp_path, BODY))
    assert run.find_posterior(study)[0] is None and "no posterior output" in run.find_posterior(study)[1]
    post = tmp_path / "posterior"
    _posterior_dir(study, post)
    (post / "manifest.json").write_text(json.dumps({"study_sha256": "0" * 64}))
    found, why = run.find_posterior(study)
    assert found is None and "another version of the study file" in why
    (post / "manifest.json").write_text(json.dumps({"study_sha256": study.sha256}))
    found, why = run.find_posterior(study)  # a posterior of a wallcal before format versions
    assert found is None and "without a format version" in why
    (post / "manifest.json").write_text(
        json.dumps({"study_sha256": study.sha256, "command": "posterior", **format_entries("posterior")})
    )
    assert run.find_posterior(study) == (post.resolve(), "")

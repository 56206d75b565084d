"""ISO 9869-1 on a study's data (wallcal.standards.insitu) as a library call: the window, gap filling, the
choice of sensor, and every field of the outputs, against the average method run here on the same series."""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pandas as pd
import pytest

import wallcal
from conftest import EXAMPLE
from wallcal.data import load_measurements
from wallcal.errors import DataError, StudyError
from wallcal.standards import iso9869
from wallcal.standards.insitu import iso9869_for_study


@pytest.fixture(scope="module")
def study():
    return wallcal.load_study(EXAMPLE)


@pytest.fixture(scope="module")
def meas(study):
    return load_measurements(study)


def _with_frame(meas, frame):
    return dataclasses.replace(meas, frame=frame)


def test_window_is_the_study_period_half_open_and_the_method_is_run_on_it(study, meas):
    r = iso9869_for_study(study, measurements=meas)
    f = meas.frame
    sel = f[(f.index >= pd.Timestamp(study.period.start)) & (f.index < pd.Timestamp(study.period.end))]
    assert (r.start, r.end) == (pd.Timestamp(study.period.start), pd.Timestamp(study.period.end))
    assert len(r.times_s) == len(sel) == 8 * 288 and r.times_s[0] == 0.0 and r.times_s[-1] == (len(sel) - 1) * 300
    ref = iso9869.average_method(
        r.times_s, sel["qi"].to_numpy(), sel["interior"].to_numpy(), sel["exterior"].to_numpy(), wall=study.wall
    )
    assert r.res.r_value == ref.r_value and r.res.r_storage_corrected == ref.r_storage_corrected
    assert r.u == pytest.approx(1 / (0.13 + ref.r_value + 0.04), rel=1e-14) and (r.rsi, r.rse) == (0.13, 0.04)
    assert r.sensor == "qi" and r.face == "interior" and r.n_filled == 0 and not r.whole_record
    assert r.verdict == ref.verdict.statement
    # the exterior sensor, over the whole record
    r = iso9869_for_study(study, face="exterior", whole_record=True, measurements=meas)
    assert r.sensor == "qe" and (r.start, r.end) == (f.index[0], f.index[-1]) and len(r.times_s) == len(f) - 1
    ref = iso9869.average_method(
        r.times_s,
        f["qe"].to_numpy()[:-1],
        f["interior"].to_numpy()[:-1],
        f["exterior"].to_numpy()[:-1],
        wall=study.wall,
        q_side="exterior",
    )
    assert r.res.r_value == ref.r_value and r.res.r_storage_corrected == ref.r_storage_corrected


def test_short_gaps_are_filled_in_time_long_ones_and_ends_refused(study, meas):
    f = meas.frame.copy()
    i0 = f.index.get_loc(pd.Timestamp("2025-06-01 12:00"))
    f.iloc[i0 : i0 + 3, f.columns.get_loc("qi")] = np.nan  # 15 min: filled
    f.iloc[i0 + 10, f.columns.get_loc("interior")] = np.nan
    r = iso9869_for_study(study, measurements=_with_frame(meas, f))
    assert r.n_filled == 4
    q = r.selection["qi"]
    a, b = meas.frame["qi"].iloc[i0 - 1], meas.frame["qi"].iloc[i0 + 3]
    np.testing.assert_allclose(q.loc[f.index[i0 : i0 + 3]], a + (b - a) * np.arange(1, 4) / 4, rtol=1e-12)
    # a gap of max_gap (7200 s) counts its bridging interval: 23 missing readings need 24 x 300 s = 7200 s: filled
    g = meas.frame.copy()
    g.iloc[i0 : i0 + 23, g.columns.get_loc("qi")] = np.nan
    assert iso9869_for_study(study, measurements=_with_frame(meas, g)).n_filled == 23
    g.iloc[i0 : i0 + 24, g.columns.get_loc("qi")] = np.nan  # 24 missing: 7500 s > 7200 s
    with pytest.raises(DataError) as exc:
        iso9869_for_study(study, measurements=_with_frame(meas, g))
    assert str(exc.value) == (
        f"column 'qi' is missing 24 reading(s) from {f.index[i0]} (longer than data.max_gap = 7200 s); "
        "the average method needs a complete series: move the period or fill the data"
    )
    h = meas.frame.copy()
    j = h.index.get_loc(pd.Timestamp(study.period.start))
    h.iloc[j, h.columns.get_loc("exterior")] = np.nan  # the first reading of the window
    with pytest.raises(
        DataError, match=r"column 'exterior' is missing 1 reading\(s\) from .* \(at an end of the window\)"
    ):
        iso9869_for_study(study, measurements=_with_frame(meas, h))
    with pytest.raises(DataError, match=r"the analysis window .* holds 1 reading\(s\); need at least 2"):
        iso9869_for_study(study, measurements=_with_frame(meas, meas.frame.iloc[:2]), whole_record=True)


def test_sensor_choice_and_its_errors(study, meas):
    assert iso9869_for_study(study, sensor="qi", measurements=meas).sensor == "qi"
    with pytest.raises(StudyError, match=r"--sensor: 'qx' is not a heat_flux sensor at the interior face; .*qi"):
        iso9869_for_study(study, sensor="qx", measurements=meas)
    no_flux = dataclasses.replace(study, sensors=tuple(s for s in study.sensors if s.quantity != "heat_flux"))
    with pytest.raises(StudyError, match=r"no heat_flux sensor at the interior face; add a \[\[sensors\]\] entry"):
        iso9869_for_study(no_flux, measurements=meas)
    with pytest.raises(StudyError, match="the study has none there"):
        iso9869_for_study(no_flux, sensor="qi", measurements=meas)
    only_qe = dataclasses.replace(study, sensors=tuple(s for s in study.sensors if s.name != "qi"))
    with pytest.raises(
        StudyError,
        match=r"no heat_flux sensor at the interior face; heat_flux sensors in the study: "
        r"qe \(exterior\) \(use --face\)",
    ):
        iso9869_for_study(only_qe, measurements=meas)
    qi = study.sensor("qi")
    two = dataclasses.replace(study, sensors=(*study.sensors, dataclasses.replace(qi, name="qi2")))
    with pytest.raises(
        StudyError, match=r"sensors: 2 heat_flux sensors at the interior face \(qi, qi2\); choose one with --sensor"
    ):
        iso9869_for_study(two, measurements=meas)


def test_json_and_criteria_table_carry_every_figure(study, meas, tmp_path):
    r = iso9869_for_study(study, measurements=meas)
    res = r.res
    j = r.to_json()
    assert j["study"] == study.name and (j["face"], j["sensor"]) == ("interior", "qi")
    assert (j["window_start"], j["window_end"], j["window"]) == (
        "2025-05-30 00:00:00",
        "2025-06-07 00:00:00",
        "study period",
    )
    assert (j["readings"], j["time_step_s"], j["duration_h"], j["filled_values"]) == (2304, 300.0, 192.0, 0)
    assert j["r_value_m2K_W"] == res.r_value and j["r_storage_corrected_m2K_W"] == res.r_storage_corrected
    assert (j["u_value_W_m2K"], j["rsi_m2K_W"], j["rse_m2K_W"]) == (r.u, 0.13, 0.04)
    assert j["areal_heat_capacity_J_m2K"] == res.areal_heat_capacity and j["heavy"] is res.heavy
    assert j["stored_heat_change_J_m2"] == res.stored_heat_change_J_m2
    assert j["heat_through_J_m2"] == res.heat_through_J_m2
    assert j["applicable"] is False and j["statement"] == res.verdict.statement
    assert j["failing"] == ["last_24h", "first_last_two_thirds", "storage"]
    assert [c["name"] for c in j["criteria"]] == [c.name for c in res.verdict.criteria]
    for cj, c in zip(j["criteria"], res.verdict.criteria, strict=True):
        assert cj == {
            "name": c.name,
            "description": c.description,
            "required": c.required,
            "passed": c.passed,
            "value": c.value,
            "limit": c.limit,
            "detail": c.detail,
        }
    assert iso9869_for_study(study, whole_record=True, measurements=meas).to_json()["window"] == "whole record"
    t = r.criteria_table()
    assert list(t.index) == ["duration", "last_24h", "first_last_two_thirds", "storage", "whole_days"]
    assert list(t.columns) == ["result", "value", "limit", "detail"]
    assert list(t["result"]) == ["pass", "FAIL", "FAIL", "FAIL", "pass"]
    v = {c.name: c.value for c in res.verdict.criteria}
    assert t.loc["duration", "value"] == "192 h" and t.loc["duration", "limit"] == "72 h"
    assert t.loc["last_24h", "value"] == f"{100 * v['last_24h']:.1f} %" and t.loc["last_24h", "limit"] == "5.0 %"
    assert t.loc["storage", "value"] == f"{100 * v['storage']:.1f} %"
    assert t.loc["whole_days", "limit"] == "24 h"
    # written files: the running estimate per reading, the JSON (strict: no NaN), the figure
    names = r.write_into(tmp_path)
    assert names == ["iso9869.csv", "iso9869.json", "iso9869.png"]
    csv = pd.read_csv(tmp_path / "iso9869.csv", index_col="timestamp")
    assert list(csv.columns) == ["elapsed_h", "q_W_m2", "t_si_C", "t_se_C", "r_running_m2K_W"]
    assert csv.index[0] == "2025-05-30T00:00:00" and len(csv) == 2304
    np.testing.assert_allclose(csv["elapsed_h"], r.times_s / 3600, rtol=1e-5)  # written with 6 digits
    np.testing.assert_allclose(csv["q_W_m2"], r.selection["qi"], rtol=1e-5, atol=1e-9)
    np.testing.assert_allclose(csv["t_si_C"], r.selection["interior"], rtol=1e-5)
    np.testing.assert_allclose(csv["t_se_C"], r.selection["exterior"], rtol=1e-5)
    np.testing.assert_allclose(csv["r_running_m2K_W"], res.r_running, rtol=1e-5)
    assert json.loads((tmp_path / "iso9869.json").read_text()) == json.loads(json.dumps(j))
    assert (tmp_path / "iso9869.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_criteria_table_statuses_and_values_when_not_evaluated(study, meas):
    """A light element: storage and whole days are not required (and say so); a value that is not a number."""
    r = iso9869_for_study(study, measurements=meas)
    light = dataclasses.replace(
        r,
        res=iso9869.average_method(
            r.times_s[:200], r.selection["qi"].to_numpy()[:200], r.selection["interior"].to_numpy()[:200],
            r.selection["exterior"].to_numpy()[:200], heavy=False,
        ),
    )  # fmt: skip
    t = light.criteria_table()
    assert t.loc["storage", "result"] == "not required" and math.isnan(t.loc["storage", "value"])
    assert t.loc["whole_days", "result"] == "FAIL (not required)"
    assert t.loc["last_24h", "result"] == "FAIL" and math.isnan(t.loc["first_last_two_thirds", "value"])
    j = light.to_json()
    assert j["criteria"][3]["value"] is None and j["criteria"][3]["passed"] is None
    inf = dataclasses.replace(light.res.verdict.criteria[1], value=float("inf"))  # a deviation against a zero reference
    from wallcal.standards.insitu import _crit_value, _json_num

    assert _crit_value(inf) == "inf" and _json_num(float("inf")) is None and _json_num(2) == 2.0


def test_needs_surface_temperatures_on_both_faces(study, meas):
    air = dataclasses.replace(study, interior=dataclasses.replace(study.interior, type="air_temperature"))
    with pytest.raises(StudyError) as exc:
        iso9869_for_study(air, measurements=meas)
    assert str(exc.value).endswith(
        "ISO 9869 needs measured surface temperatures on both faces, but boundary.interior.type is "
        "'air_temperature' (not \"surface_temperature\")"
    )


def _axes_of(r, hours=None, title="Campaign A"):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from wallcal.standards.insitu import _draw

    fig, ax = plt.subplots()
    try:
        _draw(ax, r.times_s / 3600 if hours is None else hours, r.res, r.sensor, r.face, title)
        fig.canvas.draw()
        return ax, fig
    finally:
        plt.close(fig)


def test_the_figure_shows_the_running_estimate_the_band_and_the_last_day(study, meas):
    r = iso9869_for_study(study, measurements=meas)
    res = r.res
    ax, _ = _axes_of(r)
    hours = r.times_s / 3600
    (line,) = [ln for ln in ax.get_lines() if ln.get_label() == "running estimate"]
    np.testing.assert_array_equal(line.get_xdata(), hours)
    np.testing.assert_array_equal(line.get_ydata(), res.r_running)
    (mark,) = [ln for ln in ax.get_lines() if ln.get_label() == "24 h before the end"]
    assert list(mark.get_xdata()) == [192.0 - 24, 192.0 - 24]
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    assert labels == [f"final R = {res.r_value:.2f} m2K/W ± 5 %", "running estimate", "24 h before the end"]
    ys = ax.patches[0].get_extents()  # the band's span in display units: check through the data transform
    lo_band, hi_band = ax.transData.inverted().transform([[0, ys.y0], [0, ys.y1]])[:, 1]
    assert (lo_band, hi_band) == (pytest.approx(0.95 * res.r_value), pytest.approx(1.05 * res.r_value))
    late = res.r_running[hours >= 24.0]
    lo, hi = min(late.min(), 0.9 * res.r_value), max(late.max(), 1.1 * res.r_value)
    assert ax.get_ylim() == (pytest.approx(lo - 0.05 * (hi - lo)), pytest.approx(hi + 0.05 * (hi - lo)))
    assert ax.get_xlabel() == "elapsed time [h]" and ax.get_ylabel() == "R (surface to surface) [m2K/W]"
    assert ax.get_title() == f"Campaign A: ISO 9869-1 average method (qi, interior face)\n{res.verdict.statement}"
    # a record of a day or less has no mark, and the axis is scaled from a quarter of it on; no title prefix
    short = dataclasses.replace(
        r,
        times_s=r.times_s[:240],
        res=iso9869.average_method(
            r.times_s[:240], r.selection["qi"].to_numpy()[:240], r.selection["interior"].to_numpy()[:240],
            r.selection["exterior"].to_numpy()[:240], heavy=False,
        ),
    )  # fmt: skip
    ax, _ = _axes_of(short, title="")
    assert [ln.get_label() for ln in ax.get_lines()] == ["running estimate"]
    h = short.times_s / 3600
    late = short.res.r_running[h >= 0.25 * 20.0]
    rv = short.res.r_value
    lo, hi = min(late.min(), 0.9 * rv), max(late.max(), 1.1 * rv)
    assert ax.get_ylim() == (pytest.approx(lo - 0.05 * (hi - lo)), pytest.approx(hi + 0.05 * (hi - lo)))
    assert ax.get_title().startswith("ISO 9869-1 average method (qi, interior face)\n")


def test_errors_name_the_study_file(study, meas):
    no_flux = dataclasses.replace(study, sensors=tuple(s for s in study.sensors if s.quantity != "heat_flux"))
    ext_air = dataclasses.replace(study, exterior=dataclasses.replace(study.exterior, type="air_temperature"))
    two_qe = dataclasses.replace(
        study, sensors=(*no_flux.sensors, study.sensor("qe"), dataclasses.replace(study.sensor("qe"), name="qe2"))
    )
    cases = [
        (no_flux, {}, 'no heat_flux sensor at the interior face; add a [[sensors]] entry with quantity = "heat_flux" '
         'and face = "interior"'),
        (no_flux, {"sensor": "qi"}, "--sensor: 'qi' is not a heat_flux sensor at the interior face; "
         "the study has none there"),
        (two_qe, {}, "no heat_flux sensor at the interior face; heat_flux sensors in the study: qe (exterior), "
         "qe2 (exterior) (use --face)"),
        (two_qe, {"face": "exterior"}, "sensors: 2 heat_flux sensors at the exterior face (qe, qe2); "
         "choose one with --sensor"),
        (ext_air, {}, "but boundary.exterior.type is 'air_temperature' (not \"surface_temperature\")"),
    ]  # fmt: skip
    for s, kw, text in cases:
        with pytest.raises(StudyError) as exc:
            iso9869_for_study(s, measurements=meas, **kw)
        assert text in str(exc.value)
        assert exc.value.source == str(study.path)


def test_gap_messages_name_the_longest_gap_and_the_window_end(study, meas):
    f = meas.frame.copy()
    i0 = f.index.get_loc(pd.Timestamp("2025-06-01 12:00"))
    col = f.columns.get_loc("qi")
    f.iloc[i0 : i0 + 2, col] = np.nan  # short
    f.iloc[i0 + 100 : i0 + 130, col] = np.nan  # the longest: 30 readings
    with pytest.raises(DataError, match=rf"column 'qi' is missing 30 reading\(s\) from {f.index[i0 + 100]} \(longer"):
        iso9869_for_study(study, measurements=_with_frame(meas, f))
    g = meas.frame.copy()
    last = g.index.get_loc(pd.Timestamp(study.period.end)) - 1  # the last reading of the half-open window
    g.iloc[last, g.columns.get_loc("interior")] = np.nan
    with pytest.raises(DataError, match=r"column 'interior' is missing 1 reading\(s\) .*\(at an end of the window\)"):
        iso9869_for_study(study, measurements=_with_frame(meas, g))
    g = meas.frame.copy()
    g.iloc[last - 1, g.columns.get_loc("interior")] = np.nan  # the last but one: bridged
    assert iso9869_for_study(study, measurements=_with_frame(meas, g)).n_filled == 1
    # two readings are enough
    r = iso9869_for_study(study, measurements=_with_frame(meas, meas.frame.iloc[:3]), whole_record=True)
    assert len(r.times_s) == 2 and r.times_s.dtype == np.float64


def test_u_value_only_for_a_positive_resistance(study, meas):
    f = meas.frame.copy()
    f["qi"] = -f["qi"]  # heat flowing the other way than the temperatures say: R < 0
    r = iso9869_for_study(study, measurements=_with_frame(meas, f))
    assert r.res.r_value < 0 and math.isnan(r.u) and r.to_json()["u_value_W_m2K"] != r.to_json()["u_value_W_m2K"]
    f["qi"] = meas.frame["qi"] * 20.0  # 20 times the flux: R about 0.46 m2K/W, below 1
    r = iso9869_for_study(study, measurements=_with_frame(meas, f))
    assert 0 < r.res.r_value < 1 and r.u == pytest.approx(1 / (0.17 + r.res.r_value), rel=1e-14)


def test_criteria_table_of_a_required_criterion_not_evaluated(study, meas):
    r = iso9869_for_study(study, measurements=meas)
    sel = r.selection
    heavy_no_wall = iso9869.average_method(
        r.times_s, sel["qi"].to_numpy(), sel["interior"].to_numpy(), sel["exterior"].to_numpy(), heavy=True
    )
    t = dataclasses.replace(r, res=heavy_no_wall).criteria_table()
    assert t.loc["storage", "result"] == "not evaluated" and t.loc["storage", "limit"] == "5.0 %"
    v = {c.name: c.value for c in heavy_no_wall.verdict.criteria}
    assert t.loc["first_last_two_thirds", "value"] == f"{100 * v['first_last_two_thirds']:.1f} %"


def test_written_files_format_and_the_figure_arguments(study, meas, tmp_path, monkeypatch):
    from wallcal.standards import insitu

    r = iso9869_for_study(study, measurements=meas)
    seen = {}
    monkeypatch.setattr(insitu, "_figure", lambda *a: seen.setdefault("args", a))
    r.write_into(tmp_path)
    path, hours, res, sensor, face, title = seen["args"]
    assert path == tmp_path / "iso9869.png" and (sensor, face, title) == ("qi", "interior", study.name)
    np.testing.assert_array_equal(hours, r.times_s / 3600.0)
    assert res is r.res
    text = (tmp_path / "iso9869.json").read_text()
    assert text.startswith('{\n  "study": ') and text == json.dumps(r.to_json(), indent=2)
    rows = (tmp_path / "iso9869.csv").read_text().splitlines()
    first = rows[1].split(",")
    assert first[0] == "2025-05-30T00:00:00" and first[1] == "0"
    assert first[2] == f"{r.selection['qi'].iloc[0]:.6g}" and first[5] == f"{r.res.r_running[0]:.6g}"


def test_no_u_value_for_a_zero_resistance(study, meas):
    f = meas.frame.copy()
    f["exterior"] = f["interior"]  # no temperature difference at all: R = 0, U undefined
    r = iso9869_for_study(study, measurements=_with_frame(meas, f))
    assert r.res.r_value == 0.0 and math.isnan(r.u)


def test_errors_of_a_study_without_a_file_have_no_source(study, meas):
    mem = dataclasses.replace(study, path=None)  # a study built in memory
    no_flux = dataclasses.replace(mem, sensors=tuple(s for s in mem.sensors if s.quantity != "heat_flux"))
    two = dataclasses.replace(mem, sensors=(*mem.sensors, dataclasses.replace(mem.sensor("qi"), name="qi2")))
    air = dataclasses.replace(mem, interior=dataclasses.replace(mem.interior, type="air_temperature"))
    for s, kw in ((no_flux, {}), (no_flux, {"sensor": "qi"}), (two, {}), (air, {})):
        with pytest.raises(StudyError) as exc:
            iso9869_for_study(s, measurements=meas, **kw)
        assert exc.value.source is None, kw


def test_both_faces_without_surface_temperatures_are_named(study, meas):
    both = dataclasses.replace(
        study,
        interior=dataclasses.replace(study.interior, type="air_temperature"),
        exterior=dataclasses.replace(study.exterior, type="air_temperature"),
    )
    with pytest.raises(StudyError) as exc:
        iso9869_for_study(both, measurements=meas)
    assert exc.value.problems == [
        "ISO 9869 needs measured surface temperatures on both faces, but boundary.exterior.type is "
        "'air_temperature' and boundary.interior.type is 'air_temperature' (not \"surface_temperature\")"
    ]


def test_gap_message_names_the_longest_gap_when_a_shorter_one_follows(study, meas):
    f = meas.frame.copy()
    i0 = f.index.get_loc(pd.Timestamp("2025-06-01 12:00"))
    col = f.columns.get_loc("qi")
    f.iloc[i0 : i0 + 30, col] = np.nan  # the longest: 30 readings
    f.iloc[i0 + 100 : i0 + 102, col] = np.nan  # a later short one
    with pytest.raises(DataError, match=rf"column 'qi' is missing 30 reading\(s\) from {f.index[i0]} \(longer"):
        iso9869_for_study(study, measurements=_with_frame(meas, f))


def test_the_figure_file_is_drawn_from_its_arguments(study, meas, tmp_path, monkeypatch):
    from wallcal.standards import insitu

    r = iso9869_for_study(study, measurements=meas)
    seen = {}
    draw = insitu._draw

    def spy(ax, hours, res, sensor, face, title):
        seen["args"] = (hours, res, sensor, face, title)
        draw(ax, hours, res, sensor, face, title)

    monkeypatch.setattr(insitu, "_draw", spy)
    hours = r.times_s / 3600.0
    insitu._figure(tmp_path / "f.png", hours, r.res, "qi", "interior", "Campaign A")
    assert seen["args"][2:] == ("qi", "interior", "Campaign A") and seen["args"][1] is r.res
    assert seen["args"][0] is hours
    assert (tmp_path / "f.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def _drawn(hours, running, r_end, duration_h):
    """The axes _draw fills for a running estimate made up here."""
    from types import SimpleNamespace

    res = SimpleNamespace(
        r_value=r_end,
        r_running=np.asarray(running, float),
        duration_h=duration_h,
        verdict=SimpleNamespace(statement="made up"),
    )
    return _axes_of(SimpleNamespace(res=res, sensor="q", face="interior"), hours=np.asarray(hours, float))[0]


def test_the_24_h_mark_is_drawn_for_records_longer_than_a_day_only():
    ax = _drawn([0.0, 12.0, 24.0], [1.0, 2.0, 2.0], 2.0, 24.0)
    assert [ln.get_label() for ln in ax.get_lines()] == ["running estimate"]
    ax = _drawn([0.0, 12.0, 24.5], [1.0, 2.0, 2.0], 2.0, 24.5)
    (mark,) = [ln for ln in ax.get_lines() if ln.get_label() == "24 h before the end"]
    assert list(mark.get_xdata()) == [0.5, 0.5]


def test_the_axis_is_scaled_from_24_h_or_a_quarter_of_the_record_on_whichever_is_earlier():
    r = 2.0
    # 120 h: the first day is wild; the reading at exactly 24 h is the largest of the rest
    hours = np.arange(0.0, 120.25, 0.25)
    running = np.where(hours < 24.0, 100.0, r)
    running[hours == 24.0] = 2.5
    lo, hi = 0.9 * r, 2.5
    assert _drawn(hours, running, r, 120.0).get_ylim() == pytest.approx((lo - 0.05 * (hi - lo), hi + 0.05 * (hi - lo)))
    # 8 h: scaled from a quarter of it (2 h) on
    hours = np.arange(0.0, 8.25, 0.25)
    running = np.where(hours < 2.0, 100.0, r)
    running[hours == 2.0] = 2.5
    assert _drawn(hours, running, r, 8.0).get_ylim() == pytest.approx((lo - 0.05 * (hi - lo), hi + 0.05 * (hi - lo)))
    # a flat estimate: the axis still spans R +- 10 % (plus a 5 % margin of that span)
    flat = _drawn(hours, np.full(hours.shape, r), r, 8.0).get_ylim()
    assert flat == pytest.approx((0.9 * r - 0.01 * r, 1.1 * r + 0.01 * r))

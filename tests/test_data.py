"""Monitoring data: errors name file and column; gaps, spikes, units, time formats."""

from __future__ import annotations

import tomllib

import numpy as np
import pandas as pd
import pytest

from conftest import EXAMPLE
from wallcal import DataError
from wallcal.data import detect_spikes, load_measurements, summarize
from wallcal.study import parse_study


def study_with(tmp_path, frame: pd.DataFrame | None = None, text: str | None = None, **data_keys):
    raw = tomllib.loads(EXAMPLE.read_text())
    path = tmp_path / "data.csv"
    if text is not None:
        path.write_bytes(text.encode() if isinstance(text, str) else text)
    elif frame is not None:
        frame.to_csv(path, index=False)
    raw["data"]["file"] = str(path)
    raw["data"].update(data_keys)
    raw.pop("calibration")  # its reference wall is not in tmp_path
    return parse_study(raw, base_dir=tmp_path)


@pytest.fixture(scope="module")
def measured():
    return pd.read_csv(EXAMPLE.parent / "measured.csv")


def test_example_measurements(example_study):
    m = load_measurements(example_study)
    assert list(m.frame.columns) == ["exterior", "interior", "T3A", "T2A", "T1A", "qe", "qi"]
    assert len(m.frame) == 4321
    assert len(m.spikes) == 0  # the synthetic campaign has no logger glitches
    s = summarize(m.frame, "2025-05-30", "2025-06-07")
    assert s.loc["T3A", "max"] == pytest.approx(31.22)
    qe = m.frame.loc["2025-05-30":"2025-06-07", "qe"]
    assert s.loc["qe", "effective"] == pytest.approx(np.sqrt(np.mean(qe**2)))


def test_missing_file(tmp_path):
    s = study_with(tmp_path, text="x")
    s = s.replace(data=s.data.__class__(**{**s.data.__dict__, "file": tmp_path / "nope.csv"}))
    with pytest.raises(DataError, match="data.file: file not found"):
        load_measurements(s)


def test_missing_column(tmp_path, measured):
    s = study_with(tmp_path, measured.rename(columns={"T2A": "T2a"}))
    with pytest.raises(DataError, match=r"column 'T2A' \(sensors\[1\]\.column\) not found; did you mean .*'T2a'"):
        load_measurements(s)


def test_non_numeric_value(tmp_path, measured):
    f = measured.astype({"T1A": object})
    f.loc[100, "T1A"] = "err"
    s = study_with(tmp_path, f)
    with pytest.raises(DataError, match=r"column 'T1A' has a non-numeric value 'err' at data row 101 \(line 102\)"):
        load_measurements(s)


def test_duplicate_and_unsorted_timestamps(tmp_path, measured):
    f = measured.copy()
    f.loc[10, "timestamp"] = f.loc[9, "timestamp"]
    with pytest.raises(DataError, match="duplicate timestamp 2025-05-23 00:45:00 at data rows 10 and 11"):
        load_measurements(study_with(tmp_path, f))
    f = measured.copy()
    f.loc[[10, 11], "timestamp"] = f.loc[[11, 10], "timestamp"].to_numpy()
    with pytest.raises(DataError, match="timestamps are not increasing"):
        load_measurements(study_with(tmp_path, f))


def test_period_outside_data(tmp_path, measured):
    s = study_with(tmp_path, measured.iloc[:3000])
    with pytest.raises(DataError, match="is outside the data"):
        load_measurements(s)


def test_gap_too_long_is_an_error_and_short_gaps_are_bridged(tmp_path, measured):
    f = measured.copy()
    f.loc[2100:2140, "TSe"] = np.nan  # 41 samples = 3.4 h
    with pytest.raises(DataError, match=r"column 'TSe' \(boundary.exterior\) has a gap of 3.50 h"):
        load_measurements(study_with(tmp_path, f))
    f = measured.copy()
    f.loc[2100:2110, "TSi"] = np.nan  # 1 h
    m = load_measurements(study_with(tmp_path, f))
    assert len(m.bridged_gaps) == 1 and m.bridged_gaps.iloc[0]["seconds"] == 3600


def test_spike_detected_listed_and_removed(tmp_path, measured):
    f = measured.copy()
    f.loc[2500, "T2A"] += 6.0
    m = load_measurements(study_with(tmp_path, f))
    assert list(m.spikes["signal"]) == ["T2A"]
    assert np.isnan(m.frame["T2A"].iloc[2500])
    m2 = load_measurements(study_with(tmp_path, f, remove_spikes=False))
    assert len(m2.spikes) == 1 and m2.frame["T2A"].iloc[2500] == pytest.approx(f.loc[2500, "T2A"])


def test_detect_spikes_ignores_real_steps():
    x = np.r_[np.zeros(50), np.full(50, 10.0)] + 0.01 * np.sin(np.arange(100))
    assert not detect_spikes(x).any()
    x[30] = 8.0
    assert list(np.flatnonzero(detect_spikes(x))) == [30]


def test_kelvin_elapsed_seconds_and_flux_sign(tmp_path, measured):
    f = measured.copy()
    t0 = pd.Timestamp("2025-05-23")
    f["timestamp"] = (pd.to_datetime(f["timestamp"]) - t0).dt.total_seconds()
    for c in ("TSe", "TSi", "T3A", "T2A", "T1A"):
        f[c] = f[c] + 273.15
    f["qe"] = -f["qe"]
    raw = tomllib.loads(EXAMPLE.read_text())
    path = tmp_path / "d.csv"
    f.to_csv(path, index=False, sep="\t")
    raw["data"].update(file=str(path), time_format="elapsed_seconds", start="2025-05-23T00:00:00")
    raw["boundary"]["exterior"]["unit"] = "K"
    raw["boundary"]["interior"]["unit"] = "K"
    for s in raw["sensors"][:3]:
        s["unit"] = "K"
    raw["sensors"][3]["positive"] = "towards_exterior"
    raw.pop("calibration")  # its reference wall is not in tmp_path
    m = load_measurements(parse_study(raw, base_dir=tmp_path))
    ref = load_measurements(parse_study(tomllib.loads(EXAMPLE.read_text()), base_dir=EXAMPLE.parent))
    pd.testing.assert_frame_equal(m.frame, ref.frame, check_exact=False, atol=1e-9, check_freq=False)


def test_timezone_aware_timestamps(tmp_path, measured):
    f = measured.copy()
    f["timestamp"] = f["timestamp"] + "+01:00"
    with pytest.raises(DataError, match="give data.utc_offset"):
        load_measurements(study_with(tmp_path, f))
    m = load_measurements(study_with(tmp_path, f, utc_offset="+01:00"))
    assert m.frame.index[0] == pd.Timestamp("2025-05-23 00:00")
    f.loc[5, "timestamp"] = f.loc[5, "timestamp"].replace("+01:00", "+02:00")
    with pytest.raises(DataError, match="mixes time-zone offsets"):
        load_measurements(study_with(tmp_path, f, utc_offset="+01:00"))


def test_empty_and_non_utf8_files(tmp_path):
    with pytest.raises(DataError, match="the file is empty"):
        load_measurements(study_with(tmp_path, text=""))
    with pytest.raises(DataError, match="not valid UTF-8"):
        load_measurements(study_with(tmp_path, text=b"timestamp,TSe\n2025-01-01T00:00:00,\xff\xfe\n"))
    with pytest.raises(DataError, match="header but no data rows"):
        load_measurements(study_with(tmp_path, text="timestamp,TSe,TSi\n"))


def test_too_small_time_step_is_a_clear_error(example_study):
    from wallcal import StudyError, prepare

    with pytest.raises(StudyError, match="simulation.time_step: 0.001 s gives"):
        prepare(example_study, time_step=0.001)


# ---------------------------------------------------------------------------- the study keeps its loaded data
def _age(path, seconds):
    """Set the file's modification time ``seconds`` in the past."""
    import os
    import time

    t = time.time_ns() - int(seconds * 1e9)
    os.utime(path, ns=(t, t))


@pytest.fixture()
def counted_reads(monkeypatch):
    import wallcal.data as data_mod

    reads = []
    read_table = data_mod.read_table
    monkeypatch.setattr(data_mod, "read_table", lambda *a, **k: reads.append(a[0]) or read_table(*a, **k))
    return reads


def test_loaded_data_are_kept_until_the_file_changes(tmp_path, measured, counted_reads):
    import dataclasses

    s = study_with(tmp_path, measured)
    _age(s.data.file, 60)
    m1 = load_measurements(s)
    m2 = load_measurements(s)
    assert len(counted_reads) == 1  # the second call did not read the file
    pd.testing.assert_frame_equal(m1.frame, m2.frame)
    # a study with other sensor keys (here an offset) maps the data again
    s_off = s.replace(sensors=(dataclasses.replace(s.sensors[0], offset=1.0),) + s.sensors[1:])
    assert np.allclose(load_measurements(s_off).frame["T3A"], m1.frame["T3A"] + 1.0, equal_nan=True)
    assert len(counted_reads) == 2
    # the file changes (same size, same inode): it is read again
    changed = measured.copy()
    changed["T3A"] = changed["T3A"] + 2.0
    changed.to_csv(s.data.file, index=False)
    _age(s.data.file, 30)
    m3 = load_measurements(s)
    assert np.allclose(m3.frame["T3A"], m1.frame["T3A"] + 2.0, equal_nan=True)
    assert len(counted_reads) == 3
    load_measurements(s)
    assert len(counted_reads) == 3


def test_a_file_written_just_now_is_not_kept(tmp_path, measured, counted_reads):
    """Two writes within one tick of a coarse file-system clock look alike: such a file is read every time."""
    s = study_with(tmp_path, measured)
    load_measurements(s)
    load_measurements(s)
    assert len(counted_reads) == 2


def test_kept_data_cannot_be_changed_by_a_caller(tmp_path, measured):
    s = study_with(tmp_path, measured)
    _age(s.data.file, 60)
    m1 = load_measurements(s)
    before = m1.frame.copy()
    m1.frame.iloc[0, 0] = 999.0
    m1.frame["T3A"] = 0.0
    m1.spikes.loc[len(m1.spikes)] = ["x", pd.Timestamp("2025-01-01"), 1.0, 1.0]
    m1.notes.append("changed")
    with pytest.raises(ValueError, match="read-only"):
        m1.frame["T2A"].to_numpy()[0] = 5.0
    m2 = load_measurements(s)
    pd.testing.assert_frame_equal(m2.frame, before)
    assert m2.notes == [] and "x" not in set(m2.spikes["signal"])

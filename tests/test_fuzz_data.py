"""Property-based tests of the monitoring-data reader (issue 10).

Small CSV files (two days of 10-minute data in the example's columns, any of the three
separators) are written to a temporary directory and corrupted in one random way: a
non-numeric, infinite, huge, empty or true/false cell, a missing or extra column,
duplicated, unsorted, time-zone-mixed or unreadable timestamps, non-UTF-8 bytes, an empty
file, a header without rows, a ragged row, a long gap. The property:
:func:`wallcal.data.load_measurements` either loads the data or raises
:class:`wallcal.errors.DataError` whose message names the file (and the column, for a
corrupted column) - never any other exception.
"""

from __future__ import annotations

import copy
import datetime as dt
import tomllib

import numpy as np
import pandas as pd
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from conftest import EXAMPLE
from wallcal.cli import main
from wallcal.data import load_measurements
from wallcal.errors import DataError, WallcalError
from wallcal.study import parse_study

RAW = tomllib.loads(EXAMPLE.read_text())
RAW.pop("calibration")  # these studies live in temporary folders without the reference wall
COLUMNS = ["TSe", "T3A", "T2A", "T1A", "TSi", "qe", "qi"]
BOUNDARY = {"TSe", "TSi"}
N = 2 * 144 + 1  # two days of 10-minute samples
START = dt.datetime(2025, 5, 29)
FUZZ = settings(
    max_examples=120, deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture]
)


def _clean_rows():
    t = np.arange(N) * 600.0
    rng = np.random.default_rng(0)
    day = np.sin(2 * np.pi * t / 86400)
    vals = {
        "TSe": 15 + 8 * day,
        "T3A": 20 + 4 * day,
        "T2A": 22 + 2 * day,
        "T1A": 23 + day,
        "TSi": 23 + 0.5 * day,
        "qe": -5 + 10 * day,
        "qi": 2 + day,
    }
    rows = []
    for k in range(N):
        stamp = (START + dt.timedelta(seconds=float(t[k]))).isoformat()
        rows.append([stamp] + [f"{vals[c][k] + 0.01 * rng.standard_normal():.3f}" for c in COLUMNS])
    return rows


ROWS = _clean_rows()


def _study(path, tmp, **data_keys):
    raw = copy.deepcopy(RAW)
    raw["data"] = {"file": str(path), "max_gap": 7200, **data_keys}
    raw["period"] = {
        "warmup_start": START,
        "start": START + dt.timedelta(days=1),
        "end": START + dt.timedelta(days=1, hours=12),
    }
    return parse_study(raw, base_dir=tmp)


def _encode(header, rows, sep):
    lines = [sep.join(header)] + [sep.join(r) for r in rows]
    return ("\n".join(lines) + "\n").encode()


def _load(study):
    try:
        return load_measurements(study), None
    except WallcalError as exc:
        return None, exc
    except Exception as exc:  # pragma: no cover - what the tests look for
        pytest.fail(f"load_measurements raised {type(exc).__name__} (not a WallcalError): {exc!r}")


@st.composite
def corrupted_file(draw):
    """(kind, column or None, file bytes, must_fail)."""
    sep = draw(st.sampled_from([",", ";", "\t"]))
    header = ["timestamp"] + COLUMNS
    rows = copy.deepcopy(ROWS)
    kind = draw(
        st.sampled_from(
            [
                "non_numeric",
                "infinite",
                "huge",
                "empty_cell",
                "bool_column",
                "missing_column",
                "extra_column",
                "duplicate_time",
                "unsorted_time",
                "mixed_tz",
                "aware_no_offset",
                "bad_time",
                "empty_time",
                "non_utf8_cell",
                "non_utf8_header",
                "empty_file",
                "header_only",
                "ragged_row",
                "long_gap",
                "valid",
            ]
        )
    )
    r = draw(st.integers(1, N - 2))
    c = draw(st.integers(0, len(COLUMNS) - 1))
    col = COLUMNS[c]
    if kind == "non_numeric":
        rows[r][c + 1] = draw(st.sampled_from(["err", "--", "1.2.3", "12degC", "x1", "0x1F", "++1"]))
        return kind, col, _encode(header, rows, sep), True
    if kind == "infinite":
        rows[r][c + 1] = draw(st.sampled_from(["inf", "-inf", "1e400", "-Infinity"]))
        return kind, col, _encode(header, rows, sep), True
    if kind == "huge":
        for k in range(r, min(r + draw(st.integers(1, 20)), N)):
            rows[k][c + 1] = draw(st.sampled_from(["1e300", "-1e300", "1e16", "123456789012345678901234"]))
        return kind, col, _encode(header, rows, sep), True
    if kind == "empty_cell":  # allowed: skipped in sensors, bridged in boundaries (or a clear error at the ends)
        for k in range(r, min(r + draw(st.integers(1, 30)), N)):
            rows[k][c + 1] = draw(st.sampled_from(["", "NaN", "nan", "NA"]))
        return kind, col, _encode(header, rows, sep), False
    if kind == "bool_column":
        for row in rows:
            row[c + 1] = draw(st.sampled_from(["true", "false", "True"]))
        return kind, col, _encode(header, rows, sep), True
    if kind == "missing_column":
        header = header[: c + 1] + header[c + 2 :]
        rows = [row[: c + 1] + row[c + 2 :] for row in rows]
        return kind, col, _encode(header, rows, sep), True
    if kind == "extra_column":
        header = header + ["comment"]
        rows = [row + [draw(st.sampled_from(["ok", "", "7"]))] for row in rows]
        return kind, None, _encode(header, rows, sep), False
    if kind == "duplicate_time":
        rows[r + 1][0] = rows[r][0]
        return kind, "timestamp", _encode(header, rows, sep), True
    if kind == "unsorted_time":
        rows[r][0], rows[r + 1][0] = rows[r + 1][0], rows[r][0]
        return kind, "timestamp", _encode(header, rows, sep), True
    if kind == "mixed_tz":
        for row in rows:
            row[0] += "+01:00"
        rows[r][0] = rows[r][0].replace("+01:00", draw(st.sampled_from(["+02:00", "Z", ""])))
        return kind, "timestamp", _encode(header, rows, sep), True
    if kind == "aware_no_offset":  # offset-aware stamps without data.utc_offset
        for row in rows:
            row[0] += "+02:00"
        return kind, "timestamp", _encode(header, rows, sep), True
    if kind == "bad_time":
        rows[r][0] = draw(
            st.sampled_from(["2025-05-32T00:00:00", "yesterday", "30/05/2025 10:00", "12345", "2025-05-29T25:00:00"])
        )
        return kind, "timestamp", _encode(header, rows, sep), True
    if kind == "empty_time":
        rows[r][0] = ""
        return kind, "timestamp", _encode(header, rows, sep), True
    if kind == "non_utf8_cell":
        data = _encode(header, rows, sep)
        at = data.index(rows[r][c + 1].encode())
        return kind, None, data[:at] + b"\xff\xfe" + data[at + 2 :], True
    if kind == "non_utf8_header":
        return kind, None, _encode(header, rows, sep).replace(b"T2A", b"T2\xe4", 1), True
    if kind == "empty_file":
        return kind, None, b"", True
    if kind == "header_only":
        return kind, None, _encode(header, [], sep), True
    if kind == "ragged_row":
        rows[r] = rows[r] + ["1", "2", "3"]
        return kind, None, _encode(header, rows, sep), True
    if kind == "long_gap":  # 3 h without data in the middle of the period (max_gap = 2 h)
        a = 144 + 18
        del rows[a : a + 18]
        return kind, None, _encode(header, rows, sep), True
    return kind, None, _encode(header, rows, sep), False


@FUZZ
@given(corrupted_file())
def test_corrupted_data_name_file_and_column(tmp_path, case):
    kind, col, data, must_fail = case
    path = tmp_path / "data.csv"
    path.write_bytes(data)
    study = _study(path, tmp_path, utc_offset="+01:00") if kind == "mixed_tz" else _study(path, tmp_path)
    m, exc = _load(study)
    if exc is None:
        assert not must_fail, f"{kind} ({col}) was accepted"
        assert set(m.frame.columns) == {"exterior", "interior", "T3A", "T2A", "T1A", "qe", "qi"}
        return
    assert isinstance(exc, DataError), exc
    msg = str(exc)
    assert str(path) in msg or path.name in msg, msg
    if col is not None and kind not in ("duplicate_time", "unsorted_time"):
        assert repr(col) in msg, (kind, msg)
    if kind in ("duplicate_time", "unsorted_time"):
        assert "data row" in msg, msg  # the row to fix
    assert "\n" not in msg, msg


def test_valid_data_with_every_separator_load(tmp_path):
    for sep in (",", ";", "\t"):
        path = tmp_path / f"d{ord(sep)}.csv"
        path.write_bytes(_encode(["timestamp"] + COLUMNS, ROWS, sep))
        m = load_measurements(_study(path, tmp_path))
        assert len(m.frame) == N and np.isfinite(m.frame.to_numpy()).all()


@settings(max_examples=30, deadline=None)
@given(st.lists(st.floats(-1e6, 1e6, allow_nan=False), min_size=1, max_size=50), st.integers(0, N - 60))
def test_random_values_in_a_sensor_column_load(values, at):
    """Any finite temperature above absolute zero in a sensor column loads (they are only compared, never stop
    the run); one below absolute zero is a unit or logger error, named with its column."""
    import tempfile
    from pathlib import Path

    rows = copy.deepcopy(ROWS)
    for k, v in enumerate(values):
        rows[at + k][2] = repr(v)
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "data.csv"
        path.write_bytes(_encode(["timestamp"] + COLUMNS, rows, ","))
        m, exc = _load(_study(path, Path(d)))
    if min(values) < -273.15:
        assert isinstance(exc, DataError) and "'T3A'" in str(exc) and "absolute zero" in str(exc), exc
        return
    assert exc is None, exc
    assert len(m.frame) == N


@settings(max_examples=30, deadline=None)
@given(st.lists(st.floats(-1e9, 1e12), min_size=3, max_size=40))
def test_elapsed_seconds_time_column(tmp_path_factory, secs):
    """Random elapsed-second stamps: they load when increasing, otherwise a DataError names the file."""
    d = tmp_path_factory.mktemp("el")
    path = d / "data.csv"
    frame = pd.DataFrame({"t": secs, **{c: np.linspace(10, 20, len(secs)) for c in COLUMNS}})
    frame.to_csv(path, index=False)
    raw = copy.deepcopy(RAW)
    raw["data"] = {
        "file": str(path),
        "time_column": "t",
        "time_format": "elapsed_seconds",
        "start": dt.datetime(2025, 1, 1),
    }
    raw["period"] = {"start": dt.datetime(2025, 1, 1), "end": dt.datetime(2025, 1, 1, 1)}
    study = parse_study(raw, base_dir=d)
    m, exc = _load(study)
    if exc is not None:
        assert isinstance(exc, DataError) and str(path) in str(exc), exc


# ---------------------------------------------------------------------------- the CLI on corrupted data
@pytest.mark.parametrize(
    "kind", ["non_utf8_cell", "duplicate_time", "mixed_tz", "empty_file", "huge", "missing_column"]
)
def test_cli_data_errors_one_line(kind, tmp_path, capsys):
    import tomli_w

    @settings(max_examples=1, database=None, derandomize=True)
    @given(corrupted_file().filter(lambda c: c[0] == kind))
    def one(case):
        box.append(case)

    box = []
    one()
    _, col, data, _ = box[0]
    (tmp_path / "data.csv").write_bytes(data)
    raw = copy.deepcopy(RAW)
    raw["data"] = {"file": "data.csv"}
    raw["period"] = {
        "warmup_start": START,
        "start": START + dt.timedelta(days=1),
        "end": START + dt.timedelta(days=1, hours=12),
    }
    (tmp_path / "study.toml").write_text(tomli_w.dumps(raw))
    code = main(["simulate", str(tmp_path / "study.toml"), "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert code == 2, err
    assert err.startswith("wallcal: error: ") and "Traceback" not in err, err
    assert len(err.strip().splitlines()) == 1, err
    assert "data.csv" in err
    assert not (tmp_path / "out").exists()  # nothing written on an error
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".out")]  # no temporary dir or lock left


def test_temperature_below_absolute_zero_is_rejected(tmp_path):
    rows = copy.deepcopy(ROWS)
    for k in range(150, 170):
        rows[k][1] = "-10000"
    path = tmp_path / "data.csv"
    path.write_bytes(_encode(["timestamp"] + COLUMNS, rows, ","))
    with pytest.raises(DataError, match="TSe"):
        load_measurements(_study(path, tmp_path))

"""Monitoring data: reading, column mapping, units, gaps, spikes and the summary table.

Everything read here is converted once to wallcal's conventions: temperatures
in degC, heat flux densities in W/m2 positive towards the interior, timestamps
naive in local standard time.
"""

from __future__ import annotations

import codecs
import csv
import dataclasses
import datetime as _dt
import hashlib
import os
import threading
import time
from collections import OrderedDict
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from .errors import DataError, clip, closest, require, show
from .schema import regular_file
from .study import DataFileSpec, Study

KELVIN = 273.15


@dataclass
class Measurements:
    """Monitoring data mapped onto a study.

    Attributes
    ----------
    frame : pandas.DataFrame
        Index: timestamps (naive, local standard time). Columns: ``exterior`` and
        ``interior`` (boundary series, degC or W/m2) and one column per sensor
        name, in wallcal's units and sign convention. NaN = missing.
    spikes : pandas.DataFrame
        Single-sample spikes found: columns ``signal, timestamp, value, deviation``.
        Spikes are set to NaN in ``frame`` when the study removes them.
    bridged_gaps : pandas.DataFrame
        Gaps in boundary series bridged by linear interpolation: ``signal, start, end, seconds``.
    source : Path
    sha256 : str
        Hash of the data file(s).
    """

    frame: pd.DataFrame
    spikes: pd.DataFrame
    bridged_gaps: pd.DataFrame
    source: Path
    sha256: str
    notes: list[str] = field(default_factory=list)


# ---------------------------------------------------------------------------- reading
#: Largest data file read, and largest total of a study's data files [bytes]: five years of 1-minute data in
#: eight columns take about 160 MB, and reading 100 MB of CSV peaks at about 0.8 GB. A larger file is refused
#: before it is read (keep only the period and the columns the study uses).
MAX_DATA_BYTES = 200_000_000
#: Longest line of a CSV data file [bytes] (a header of 10,000 columns fits): a longer one is not a table.
MAX_LINE_BYTES = 1_000_000
_CHUNK = 1 << 23


def _check_file(path: Path, key: str = "data.file") -> int:
    """The size of the data file ``path`` [bytes] after checking, without opening it, that it exists, is a regular
    file (a FIFO or a device such as ``/dev/zero`` never ends) of at most :data:`MAX_DATA_BYTES` bytes and is
    not empty."""
    try:
        size = regular_file(path, "data", MAX_DATA_BYTES)
    except FileNotFoundError as exc:
        raise DataError(f"{key}: file not found: {path}") from exc
    except OSError as exc:
        raise DataError(f"{path}: cannot read the file: {exc.strerror}") from exc
    except ValueError as exc:
        raise DataError(f"{path}: {exc}") from exc
    if size == 0:
        raise DataError(f"{path}: the file is empty")
    return size


def _scan_text(path: Path, sep: str, fields: int) -> int:
    """Refuse a CSV file holding a NUL byte (binary content), bytes that are not UTF-8, a line longer than
    :data:`MAX_LINE_BYTES`, or (in a file without quotes and with a one-character separator) a row of more than
    ``fields`` fields, reading it in chunks (memory bounded whatever the file holds). Returns the number of
    lines."""
    offset = 0  # of the chunk in the file
    line_start = 0  # offset of the line under way
    lines = 0  # complete lines before the chunk
    seps = 0  # separators of the line under way before the chunk
    count_fields = len(sep) == 1 and ord(sep) < 128
    utf8 = codecs.getincrementaldecoder("utf-8")()
    with open(path, "rb") as fh:
        while chunk := fh.read(_CHUNK):
            k = chunk.find(b"\0")
            if k >= 0:
                line = lines + chunk.count(b"\n", 0, k) + 1
                raise DataError(
                    f"{path}: holds a NUL byte at byte {offset + k:,} (line {line}): "
                    "binary content, not CSV text; give the data as a CSV text file (UTF-8) or Parquet"
                )
            try:
                utf8.decode(chunk)
            except UnicodeDecodeError as exc:
                raise DataError(
                    f"{path}: not valid UTF-8 text (byte {offset + exc.start:,}); save the file as UTF-8"
                ) from exc
            arr = np.frombuffer(chunk, dtype=np.uint8)
            nl = np.flatnonzero(arr == 10)
            starts = np.concatenate([[line_start], nl + offset + 1])
            ends = np.concatenate([nl + offset, [offset + len(chunk)]])
            long = np.flatnonzero(ends - starts > MAX_LINE_BYTES)
            if len(long):
                raise DataError(
                    f"{path}: line {lines + int(long[0]) + 1} is longer than {MAX_LINE_BYTES:,} bytes: "
                    "not a table of measurements (CSV rows)"
                )
            count_fields = count_fields and b'"' not in chunk  # quoted fields: pandas counts them
            if count_fields:
                cs = np.cumsum(arr == ord(sep), dtype=np.int64)
                over = np.zeros(0, dtype=np.int64)
                if len(nl):
                    at = cs[nl]
                    per_line = np.diff(at, prepend=0)
                    per_line[0] += seps
                    seps = int(cs[-1] - at[-1])
                    over = np.flatnonzero(per_line >= fields)
                else:
                    seps += int(cs[-1])
                if len(over) or seps >= fields:
                    i = lines + (int(over[0]) if len(over) else len(nl)) + 1
                    raise DataError(
                        f"{path}: line {i} has more fields than the header's {fields}; fix the row or the header"
                    )
            line_start = int(starts[-1])
            lines += len(nl)
            offset += len(chunk)
    try:
        utf8.decode(b"", final=True)
    except UnicodeDecodeError as exc:
        raise DataError(f"{path}: not valid UTF-8 text (it ends inside a character); save the file as UTF-8") from exc
    return lines + (offset > line_start)


def _header(path: Path, separator: str | None, key: str = "data.file") -> tuple[str | None, list[str]]:
    """Check the data file (:func:`_check_file`, :func:`_scan_text`) and read its header: ``(separator, column
    names)`` (no separator for Parquet). A column name given twice is an error."""
    _check_file(path, key)
    if path.suffix.lower() in (".parquet", ".pq"):
        require("pyarrow", "parquet")
        import pyarrow.parquet as pq

        try:
            names = [str(c).strip() for c in pq.read_schema(path).names]
        except Exception as exc:  # pyarrow raises many types
            raise DataError(f"{path}: cannot read as Parquet: {clip(str(exc), 150)}") from exc
        sep = None
    else:
        with open(path, "rb") as fh:
            raw = fh.readline(MAX_LINE_BYTES + 1)
        head = raw.decode("utf-8-sig", errors="replace").rstrip("\r\n")  # strict in _scan_text
        if separator:
            sep = separator
        else:
            counts = {c: head.count(c) for c in (",", "\t", ";")}
            best = max(counts, key=counts.get)
            sep = best if counts[best] > 0 else ","
        try:
            row = next(csv.reader([head], delimiter=sep, skipinitialspace=True), [])
        except (csv.Error, TypeError):
            row = head.split(sep)
        names = [c.strip() for c in row]
        if _scan_text(path, sep, max(len(head.split(sep)), 1)) < 2:
            raise DataError(f"{path}: the file has a header but no data rows")
    seen: dict[str, int] = {}
    for i, name in enumerate(names):
        if name and name in seen:
            raise DataError(
                f"{path}: column {show(name)} appears twice in the header (columns {seen[name] + 1} and {i + 1}); "
                "rename or remove one"
            )
        seen[name] = i
    return sep, names


def read_table(
    path: Path, separator: str | None = None, columns: dict[str, tuple[str, str]] | None = None
) -> pd.DataFrame:
    """Read a CSV (any of , ; tab) or Parquet file into a DataFrame of raw columns.

    Parameters
    ----------
    path : Path
    separator : str, optional
        Detected from the header when not given.
    columns : dict, optional
        Only these columns are read, ``{name: ("float" | "text", study key)}``: text columns as text, float
        columns as pandas infers them (:func:`_numeric` then names a cell that is not a number). A missing one
        is an error naming its study key. Default: every column, types inferred.

    Raises
    ------
    DataError
        Missing, empty, non-regular, oversized, binary or unreadable file, a duplicated column name, with the
        file name.
    """
    path = Path(path)
    sep, header = _header(path, separator)
    return _read(path, sep, header, columns)


def _read(path: Path, sep: str | None, header: list[str], columns: dict[str, tuple[str, str]] | None) -> pd.DataFrame:
    """:func:`read_table` after :func:`_header`."""
    for col, (_, key) in (columns or {}).items():
        if col not in header:
            raise DataError(f"{path}: column {show(col)} ({key}) not found; {closest(col, header)}")
    if sep is None:
        try:
            frame = pd.read_parquet(path, columns=[c for c in columns if c in header] if columns else None)
        except Exception as exc:  # pyarrow raises many types
            raise DataError(f"{path}: cannot read as Parquet: {clip(str(exc), 150)}") from exc
        frame.columns = [str(c).strip() for c in frame.columns]
        return frame
    kw: dict = {}
    if columns is not None:  # only these columns; text ones as text (numbers are checked by _numeric)
        use = {c: columns[c][0] for c in header if c in columns}
        kw["usecols"] = lambda c: str(c).strip() in use
        kw["dtype"] = {raw: str for raw in _raw_names(path, sep) if use.get(raw.strip()) == "text"}
    try:
        frame = pd.read_csv(path, sep=sep, encoding="utf-8", skipinitialspace=True, **kw)
    except UnicodeDecodeError as exc:
        raise DataError(f"{path}: not valid UTF-8 text (byte {exc.start}); save the file as UTF-8") from exc
    except pd.errors.EmptyDataError as exc:
        raise DataError(f"{path}: the file is empty") from exc
    except pd.errors.ParserError as exc:
        raise DataError(f"{path}: cannot parse as CSV: {clip(str(exc).splitlines()[0], 150)}") from exc
    if frame.empty:
        raise DataError(f"{path}: the file has a header but no data rows")
    frame.columns = [str(c).strip() for c in frame.columns]
    return frame


def _raw_names(path: Path, sep: str) -> list[str]:
    """The header's names as pandas reads them (before stripping), for ``dtype``."""
    return [str(c) for c in pd.read_csv(path, sep=sep, encoding="utf-8", skipinitialspace=True, nrows=0).columns]


def _column(frame: pd.DataFrame, col: str, key: str, path: Path) -> pd.Series:
    if col not in frame.columns:
        raise DataError(f"{path}: column {show(col)} ({key}) not found; {closest(col, list(frame.columns))}")
    return frame[col]


def _numeric(series: pd.Series, col: str, path: Path) -> np.ndarray:
    if pd.api.types.is_bool_dtype(series.dtype):
        raise DataError(f"{path}: column {show(col)} holds true/false values, not numbers")
    values = pd.to_numeric(series, errors="coerce")
    if not pd.api.types.is_float_dtype(series.dtype):  # read as text: name the first cell that is not a number
        bad = values.isna() & series.notna() & (series.astype(str).str.strip() != "")
        if bad.any():
            i = int(np.flatnonzero(bad.to_numpy())[0])
            raise DataError(
                f"{path}: column {show(col)} has a non-numeric value {show(series.iloc[i])} at data row {i + 1} "
                f"(line {i + 2}); fix or blank it"
            )
    out = values.to_numpy(dtype=float)
    if np.isinf(out).any():
        i = int(np.flatnonzero(np.isinf(out))[0])
        raise DataError(f"{path}: column {show(col)} has an infinite value at data row {i + 1} (line {i + 2})")
    huge = np.abs(out) > 1e15  # beyond any physical reading; squares of such values overflow in the metrics
    if huge.any():
        i = int(np.flatnonzero(huge)[0])
        raise DataError(
            f"{path}: column {show(col)} has a value out of any physical range, {out[i]:g}, at data row "
            f"{i + 1} (line {i + 2})"
        )
    return out


def _timestamps(
    frame: pd.DataFrame, study: Study, path: Path, time_column: str | None = None, key: str = "data.time_column"
) -> pd.DatetimeIndex:
    spec = study.data
    if time_column is not None:
        import dataclasses

        spec = dataclasses.replace(spec, time_column=time_column)
    col = _column(frame, spec.time_column, key, path)
    if spec.time_format == "elapsed_seconds":
        secs = _numeric(col, spec.time_column, path)
        if np.isnan(secs).any():
            i = int(np.flatnonzero(np.isnan(secs))[0])
            raise DataError(f"{path}: column {show(spec.time_column)} is empty at data row {i + 1} (line {i + 2})")
        try:
            idx = pd.DatetimeIndex(pd.Timestamp(spec.start) + pd.to_timedelta(secs, unit="s"))
        except (OverflowError, pd.errors.OutOfBoundsTimedelta, pd.errors.OutOfBoundsDatetime) as exc:
            raise DataError(
                f"{path}: column {show(spec.time_column)} has elapsed seconds that put the timestamps "
                f"outside the years 1677-2262 (from {np.nanmin(secs):g} to {np.nanmax(secs):g} s after "
                "data.start)"
            ) from exc
    else:
        text = col.astype(str).str.strip()
        try:
            parsed = pd.to_datetime(text, format="ISO8601", utc=False)
        except (ValueError, TypeError) as exc:
            if "mixed timezones" in str(exc).lower() or "mixed time" in str(exc).lower():
                raise DataError(
                    f"{path}: column {show(spec.time_column)} mixes time-zone offsets (e.g. summer and "
                    "winter time) or naive and aware timestamps; wallcal needs one local standard "
                    "time: convert the column to a single offset"
                ) from exc
            # find the first bad row for the message
            for i, v in enumerate(text):
                try:
                    _dt.datetime.fromisoformat(v)
                except ValueError:
                    raise DataError(
                        f"{path}: column {show(spec.time_column)} has a value that is not an ISO 8601 date-time: "
                        f"{show(v)} at data row {i + 1} (line {i + 2})"
                    ) from exc
            raise DataError(
                f"{path}: column {show(spec.time_column)}: mixed time-zone offsets or unreadable "
                f"date-times ({clip(str(exc), 100)}); give every timestamp the same offset or none"
            ) from exc
        if isinstance(parsed, pd.Series):
            if parsed.dtype == object:
                raise DataError(
                    f"{path}: column {show(spec.time_column)} mixes time-zone offsets (e.g. summer and "
                    "winter time) or naive and aware timestamps; wallcal needs one local standard "
                    "time: convert the column or give data.utc_offset"
                )
            idx = pd.DatetimeIndex(parsed)
        else:
            idx = pd.DatetimeIndex(parsed)
        if idx.tz is not None:
            if spec.utc_offset is None:
                raise DataError(
                    f"{path}: column {show(spec.time_column)} carries a time-zone offset; give "
                    'data.utc_offset (the offset of local standard time, e.g. "+01:00") so that '
                    "wallcal can convert to local standard time"
                )
            offset = _dt.datetime.strptime(spec.utc_offset.replace("Z", "+00:00"), "%z").tzinfo
            idx = idx.tz_convert(offset).tz_localize(None)
    if idx.isna().any():
        i = int(np.flatnonzero(idx.isna())[0])
        raise DataError(f"{path}: column {show(spec.time_column)} is empty at data row {i + 1} (line {i + 2})")
    d = np.diff(idx.asi8)
    if (d == 0).any():
        i = int(np.flatnonzero(d == 0)[0])
        raise DataError(
            f"{path}: duplicate timestamp {idx[i]} at data rows {i + 1} and {i + 2}; remove the duplicate rows"
        )
    if (d < 0).any():
        i = int(np.flatnonzero(d < 0)[0])
        raise DataError(
            f"{path}: timestamps are not increasing: {idx[i]} (data row {i + 1}) is followed by "
            f"{idx[i + 1]} (data row {i + 2}); sort the file by time"
        )
    return idx


def _convert(values: np.ndarray, unit: str, positive: str, offset: float = 0.0) -> np.ndarray:
    """To wallcal's units and sign, then plus the study's declared ``offset``."""
    out = values.copy()
    if unit == "K":
        out = out - KELVIN
    if positive == "towards_exterior":
        out = -out
    if offset:
        out = out + offset
    return out


def humidity_name(face: str) -> str:
    """The measurements frame's column of a face's relative humidity (fraction)."""
    return f"{face}_relative_humidity"


def _humidity(values: np.ndarray, col: str, unit: str, key: str, path) -> np.ndarray:
    """A relative humidity column as a fraction, refusing a fraction above 1 and a percent column whose values
    are all <= 1 (a fraction read as percent)."""
    ok = values[np.isfinite(values)]
    if unit == "fraction":
        if ok.size and ok.max() > 1.0:
            i = int(np.flatnonzero(values > 1.0)[0])
            raise DataError(
                f"{path}: column {show(col)} holds a relative humidity of {values[i]:g} at data row {i + 1} (line "
                f'{i + 2}), above 1, but {key} says "fraction"; if the column is in percent, say unit = "percent"'
            )
        return values.copy()
    if ok.size and ok.max() <= 1.0:
        raise DataError(
            f"{path}: column {show(col)}: every value is <= 1 (largest {ok.max():g}), but {key} says "
            '"percent": the column looks like a fraction; say "fraction"'
        )
    return values / 100.0


def _check_temperature(values_C: np.ndarray, col: str, unit: str, path) -> None:
    """Temperatures below absolute zero are a unit or logger error, never data."""
    bad = values_C < -KELVIN
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        hint = ' (is the column in kelvin? say unit = "K")' if unit == "degC" else ""
        raise DataError(
            f"{path}: column {show(col)} holds a temperature below absolute zero at data row {i + 1} "
            f"(line {i + 2}): {values_C[i] + (KELVIN if unit == 'K' else 0):g} {unit}{hint}"
        )


# ---------------------------------------------------------------------------- spikes and gaps
def detect_spikes(values: np.ndarray, sigma: float = 8.0) -> np.ndarray:
    """Single-sample spikes: a value far from both neighbours, which agree with each other.

    Robust rule: with ``r_k = x_k - (x_{k-1} + x_{k+1}) / 2`` and its robust
    scale ``s = 1.4826 MAD(r)``, sample k is a spike when
    ``|r_k| > max(sigma s, 0.01 range(x))`` and ``|x_{k+1} - x_{k-1}| < |r_k| / 2``
    (the signal returns at once). Missing values are skipped (neighbours are the
    nearest valid samples).

    Parameters
    ----------
    values : ndarray
    sigma : float
        Threshold in robust standard deviations.

    Returns
    -------
    ndarray of bool
    """
    x = np.asarray(values, dtype=float)
    mask = np.zeros(len(x), dtype=bool)
    valid = np.flatnonzero(np.isfinite(x))
    if len(valid) < 5:
        return mask
    v = x[valid]
    r = v[1:-1] - 0.5 * (v[:-2] + v[2:])
    mad = np.median(np.abs(r - np.median(r)))
    s = 1.4826 * mad
    floor = 0.01 * (np.max(v) - np.min(v))
    thr = max(sigma * s, floor, 1e-12)
    jump_back = np.abs(v[2:] - v[:-2])
    hit = (np.abs(r) > thr) & (jump_back < 0.5 * np.abs(r))
    mask[valid[1:-1][hit]] = True
    return mask


def find_gaps(index: pd.DatetimeIndex, values: np.ndarray, start, end) -> list[tuple]:
    """Gaps between consecutive valid samples inside [start, end].

    Returns a list of ``(gap_start, gap_end, seconds)`` for every spacing larger
    than 1.5 times the median sampling interval.
    """
    ok = np.isfinite(values)
    t = index[ok]
    if len(t) < 2:
        return []
    secs = np.asarray((t[1:] - t[:-1]).total_seconds(), dtype=float)
    nominal = float(np.median(secs))
    out = []
    for i in np.flatnonzero(secs > 1.5 * nominal):
        a, b = t[i], t[i + 1]
        if b < start or a > end:
            continue
        out.append((a, b, float(secs[i])))
    return out


# ---------------------------------------------------------------------------- main entry
def file_sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def _study_columns(study: Study) -> dict[str, str]:
    """Data column -> the study key that uses it."""
    out = {}
    for face, b in (("exterior", study.exterior), ("interior", study.interior)):
        out.setdefault(b.column, f"boundary.{face}.column")
        if b.humidity_column:
            out.setdefault(b.humidity_column, f"boundary.{face}.humidity_column")
    for i, s in enumerate(study.sensors):
        out.setdefault(s.column, f"sensors[{i}].column")
    return out


def read_joined(study: Study) -> tuple[pd.DataFrame, list[str]]:
    """Read ``[[data.files]]`` and join them on their timestamps.

    Outer join: the result has every timestamp of any file; a column has a value only
    at its own file's timestamps and is missing (NaN) elsewhere - nothing is
    interpolated here. Sensors are then compared at their own timestamps only, and
    boundary series are interpolated to the engine grid as for a single file (gaps up
    to ``data.max_gap``). Only the columns the study uses are converted to numbers.

    Returns
    -------
    frame : DataFrame
        Index: the union of the timestamps; one float column per study column.
    notes : list of str
        How many timestamps each file has and how many are common to all.

    Raises
    ------
    DataError
        A missing file or column, a name given by two files, bad timestamps or values
        (naming the file).
    """
    spec = study.data
    wanted = _study_columns(study)
    parts: list[pd.DataFrame] = []
    owner: dict[str, str] = {}
    available: list[str] = []
    stamps = []
    total = 0
    for i, f in enumerate(spec.files):
        key = f"data.files[{i}]"
        total += _check_file(f.file, f"{key}.file")
        if total > MAX_DATA_BYTES:
            raise DataError(
                f"{key}.file: the data files up to {f.file.name} hold {total / 1e6:,.0f} MB, more than wallcal reads "
                f"({MAX_DATA_BYTES / 1e6:,.0f} MB)"
            )
        sep, header = _header(f.file, f.separator or spec.separator, f"{key}.file")
        pairs = _file_columns(f, header, key)
        time_kind = "float" if spec.time_format == "elapsed_seconds" else "text"
        needed = {f.time_column: (time_kind, f"{key}.time_column")}
        needed.update({col: ("float", f"{key}") for name, col in pairs if name in wanted})
        raw = _read(f.file, sep, header, needed)
        index = _timestamps(raw, study, f.file, f.time_column, f"{key}.time_column")
        stamps.append(index)
        cols: dict[str, np.ndarray] = {}
        for name, col in pairs:
            if name in owner:
                raise DataError(
                    f"{f.file}: column {show(col)} would be named {show(name)}, which {owner[name]} already "
                    f"gives; use a prefix or a columns mapping in {key}"
                )
            owner[name] = f"{key} ({f.file.name})"
            available.append(name)
            if name in wanted:
                cols[name] = _numeric(raw[col], col, f.file)
        parts.append(pd.DataFrame(cols, index=index))
    for col, key in wanted.items():
        if col not in owner:
            raise DataError(
                f"data.files: column {show(col)} ({key}) is not given by any file; {closest(col, available)}"
            )
    frame = pd.concat(parts, axis=1, join="outer", sort=True)
    frame.index.name = "timestamp"
    common = stamps[0]
    for idx in stamps[1:]:
        common = common.intersection(idx)
    notes = [
        f"data.files: {len(spec.files)} files joined on their timestamps (outer join): {len(frame)} timestamps, "
        f"{len(common)} present in every file"
        + ("" if len(common) == len(frame) else "; values are compared only at their own file's timestamps")
    ]
    return frame, notes


def _file_columns(f: DataFileSpec, header: list[str], key: str) -> list[tuple[str, str]]:
    """(name in the study, column in the file) for one of ``[[data.files]]``, from its ``header``."""
    if f.columns is not None:
        for name, col in f.columns:
            if col not in header:
                raise DataError(
                    f"{f.file}: column {show(col)} ({key}.columns.{clip(name)}) not found; {closest(col, header)}"
                )
        return list(f.columns)
    return [(f.prefix + c, c) for c in header if c and c != f.time_column]


def data_sha256(study: Study) -> str:
    """Hash of the study's data: the file's, or for ``[[data.files]]`` the hash of the files' hashes in order."""
    paths = study.data.paths
    if len(paths) == 1 and not study.data.files:
        return file_sha256(paths[0])
    h = hashlib.sha256()
    for p in paths:
        h.update(file_sha256(p).encode())
    return h.hexdigest()


# the measurements of the last few studies, keyed by what they depend on (see load_measurements)
_LOADED: OrderedDict[tuple, Measurements] = OrderedDict()
_LOADED_MAX = 4
_LOADED_LOCK = threading.Lock()
#: a file modified less than this before it is read may change again within the same time stamp
#: (coarse file-system clocks): its measurements are not kept
_RACY_NS = 2_000_000_000


def _loaded_key(study: Study) -> tuple | None:
    """What a study's measurements depend on: its data, boundary, sensor and period keys, and each data
    file's path, size, inode and modification time [ns]. None when a file cannot be read (the loader
    then says why)."""
    try:
        files = tuple(
            (os.path.abspath(p), st.st_size, st.st_ino, st.st_mtime_ns)
            for p in study.data.paths
            for st in (os.stat(p),)
        )
    except OSError:
        return None
    return (study.data, study.exterior, study.interior, study.sensors, study.period, files)


def _settled(key: tuple, now_ns: int) -> bool:
    """Every data file of ``key`` was last modified well before ``now_ns`` (see _RACY_NS)."""
    return all(mtime < now_ns - _RACY_NS for *_, mtime in key[-1])


def _view(m: Measurements) -> Measurements:
    """A copy of ``m`` sharing its data: pandas' copy-on-write keeps the cached frames unchanged when
    the copy's are written to, and their ``to_numpy()`` arrays are read-only."""
    return dataclasses.replace(
        m,
        frame=m.frame.copy(deep=False),
        spikes=m.spikes.copy(deep=False),
        bridged_gaps=m.bridged_gaps.copy(deep=False),
        notes=list(m.notes),
    )


def load_measurements(study: Study) -> Measurements:
    """Read the study's data file (or its ``[[data.files]]``, joined on their timestamps) and map it onto
    the study.

    The result is kept: a later call for the same data, boundary, sensor and period keys returns it
    without reading the files again, as long as every data file keeps its path, size, inode and
    modification time. Data files modified less than 2 s before they are read are not kept (they
    might change again within one tick of a coarse file-system clock, unnoticed). Each call returns its
    own copy of the frames, sharing their data (copy-on-write): writing to them leaves the kept ones
    unchanged.

    Raises
    ------
    DataError
        Naming the file and column: missing file or column, non-numeric values,
        duplicate or non-increasing timestamps, a period outside the data, a gap in a
        boundary series longer than ``data.max_gap``.
    """
    key = _loaded_key(study)  # before reading: a file changed while it is read is read again next time
    now = time.time_ns()
    if key is not None:
        with _LOADED_LOCK:
            m = _LOADED.get(key)
            if m is not None:
                _LOADED.move_to_end(key)
        if m is not None:
            return _view(m)
    m = _read_measurements(study)
    if key is not None and _settled(key, now):
        with _LOADED_LOCK:
            _LOADED[key] = m
            while len(_LOADED) > _LOADED_MAX:
                _LOADED.popitem(last=False)
    return _view(m)


def _read_measurements(study: Study) -> Measurements:
    spec = study.data
    notes: list[str] = []
    if spec.files:
        raw, notes = read_joined(study)
        index = pd.DatetimeIndex(raw.index)
        path = "data.files (" + ", ".join(f.file.name for f in spec.files) + ")"
    else:
        path = spec.file
        time_kind = "float" if spec.time_format == "elapsed_seconds" else "text"
        needed = {spec.time_column: (time_kind, "data.time_column")}
        for face, b in (("exterior", study.exterior), ("interior", study.interior)):
            needed.setdefault(b.column, ("float", f"boundary.{face}.column"))
            if b.humidity_column:
                needed.setdefault(b.humidity_column, ("float", f"boundary.{face}.humidity_column"))
        for i, sensor in enumerate(study.sensors):
            needed.setdefault(sensor.column, ("float", f"sensors[{i}].column"))
        raw = read_table(path, spec.separator, needed)
        index = _timestamps(raw, study, path)
    cols: dict[str, np.ndarray] = {}
    for face, b in (("exterior", study.exterior), ("interior", study.interior)):
        vals = _numeric(_column(raw, b.column, f"boundary.{face}.column", path), b.column, path)
        cols[face] = _convert(vals, b.unit, b.positive, b.offset)
        if b.type != "heat_flux":
            _check_temperature(cols[face], b.column, b.unit, path)
        if b.humidity_column:
            key = f"boundary.{face}.humidity_column"
            vals = _numeric(_column(raw, b.humidity_column, key, path), b.humidity_column, path)
            rh = _humidity(vals, b.humidity_column, b.humidity_unit, f"boundary.{face}.humidity_unit", path)
            if not np.isfinite(rh).any():
                raise DataError(f"{path}: column {show(b.humidity_column)} ({key}) has no value")
            cols[humidity_name(face)] = np.clip(rh, 1e-4, 1.0)  # a saturated sensor may read 100.5 %
    for i, s in enumerate(study.sensors):
        vals = _numeric(_column(raw, s.column, f"sensors[{i}].column", path), s.column, path)
        if s.quantity == "relative_humidity":
            cols[s.name] = _humidity(vals, s.column, s.unit, f"sensors[{i}].unit", path) + s.offset
            continue
        cols[s.name] = _convert(vals, s.unit, s.positive, s.offset)
        if s.quantity == "temperature":
            _check_temperature(cols[s.name], s.column, s.unit, path)
    frame = pd.DataFrame(cols, index=index)
    frame.index.name = "timestamp"

    # period inside the data
    p = study.period
    warm = pd.Timestamp(p.warmup_start) if p.warmup_start else index[0]
    start, end = pd.Timestamp(p.start), pd.Timestamp(p.end)
    first, last = index[0], index[-1]
    if warm < first or end > last or start < first:
        raise DataError(
            f"{path}: the period {warm} .. {end} (period.warmup_start/start/end) is outside the data, which "
            f"run from {first} to {last}"
        )

    # spikes
    spike_rows = []
    for name in frame.columns:
        s = frame[name].to_numpy()
        hit = detect_spikes(s, spec.spike_sigma)
        if hit.any():
            med = pd.Series(s).rolling(3, center=True, min_periods=1).median().to_numpy()
            for k in np.flatnonzero(hit):
                spike_rows.append((name, index[k], float(s[k]), float(s[k] - med[k])))
            if spec.remove_spikes:
                s = s.copy()
                s[hit] = np.nan
                frame[name] = s
    spikes = pd.DataFrame(spike_rows, columns=["signal", "timestamp", "value", "deviation"])

    # boundary gaps
    gap_rows = []
    for face, b in (("exterior", study.exterior), ("interior", study.interior)):
        v = frame[face].to_numpy()
        inside = (index >= warm) & (index <= end)
        if spec.files:
            # joined files need not share stamps: a boundary sample up to max_gap outside the period bridges its ends
            margin = pd.Timedelta(seconds=spec.max_gap)
            inside = (index >= warm - margin) & (index <= end + margin)
        ok = np.isfinite(v) & inside
        if not ok.any():
            raise DataError(f"{path}: column {show(b.column)} (boundary.{face}) has no value in the period")
        t_ok = index[ok]
        if t_ok[0] > warm or t_ok[-1] < end:
            raise DataError(
                f"{path}: column {show(b.column)} (boundary.{face}) has no value at the start or end of the period "
                f"({t_ok[0]} .. {t_ok[-1]} inside {warm} .. {end}); move the period or fill the data"
            )
        for a, c, secs in find_gaps(index, np.where(inside, v, np.nan), warm, end):
            if secs > spec.max_gap:
                raise DataError(
                    f"{path}: column {show(b.column)} (boundary.{face}) has a gap of {secs / 3600:.2f} h from {a} "
                    f"to {c}, longer than data.max_gap = {spec.max_gap:g} s; raise max_gap or move the period"
                )
            gap_rows.append((b.column, a, c, secs))
    gaps = pd.DataFrame(gap_rows, columns=["signal", "start", "end", "seconds"])
    return Measurements(
        frame=frame, spikes=spikes, bridged_gaps=gaps, source=spec.file, sha256=data_sha256(study), notes=notes
    )


def summarize(frame: pd.DataFrame, start, end) -> pd.DataFrame:
    """Summary of measured signals over [start, end] (the paper's Table III).

    Returns
    -------
    DataFrame
        One row per signal: ``n, max, min, range, mean, effective`` (effective =
        root mean square value, the normalisation of CV(RMSE) for heat fluxes).
    """
    sel = frame.loc[(frame.index >= pd.Timestamp(start)) & (frame.index <= pd.Timestamp(end))]
    rows = {}
    for col in sel.columns:
        v = sel[col].to_numpy(dtype=float)
        v = v[np.isfinite(v)]
        if len(v) == 0:
            rows[col] = dict(n=0, max=np.nan, min=np.nan, range=np.nan, mean=np.nan, effective=np.nan)
            continue
        rows[col] = dict(
            n=len(v),
            max=v.max(),
            min=v.min(),
            range=v.max() - v.min(),
            mean=v.mean(),
            effective=float(np.sqrt(np.mean(v**2))),
        )
    out = pd.DataFrame.from_dict(rows, orient="index")
    out["n"] = out["n"].astype(int)
    out.index.name = "signal"
    return out

"""Hostile inputs at load and non-finite results (issue 36): each is refused by ``wallcal simulate`` in a
subprocess with exit 2 and one line of at most 300 characters on stderr, no traceback, nothing in ``--out``,
in bounded memory (peak RSS < 1 GB, under an address-space limit of 3 GB) and time (< 30 s).

The limits are documented in docs/robustness.md ("Limits and refusals").
"""

from __future__ import annotations

import math
import os
import resource
import subprocess
import sys
import threading
import time
import tomllib
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
import tomli_w

from conftest import EXAMPLE, make_input, three_layer_wall
from wallcal.errors import MAX_LINE, EngineError, StudyError, format_message

SRC = Path(__file__).resolve().parents[1] / "src"
DATA = EXAMPLE.parent / "measured.csv"
ADDRESS_SPACE = 3 << 30  # numba reserves address space; RSS is what is asserted
MAX_RSS_MB = 1024
MAX_SECONDS = 30


@dataclass
class Run:
    code: int
    out: str
    err: str
    seconds: float
    rss_mb: float


def _limit():  # in the child, before exec
    resource.setrlimit(resource.RLIMIT_AS, (ADDRESS_SPACE, ADDRESS_SPACE))


def wallcal(tmp_path: Path, *args: str) -> Run:
    """``wallcal ARGS`` in a child process; its own peak RSS from ``os.wait4``."""
    env = dict(os.environ, PYTHONPATH=str(SRC))
    so, se = tmp_path / "stdout.txt", tmp_path / "stderr.txt"
    with open(so, "wb") as fo, open(se, "wb") as fe:
        t = time.monotonic()
        p = subprocess.Popen(
            [sys.executable, "-m", "wallcal.cli", *args], stdout=fo, stderr=fe, cwd=tmp_path, env=env, preexec_fn=_limit
        )
        timer = threading.Timer(MAX_SECONDS + 30, p.kill)
        timer.start()
        try:
            _, status, usage = os.wait4(p.pid, 0)
        finally:
            timer.cancel()
        p.returncode = os.waitstatus_to_exitcode(status)
        seconds = time.monotonic() - t
    return Run(
        p.returncode, so.read_text(errors="replace"), se.read_text(errors="replace"), seconds, usage.ru_maxrss / 1024
    )


def refused(run: Run, out: Path, *fragments: str, lines: int = 1) -> str:
    """Exit 2, ``lines`` line(s) of at most 300 characters (the first ``wallcal: error: ...`` holding each fragment),
    no traceback, nothing at ``out``, bounded memory and time."""
    err = run.err.rstrip("\n").split("\n")
    err = [e for e in err if not e.startswith("wallcal: compiling")]  # numba's one-time notice
    assert run.code == 2, run.err[-2000:]
    assert "Traceback" not in run.err, run.err[-2000:]
    assert len(err) == lines, run.err[:2000]
    assert all(len(e) <= MAX_LINE for e in err), [len(e) for e in err]
    assert err[0].startswith("wallcal: error: "), err[0]
    for f in fragments:
        assert f in run.err, (f, run.err[:1000])
    assert not out.exists() and not list(out.parent.glob(f".{out.name}*"))
    assert run.rss_mb < MAX_RSS_MB, run.rss_mb
    assert run.seconds < MAX_SECONDS, run.seconds
    return err[0]


def study_dict(data: Path | str = DATA) -> dict:
    raw = tomllib.loads(EXAMPLE.read_text())
    for key in ("calibration", "retrofit", "building"):
        raw.pop(key, None)
    raw["data"]["file"] = str(data)
    return raw


def write_study(tmp_path: Path, raw: dict, name: str = "study.toml") -> Path:
    path = tmp_path / name
    path.write_text(tomli_w.dumps(raw))
    return path


def simulate(tmp_path: Path, study: Path, *args: str) -> tuple[Run, Path]:
    out = tmp_path / "out"
    return wallcal(tmp_path, "simulate", str(study), "--out", str(out), *args), out


# ---------------------------------------------------------------------------- unbounded memory and time
def test_tiny_conductivity_is_refused_at_load(tmp_path):
    raw = study_dict()
    raw["wall"]["layers"][0]["conductivity"] = 1e-300
    run, out = simulate(tmp_path, write_study(tmp_path, raw))
    refused(run, out, "wall.layers[0].conductivity: must be >= 0.001, got 1e-300")


@pytest.mark.parametrize(
    ("key", "value", "fragment"),
    [
        ("thickness", 50.0, "wall.layers[2].thickness: must be <= 10"),
        ("density", 1e6, "wall.layers[2].density: must be <= 25000"),
        ("specific_heat", 5.0, "wall.layers[2].specific_heat: must be >= 50"),
        ("conductivity", 1e4, "wall.layers[2].conductivity: must be <= 500"),
        ("contact_resistance", 1e3, "wall.layers[2].contact_resistance: must be <= 10"),
    ],
)
def test_layer_properties_have_physical_ranges(tmp_path, key, value, fragment):
    raw = study_dict()
    raw["wall"]["layers"][2][key] = value
    run, out = simulate(tmp_path, write_study(tmp_path, raw))
    refused(run, out, fragment)


def test_twenty_thousand_layers_are_refused(tmp_path):
    raw = study_dict()
    thermal = ("conductivity", "density", "specific_heat")  # the thermal keys only: the file stays under 4 MB
    layer = {k: raw["wall"]["layers"][1][k] for k in thermal} | {"thickness": 1e-5}
    raw["wall"]["layers"] = [dict(layer, id=str(i)) for i in range(20_000)]
    run, out = simulate(tmp_path, write_study(tmp_path, raw))
    refused(run, out, "wall.layers: 20,000 layers, more than wallcal takes (200)")


def test_grid_beyond_the_node_ceiling_is_refused(tmp_path):
    """A legal 10 m concrete layer at dt = 3 s needs 4,473 nodes (> 2,000): refused before the grid is built."""
    raw = study_dict()
    raw["wall"]["layers"] = [
        {"id": "c", "thickness": 10.0, "conductivity": 2.0, "density": 2400.0, "specific_heat": 1000.0}
    ]
    raw["simulation"]["time_step"] = 3
    run, out = simulate(tmp_path, write_study(tmp_path, raw))
    refused(run, out, "wall.layers[0]: needs 4,473 nodes", "more than 2,000")


def test_sensors_beyond_the_ceiling_are_refused(tmp_path):
    raw = study_dict()
    flux = {"column": "qe", "quantity": "heat_flux", "depth": 0.05}
    raw["sensors"] += [dict(flux, name=f"q{i}") for i in range(401)]
    run, out = simulate(tmp_path, write_study(tmp_path, raw))
    refused(run, out, "sensors: 406 sensors, more than wallcal compares (400)")


def test_two_gigabyte_data_file_is_refused_before_reading(tmp_path):
    data = tmp_path / "big.csv"
    data.write_bytes(DATA.read_bytes())
    os.truncate(data, 2 << 30)  # sparse: no real 2 GB write
    run, out = simulate(tmp_path, write_study(tmp_path, study_dict(data)))
    refused(run, out, "big.csv: is 2,147 MB, larger than wallcal reads as a data file (200 MB)")


def test_nul_padded_csv_is_refused(tmp_path):
    """200 MB of NUL bytes after the data (refused by size), and 20 MB (refused as binary content): one short
    line that never echoes the file's content."""
    for size, fragment in ((200 << 20, "larger than wallcal reads"), (20 << 20, "holds a NUL byte at byte")):
        data = tmp_path / "nul.csv"
        data.write_bytes(DATA.read_bytes())
        os.truncate(data, size)
        run, out = simulate(tmp_path, write_study(tmp_path, study_dict(data)))
        refused(run, out, fragment)
        assert "\\x00" not in run.err


def test_one_endless_line_is_refused(tmp_path):
    data = tmp_path / "line.csv"
    data.write_bytes(b"timestamp," + b"x" * (3 << 20))
    run, out = simulate(tmp_path, write_study(tmp_path, study_dict(data)))
    refused(run, out, "line 1 is longer than 1,000,000 bytes")


def test_long_values_are_cut_in_messages(tmp_path):
    raw = study_dict()
    raw["simulation"]["engine"] = "fd-" + "x" * 1_000_000
    run, out = simulate(tmp_path, write_study(tmp_path, raw))
    refused(run, out, "simulation.engine: must be one of", "...")


# ---------------------------------------------------------------------------- recursion
@pytest.mark.parametrize(
    "text", ["a = " + "[" * 100_000 + "]" * 100_000, "a = " + "{b = " * 100_000 + "1" + "}" * 100_000]
)
def test_deeply_nested_toml_is_refused(tmp_path, text):
    study = tmp_path / "deep.toml"
    study.write_text(text + "\n")
    run, out = simulate(tmp_path, study)
    refused(run, out, "deep.toml: tables or arrays nested deeper than 16 levels")


def test_wall_file_pointing_at_its_own_study(tmp_path):
    raw = study_dict()
    raw["wall"] = {"file": "study.toml"}
    run, out = simulate(tmp_path, write_study(tmp_path, raw))
    refused(run, out, "wall.file: the wall files refer back to themselves (study.toml -> study.toml)")


def test_cycle_of_two_wall_files(tmp_path):
    raw = study_dict()
    raw["wall"] = {"file": "b.toml"}
    (tmp_path / "b.toml").write_text('[wall]\nfile = "study.toml"\n')
    run, out = simulate(tmp_path, write_study(tmp_path, raw))
    refused(run, out, "refer back to themselves (b.toml -> study.toml -> b.toml)")


# ---------------------------------------------------------------------------- lambda(T) and non-finite results
def test_temperature_coefficient_beyond_its_range(tmp_path):
    """0.2 1/K (allowed before, all-NaN series with exit 0 from fd-cn and fd-reference) is refused at load: on
    one layer in one line, on every layer every one is listed (lines of at most 300 characters)."""
    raw = study_dict()
    raw["wall"]["layers"][0]["conductivity_temperature_coefficient"] = 0.2
    run, out = simulate(tmp_path, write_study(tmp_path, raw))
    refused(run, out, "wall.layers[0].conductivity_temperature_coefficient: must be <= 0.05, got 0.2")
    for layer in raw["wall"]["layers"]:
        layer["conductivity_temperature_coefficient"] = 0.2
    for engine in ("fd-cn", "fd-reference"):
        run, out = simulate(tmp_path, write_study(tmp_path, raw), "--engine", engine)
        refused(run, out, "7 problems", lines=8)


def test_lambda_out_of_range_over_the_data_temperatures(tmp_path):
    """A coefficient within its range, but a reference temperature far from the data: lambda(T) grows 36-fold
    over the data's temperatures (5 .. 58 degC)."""
    raw = study_dict()
    raw["wall"]["layers"][0].update(conductivity_temperature_coefficient=0.05, reference_temperature=-60.0)
    run, out = simulate(tmp_path, write_study(tmp_path, raw))
    refused(run, out, "wall.layers[0].conductivity_temperature_coefficient: lambda(T) spans", "a factor 10")


def test_non_finite_results_are_errors_naming_the_series():
    """Any NaN in a result is an error naming the series and the likely cause, on fd's general path, in
    fd-reference and in the simulation's result (whatever the engine)."""
    from wallcal.engines import get_engine

    wall = three_layer_wall()
    ue = np.full(200, 5.0)
    ue[100:] = np.nan
    inp = make_input(wall, ue, np.full(200, 20.0), 60.0)
    with pytest.raises(
        EngineError, match=r"fd-cn: the simulated P0 is not finite .* from output 10[01] of 200 on; likely"
    ):
        get_engine("fd-cn").run(inp, path="general")
    with pytest.raises(EngineError, match=r"fd-reference: the simulated P0 is not finite .*; likely cause"):
        get_engine("fd-reference").run(inp)
    nonlinear = wall.replace_layer("wool", conductivity_temperature_coefficient=0.01)
    assert "lambda(T) law of wall.layers[1]" in nonlinear.nonfinite_cause()


def test_non_finite_simulation_result_is_an_error(example_study):
    from wallcal.simulation import prepare, result_from_output

    prep = prepare(example_study)
    out = prep.run()
    out.fluxes["interior"] = out.fluxes["interior"].copy()
    out.fluxes["interior"][7] = math.inf
    with pytest.raises(EngineError, match=r"fd-cn: the simulated qi is not finite \(NaN or inf\) from output 8 of"):
        result_from_output(prep, out, "fd-cn")


def test_modal_failure_says_what_to_do():
    """A layer far too thin for the modal path (built in the library, past the load checks): the error names
    what the user can do, not an API argument no command accepts."""
    from wallcal.engines import get_engine
    from wallcal.wall import Layer, Probe, Wall

    thin = Wall(
        (Layer("a", 0.1, 0.04, 135, 1030), Layer("b", 1e-30, 0.2, 530, 1600), Layer("c", 0.1, 0.035, 40, 1030)),
        (Probe("P", 0.1),),
    )
    ue = 10 + 5 * np.sin(np.arange(2000) / 100)
    try:
        out = get_engine("fd-cn").run(make_input(thin, ue, np.full(2000, 20.0), 60.0))
    except EngineError as exc:
        assert "path=" not in str(exc) and "thermal_resistance" in str(exc), exc
    else:  # the modal path coped: then its result is finite
        assert np.isfinite(out.temperatures["P"]).all()


def test_too_thin_layer_says_what_to_do(tmp_path):
    raw = study_dict()
    raw["wall"]["layers"][3]["thickness"] = 1e-9
    run, out = simulate(tmp_path, write_study(tmp_path, raw))
    line = refused(run, out, "wall.layers[3].thickness: 1e-09 m is thinner than 1e-06 m")
    assert "massless with thermal_resistance" in line and "path=" not in line


# ---------------------------------------------------------------------------- data files
def test_duplicated_data_column_is_refused(tmp_path):
    data = tmp_path / "dup.csv"
    head, rest = DATA.read_text().split("\n", 1)
    data.write_text(head.replace("T1A", "T3A") + "\n" + rest)
    run, out = simulate(tmp_path, write_study(tmp_path, study_dict(data)))
    refused(run, out, "dup.csv: column 'T3A' appears twice in the header (columns 3 and 5)")


@pytest.mark.parametrize("kind", ["fifo", "dev_zero", "directory"])
def test_data_that_is_not_a_regular_file(tmp_path, kind):
    if kind == "fifo":
        data = tmp_path / "fifo.csv"
        os.mkfifo(data)
    elif kind == "dev_zero":
        data = Path("/dev/zero")
    else:
        data = tmp_path / "dir.csv"
        data.mkdir()
    run, out = simulate(tmp_path, write_study(tmp_path, study_dict(data)))
    refused(run, out, f"{data.name}: is not a regular file")
    assert "empty" not in run.err


def test_study_file_that_is_a_fifo(tmp_path):
    study = tmp_path / "study.toml"
    os.mkfifo(study)
    run, out = simulate(tmp_path, study)
    refused(run, out, "study.toml: is not a regular file")


def test_only_the_needed_columns_are_read(tmp_path):
    """An extra column the study does not use may hold anything (text, a huge string)."""
    from wallcal.data import load_measurements
    from wallcal.study import parse_study

    data = tmp_path / "extra.csv"
    lines = DATA.read_text().splitlines()
    data.write_text("\n".join([lines[0] + ",notes"] + [line + ",x" * 1 + "y" * 1000 for line in lines[1:]]) + "\n")
    m = load_measurements(parse_study(study_dict(data), base_dir=tmp_path))
    assert list(m.frame.columns) == ["exterior", "interior", "T3A", "T2A", "T1A", "qe", "qi"]


# ---------------------------------------------------------------------------- the message itself
def test_messages_are_cut_and_escaped_centrally():
    msg = format_message("a\x00b\x1b[2J\r" + "x" * 10_000 + "\n" * 100, "wallcal: error: ")
    lines = msg.split("\n")
    assert len(lines) <= 26 and all(len(line) <= MAX_LINE for line in lines)
    assert lines[0].startswith("wallcal: error: a\\x00b\\x1b[2J\\r") and " ... " in lines[0]
    long = format_message("data.csv: column " + "y" * 5000 + " not found; did you mean 'T3A'?", "wallcal: error: ")
    assert len(long) == MAX_LINE and long.startswith("wallcal: error: data.csv: column yyy")
    assert long.endswith("not found; did you mean 'T3A'?")  # the start and what to do both kept
    many = StudyError([f"wall.layers[{i}].density: must be > 0" for i in range(500)], source="s.toml")
    assert str(many).count("\n") == 21 and str(many).endswith("... and 480 more")

"""Outputs (issue 10): every command writes into a temporary directory moved into place only when complete;
two runs into the same --out never interleave; an interrupted command leaves the previous result (or nothing)
and a clear message; results carry the wallcal version and the hashes of the study and of the input data."""

from __future__ import annotations

import hashlib
import json
import shutil
import subprocess
import sys
import threading
import tomllib

import pytest
import tomli_w

import wallcal
from conftest import EXAMPLE
from wallcal.cli import main
from wallcal.outputs import OutputBusyError, output_dir

QUICK = {"particles": 4, "generations": 2, "step_reductions": 0, "polish": False}


@pytest.fixture()
def study(tmp_path):
    """The example study with a tiny calibration, in a temporary directory."""
    raw = tomllib.loads(EXAMPLE.read_text())
    raw["calibration"]["settings"] = QUICK
    raw["calibration"].pop("reference_wall", None)
    shutil.copy(EXAMPLE.parent / "measured.csv", tmp_path / "measured.csv")
    path = tmp_path / "study.toml"
    path.write_text(tomli_w.dumps(raw))
    return path


def sha(path):
    return hashlib.sha256(path.read_bytes()).hexdigest()


def leftovers(d):
    """Temporary directories, old copies and lock files next to the outputs."""
    return sorted(
        p.name
        for p in d.iterdir()
        if p.name.startswith(".") and ("tmp" in p.name or "old" in p.name or p.name.endswith(".lock"))
    )


def check_manifest(out, study, command):
    m = json.loads((out / "manifest.json").read_text())
    assert m["wallcal_version"] == wallcal.__version__
    assert m["study_sha256"] == sha(study)
    assert m["data_sha256"] == sha(study.parent / "measured.csv")
    assert m["command"] == command
    return m


@pytest.mark.parametrize(
    "argv,command,files",
    [
        (["simulate"], "simulate", ["simulated.csv", "metrics.csv", "summary.csv", "info.json"]),
        (["calibrate", "--quiet"], "calibrate", ["calibrated_wall.toml", "calibration.json", "metrics.csv"]),
        (["iso9869"], "iso9869", ["iso9869.csv", "iso9869.json"]),
    ],
)
def test_commands_write_complete_traceable_results(study, argv, command, files, capsys):
    out = study.parent / "out"
    assert main([argv[0], str(study), "--out", str(out), *argv[1:]]) == 0
    for f in files:
        assert (out / f).is_file(), f
    check_manifest(out, study, command)
    assert leftovers(study.parent) == []
    # a second run replaces the first one as a whole
    assert main([argv[0], str(study), "--out", str(out), *argv[1:]]) == 0
    assert leftovers(study.parent) == []


def test_crosscheck_writes_a_traceable_result(study, capsys):
    wall = study.parent / "wall.toml"
    assert main(["simulate", str(study)]) == 0
    from wallcal.study import dump_wall, load_study

    wall.write_text(dump_wall(load_study(study).wall))
    out = study.parent / "cc"
    assert main(["crosscheck", str(study), str(wall), "--out", str(out)]) == 0
    check_manifest(out, study, "crosscheck")
    assert leftovers(study.parent) == []


def _interrupt_in(monkeypatch, cls, files_before=1):
    original = cls.write_into

    def write_into(self, d):
        original(self, d)  # every file is written into the temporary directory...
        assert any(d.iterdir())
        raise KeyboardInterrupt  # ... then Ctrl-C before it is moved into place

    monkeypatch.setattr(cls, "write_into", write_into)


def test_interrupted_simulate_keeps_the_previous_result(study, monkeypatch, capsys):
    from wallcal.simulation import SimulationResult

    out = study.parent / "out"
    assert main(["simulate", str(study), "--out", str(out)]) == 0
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    _interrupt_in(monkeypatch, SimulationResult)
    capsys.readouterr()
    assert main(["simulate", str(study), "--out", str(out)]) == 130
    err = capsys.readouterr().err
    assert "interrupted" in err and "Traceback" not in err
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before
    assert leftovers(study.parent) == []


def test_interrupted_first_run_leaves_nothing(study, monkeypatch, capsys):
    from wallcal.calibration.run import CalibrationResult

    _interrupt_in(monkeypatch, CalibrationResult)
    out = study.parent / "cal"
    code = main(["calibrate", str(study), "--out", str(out), "--quiet"])
    assert code == 130
    assert "interrupted" in capsys.readouterr().err
    # the calibration's own checkpoint may live in --out; the result files must not
    assert not (out / "calibration.json").exists() and not (out / "manifest.json").exists()
    assert leftovers(study.parent) == []


def test_concurrent_run_into_the_same_out_is_refused(study, capsys):
    out = study.parent / "out"
    entered, release = threading.Event(), threading.Event()
    errors = []

    def holder():
        try:
            with output_dir(out, manifest={"command": "holder"}) as tmp:
                (tmp / "holder.txt").write_text("first run")
                entered.set()
                release.wait(30)
        except BaseException as exc:  # pragma: no cover
            errors.append(exc)

    th = threading.Thread(target=holder)
    th.start()
    try:
        assert entered.wait(30)
        code = main(["simulate", str(study), "--out", str(out)])
        err = capsys.readouterr().err
        assert code == 2
        assert err.startswith("wallcal: error: ") and "another wallcal run" in err and "--out" in err, err
        assert not out.exists()  # the refused run wrote nothing
    finally:
        release.set()
        th.join(30)
    assert not errors
    assert sorted(p.name for p in out.iterdir()) == ["holder.txt", "manifest.json"]  # the first run, whole
    assert leftovers(study.parent) == []
    # and the lock is gone: the next run goes through
    assert main(["simulate", str(study), "--out", str(out)]) == 0
    assert not (out / "holder.txt").exists()


def test_concurrent_processes_never_interleave(study, tmp_path):
    """Two processes race into the same --out: each either writes a whole result or is refused."""
    out = tmp_path / "race"
    code = (
        "import sys, time\nfrom wallcal.outputs import output_dir, OutputBusyError\n"
        "try:\n    with output_dir(sys.argv[1]) as d:\n"
        "        for i in range(20):\n            (d / f'f{i}.txt').write_text(sys.argv[2]); time.sleep(0.01)\n"
        "except OutputBusyError as e:\n    print('busy'); sys.exit(3)\n"
    )
    procs = [
        subprocess.Popen([sys.executable, "-c", code, str(out), tag], stdout=subprocess.PIPE, text=True)
        for tag in ("A", "B")
    ]
    codes = [p.wait(60) for p in procs]
    assert sorted(codes) in ([0, 0], [0, 3]), codes
    tags = {(out / f"f{i}.txt").read_text() for i in range(20)}
    assert len(tags) == 1  # one run's files only
    assert leftovers(tmp_path) == []


def test_stale_lock_of_a_killed_run_is_taken_over(tmp_path):
    p = subprocess.Popen([sys.executable, "-c", "pass"])
    p.wait()
    lock = tmp_path / ".out.lock"
    lock.write_text(str(p.pid))  # a run that died without removing its lock
    with output_dir(tmp_path / "out") as d:
        (d / "x.txt").write_text("ok")
    assert (tmp_path / "out" / "x.txt").read_text() == "ok" and not lock.exists()


def test_live_lock_is_respected(tmp_path):
    import os

    (tmp_path / ".out.lock").write_text(str(os.getpid()))
    with pytest.raises(OutputBusyError, match="another wallcal run"):
        with output_dir(tmp_path / "out"):
            pass
    assert not (tmp_path / "out").exists()


def test_error_inside_leaves_previous_result(tmp_path):
    with output_dir(tmp_path / "out") as d:
        (d / "a.txt").write_text("1")
    with pytest.raises(ValueError):
        with output_dir(tmp_path / "out") as d:
            (d / "a.txt").write_text("2")
            raise ValueError("disk full")
    assert (tmp_path / "out" / "a.txt").read_text() == "1"
    assert leftovers(tmp_path) == []


def test_multi_file_data_are_hashed(tmp_path, capsys):
    """[[data.files]] studies: data_sha256 is the hash of every file's hash, in order."""
    from wallcal.data import data_sha256, file_sha256
    from wallcal.simulation import manifest_of
    from wallcal.study import load_study

    study = load_study(EXAMPLE.parents[1] / "trh" / "study.toml")
    with output_dir(tmp_path / "out", manifest=manifest_of(study, "simulate")):
        pass
    m = json.loads((tmp_path / "out" / "manifest.json").read_text())
    assert m["data_sha256"] == data_sha256(study)
    expect = hashlib.sha256("".join(file_sha256(p) for p in study.data.paths).encode()).hexdigest()
    assert m["data_sha256"] == expect and len(study.data.paths) > 1

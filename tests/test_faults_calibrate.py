"""Faults around calibration checkpoints (issue 36): bad checkpoints are refused in one line, and a calibration
killed at any moment resumes to the uninterrupted result.

Every command runs in a process of its own with a time-out and an address-space limit (RLIMIT_AS). The refusals
run the real CLI (``python -m wallcal.cli``), each measured (seconds, peak RSS from ``os.wait4``). The kills use
children forked from one warm process (a multiprocessing fork server that has imported wallcal, scipy and
matplotlib), so that twenty kill-and-resume rounds fit in seconds, not minutes: each child is a whole process
running ``wallcal.cli.main``, killed with SIGKILL.
"""

from __future__ import annotations

import json
import os
import random
import resource
import shutil
import subprocess
import sys
import tempfile
import threading
import time
import tomllib
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import pytest
import tomli_w

from conftest import EXAMPLE

#: address-space limit of every child [bytes]. numba/LLVM and OpenBLAS reserve much more address space than they
#: use: a small calibration peaks at about 380 MB RSS but fails to load llvmlite under 1.5 GB (measured); 3 GB
#: leaves room and still stops a runaway allocation.
ADDRESS_SPACE = 3 * 2**30
#: a refusal must stay under this peak RSS [bytes] and this time [s]
REFUSAL_RSS = 2**30
REFUSAL_SECONDS = 30.0
TIMEOUT = 120.0
PSO = {"particles": 6, "generations": 4, "step_reductions": 1, "polish_max_evaluations": 3}
CMA = {"maxfevals": 3000}
RESULT_FILES = ("calibrated_wall.toml", "parameters.csv", "metrics.csv")
KILLS = 20


def _limit():  # (in the child, before exec)
    resource.setrlimit(resource.RLIMIT_AS, (ADDRESS_SPACE, ADDRESS_SPACE))


def _study(directory: Path, algorithm: str, settings: dict) -> Path:
    """The bundled example over 2 days (1 day of warm-up) with a tiny budget, in ``directory``."""
    raw = tomllib.loads(EXAMPLE.read_text())
    raw["period"] = {
        "warmup_start": "2025-05-29T00:00:00",
        "start": "2025-05-30T00:00:00",
        "end": "2025-05-31T00:00:00",
    }
    for key in ("retrofit", "building"):
        raw.pop(key, None)
    raw["calibration"].pop("reference_wall", None)
    raw["calibration"]["algorithm"] = algorithm
    raw["calibration"]["settings"] = settings
    directory.mkdir(parents=True, exist_ok=True)
    shutil.copy(EXAMPLE.parent / "measured.csv", directory / "measured.csv")
    path = directory / "study.toml"
    text = tomli_w.dumps(raw)
    for k in ("warmup_start", "start", "end"):  # TOML datetimes, not strings
        text = text.replace(f'{k} = "{raw["period"][k]}"', f"{k} = {raw['period'][k]}")
    path.write_text(text)
    return path


@dataclass
class Run:
    code: int
    out: str
    err: str
    seconds: float
    rss: int  # peak resident set [bytes]


def cli(*args, cwd: Path, timeout: float = TIMEOUT) -> Run:
    """``python -m wallcal.cli ARGS`` in a fresh process with the address-space limit and a time-out."""
    env = dict(os.environ, PYTHONPATH=str(Path(__file__).resolve().parents[1] / "src"))
    t0 = time.perf_counter()
    p = subprocess.Popen(
        [sys.executable, "-m", "wallcal.cli", *map(str, args)],
        cwd=cwd,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=_limit,
    )
    box = {}
    readers = [
        threading.Thread(target=lambda k=k, f=f: box.update({k: f.read()}))
        for k, f in (("out", p.stdout), ("err", p.stderr))
    ]
    for t in readers:
        t.start()
    while True:  # wait4 (not Popen.wait): this child's own peak RSS
        pid, status, usage = os.wait4(p.pid, os.WNOHANG)
        if pid:
            break
        if time.perf_counter() - t0 > timeout:
            p.kill()
            os.wait4(p.pid, 0)
            p.returncode = -9
            pytest.fail(f"wallcal {' '.join(map(str, args))} did not end within {timeout} s")
        time.sleep(0.01)
    p.returncode = os.waitstatus_to_exitcode(status)
    for t in readers:
        t.join()
    p.stdout.close()
    p.stderr.close()
    return Run(p.returncode, box["out"], box["err"], time.perf_counter() - t0, usage.ru_maxrss * 1024)


# ------------------------------------------------------------------------- children forked from a warm process
def _warm(study: str) -> None:
    """(in the fork server) Load what every child would load: the numba kernels from their cache, the data, the
    fonts. Only single-candidate batches: no thread is started, so forking stays safe."""
    import io

    import matplotlib.pyplot as plt

    from wallcal import load_study
    from wallcal.calibration.objective import Evaluator
    from wallcal.calibration.space import space_of
    from wallcal.engines import fd
    from wallcal.simulation import BATCH_NEEDS, prepare, simulate

    st = load_study(study)
    prep = prepare(st, needs=BATCH_NEEDS, purpose="calibration")
    space = space_of(st)
    ev = Evaluator(prep, space)
    ev.objective(space.base[None])
    ev.objective_and_residuals(space.base[None])
    simulate(st, prepared=prep)
    fig, ax = plt.subplots(layout="constrained")
    ax.plot([0, 1], label="x")
    ax.legend()
    fig.savefig(io.BytesIO(), format="png")
    plt.close(fig)
    assert fd._POOL is None  # no worker thread in a process that forks
    # checkpoints of the time-saved algorithms (cma-es) every 0.1 s instead of every second: a warm child runs the
    # small cma-es study's 3,000 evaluations in about a second, and the test must see one mid-run checkpoint
    from wallcal.calibration import algorithms

    algorithms.AUTOSAVE_SECONDS = 0.1


if os.environ.get("WALLCAL_FAULTS_WARM"):  # imported by the fork server (see the fixture ``forked``)
    _warm(os.environ.pop("WALLCAL_FAULTS_WARM"))


def _child(argv, cwd, out_path, err_path):
    """A fork-server child: the CLI's ``main(argv)`` with its output in files, under the address-space limit;
    its peak RSS [kB] goes to ``err_path + ".rss"``."""
    _limit()
    for fd, path in ((1, out_path), (2, err_path)):
        f = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
        os.dup2(f, fd)
        os.close(f)
    os.chdir(cwd)
    code = 1
    try:
        from wallcal.cli import main

        code = main(argv)
    except SystemExit as exc:  # argparse (--help)
        code = exc.code if isinstance(exc.code, int) else 1
    except BaseException:  # noqa: BLE001 - shown in the test's failure message
        import traceback

        traceback.print_exc()
    finally:
        sys.stdout.flush()
        sys.stderr.flush()
        Path(err_path + ".rss").write_text(str(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss))
        # the exit code as the child saw it: the fork server relays it over a socket, and multiprocessing reports
        # 255 when that read fails (seen on a loaded host, with the child's output complete)
        Path(err_path + ".code").write_text(str(code))
        os._exit(code)


@pytest.fixture(scope="module")
def forked(pso):
    """A fork server that has imported and loaded what a calibration needs (:func:`_warm`); returns
    ``start(argv, cwd) -> (process, read)``. Its children's peak RSS includes the server's pages they share."""
    import multiprocessing.forkserver

    ctx = multiprocessing.get_context("forkserver")
    ctx.set_forkserver_preload(
        ["numpy", "scipy.optimize", "pandas", "matplotlib.pyplot", "wallcal.cli", "wallcal.calibration.run",
         "wallcal.calibration.plots", "wallcal.engines.fd", "wallcal.engines.modal", "test_faults_calibrate"]
    )  # fmt: skip
    here = Path(__file__).resolve().parent
    saved = dict(os.environ)
    # the server imports its preload modules with the environment's path (Python 3.11 ignores the parent's
    # sys.path there): this folder and src must be on it
    os.environ["PYTHONPATH"] = os.pathsep.join([str(here), str(here.parent / "src"), saved.get("PYTHONPATH", "")])
    os.environ["WALLCAL_FAULTS_WARM"] = str(pso[0])
    try:
        multiprocessing.forkserver.ensure_running()
    finally:
        os.environ.clear()
        os.environ.update(saved)
    counter = iter(range(10**6))

    def start(argv, cwd: Path):
        k = next(counter)
        out, err = cwd / f"stdout-{k}.txt", cwd / f"stderr-{k}.txt"
        p = ctx.Process(target=_child, args=([str(a) for a in argv], str(cwd), str(out), str(err)), daemon=True)
        p.start()
        return p, lambda: (out.read_text(), err.read_text(), int(Path(f"{err}.rss").read_text()) * 1024, err)

    probe = Path(tempfile.mkdtemp(prefix="forked-"))
    r = run_forked(start, ["--help"], probe)  # returns once the server has warmed up and forks
    shutil.rmtree(probe, ignore_errors=True)
    assert r.code == 0, r.err
    return start


def run_forked(forked, argv, cwd: Path, timeout: float = TIMEOUT) -> Run:
    t0 = time.perf_counter()
    p, read = forked(argv, cwd)
    p.join(timeout)
    if p.is_alive():
        p.kill()
        p.join()
        pytest.fail(f"wallcal {' '.join(map(str, argv))} did not end within {timeout} s")
    out, err, rss, err_path = read()
    code_file = Path(f"{err_path}.code")
    code = int(code_file.read_text()) if code_file.is_file() else p.exitcode
    return Run(code, out, err, time.perf_counter() - t0, rss)


# ------------------------------------------------------------------------- helpers
def leftovers(d: Path, name: str = "cal") -> list[str]:
    """What a run may leave next to its output only while it runs: temporary directories, old copies, locks,
    the checkpoint."""
    return sorted(p.name for p in d.iterdir() if p.name.startswith(f".{name}."))


def result_of(out: Path) -> dict:
    """The result files' bytes, and calibration.json without its wall times."""
    files = {f: (out / f).read_bytes() for f in RESULT_FILES}
    cal = json.loads((out / "calibration.json").read_text())
    cal.pop("wall_time_s")
    cal["history"] = [[e, f] for e, _, f in cal["history"]]
    files["calibration.json"] = cal
    assert json.loads((out / "manifest.json").read_text())["command"] == "calibrate"
    return files


def assert_refused(r: Run, *expected: str):
    lines = r.err.strip().splitlines()
    assert r.code == 2, r.err
    assert len(lines) == 1 and "Traceback" not in r.err, r.err
    assert lines[0].startswith("wallcal: error: ") and len(lines[0]) <= 300, lines[0]
    assert "without --resume" in lines[0] or "remove" in lines[0], lines[0]
    for e in expected:
        assert e in lines[0], lines[0]
    assert r.seconds < REFUSAL_SECONDS and r.rss < REFUSAL_RSS, (r.seconds, r.rss)


# ------------------------------------------------------------------------- fixtures
@pytest.fixture(scope="module")
def pso(tmp_path_factory):
    """The small pso-hj study, its uninterrupted result (the CLI in a fresh process: also warms the numba cache)
    and a checkpoint of the same run stopped in its swarm phase."""
    d = tmp_path_factory.mktemp("pso")
    study = _study(d / "study", "pso-hj", PSO)
    r = cli("calibrate", study, "--out", d / "ref", "--quiet", cwd=d)
    assert r.code == 0, r.err
    ckpt = _interrupted_checkpoint(study, d / "mid", stop_at_call=6)
    return study, result_of(d / "ref"), ckpt


def _interrupted_checkpoint(study: Path, out: Path, stop_at_call: int, in_kernel: bool = False) -> Path:
    """The checkpoint of a calibration interrupted (Ctrl-C) at its ``stop_at_call``-th batch, run in this process
    (``in_kernel``: the Ctrl-C arrives while a numba kernel runs, as a SystemError caused by it)."""
    import pytest as _pytest

    from wallcal import load_study
    from wallcal.calibration import calibrate
    from wallcal.calibration.objective import Evaluator

    calls = {"n": 0}
    orig = Evaluator.objective

    def flaky(self, X):
        calls["n"] += 1
        if calls["n"] == stop_at_call:
            if in_kernel:
                raise SystemError("returned a result with an exception set") from KeyboardInterrupt()
            raise KeyboardInterrupt
        return orig(self, X)

    with _pytest.MonkeyPatch.context() as mp:
        mp.setattr(Evaluator, "objective", flaky)
        res = calibrate(load_study(study), progress=False, out_dir=out)
    assert res.status == "interrupted"
    ckpt = out.parent / f".{out.name}.checkpoint.json"
    assert ckpt.is_file()
    return ckpt


def test_ctrl_c_inside_a_kernel_saves_the_checkpoint(pso, tmp_path):
    """A Ctrl-C that lands in a numba kernel surfaces as a SystemError caused by the KeyboardInterrupt: the
    calibration still stops as interrupted with its checkpoint, like a plain Ctrl-C."""
    ckpt = _interrupted_checkpoint(pso[0], tmp_path / "mid", stop_at_call=6, in_kernel=True)
    assert json.loads(ckpt.read_text())["history"]


def test_a_system_error_without_ctrl_c_is_not_an_interruption():
    from wallcal.errors import interrupted

    assert not interrupted(SystemError("a real error"))
    assert interrupted(KeyboardInterrupt())


# ------------------------------------------------------------------------- bad checkpoints
def _tamper(d: dict, case: str):
    """The checkpoint ``d`` damaged as ``case`` says: text to write, or None when the test makes the file."""
    last = d["history"][-1]

    def consistent(best_f):  # best_f and the history's last row together, so that only re-evaluation can tell
        return json.dumps({**d, "best_f": best_f, "history": d["history"][:-1] + [[last[0], last[1], best_f]]})

    return {
        "empty": "",
        "list": "[]",
        "null": "null",
        "truncated": json.dumps(d)[: len(json.dumps(d)) // 2],
        "garbage": None,
        "nan": json.dumps({**d, "best_f": float("nan")}),
        "nan-consistent": consistent(float("nan")),
        "huge-negative": consistent(-1e300),
        "slightly-better": consistent(d["best_f"] * 0.999),
        "unknown-phase": json.dumps({**d, "state": {**d["state"], "phase": "annealing"}}),
        "unknown-progress-phase": json.dumps({**d, "phase": "annealing"}),
        "short-history-rows": json.dumps({**d, "history": [h[:2] for h in d["history"]]}),
        "history-cut": json.dumps({**d, "history": d["history"][:1]}),
        "no-history": json.dumps({k: v for k, v in d.items() if k != "history"}),
        "best-outside-box": json.dumps({**d, "best_u": [1.5] + d["best_u"][1:]}),
        "best-too-short": json.dumps({**d, "best_u": d["best_u"][:-1]}),
        "moved-best": json.dumps({**d, "best_u": [min(1.0, d["best_u"][0] + 0.01)] + d["best_u"][1:]}),
        "swarm-altered": json.dumps(
            {**d, "state": {**d["state"], "pbest_f": [v * 1.5 for v in d["state"]["pbest_f"]]}}
        ),
        "swarm-misshapen": json.dumps({**d, "state": {**d["state"], "x": d["state"]["x"][:-1]}}),
        "strings": json.dumps({**d, "best_u": [str(x) for x in d["best_u"]]}),
        "other-seed": json.dumps({**d, "seed": d["seed"] + 1}),
        "old-format": json.dumps({k: v for k, v in d.items() if k != "format"}),
        "huge-integer": json.dumps({**d, "best_f": 10**400}),
        "endless-digits": '{"format": 2, "seed": 1' + "0" * 5000 + "}",
        "deep-nesting": "[" * 100_000 + "]" * 100_000,
    }[case]


CASES = [
    ("empty", "empty"),
    ("list", "JSON list"),
    ("null", "JSON null"),
    ("truncated", "not valid JSON"),
    ("garbage", "UTF-8"),
    ("nan", "best_f must be a finite number"),
    ("nan-consistent", "best_f must be a finite number"),
    ("huge-negative", "its best point gives"),
    ("slightly-better", "its best point gives"),
    ("unknown-phase", "unknown state.phase"),
    ("unknown-progress-phase", "unknown phase"),
    ("short-history-rows", "history[0]"),
    ("history-cut", "history does not end"),
    ("no-history", "history must be"),
    ("best-outside-box", "unit box"),
    ("best-too-short", "shape"),
    ("moved-best", "its best point gives"),
    ("swarm-altered", "particle best"),
    ("swarm-misshapen", "state.x"),
    ("strings", "best_u must be a list of numbers"),
    ("other-seed", "another seed"),
    ("old-format", "format"),
    ("huge-integer", "best_f must be a finite number"),
    ("endless-digits", "digits"),
    ("deep-nesting", "nested too deeply"),
]


def _refusal_case(pso, forked, tmp_path, case):
    study, _, good = pso
    d = json.loads(good.read_text())
    out = tmp_path / "cal"
    ckpt = tmp_path / ".cal.checkpoint.json"
    text = _tamper(d, case)
    if text is None:
        ckpt.write_bytes(b"\xff\xfe\x00garbage\x9c" * 50)
    else:
        ckpt.write_text(text)
    before = ckpt.read_bytes()
    r = run_forked(forked, ["calibrate", study, "--out", out, "--quiet", "--resume"], tmp_path)
    return r, out, ckpt, before


@pytest.mark.slow
def test_bad_checkpoints_are_refused_in_one_line(pso, forked, tmp_path):
    """Each damaged or tampered checkpoint: exit 2, one line of at most 300 characters naming the file, the problem
    and how to start afresh; no traceback; nothing written; the checkpoint left as it was; < 30 s, < 1 GB (each
    case a child of the warm fork server; the real CLI in fresh processes in the next test)."""
    study, _, good = pso
    assert json.loads(good.read_text())["state"]["phase"] == "pso"  # a swarm state to tamper with

    def one(item):
        case, expected = item
        d = tmp_path / case
        d.mkdir()
        r, out, ckpt, before = _refusal_case(pso, forked, d, case)
        return case, expected, r, out, ckpt, before

    with ThreadPoolExecutor(3) as ex:
        results = list(ex.map(one, CASES))
    for case, expected, r, out, ckpt, before in results:
        try:
            assert_refused(r, expected, str(ckpt.name))
        except AssertionError as exc:
            raise AssertionError(f"case {case}: {exc}") from None
        assert not out.exists(), case
        assert ckpt.read_bytes() == before, case
        assert leftovers(ckpt.parent) == [".cal.checkpoint.json"], case
    worst = max(results, key=lambda x: x[2].seconds)[2]
    print(f"\nrefusals: slowest {worst.seconds:.1f} s, peak RSS {max(x[2].rss for x in results) / 2**20:.0f} MB")


@pytest.mark.slow
def test_checkpoints_that_are_not_files_are_refused(pso, tmp_path):
    """A directory, a symbolic link (even to a good checkpoint) or a pipe at the checkpoint's path: refused in one
    line (a pipe is not read: it would hang); a fresh run refuses to write over a directory; a tampered best value
    is refused after re-evaluation. The real CLI, each in a fresh process (< 30 s, < 1 GB peak RSS)."""
    study, _, good = pso
    ckpt = tmp_path / ".cal.checkpoint.json"
    out = tmp_path / "cal"
    ckpt.mkdir()
    r = cli("calibrate", study, "--out", out, "--quiet", "--resume", cwd=tmp_path)
    assert_refused(r, "is a directory")
    r = cli("calibrate", study, "--out", out, "--quiet", cwd=tmp_path)
    assert_refused(r, "directory")
    assert not out.exists() and ckpt.is_dir()
    ckpt.rmdir()
    shutil.copy(good, tmp_path / "elsewhere.json")
    ckpt.symlink_to(tmp_path / "elsewhere.json")
    r = cli("calibrate", study, "--out", out, "--quiet", "--resume", cwd=tmp_path)
    assert_refused(r, "symbolic link")
    ckpt.unlink()
    os.mkfifo(ckpt)
    r = cli("calibrate", study, "--out", out, "--quiet", "--resume", cwd=tmp_path, timeout=REFUSAL_SECONDS)
    assert_refused(r, "not a regular file")
    ckpt.unlink()
    ckpt.write_text(_tamper(json.loads(good.read_text()), "huge-negative"))  # refused after re-evaluation
    r = cli("calibrate", study, "--out", out, "--quiet", "--resume", cwd=tmp_path)
    assert_refused(r, "its best point gives")
    assert not out.exists()
    print(f"\nfresh-process refusal with re-evaluation: {r.seconds:.1f} s, peak RSS {r.rss / 2**20:.0f} MB")


# ------------------------------------------------------------------------- kills
@pytest.mark.slow
def test_kill_at_random_moments_then_resume(pso, forked, tmp_path):
    """SIGKILL at 20 moments spread over a whole calibration (imports, the swarm, the pattern search, the polish,
    the outputs, after the end), each followed by ``--resume``: every resume completes, with exactly the
    uninterrupted result, and leaves no temporary directory, lock or checkpoint. "nothing to resume" only when
    the outputs were complete."""
    study, reference, _ = pso
    argv = ["calibrate", study, "--out", "cal", "--quiet"]
    first = tmp_path / "first"
    first.mkdir()
    r = run_forked(forked, argv, first)
    assert r.code == 0, r.err
    assert result_of(first / "cal") == reference  # a forked child gives the fresh process's result
    span = r.seconds
    rng = random.Random(36)
    moments = [span * (i + rng.random()) / KILLS for i in range(KILLS)]  # one in each twentieth of the run

    def one(i):
        d = tmp_path / f"kill{i:02d}"
        d.mkdir()
        p, _ = forked(argv, d)
        time.sleep(moments[i])
        p.kill()
        p.join(TIMEOUT)
        ck = d / ".cal.checkpoint.json"
        seen = {
            "checkpoint": json.loads(ck.read_text()).get("state", {}) if ck.is_file() else None,
            "complete": (d / "cal" / "manifest.json").is_file(),
            "leftovers": leftovers(d),
        }
        return i, seen, run_forked(forked, [*argv, "--resume"], d)

    with ThreadPoolExecutor(2) as ex:
        rounds = list(ex.map(one, range(KILLS)))
    stages = []
    for i, seen, r in rounds:
        d = tmp_path / f"kill{i:02d}"
        where = f"kill {i} at {moments[i]:.2f} s of {span:.2f} s ({seen}): {r.err[-500:]}"
        assert r.code == 0 and "Traceback" not in r.err, where
        if "nothing to resume" in r.out:
            assert seen["complete"], where
        assert result_of(d / "cal") == reference, where
        assert leftovers(d) == [], where
        st = seen["checkpoint"]
        stages.append("written" if seen["complete"] else (st or {}).get("phase", "none") if st is not None else "none")
    print(f"\nkills over {span:.2f} s, checkpoint phase at each kill: {stages}")
    print("moments", [round(m, 2) for m in moments], "resumes", [round(r.seconds, 1) for _, _, r in rounds])
    # the kills reached the run's stages: before the first checkpoint, during the search, after it
    assert "none" in stages and len(set(stages)) >= 3, stages


@pytest.mark.slow
def test_cma_es_resumes_to_the_uninterrupted_result_within_its_budget(forked, tmp_path):
    """cma-es killed mid-run: --resume replays its logged batches from the seed and goes on, so it ends with the
    uninterrupted run's result and evaluations (not beyond maxfevals)."""
    study = _study(tmp_path / "study", "cma-es", CMA)
    argv = ["calibrate", study, "--out", "cal", "--quiet"]
    ref = tmp_path / "ref"
    ref.mkdir()
    r = run_forked(forked, argv, ref)
    assert r.code == 0, r.err
    reference = result_of(ref / "cal")
    assert reference["calibration.json"]["evaluations"] <= CMA["maxfevals"] + 20  # (one generation beyond at most)
    d = tmp_path / "killed"
    d.mkdir()
    p, _ = forked(argv, d)
    ck = d / ".cal.checkpoint.json"
    t0 = time.perf_counter()
    mid = 0
    while time.perf_counter() - t0 < TIMEOUT and p.is_alive():
        try:
            data = json.loads(ck.read_text())
        except (OSError, ValueError):
            data = {}
        if data.get("state") is None and data.get("evaluations", 0) > 100:
            mid = data["evaluations"]
            break
        time.sleep(0.01)
    p.kill()
    p.join(TIMEOUT)
    assert 100 < mid < reference["calibration.json"]["evaluations"], f"no mid-run checkpoint seen in {r.seconds:.2f} s"
    r = run_forked(forked, [*argv, "--resume"], d)
    assert r.code == 0, r.err
    assert result_of(d / "cal") == reference
    assert leftovers(d) == []
    # its log cut short: refused
    data = json.loads((ref / "cal" / "calibration.json").read_text())
    assert data["algorithm"] == "cma-es"


def test_a_bad_checkpoint_is_refused_before_any_simulation(pso, tmp_path, monkeypatch):
    """Library: the checkpoint is read and checked before the data are prepared (a refusal costs no simulation)."""
    from wallcal import load_study
    from wallcal.calibration import calibrate
    from wallcal.calibration import run as run_mod
    from wallcal.calibration.checkpoint import CheckpointError

    study, _, _ = pso
    (tmp_path / ".cal.checkpoint.json").write_text("[]")

    def no_prepare(*a, **k):
        raise AssertionError("prepared the data before checking the checkpoint")

    monkeypatch.setattr(run_mod, "prepare", no_prepare)
    with pytest.raises(CheckpointError, match="JSON list"):
        calibrate(load_study(study), out_dir=tmp_path / "cal", resume=True, progress=False)


def test_stale_temporary_directories_are_cleaned(tmp_path):
    """What a killed run leaves (a temporary directory, an old copy, a half-made lock) goes on the next run; a
    previous result moved aside just before the kill is put back; nothing of a live run is touched."""
    from wallcal.outputs import clean_stale, output_dir

    out = tmp_path / "cal"
    (tmp_path / ".cal.tmp-abc123").mkdir()
    (tmp_path / ".cal.tmp-abc123" / "fit.png").write_bytes(b"half")
    old = tmp_path / ".cal.old-999999"
    old.mkdir()
    (old / "manifest.json").write_text("{}")
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    (tmp_path / f".cal.lock.{dead.pid}.1234").write_text(str(dead.pid))
    (tmp_path / ".other.tmp-x").mkdir()  # another output's: not ours
    assert sorted(clean_stale(out)) == [".cal.old-999999", ".cal.tmp-abc123"]
    assert (out / "manifest.json").is_file()  # the previous result, back in place
    assert sorted(p.name for p in tmp_path.iterdir()) == [".other.tmp-x", "cal"]
    with output_dir(out) as tmp:
        (tmp / "x.txt").write_text("x")
        (tmp_path / ".cal.tmp-zzz").mkdir()  # (a killed run's, made while we write: cleaned by the next run)
        assert clean_stale(out) == []  # we hold the lock: nothing is touched
    assert (out / "x.txt").is_file()
    with output_dir(out) as tmp:
        (tmp / "y.txt").write_text("y")
    assert sorted(p.name for p in tmp_path.iterdir()) == [".other.tmp-x", "cal"]


def test_resume_without_a_checkpoint(pso, tmp_path):
    """--resume with no checkpoint: a complete output says "nothing to resume" (exit 0); without outputs, the run
    starts from the beginning (a kill before the first checkpoint loses nothing but time)."""
    study, reference, _ = pso
    r = cli("calibrate", study, "--out", tmp_path / "cal", "--quiet", "--resume", cwd=tmp_path)
    assert r.code == 0 and "calibrating from the start" in r.err, r.err
    assert result_of(tmp_path / "cal") == reference
    r = cli("calibrate", study, "--out", tmp_path / "cal", "--quiet", "--resume", cwd=tmp_path)
    assert r.code == 0 and "nothing to resume" in r.out, r.out
    assert leftovers(tmp_path) == []


@pytest.mark.parametrize(
    "algorithm,settings",
    [("differential-evolution", {"maxiter": 12, "popsize": 2}), ("nelder-mead", {"maxfev": 120}), ("cma-es", {})],
)
def test_replayed_algorithms_resume_to_the_uninterrupted_result(pso, tmp_path, algorithm, settings):
    """Library: interrupted (Ctrl-C) after a few batches, the run resumes by replaying its logged batches from the
    seed: the same optimum, objective, evaluations and history values as the uninterrupted run. A log altered so
    that the replay cannot reach the stored best point is refused."""
    import numpy as np

    from wallcal import load_study
    from wallcal.calibration import calibrate
    from wallcal.calibration.checkpoint import CheckpointError
    from wallcal.calibration.objective import Evaluator

    settings = settings or {"maxfevals": 120, "popsize": 6}
    study = load_study(pso[0])
    full = calibrate(study, algorithm=algorithm, settings=settings, progress=False)
    out = tmp_path / "cal"
    calls = {"n": 0}
    orig = Evaluator.objective

    def flaky(self, X):
        calls["n"] += 1
        if calls["n"] == 8:
            raise KeyboardInterrupt
        return orig(self, X)

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(Evaluator, "objective", flaky)
        part = calibrate(study, algorithm=algorithm, settings=settings, progress=False, out_dir=out)
    assert part.status == "interrupted"
    ckpt = tmp_path / ".cal.checkpoint.json"
    saved = json.loads(ckpt.read_text())
    assert saved["state"] is None and len(saved["log"]) >= 5
    good = ckpt.read_text()
    forged = {**saved, "log": [[1.0] + saved["log"][0][1:]] + saved["log"][1:]}  # a better base case than real
    ckpt.write_text(json.dumps(forged))
    with pytest.raises(CheckpointError, match="does not retrace its log"):
        calibrate(study, algorithm=algorithm, settings=settings, progress=False, out_dir=out, resume=True)
    ckpt.write_text(good)
    done = calibrate(study, algorithm=algorithm, settings=settings, progress=False, out_dir=out, resume=True)
    assert done.status == "complete"
    np.testing.assert_array_equal(done.x_opt, full.x_opt)
    assert done.f_opt == full.f_opt and done.evaluations == full.evaluations
    assert [(e, f) for e, _, f in done.history] == [(e, f) for e, _, f in full.history]

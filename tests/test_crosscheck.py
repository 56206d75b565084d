"""One cross-check (:mod:`wallcal.crosscheck`) for ``wallcal crosscheck`` and the ``crosscheck`` stage of ``wallcal
run``: one table (``wall``, ``engine``, ``rmse_<target>``), the walls beside it, read back by ``building --from``."""

from __future__ import annotations

import ast
from types import SimpleNamespace

import pandas as pd
import pytest

from conftest import EXAMPLE, REPO
from wallcal import dump_wall, load_study
from wallcal.building import collect_walls
from wallcal.cli import main
from wallcal.crosscheck import CSV, WALLS, crosscheck, read_crosscheck, with_study_probes
from wallcal.errors import StudyError
from wallcal.outputs import OutputFormatError

TARGETS = ["T3A", "T2A", "T1A"]


def _layer(wall, lid):
    return next(layer for layer in wall.layers if layer.id == lid)


@pytest.fixture(scope="module")
def study():
    return load_study(EXAMPLE)


@pytest.fixture(scope="module")
def command_output(tmp_path_factory, study):
    """``wallcal crosscheck`` on the study's wall and a 20 % more conductive layer 3, fd-cn."""
    tmp = tmp_path_factory.mktemp("cc")
    (tmp / "base.toml").write_text(dump_wall(study.wall))
    lam = _layer(study.wall, "3").conductivity
    (tmp / "kplus.toml").write_text(dump_wall(study.wall.replace_layer("3", conductivity=1.2 * lam)))
    out = tmp / "out"
    argv = ["crosscheck", str(EXAMPLE), str(tmp / "base.toml"), str(tmp / "kplus.toml"), "--engines", "fd-cn"]
    assert main([*argv, "--out", str(out)]) == 0
    return out


def test_the_command_writes_the_documented_columns_and_the_walls(command_output, study):
    df = pd.read_csv(command_output / CSV)
    assert list(df.columns) == ["wall", "engine"] + [f"rmse_{t}" for t in TARGETS]
    assert list(df["wall"]) == ["base", "kplus"] and set(df["engine"]) == {"fd-cn"}
    assert sorted(p.name for p in (command_output / WALLS).iterdir()) == ["base.toml", "kplus.toml"]
    back = read_crosscheck(command_output)
    assert list(back.walls) == ["base", "kplus"] and back.walls["base"].layers == study.wall.layers
    assert back.table.equals(df)


def test_building_from_reads_the_crosscheck_output(command_output, study):
    walls = collect_walls(study, (), [command_output])
    assert [(w.name, w.kind) for w in walls] == [("base", "optimal"), ("kplus", "optimal")]
    assert _layer(walls[1].wall, "3").conductivity == pytest.approx(1.2 * _layer(study.wall, "3").conductivity)


def test_the_run_stage_writes_the_same_format(tmp_path, study, command_output):
    """The stage of ``wallcal run`` (base case and calibrated wall) writes what the command writes, and a
    manifest with the crosscheck format, so ``building --from RUN/crosscheck`` reads it."""
    from wallcal.workflow import RunContext, StageOutput, _stage_crosscheck

    cal = SimpleNamespace(
        wall_opt=study.wall.replace_layer("3", conductivity=0.05), space=SimpleNamespace(targets=TARGETS)
    )
    ctx = RunContext(study=study, out=tmp_path, progress=False, engines=["fd-cn"], results={"calibration": cal})
    so = StageOutput("crosscheck", "Cross-check")
    _stage_crosscheck(ctx, tmp_path, so)
    df = pd.read_csv(tmp_path / CSV)
    assert list(df.columns) == list(pd.read_csv(command_output / CSV).columns)
    assert list(df["wall"]) == ["base case", "calibrated"]
    assert {CSV, f"{WALLS}/base case.toml", f"{WALLS}/calibrated.toml"} <= set(so.files)
    walls = collect_walls(study, (), [tmp_path])
    assert [w.name for w in walls] == ["base case", "calibrated"] and _layer(walls[1].wall, "3").conductivity == 0.05


def test_a_wall_without_probes_takes_the_study_s_and_a_missing_probe_is_named(study):
    bare = study.wall.replace(probes=())
    assert with_study_probes(study, bare, "x.toml").probes == study.wall.probes
    one = study.wall.replace(probes=study.wall.probes[:1])
    with pytest.raises(StudyError, match="x.toml: the wall has no probe"):
        with_study_probes(study, one, "x.toml")


def test_known_comparisons_are_reused(study, monkeypatch):
    """The run stage's base case is the engines stage's comparison: not run again."""
    import wallcal.comparison as comparison

    seen = []
    real = comparison.compare_many

    def spy(studies, engines, **kw):
        seen.append(len(studies))
        return real(studies, engines, **kw)

    monkeypatch.setattr(comparison, "compare_many", spy)
    base = comparison.compare_engines(study, ["fd-cn"])
    seen.clear()
    res = crosscheck(study, {"a": study.wall, "b": study.wall}, ["fd-cn"], known={"a": base})
    assert seen == [1] and len(res.table) == 2
    assert res.table.iloc[0]["rmse_T1A"] == pytest.approx(res.table.iloc[1]["rmse_T1A"])


def test_an_old_crosscheck_output_is_refused_with_its_folder_and_versions(command_output, tmp_path):
    import shutil

    old = tmp_path / "old"
    shutil.copytree(command_output, old)
    (old / "manifest.json").unlink()
    with pytest.raises(OutputFormatError, match=f"{old}: no manifest.json.*crosscheck output of format 1"):
        read_crosscheck(old)


def test_one_crosscheck_in_the_code():
    """Only wallcal.crosscheck names the table's file and its columns: the command and the stage call it."""
    src = REPO / "src" / "wallcal"
    hits = []
    for path in src.rglob("*.py"):
        if path.name == "crosscheck.py" or path.name == "outputs.py":
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Constant) and node.value == "crosscheck.csv":
                hits.append(str(path.relative_to(src)))
    assert hits == []
    for rel, func in (("commands/calibrate.py", "crosscheck_command"), ("workflow.py", "_stage_crosscheck")):
        tree = ast.parse((src / rel).read_text())
        (fn,) = [n for n in ast.walk(tree) if isinstance(n, ast.FunctionDef) and n.name == func]
        called = {n.func.id for n in ast.walk(fn) if isinstance(n, ast.Call) and isinstance(n.func, ast.Name)}
        assert "crosscheck" in called, rel

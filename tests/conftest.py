"""Shared test helpers: small walls, engine inputs built from arrays, paths to shared data."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from skip_policy import (  # noqa: F401  (the skip policy's hooks: CI fails on a skip that is not allow-listed)
    pytest_make_collect_report,
    pytest_runtest_makereport,
    pytest_terminal_summary,
)
from wallcal.engines.base import BoundaryInput, EngineOptions, SimulationInput
from wallcal.wall import Layer, Probe, Wall

REPO = Path(__file__).resolve().parents[1]
EXAMPLE = REPO / "src" / "wallcal" / "examples" / "campaign_a" / "study.toml"
SHARED = REPO.parent / "shared" / "data"
CAMPAIGN = SHARED / "campaign_visible"


def three_layer_wall(probes=(0.05, 0.12, 0.2, 0.235)) -> Wall:
    """Brick / mineral wool / gypsum, 0.25 m (a massive + insulating + light wall)."""
    layers = (
        Layer("brick", 0.10, conductivity=0.8, density=1800.0, specific_heat=840.0),
        Layer("wool", 0.12, conductivity=0.04, density=60.0, specific_heat=1030.0),
        Layer("gypsum", 0.03, conductivity=0.25, density=900.0, specific_heat=1000.0),
    )
    return Wall(layers, tuple(Probe(f"P{i}", d) for i, d in enumerate(probes)))


def base_case_wall() -> Wall:
    import json

    d = json.loads((CAMPAIGN / "wall_base_case.json").read_text())
    layers = tuple(
        Layer(str(L["id"]), L["thickness_m"], conductivity=L["lambda"], density=L["rho"], specific_heat=L["c"])
        for L in d["layers"]
    )
    probes = tuple(Probe(p["name"], p["depth_m"]) for p in d["probes"] if p["name"] in ("T3A", "T2A", "T1A"))
    return Wall(layers, probes)


def make_input(
    wall: Wall,
    ue,
    ui,
    dt: float,
    *,
    out_every: int = 1,
    scheme="cn",
    C=2.0,
    rule="wallcal",
    ext="surface_temperature",
    intr="surface_temperature",
    h_e=None,
    h_i=None,
    probes=None,
    faces=("exterior", "interior"),
    **options,
) -> SimulationInput:
    ue = np.asarray(ue, dtype=float)
    ui = np.asarray(ui, dtype=float)
    n = len(ue) - 1
    pos = np.arange(0, n + 1, out_every, dtype=float)
    return SimulationInput(
        wall=wall,
        t0=pd.Timestamp("2025-01-01"),
        time_step=dt,
        exterior=BoundaryInput(ext, ue, h_e),
        interior=BoundaryInput(intr, ui, h_i),
        output_positions=pos,
        probes=tuple(probes or [p.name for p in wall.probes]),
        flux_faces=faces,
        grid_constant=C,
        node_rule=rule,
        scheme=scheme,
        options=EngineOptions(**options),
    )


@pytest.fixture(scope="session")
def example_study():
    from wallcal import load_study

    return load_study(EXAMPLE)


def assert_clean_error(code, cap, out, *fragments):
    """A command's bad-input exit: code 2, one line ``wallcal: error: ...`` holding each fragment, and nothing
    written at ``out`` (no output, no temporary, lock or cache file beside it)."""
    assert code == 2, cap.err
    err = cap.err.strip()
    assert err.startswith("wallcal: error:") and "\n" not in err, err
    for f in fragments:
        assert f in err, err
    assert not out.exists()
    assert not list(out.parent.glob(f".{out.name}*")), "a temporary, lock or cache file was left behind"

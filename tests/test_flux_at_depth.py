"""Heat-flux sensors inside the wall (e.g. PASSYS' FLX_8): the engine's flux through the plane at the depth."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from analytic import periodic_solution
from wallcal import StudyError, simulate
from wallcal.study import parse_study

PERIOD = 86400.0


def study(tmp_path, depth=0.06, extra=None):
    t = pd.date_range("2025-01-01", "2025-01-09", freq="300s")
    s = (t - t[0]).total_seconds().to_numpy()
    w = 2 * np.pi / PERIOD
    df = pd.DataFrame(
        {
            "timestamp": t.strftime("%Y-%m-%dT%H:%M:%S"),
            "Te": 5 + 10 * np.cos(w * s),
            "Ti": np.full(len(s), 20.0),
            "q": np.zeros(len(s)),
        }
    )
    df.to_csv(tmp_path / "d.csv", index=False)
    raw = {
        "wall": {
            "layers": [
                {"id": "brick", "thickness": 0.1, "conductivity": 0.8, "density": 1800.0, "specific_heat": 840.0},
                {"id": "wool", "thickness": 0.1, "conductivity": 0.04, "density": 60.0, "specific_heat": 1030.0},
            ],
            "probes": [{"name": "P", "depth": 0.05}],
        },
        "data": {"file": "d.csv"},
        "boundary": {
            "exterior": {"type": "surface_temperature", "column": "Te"},
            "interior": {"type": "surface_temperature", "column": "Ti"},
        },
        "sensors": [
            {"name": "P", "column": "Te"},
            {"name": "qx", "column": "q", "quantity": "heat_flux", "depth": depth, **(extra or {})},
        ],
        "period": {"warmup_start": "2025-01-01T00:00:00", "start": "2025-01-07T00:00:00", "end": "2025-01-08T00:00:00"},
        "simulation": {"time_step": 60, "grid_constant": 1.0},
    }
    return parse_study(raw, base_dir=tmp_path)


@pytest.mark.parametrize("depth", [0.05, 0.1, 0.15])  # in the brick, at the brick/wool interface, in the wool
def test_flux_at_depth_matches_the_periodic_solution(tmp_path, depth):
    st = study(tmp_path, depth)
    res = simulate(st)
    rows, _, _ = periodic_solution(st.wall, PERIOD, 10.0, 0.0, [depth], with_flux=True)
    q_amp = rows[0][1]
    t = (res.simulated.index - pd.Timestamp("2025-01-01")).total_seconds().to_numpy()
    exact = (5 - 20) / st.wall.resistance + np.real(q_amp * np.exp(1j * 2 * np.pi * t / PERIOD))
    err = np.abs(res.simulated["qx"].to_numpy() - exact).max()
    # the scheme's flux through the plane on a C = 1 grid: within 1 % of the flux amplitude
    assert err < 0.01 * abs(q_amp) + 0.01, (err, abs(q_amp))


def test_flux_at_depth_in_calibration_objective(tmp_path):
    from wallcal.calibration import parse_space
    from wallcal.calibration.objective import Evaluator
    from wallcal.simulation import prepare

    st = study(tmp_path, 0.12)
    raw = dict(st.raw)
    raw["calibration"] = {
        "targets": ["P", "qx"],
        "parameters": [{"layers": ["wool"], "property": "conductivity", "bounds": [-0.2, 0.2]}],
    }
    st = parse_study(raw, base_dir=tmp_path)
    space = parse_space(st)
    prep = prepare(st)
    ev = Evaluator(prep, space)
    sim = ev.simulate(np.array([[0.04], [0.048]]))
    res = simulate(st, prepared=prep)  # the base wall: the same grid as the calibration's
    np.testing.assert_allclose(sim[0, 1], res.simulated["qx"].to_numpy(), rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(sim[0, 0], res.simulated["P"].to_numpy(), rtol=1e-12, atol=1e-12)
    # a more conductive wool lets more heat out through the wall (flux towards the interior more negative)
    assert sim[1, 1].mean() < sim[0, 1].mean()


def test_flux_sensor_depth_validation(tmp_path):
    with pytest.raises(StudyError, match="must be inside the wall"):
        study(tmp_path, 0.25)
    with pytest.raises(StudyError, match="give face .* or depth .*, not both"):
        study(tmp_path, 0.1, {"face": "exterior"})
    st = study(tmp_path, 0.05, {"depth_from": "interior"})
    assert st.sensor("qx").depth == pytest.approx(0.15)

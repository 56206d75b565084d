"""Grid study: RMSE against time step and grid constant, convergence as dt -> 1 min."""

import numpy as np
import pytest

from wallcal.analysis.gridstudy import grid_study


@pytest.fixture(scope="module")
def grid(example_study):
    return grid_study(example_study, (60, 300, 1800), (1, 2, 3), targets=["T3A", "T2A", "T1A"], progress=False)


def test_table_shape_and_finest(grid):
    assert len(grid.table) == 3 * 3 * 3
    assert grid.finest == (60.0, 1.0)
    w = grid.rmse_table()
    assert list(w.index) == [60.0, 300.0, 1800.0]
    assert "T3A C=2" in w.columns
    fin = grid.table[(grid.table.time_step == 60) & (grid.table.grid_constant == 1)]
    assert np.allclose(fin["deviation"], 0.0)


def test_curves_converge_as_the_step_shrinks(grid):
    conv = grid.convergence()
    spread = conv.groupby(level="time_step")["spread over C"].first()
    assert spread.loc[60.0] < spread.loc[1800.0]
    assert spread.loc[60.0] < 0.01
    assert grid.recommended is not None
    assert "converge" in grid.summary() or "shrinks" in grid.summary()


def test_cli_grid_study(tmp_path, capsys):
    from conftest import EXAMPLE
    from wallcal.cli import main

    out = tmp_path / "g"
    assert (
        main(
            [
                "grid-study",
                str(EXAMPLE),
                "--time-steps",
                "300,900",
                "--grid-constants",
                "2,3",
                "--targets",
                "T3A",
                "--out",
                str(out),
                "--quiet",
            ]
        )
        == 0
    )
    text = capsys.readouterr().out
    assert "T3A C=2" in text and "tolerance" in text
    assert (out / "grid_study.png").exists() and (out / "rmse_vs_time_step.csv").exists()
    assert main(["grid-study", str(EXAMPLE), "--time-steps", "a,b", "--out", str(out)]) == 2

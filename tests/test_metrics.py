"""Metrics: definitions checked on hand-computed numbers."""

import numpy as np
import pytest

from wallcal.metrics import compute


def test_metrics_by_hand():
    y = np.array([1.0, 2.0, 3.0, 4.0])
    s = np.array([1.5, 2.0, 2.0, 4.5])
    m = compute(y, s, accuracy=0.6)
    e = s - y  # 0.5, 0, -1, 0.5
    assert m["n"] == 4
    assert m["rmse"] == pytest.approx(np.sqrt(1.5 / 4))
    assert m["rn_rmse"] == pytest.approx(np.sqrt(1.5 / 4) / 3.0)
    assert m["cv_rmse_eff"] == pytest.approx(np.sqrt(1.5 / 4) / np.sqrt(30 / 4))
    assert m["mbe"] == pytest.approx(-e.sum() / 4)  # Guideline 14: measured minus simulated
    assert m["nmbe"] == pytest.approx(-e.sum() / (3 * 2.5))
    assert m["cv_rmse_g14"] == pytest.approx(np.sqrt(1.5 / 3) / 2.5)
    assert m["mae"] == pytest.approx(0.5)
    assert m["max_abs_error"] == pytest.approx(1.0)
    assert m["within_accuracy"] is False  # rmse 0.612 > 0.6


def test_relative_accuracy_and_nan_skipped():
    y = np.array([10.0, -10.0, np.nan, 10.0])
    s = np.array([10.1, -10.1, 0.0, 10.1])
    m = compute(y, s, accuracy_relative=0.03)
    assert m["n"] == 3
    assert m["accuracy"] == pytest.approx(0.3)
    assert m["within_accuracy"]


@pytest.mark.parametrize("case", ["plain", "missing simulated", "zero range and mean"])
def test_table_of_arrays_equals_compute_per_signal(case):
    """The one-pass table (all signals at once, measured statistics reused) gives compute()'s figures."""
    import pandas as pd

    from wallcal import metrics

    rng = np.random.default_rng(0)
    y = rng.normal(10, 3, (500, 5))
    s = y + rng.normal(0, 0.3, (500, 5))
    y[3, 0] = np.nan
    y[:, 3] = np.nan  # no valid sample
    y[:, 4] = s[:, 4] = 2.0  # constant: zero range
    if case == "missing simulated":
        s[7, 1] = np.nan
    if case == "zero range and mean":
        y[:, 2] = 0.0
    acc = [(0.5, None), (None, 0.05), (None, None), (0.1, None), (None, 0.1)]
    names = ["a", "b", "c", "d", "e"]
    got = metrics.table_arrays(names, y.T, s.T, acc, metrics.measured_stats(y.T))
    rows = [{"signal": n, **metrics.compute(y[:, k], s[:, k], *acc[k])} for k, n in enumerate(names)]
    pd.testing.assert_frame_equal(got, pd.DataFrame(rows, columns=list(metrics.METRIC_COLUMNS)), rtol=1e-12)

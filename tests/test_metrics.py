"""Metrics: definitions checked on hand-computed numbers."""

import math

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


def test_batch_rmse_by_hand():
    from wallcal.metrics import rmse

    y = np.array([[1.0, 2.0, np.nan, 4.0], [0.0, 0.0, 0.0, 0.0]])
    s = np.array([[2.0, 2.0, 9.0, 2.0], [3.0, -4.0, 0.0, 0.0]])
    # row 0: errors 1, 0, (skipped), -2 -> sqrt(5 / 3); row 1: 3, -4, 0, 0 -> sqrt(25 / 4)
    np.testing.assert_allclose(rmse(y, s), [math.sqrt(5 / 3), 2.5], rtol=1e-15)
    # over the other axis: column 2 has one valid pair (0 - 0); columns are (1,3), (0,-4), (nan,0), (-2,0)
    np.testing.assert_allclose(rmse(y, s, axis=0), [math.sqrt(5), math.sqrt(8), 0.0, math.sqrt(2)], rtol=1e-15)
    assert rmse(np.array([np.nan]), np.array([1.0])) == 0.0  # no valid pair: 0 / max(0, 1)


def test_metrics_of_an_empty_or_constant_series():
    m = compute([np.nan, 1.0], [2.0, np.nan], accuracy=0.5)
    assert m["n"] == 0 and np.isnan(m["rmse"]) and m["accuracy"] == 0.5 and m["within_accuracy"] is False
    m = compute([2.0, 2.0], [2.5, 1.5])  # constant measured series: no range, rmse 0.5
    assert m["rmse"] == pytest.approx(0.5) and np.isnan(m["rn_rmse"])
    assert m["cv_rmse_eff"] == pytest.approx(0.25) and np.isnan(m["accuracy"]) and m["within_accuracy"] is False
    m = compute([0.0, 0.0], [1.0, -1.0])  # zero mean: the Guideline-14 ratios are undefined
    assert np.isnan(m["nmbe"]) and np.isnan(m["cv_rmse_g14"]) and np.isnan(m["cv_rmse_eff"])
    assert m["mbe"] == 0.0
    m = compute([1.0], [2.0])  # n - p = 0 degrees of freedom
    assert np.isnan(m["nmbe"]) and np.isnan(m["cv_rmse_g14"]) and m["rmse"] == 1.0


def test_metrics_table_by_hand():
    import pandas as pd

    from wallcal.metrics import METRIC_COLUMNS, table

    meas = pd.DataFrame({"a": [1.0, 2.0, 3.0], "b": [10.0, 10.0, 20.0]})
    sim = pd.DataFrame({"a": [1.0, 2.0, 4.0], "b": [10.0, 11.0, 20.0]})
    t = table(meas, sim, {"a": (0.5, None), "b": (None, 0.1)})
    assert list(t.columns) == list(METRIC_COLUMNS)
    assert list(t["signal"]) == ["a", "b"]
    assert t.loc[0, "rmse"] == pytest.approx(math.sqrt(1 / 3)) and t.loc[0, "accuracy"] == 0.5
    assert not t.loc[0, "within_accuracy"]  # 0.577 > 0.5
    y_eff = math.sqrt((100 + 100 + 400) / 3)
    assert t.loc[1, "accuracy"] == pytest.approx(0.1 * y_eff) and t.loc[1, "within_accuracy"]
    t2 = table(meas, sim, {})  # no accuracy stated
    assert np.isnan(t2.loc[0, "accuracy"]) and not t2.loc[0, "within_accuracy"]


def test_guideline_14_figures_by_hand():
    # y = 2, 4 (mean 3), s = 3, 6: errors s - y = 1, 2; n - p = 1 degree of freedom
    m = compute([2.0, 4.0], [3.0, 6.0])
    assert m["mbe"] == pytest.approx(-3.0 / 2)  # sum(y - s) / n
    assert m["nmbe"] == pytest.approx(-3.0 / (1 * 3.0))  # sum(y - s) / ((n - p) mean(y))
    assert m["cv_rmse_g14"] == pytest.approx(math.sqrt(5.0 / 1) / 3.0)
    assert m["rmse"] == pytest.approx(math.sqrt(2.5)) and m["rn_rmse"] == pytest.approx(math.sqrt(2.5) / 2.0)
    assert m["cv_rmse_eff"] == pytest.approx(math.sqrt(2.5) / math.sqrt(10.0))
    assert m["mae"] == pytest.approx(1.5) and m["max_abs_error"] == pytest.approx(2.0)


def test_metrics_of_no_valid_pair_are_all_nan():
    from wallcal.metrics import METRIC_COLUMNS

    m = compute([np.nan], [1.0])
    assert list(m) == list(METRIC_COLUMNS[1:])
    for k in ("rmse", "rn_rmse", "cv_rmse_eff", "mbe", "nmbe", "cv_rmse_g14", "mae", "max_abs_error", "accuracy"):
        assert np.isnan(m[k]), k
    assert m["n"] == 0 and m["within_accuracy"] is False


def test_thresholds_at_their_edges():
    # mean exactly 1, range 1 and y_eff < 1 still give finite normalised figures
    m = compute([0.5, 1.5], [1.0, 1.0])
    assert m["nmbe"] == pytest.approx(0.0 / 1.0) and m["cv_rmse_g14"] == pytest.approx(math.sqrt(0.5) / 1.0)
    m = compute([0.2, 0.4], [0.3, 0.4])  # range 0.2, y_eff 0.316, mean 0.3
    assert m["rn_rmse"] == pytest.approx(math.sqrt(0.005) / 0.2)
    assert m["cv_rmse_eff"] == pytest.approx(math.sqrt(0.005) / math.sqrt(0.1))
    assert m["nmbe"] == pytest.approx(-0.1 / (1 * 0.3))
    # an RMSE equal to the accuracy is within it
    assert compute([0.0, 0.0], [0.5, -0.5], accuracy=0.5)["within_accuracy"] is True
    # the batch RMSE of a single valid pair divides by 1
    from wallcal.metrics import METRIC_COLUMNS, rmse, table

    assert rmse(np.array([np.nan, 1.0]), np.array([0.0, 3.0])) == pytest.approx(2.0)
    # a table with no signal still has the metric columns
    import pandas as pd

    assert list(table(pd.DataFrame(), pd.DataFrame(), {}).columns) == list(METRIC_COLUMNS)


def test_missing_values_given_as_none_are_skipped():
    # a plain list with None (as a user might pass) is read as NaN and skipped, in either argument
    m = compute([1.0, None, 3.0], [1.5, 2.0, None])
    assert m["n"] == 1 and m["rmse"] == pytest.approx(0.5)
    from wallcal.metrics import rmse

    assert rmse([1.0, None, 3.0], [2.0, 2.0, 5.0]) == pytest.approx(math.sqrt(2.5))
    assert rmse([1.0, 2.0], [None, 4.0]) == pytest.approx(2.0)

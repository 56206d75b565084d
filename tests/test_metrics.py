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

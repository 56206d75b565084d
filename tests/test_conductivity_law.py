"""The lambda(T) law is written once (:mod:`wallcal.conductivity`) and every evaluation goes through it."""

from __future__ import annotations

import re

import numpy as np
import pytest

from conftest import REPO
from wallcal import conductivity
from wallcal.standards import iso10456
from wallcal.wall import Layer

SRC = REPO / "src" / "wallcal"
#: np.exp / math.exp of something holding a lambda(T) coefficient or reference temperature
LAW = re.compile(r"\b(?:np|math)\.exp\(\s*[^)\n]*\b(?:coef|coefficient|temperature_coefficient|tref|f)\b")


def test_the_law_is_written_in_one_module():
    hits = [
        f"{p.relative_to(REPO)}:{i}: {line.strip()}"
        for p in SRC.rglob("*.py")
        if p.name != "conductivity.py"
        for i, line in enumerate(p.read_text().splitlines(), 1)
        if LAW.search(line) and not line.lstrip().startswith("#")
    ]
    assert not hits, "lambda(T) evaluated outside wallcal.conductivity:\n" + "\n".join(hits)


def test_python_and_compiled_forms_agree_with_wall_and_iso10456():
    layer = Layer("w", 0.1, 0.04, 40.0, 1030.0, conductivity_temperature_coefficient=0.0046, reference_temperature=10.0)
    T = np.array([-10.0, 10.0, 35.0])
    lam = conductivity.conductivity(0.04, 0.0046, 10.0, T)
    assert lam == pytest.approx(0.04 * np.exp(0.0046 * (T - 10.0)), rel=1e-15)
    assert layer.conductivity_at(T) == pytest.approx(lam, rel=1e-15)
    assert iso10456.temperature_factor(0.0046, 25.0) == conductivity.exponential_factor(0.0046, 25.0)
    from numba import njit

    inner = conductivity.exponential_factor_inner  # no CPython entry point: called from compiled code
    compiled = njit(lambda f, dt: inner(f, dt))
    assert compiled(0.0046, 25.0) == pytest.approx(np.exp(0.0046 * 25.0), rel=1e-15)


def test_table_law_scaled_by_a_calibrated_conductivity():
    table = ((0.0, 0.030), (20.0, 0.034), (40.0, 0.040))
    layer = Layer("t", 0.1, 0.035, 40.0, 1030.0, conductivity_table=table, reference_temperature=20.0)
    T = np.array([-5.0, 10.0, 30.0, 50.0])
    lam = conductivity.conductivity(0.035, 0.0, 20.0, T, table)
    assert layer.conductivity_at(T) == pytest.approx(lam, rel=1e-15)
    assert lam[1] == pytest.approx(0.032 * 0.035 / 0.034)

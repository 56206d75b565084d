"""Tests of wallcal.standards.iso9869 (ISO 9869-1:2014 average method).

References: the criteria of ISO 9869-1:2014 7.2 as listed in the brief and in e.g. greenTEG's
ISO 9869-1 application note (duration >= 72 h; R within 5 % of R 24 h earlier; first / last
INT(2 DT/3) days within 5 %; stored heat < 5 % of heat through; whole days for heavy elements).
Storage factors: the quasi-static result for a homogeneous slab (F_i = C/3, F_e = C/6 at the
face of the measured flux), derived by hand in docs/standards.md; the storage correction is
checked against an implicit finite-volume simulation written in this file.
"""

import numpy as np
import pytest

from wallcal.errors import DataError, StudyError
from wallcal.standards import iso9869
from wallcal.wall import Layer, Wall

HOUR = 3600.0


def steady(hours, r=2.5, dt=600.0, ti=20.0, te=0.0):
    t = np.arange(int(round(hours * HOUR / dt))) * dt
    n = t.size
    q = np.full(n, -(ti - te) / r)  # heat leaves the interior: negative in wallcal's convention
    return t, q, np.full(n, ti), np.full(n, te)


def heavy_wall():
    return Wall((Layer("ins", 0.1, 0.04, 30, 1000), Layer("conc", 0.2, 1.8, 2400, 1000)))


def light_wall():
    return Wall((Layer("ins", 0.1, 0.04, 30, 1000),))  # 3 kJ/(m2K)


def test_steady_data_give_r_and_pass():
    res = iso9869.average_method(*steady(72), wall=heavy_wall())
    assert res.r_value == pytest.approx(2.5, rel=1e-12)
    np.testing.assert_allclose(res.r_running, 2.5, rtol=1e-12)
    assert res.duration_h == pytest.approx(72.0)
    assert res.heavy is True
    assert res.verdict.applicable is True
    assert res.verdict.statement == "applicable"
    assert all(c.passed for c in res.verdict.criteria)
    assert res.r_storage_corrected == pytest.approx(2.5, rel=1e-12)


def test_sign_convention():
    t, q, ti, te = steady(72)
    # q of the wrong sign (positive towards the exterior) gives a negative R
    assert iso9869.average_method(t, -q, ti, te).r_value == pytest.approx(-2.5)


def test_too_short():
    res = iso9869.average_method(*steady(48), wall=heavy_wall())
    assert res.verdict.applicable is False
    assert res.verdict["duration"].passed is False
    assert res.verdict.statement.startswith("not applicable: fails duration")


def test_whole_days_only_for_heavy_elements():
    heavy = iso9869.average_method(*steady(73), wall=heavy_wall())
    assert heavy.verdict.failing == ["whole_days"]
    light = iso9869.average_method(*steady(73), wall=light_wall())
    assert light.heavy is False
    assert light.verdict["whole_days"].required is False
    assert light.verdict.applicable is True


def test_without_wall_storage_is_undetermined():
    res = iso9869.average_method(*steady(96))
    assert res.verdict.applicable is None
    assert "storage" in res.verdict.statement
    assert res.r_storage_corrected is None
    res = iso9869.average_method(*steady(96), heavy=False)
    assert res.verdict.applicable is True


def test_last_24h_criterion():
    t, q, ti, te = steady(96)
    # the last day's flux is 20 % lower: running R rises by more than 5 % over the last 24 h
    q = q.copy()
    q[t >= 72 * HOUR] *= 0.6
    res = iso9869.average_method(t, q, ti, te, heavy=False)
    assert res.verdict["last_24h"].passed is False
    # hand value: R_end = 20*N / (8*(0.75N) + 4.8*(0.25N)), R_-24h = 2.5
    r_end = 20 / (8 * 0.75 + 4.8 * 0.25)
    assert res.r_value == pytest.approx(r_end, rel=1e-12)
    assert res.verdict["last_24h"].value == pytest.approx(abs(r_end - 2.5) / 2.5, rel=1e-9)


def test_two_thirds_uses_whole_days():
    # DT = 4.5 days -> INT(3.0) = 3 days; make the first 1.5 days differ
    t, q, ti, te = steady(108)
    q = q.copy()
    q[t < 36 * HOUR] *= 1.2
    res = iso9869.average_method(t, q, ti, te, heavy=False)
    c = res.verdict["first_last_two_thirds"]
    assert "3 day(s)" in c.detail
    n3 = int(72 * HOUR / 600)
    r_first = (ti[:n3] - te[:n3]).sum() / (-q[:n3]).sum()
    r_last = (ti[-n3:] - te[-n3:]).sum() / (-q[-n3:]).sum()
    assert c.value == pytest.approx(abs(r_first - r_last) / r_last, rel=1e-12)
    assert c.passed is False


def test_storage_factors_homogeneous_slab():
    c = 2400 * 1000 * 0.2
    slab = Wall((Layer("conc", 0.2, 1.8, 2400, 1000),))
    assert iso9869.storage_factors(slab, "interior") == pytest.approx((c / 3, c / 6))
    assert iso9869.storage_factors(slab, "exterior") == pytest.approx((c / 6, c / 3))
    assert iso9869.stored_heat_change(slab, 1.0, 0.0) == pytest.approx(c / 2)


def test_storage_factors_sum_to_total_storage():
    wall = heavy_wall()
    fi_i, fe_i = iso9869.storage_factors(wall, "interior")
    fi_e, fe_e = iso9869.storage_factors(wall, "exterior")
    assert fi_i + fi_e == pytest.approx(iso9869.stored_heat_change(wall, 1.0, 0.0))
    assert fe_i + fe_e == pytest.approx(iso9869.stored_heat_change(wall, 0.0, 1.0))
    assert fi_i + fi_e + fe_i + fe_e == pytest.approx(wall.areal_heat_capacity)
    # two layers by hand: insulation R = 2.5 (s in [0, 0.9804]), concrete R = 0.1111 (s in [0.9804, 1])
    r = 2.5 + 0.2 / 1.8
    s0, ds = 2.5 / r, (0.2 / 1.8) / r
    c_ins, c_con = 30 * 1000 * 0.1, 2400 * 1000 * 0.2
    fi = c_ins * (ds * 0 + (2.5 / r) ** 2 / 3) + c_con * (s0**2 + s0 * ds + ds**2 / 3)
    assert fi_i == pytest.approx(fi, rel=1e-12)
    with pytest.raises(StudyError, match="q_side"):
        iso9869.storage_factors(wall, "top")


def simulate(wall, times, ti, te, n_per_layer=20):
    """Implicit-Euler finite volumes with imposed surface temperatures; returns q at the interior face
    (positive towards the interior) averaged over each step, starting from the steady state."""
    from scipy.linalg import lu_factor, lu_solve

    cap, half_r = [], []
    for layer in wall.layers:
        dx = layer.thickness / n_per_layer
        cap += [layer.volumetric_heat_capacity * dx] * n_per_layer
        half_r += [dx / (2 * layer.conductivity)] * n_per_layer
    cap, half_r = np.array(cap), np.array(half_r)
    r_face = np.concatenate([[half_r[0]], half_r[:-1] + half_r[1:], [half_r[-1]]])
    g = 1 / r_face
    dt = times[1] - times[0]
    a = np.diag(cap / dt + g[:-1] + g[1:]) - np.diag(g[1:-1], 1) - np.diag(g[1:-1], -1)
    lu = lu_factor(a)
    # steady initial state: temperatures linear in resistance
    rc = np.cumsum(r_face)[:-1]
    th = te[0] + (ti[0] - te[0]) * rc / r_face.sum()
    q = np.empty(times.size)
    for j in range(times.size):
        rhs = cap / dt * th
        rhs[0] += g[0] * te[j]
        rhs[-1] += g[-1] * ti[j]
        th = lu_solve(lu, rhs)
        q[j] = g[-1] * (th[-1] - ti[j])
    return q


def test_storage_criterion_and_correction_against_simulation():
    wall = heavy_wall()  # concrete on the interior side, where q is measured
    dt = 600.0
    t = np.arange(int(96 * HOUR / dt)) * dt
    ti = 20.0 + 4.0 * t / t[-1]  # slow warm-up of the interior by 4 K over 4 days
    te = np.zeros_like(t)
    q = simulate(wall, t, ti, te)
    r_true = wall.resistance
    res = iso9869.average_method(t, q, ti, te, wall=wall)
    err_plain = abs(res.r_value - r_true) / r_true
    err_corr = abs(res.r_storage_corrected - r_true) / r_true
    assert err_plain > 0.02  # storage biases the plain average
    assert err_corr < err_plain / 2  # the correction removes most of it (38 % -> 11 % here; the 24 h-mean
    # temperature change of the standard under-reads a steady ramp, so it cannot remove all)
    assert res.verdict["storage"].passed is False
    assert res.verdict.applicable is False


def test_bad_data():
    t, q, ti, te = steady(72)
    with pytest.raises(DataError, match="q_W_m2"):
        iso9869.average_method(t, q[:-1], ti, te)
    q2 = q.copy()
    q2[3] = np.nan
    with pytest.raises(DataError, match="NaN"):
        iso9869.average_method(t, q2, ti, te)
    t2 = t.copy()
    t2[5:] += 60
    with pytest.raises(DataError, match="equally spaced"):
        iso9869.average_method(t2, q, ti, te)
    with pytest.raises(StudyError, match="q_side"):
        iso9869.average_method(t, q, ti, te, q_side="middle")


# ---------------------------------------------------------------------------- the criteria table, field by field
def test_criteria_table_of_a_steady_heavy_test_by_hand():
    res = iso9869.average_method(*steady(72), wall=heavy_wall())
    rows = [(c.name, c.description, c.required, c.passed, c.value, c.limit) for c in res.verdict.criteria]
    assert rows == [
        ("duration", "test duration >= 72 h", True, True, pytest.approx(72.0), 72.0),
        ("last_24h", "final R within 5 % of R 24 h earlier", True, True, pytest.approx(0.0, abs=1e-12), 0.05),
        (
            "first_last_two_thirds",
            "R of the first and of the last INT(2 DT/3) days within 5 %",
            True,
            True,
            pytest.approx(0.0, abs=1e-12),
            0.05,
        ),
        (
            "storage",
            "change of stored heat < 5 % of the heat through the element (heavy elements)",
            True,
            True,
            0.0,
            0.05,
        ),
        ("whole_days", "duration an integer multiple of 24 h (heavy elements)", True, True, pytest.approx(72.0), 24.0),
    ]
    d = {c.name: c.detail for c in res.verdict.criteria}
    assert d["duration"] == "N = 432 readings x dt = 600 s"  # 72 h / 10 min
    assert d["last_24h"] == "R_end = 2.5, R_end-24h = 2.5 m2K/W"
    assert d["first_last_two_thirds"] == "2 day(s): R_first = 2.5, R_last = 2.5 m2K/W"  # INT(2 x 3 / 3) = 2
    assert d["whole_days"] == "duration 72 h"
    assert d["storage"].startswith("dQ_stored = 0 J/m2") and "heat through = 2.074e+06 J/m2" in d["storage"]
    assert res.stored_heat_change_J_m2 == 0.0 and res.heat_through_J_m2 == pytest.approx(8.0 * 72 * 3600)
    assert res.areal_heat_capacity == pytest.approx(30 * 1000 * 0.1 + 2400 * 1000 * 0.2)


def test_criteria_edge_cases():
    # 420 s readings do not divide 24 h: b) cannot be evaluated, c) has no whole number of readings per day
    t, q, ti, te = steady(84, dt=420.0)
    res = iso9869.average_method(t, q, ti, te, heavy=False)
    c = res.verdict["last_24h"]
    assert (c.passed, c.value, c.detail) == (None, None, "dt = 420 s does not divide 24 h")
    assert res.verdict["first_last_two_thirds"].passed is False
    assert res.verdict.applicable is False and res.verdict.statement == "not applicable: fails first_last_two_thirds"
    # shorter than 24 h: b) and c) fail, with their reason
    res = iso9869.average_method(*steady(12), heavy=False)
    assert res.verdict["last_24h"].passed is False and res.verdict["last_24h"].detail == "test shorter than 24 h"
    c = res.verdict["first_last_two_thirds"]
    assert c.passed is False and c.detail == "INT(2 DT/3) = 0 day(s): not enough data"
    assert res.verdict.statement == "not applicable: fails duration, last_24h, first_last_two_thirds"
    # without a wall and without heavy=: the statement says the weight is unknown
    res = iso9869.average_method(*steady(96))
    assert res.verdict.statement.endswith("(element weight unknown: heavy-element criteria required)")
    assert res.verdict["storage"].detail == "not evaluated: pass wall= to estimate the stored heat"
    assert res.verdict["storage"].required is True
    # exactly 72 h passes a), a tolerance changes b)-d)'s limit
    res = iso9869.average_method(*steady(72), heavy=False, tolerance=0.1, min_duration_h=48.0)
    assert res.verdict["duration"].limit == 48.0 and res.verdict["last_24h"].limit == 0.1
    assert res.verdict["duration"].description == "test duration >= 48 h"
    # two readings are enough to compute R
    t, q, ti, te = steady(1.0 / 3)  # 2 readings of 10 min
    assert t.size == 2 and iso9869.average_method(t, q, ti, te, heavy=False).r_value == pytest.approx(2.5)
    with pytest.raises(DataError, match="need at least 2 readings, got 1"):
        iso9869.average_method(t[:1], q[:1], ti[:1], te[:1])


def test_heavy_threshold_is_strictly_above_20_kJ():
    # 20 kJ/(m2K) exactly is light: heavy = C > 20 kJ/(m2K)
    wall = Wall((Layer("a", 0.1, 0.5, 200.0, 1000.0),))
    assert iso9869.average_method(*steady(72), wall=wall).heavy is False
    wall = Wall((Layer("a", 0.1, 0.5, 200.1, 1000.0),))
    assert iso9869.average_method(*steady(72), wall=wall).heavy is True

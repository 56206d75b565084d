"""``wallcal verify hamstad1`` on made-up files in the HAMSTAD archive's formats (the archive's data are not
part of wallcal): the run's length follows the climate file, M_A / M_B are checked hour by hour against the
bands of years 1 and 5, and missing or malformed files give one clean line."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest

from conftest import assert_clean_error
from wallcal.cli import main
from wallcal.moisture import cases

HOURS = 48  # the made-up "year": the run is 5 x 48 h
CODES = ["CTH", "TUD", "Technion", "KUL", "IBP", "TUE", "NRC"]


def write_climate(folder, hours=HOURS):
    """Rows ``time s, T_eq,e C, T_eq,i C, p_a,e Pa, p_a,i Pa`` in the archive's layout (made-up values)."""
    h = np.arange(hours + 1)
    t_ext = 2.0 + 3.0 * np.sin(2 * np.pi * h / 24.0)
    rows = np.column_stack([h * 3600.0, t_ext, np.full(h.size, 20.0), 500.0 + 5.0 * h, 900.0 + 5.0 * h])
    np.savetxt(folder / "ClimateBench1.txt", rows, fmt="%16.7e")


def write_band(path, lower, upper, hours=HOURS):
    """The archive's columns: time (h), the seven codes, Average, StandDev, CI-, CI+ (made-up values)."""
    h = np.arange(hours + 1)
    mid = 0.5 * (np.asarray(lower) + np.asarray(upper)) * np.ones(h.size)
    table = pd.DataFrame({"time (h)": h, **{c: mid for c in CODES}, "Average": mid, "StandDev": 0.1})
    table["CI-(p=0.1%)"] = lower
    table["CI+(p=0.1%)"] = upper
    table.to_csv(path, index=False)


def write_data(folder):
    write_climate(folder)
    for year in (1, 5):
        write_band(folder / f"Bench1Year{year}_MA.csv", 10.0, 20.0)
        write_band(folder / f"Bench1Year{year}_MB.csv", 0.0, 1.0)


def test_verify_hamstad1_runs_five_climate_periods_and_checks_every_hour(tmp_path, capsys):
    data = tmp_path / "data"
    data.mkdir()
    write_data(data)
    lower = np.full(HOURS + 1, 10.0)
    lower[0] = 14.6  # year 1, hour 0: M_A = 145 kg/m3 x 0.1 m = 14.5 kg/m2 lies below this band
    write_band(data / "Bench1Year1_MA.csv", lower, 20.0)
    out = tmp_path / "v"
    assert main(["verify", "hamstad1", "--data", str(data), "--out", str(out)]) == 1
    assert "outside their limits" in capsys.readouterr().out

    v = pd.read_csv(out / "verification.csv")
    assert list(v.columns) == ["case", "quantity", "day", "x_m", "value", "lower", "upper", "passed"]
    assert set(v["case"]) == {"hamstad1"}
    for q in ("M_A", "M_B"):
        rows = v[v["quantity"] == q]
        assert len(rows) == 2 * (HOURS + 1) and rows["x_m"].isna().all()  # a layer's integral: no position
        days = rows["day"].to_numpy()
        hours_1 = np.arange(HOURS + 1) / 24.0
        np.testing.assert_allclose(days, np.concatenate([hours_1, 4 * HOURS / 24.0 + hours_1]))
    failed = v[~v["passed"]]
    assert failed[["quantity", "day"]].values.tolist() == [["M_A", 0.0]]
    start = v[v["day"] == 0.0].set_index("quantity")["value"]
    assert start["M_A"] == pytest.approx(14.5, abs=1e-9) and start["M_B"] == pytest.approx(0.065 * 0.05, abs=1e-12)
    balance = v[v["quantity"].str.endswith("balance_error")]
    assert len(balance) == 2 * 11 and balance["passed"].all()  # every half period of the 5 x 48 h

    p = pd.read_csv(out / "hamstad1" / "profiles.csv")
    assert list(p.columns) == ["time_s", "x_m", "temperature", "relative_humidity", "water_content"]
    np.testing.assert_allclose(sorted(set(p["time_s"])), np.arange(11) * 0.5 * HOURS * 3600.0)
    assert p["x_m"].between(0, 0.15).all() and p["relative_humidity"].between(0, 1).all()


def test_hamstad1_series_is_hourly_over_five_periods(tmp_path):
    write_data(tmp_path)
    run = cases.run_case("hamstad1", tmp_path)
    s = run.series
    np.testing.assert_allclose(s["time_s"], np.arange(5 * HOURS + 1) * 3600.0)
    # sealed outside: what the layers gained is what came in through the interior face
    gained = s["M_A"].iloc[-1] + s["M_B"].iloc[-1] - s["M_A"].iloc[0] - s["M_B"].iloc[0]
    assert gained == pytest.approx(run.result.inflow[-1, :, 0].sum(), rel=1e-8, abs=1e-12)
    assert run.result.inflow[-1, 0, 0] == 0.0


def test_verify_hamstad1_without_its_data_says_which_files_and_where_in_one_line(tmp_path, capsys):
    out = tmp_path / "v"
    code = main(["verify", "hamstad1", "--data", str(tmp_path / "none"), "--out", str(out)])
    assert_clean_error(
        code, capsys.readouterr(), out, "hamstad1", "ClimateBench1.txt", "Bench1Year", "LBNL-ETA/HygroThermFEM"
    )


def test_verify_hamstad1_names_the_one_missing_band(tmp_path, capsys):
    write_data(tmp_path)
    (tmp_path / "Bench1Year5_MB.csv").unlink()
    out = tmp_path / "v"
    code = main(["verify", "hamstad1", "--data", str(tmp_path), "--out", str(out)])
    assert_clean_error(code, capsys.readouterr(), out, "Bench1Year5_MB.csv")


@pytest.mark.parametrize(
    ("spoil", "fragments"),
    [
        (lambda d: (d / "ClimateBench1.txt").write_text("0 1 2 3\n3600 1 2 3\n"), ["ClimateBench1.txt", "5 numbers"]),
        (lambda d: (d / "ClimateBench1.txt").write_text("0 1 2 3 4\n0 1 2 3 4\n"), ["ClimateBench1.txt", "increase"]),
        (lambda d: (d / "ClimateBench1.txt").write_text("0 1 20 -3 4\n3600 1 20 3 4\n"), ["column 4", "> 0"]),
        (lambda d: (d / "ClimateBench1.txt").write_text("0 1 20 a 4\n"), ["ClimateBench1.txt", "numbers"]),
        (lambda d: (d / "Bench1Year1_MA.csv").write_text("time (h),Average\n0,1\n"), ["Bench1Year1_MA.csv", "CI-"]),
        (
            lambda d: (d / "Bench1Year5_MB.csv").write_text("time (h),Average,CI-(p=0.1%),CI+(p=0.1%)\n0,1,x,2\n"),
            ["Bench1Year5_MB.csv", "a number on every row"],
        ),
    ],
)
def test_verify_hamstad1_refuses_malformed_files_in_one_line(tmp_path, capsys, spoil, fragments):
    data = tmp_path / "data"
    data.mkdir()
    write_data(data)
    spoil(data)
    out = tmp_path / "v"
    assert_clean_error(
        main(["verify", "hamstad1", "--data", str(data), "--out", str(out)]), capsys.readouterr(), out, *fragments
    )


def test_verify_without_cases_leaves_hamstad1_out_when_its_data_are_missing(tmp_path, monkeypatch, capsys):
    ran = []

    def fake(name):
        def run(*_):
            ran.append(name)
            checks = pd.DataFrame(
                [{"case": name, "quantity": "q", "day": 0.0, "x_m": 0.0, "value": 1.0, "lower": 0.0, "upper": 2.0}]
            ).assign(passed=True)
            result = SimpleNamespace(
                mass_balance_error=np.zeros(1), energy_balance_error=np.zeros(1), stats={"steps": 1}
            )
            return cases.CaseRun(name, checks, pd.DataFrame({"time_s": [0.0]}), result, 0.0)

        return run

    monkeypatch.setattr(cases, "CASES", {n: fake(n) for n in ("en15026", "hamstad1", "hamstad2")})
    monkeypatch.setattr(cases, "hamstad1", fake("hamstad1"))
    assert main(["verify", "--data", str(tmp_path / "none"), "--out", str(tmp_path / "a")]) == 0
    assert ran == ["en15026", "hamstad2"]
    write_data(tmp_path)
    assert main(["verify", "--data", str(tmp_path), "--out", str(tmp_path / "b")]) == 0
    assert ran[2:] == ["en15026", "hamstad1", "hamstad2"]


def test_verify_counts_many_failed_hours_by_quantity_and_prints_the_first_ones(tmp_path, capsys):
    write_data(tmp_path)
    write_band(tmp_path / "Bench1Year1_MA.csv", 20.0, 30.0)  # every hour of year 1 outside: 49 failures
    assert main(["verify", "hamstad1", "--data", str(tmp_path), "--out", str(tmp_path / "v")]) == 1
    out = capsys.readouterr().out
    assert "by quantity" in out and "(the first 30)" in out
    v = pd.read_csv(tmp_path / "v" / "verification.csv")
    assert (~v["passed"]).sum() == HOURS + 1

"""ISO 9869-1 on a study's measurements: the average method with its verdict, as a library call.

:func:`iso9869_for_study` picks the study's heat-flux sensor at a face and its measured
surface temperatures over the comparison period (or the whole record), runs
:func:`wallcal.standards.iso9869.average_method` and returns an :class:`InSituResult`
that prints, serialises (``iso9869.csv``, ``iso9869.json``) and plots (``iso9869.png``).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from ..errors import DataError, StudyError
from ..formatting import fmt
from . import iso6946, iso9869


def _heat_flux_sensor(study, face: str, name: str | None):
    from ..errors import closest

    cands = [s for s in study.sensors if s.quantity == "heat_flux" and s.face == face]
    if name is not None:
        for s in cands:
            if s.name == name:
                return s
        valid = [s.name for s in cands]
        raise StudyError(
            [
                f"--sensor: {name!r} is not a heat_flux sensor at the {face} face; "
                + (closest(name, valid) if valid else "the study has none there")
            ],
            source=str(study.path) if study.path else None,
        )
    if not cands:
        others = [f"{s.name} ({s.face})" for s in study.sensors if s.quantity == "heat_flux"]
        hint = (
            f"; heat_flux sensors in the study: {', '.join(others)} (use --face)"
            if others
            else '; add a [[sensors]] entry with quantity = "heat_flux" and face = "' + face + '"'
        )
        raise StudyError(
            [f"sensors: no heat_flux sensor at the {face} face{hint}"], source=str(study.path) if study.path else None
        )
    if len(cands) > 1:
        raise StudyError(
            [
                f"sensors: {len(cands)} heat_flux sensors at the {face} face "
                f"({', '.join(s.name for s in cands)}); choose one with --sensor"
            ],
            source=str(study.path) if study.path else None,
        )
    return cands[0]


def _check_surface_boundaries(study) -> None:
    bad = [
        f"boundary.{face}.type is {b.type!r}"
        for face, b in (("exterior", study.exterior), ("interior", study.interior))
        if b.type != "surface_temperature"
    ]
    if bad:
        raise StudyError(
            [
                f"ISO 9869 needs measured surface temperatures on both faces, but {' and '.join(bad)}"
                ' (not "surface_temperature")'
            ],
            source=str(study.path) if study.path else None,
        )


def _select(frame: pd.DataFrame, cols: list[str], start, end, max_gap: float) -> tuple[pd.DataFrame, int]:
    """Readings in [start, end) with short gaps filled by linear interpolation in time.

    Each reading stands for one interval (ISO 9869-1 sums), so the half-open window makes
    the analysed duration exactly end - start. Returns the frame and the number of filled values.
    """
    sel = frame.loc[(frame.index >= start) & (frame.index < end), cols]
    if len(sel) < 2:
        raise DataError(f"the analysis window {start} .. {end} holds {len(sel)} reading(s); need at least 2")
    missing = sel.isna()
    n_filled = int(missing.to_numpy().sum())
    if n_filled:
        secs = sel.index.to_series().diff().dt.total_seconds().median()
        for c in cols:
            m = missing[c].to_numpy()
            if not m.any():
                continue
            runs = np.diff(np.concatenate([[0], m.astype(int), [0]]))
            starts, ends = np.flatnonzero(runs == 1), np.flatnonzero(runs == -1)
            longest = int((ends - starts).max())
            if m[0] or m[-1] or (longest + 1) * secs > max_gap:
                i = int(starts[np.argmax(ends - starts)])
                raise DataError(
                    f"column {c!r} is missing {longest} reading(s) from {sel.index[i]} "
                    f"({'at an end of the window' if m[0] or m[-1] else f'longer than data.max_gap = {max_gap:g} s'})"
                    "; the average method needs a complete series: move the period or fill the data"
                )
        sel = sel.interpolate(method="time", limit_area="inside")
    return sel, n_filled


@dataclass
class InSituResult:
    """The ISO 9869-1 average method applied to a study's data."""

    study: object
    face: str
    sensor: str
    start: pd.Timestamp
    end: pd.Timestamp
    whole_record: bool
    times_s: np.ndarray
    selection: pd.DataFrame
    n_filled: int
    res: iso9869.AverageMethodResult
    u: float
    rsi: float
    rse: float

    @property
    def verdict(self) -> str:
        return self.res.verdict.statement

    def criteria_table(self) -> pd.DataFrame:
        rows = []
        for c in self.res.verdict.criteria:
            status = (
                "not required"
                if not c.required and c.passed is None
                else "not evaluated"
                if c.passed is None
                else "pass"
                if c.passed
                else "FAIL"
            )
            if not c.required and c.passed is not None:
                status += " (not required)"
            rows.append(
                {
                    "criterion": c.name,
                    "result": status,
                    "value": _crit_value(c),
                    "limit": _crit_value(c, limit=True),
                    "detail": c.detail,
                }
            )
        return pd.DataFrame(rows).set_index("criterion")

    def to_json(self) -> dict:
        res = self.res
        t = self.times_s
        return {
            "study": self.study.name,
            "face": self.face,
            "sensor": self.sensor,
            "window_start": str(self.start),
            "window_end": str(self.end),
            "window": "whole record" if self.whole_record else "study period",
            "readings": int(len(t)),
            "time_step_s": float(np.median(np.diff(t))),
            "duration_h": res.duration_h,
            "filled_values": self.n_filled,
            "r_value_m2K_W": res.r_value,
            "r_storage_corrected_m2K_W": res.r_storage_corrected,
            "u_value_W_m2K": self.u,
            "rsi_m2K_W": self.rsi,
            "rse_m2K_W": self.rse,
            "areal_heat_capacity_J_m2K": res.areal_heat_capacity,
            "heavy": res.heavy,
            "stored_heat_change_J_m2": res.stored_heat_change_J_m2,
            "heat_through_J_m2": res.heat_through_J_m2,
            "applicable": res.verdict.applicable,
            "statement": res.verdict.statement,
            "failing": res.verdict.failing,
            "criteria": [
                {
                    "name": c.name,
                    "description": c.description,
                    "required": c.required,
                    "passed": c.passed,
                    "value": _json_num(c.value),
                    "limit": _json_num(c.limit),
                    "detail": c.detail,
                }
                for c in res.verdict.criteria
            ],
        }

    def write_into(self, d) -> list[str]:
        d = Path(d)
        sel, t = self.selection, self.times_s
        running = pd.DataFrame(
            {
                "elapsed_h": t / 3600.0,
                "q_W_m2": sel[self.sensor].to_numpy(),
                "t_si_C": sel["interior"].to_numpy(),
                "t_se_C": sel["exterior"].to_numpy(),
                "r_running_m2K_W": self.res.r_running,
            },
            index=sel.index.strftime("%Y-%m-%dT%H:%M:%S"),
        )
        running.index.name = "timestamp"
        running.to_csv(d / "iso9869.csv", float_format="%.6g")
        (d / "iso9869.json").write_text(json.dumps(self.to_json(), indent=2, allow_nan=False))
        _figure(d / "iso9869.png", t / 3600.0, self.res, self.sensor, self.face, self.study.name)
        return ["iso9869.csv", "iso9869.json", "iso9869.png"]


def iso9869_for_study(
    study, face: str = "interior", sensor: str | None = None, whole_record: bool = False, measurements=None
) -> InSituResult:
    """Run the ISO 9869-1 average method on the study's measured heat flux at ``face``.

    Raises
    ------
    StudyError
        No (or several) heat-flux sensor at that face, or boundaries that are not surface temperatures.
    DataError
        Gaps the method cannot bridge.
    """
    from ..data import load_measurements

    s = _heat_flux_sensor(study, face, sensor)
    _check_surface_boundaries(study)
    meas = measurements if measurements is not None else load_measurements(study)
    frame = meas.frame
    if whole_record:
        start, end = frame.index[0], frame.index[-1]
    else:
        start, end = pd.Timestamp(study.period.start), pd.Timestamp(study.period.end)
    sel, n_filled = _select(frame, [s.name, "interior", "exterior"], start, end, study.data.max_gap)
    t = (sel.index - sel.index[0]).total_seconds().to_numpy(dtype=float)
    res = iso9869.average_method(
        t, sel[s.name].to_numpy(), sel["interior"].to_numpy(), sel["exterior"].to_numpy(), wall=study.wall, q_side=face
    )
    rsi, rse = iso6946.surface_resistances("horizontal")
    u = 1.0 / (rsi + res.r_value + rse) if res.r_value > 0 else float("nan")
    return InSituResult(
        study=study,
        face=face,
        sensor=s.name,
        start=start,
        end=end,
        whole_record=whole_record,
        times_s=t,
        selection=sel,
        n_filled=n_filled,
        res=res,
        u=u,
        rsi=rsi,
        rse=rse,
    )


def _crit_value(c, limit: bool = False):
    v = c.limit if limit else c.value
    if v is None:
        return float("nan")
    if c.name in ("last_24h", "first_last_two_thirds", "storage"):
        return f"{100 * v:.1f} %" if np.isfinite(v) else "inf"
    return f"{fmt(float(v))} h"


def _json_num(v):
    if v is None:
        return None
    v = float(v)
    return v if math.isfinite(v) else None


def _figure(path: Path, hours: np.ndarray, res, sensor: str, face: str, title: str) -> None:
    # Lines marked "pragma: no mutate" are styling (sizes, colours, line widths, fonts): mutation testing
    # leaves them alone, as no test should pin them (docs/testing.md); what the figure shows is tested.
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 4.5))  # pragma: no mutate
    try:
        _draw(ax, hours, res, sensor, face, title)
        fig.tight_layout()
        fig.savefig(
            path,
            dpi=120,  # pragma: no mutate
        )
    finally:
        plt.close(fig)


def _draw(ax, hours: np.ndarray, res, sensor: str, face: str, title: str) -> None:
    """The running estimate of R with its final value +- 5 % and the mark 24 h before the end."""
    r_end = res.r_value
    ax.axhspan(
        0.95 * r_end,
        1.05 * r_end,
        label=f"final R = {r_end:.2f} m2K/W ± 5 %",
        color="tab:green",  # pragma: no mutate
        alpha=0.2,  # pragma: no mutate
    )
    ax.plot(
        hours,
        res.r_running,
        label="running estimate",
        color="tab:blue",  # pragma: no mutate
        lw=1.2,  # pragma: no mutate
    )
    if res.duration_h > 24:
        ax.axvline(
            res.duration_h - 24,
            label="24 h before the end",
            color="0.5",  # pragma: no mutate
            ls=":",  # pragma: no mutate
            lw=1,  # pragma: no mutate
        )
    ax.set_xlabel("elapsed time [h]")
    ax.set_ylabel("R (surface to surface) [m2K/W]")
    # the first day can be wild (sum of q near 0): scale the axis on the rest of the record
    late = res.r_running[hours >= min(24.0, 0.25 * res.duration_h)]
    finite = late[np.isfinite(late)]
    if finite.size:
        lo, hi = float(finite.min()), float(finite.max())
        lo, hi = min(lo, 0.9 * r_end), max(hi, 1.1 * r_end)
        ax.set_ylim(lo - 0.05 * (hi - lo), hi + 0.05 * (hi - lo))
    ax.set_title(
        f"{title + ': ' if title else ''}ISO 9869-1 average method ({sensor}, {face} face)\n{res.verdict.statement}",
        fontsize=9,  # pragma: no mutate
    )
    ax.grid(True, alpha=0.3)  # pragma: no mutate
    ax.legend(
        loc="best",  # pragma: no mutate
        fontsize=8,  # pragma: no mutate
    )

"""The candidates of ``wallcal diagnose`` (:mod:`wallcal.analysis.diagnose`): the residual analysis of each target
and the structural extensions it proposes.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

#: an insulation layer (candidate for lambda(T)) conducts less than this [W/(m K)]
INSULATION_LAMBDA = 0.1
#: half-range of a candidate probe depth [m]
DEPTH_RANGE = 0.01
#: bounds of a candidate contact resistance [m2K/W]
CONTACT_BOUNDS = (0.0, 0.5)
#: range of a candidate conductivity temperature coefficient above its base value [1/K]; an insulation's
#: conductivity rises with temperature (ISO 10456), so the lower bound is min(base, 0)
COEFFICIENT_RANGE = 0.02
#: a moisture study's lambda(w) candidate: b from 0 to the layer's own value plus this (ISO 10456:2007 Table 4's
#: mass-based f_u of insulation materials reach about 4)
MOISTURE_COEFFICIENT_RANGE = 4.0
#: half-range of a candidate sensor offset: this many times the sensor's accuracy, and at least
#: OFFSET_SPREAD times the standard deviation of its measured signal
OFFSET_ACCURACIES = 2.0
OFFSET_SPREAD = 0.25
#: half-range of the candidate offset of both face sensors: this many times the temperature targets' largest
#: stated accuracy (the study states none for its boundary sensors; they are read by sensors of the same kind)
FACE_OFFSET_ACCURACIES = 3.0
#: box of a candidate probe response time (first-order lag) [s]
RESPONSE_RANGE = (0.0, 3600.0)

# ---------------------------------------------------------------------------- plausible ranges
# An extension is adopted only when its fitted value lies inside its plausible range and off the bounds of its
# candidate box (``plausibility``); docs/identifiability.md, "Real walls".
#: a probe's placement tolerance: most distance from its nominal depth [m] (the candidate's box: a depth is
#: plausible inside it and off its bounds)
PROBE_TOLERANCE = DEPTH_RANGE
#: ISO 10456:2007 Table 4 gives temperature conversion coefficients of about 0.003 to 0.0056 1/K for insulation
#: materials (0.0046 mineral wool); plausible up to this, about 1.5 x the largest, for the fit's own uncertainty [1/K]
COEFFICIENT_PLAUSIBLE = 0.008
#: a contact resistance between two building layers: up to that of a thin unventilated air gap [m2K/W]
CONTACT_PLAUSIBLE = 0.2
#: a sensor offset (of a target, or of both faces): at most this many times the sensor's stated accuracy
OFFSET_PLAUSIBLE_ACCURACIES = 2.0
#: a probe's first-order response time: a sheathed probe in its hole, or a sensor under tape, responds within
#: minutes; up to this [s]
RESPONSE_PLAUSIBLE = 1800.0


# ============================================================================ residual analysis
def residual_analysis(ev, x, times) -> pd.DataFrame:
    """Bias, lag, daily pattern and autocorrelation of each target's residuals (simulated - measured) at ``x``.

    Columns: ``rmse``, ``bias`` (mean residual), ``sd`` (about the bias), ``phi`` (lag-1 autocorrelation of
    the de-meaned residuals), ``lag_min`` (the shift of the simulated series [min] that best matches the
    measured one; positive: the model is late), ``daily_amplitude`` (peak-to-peak of the mean residual per
    hour of the day), ``daily_share`` (the part of the residual variance about the bias that the daily
    pattern explains), ``step`` and ``step_at`` (:func:`largest_step`: the largest change of the residual's mean
    over a day, and when; an event the model does not see, e.g. the room humidified, shows there).
    """
    from .posterior import lag1

    sim = ev.simulate(np.atleast_2d(x))[0]
    y = ev.y + ev.space.offsets(np.atleast_2d(x))[0][:, None]
    times = pd.DatetimeIndex(times)
    step = float(np.median(np.diff(times.asi8))) / 1e9 if len(times) > 1 else 300.0
    hours = times.hour.to_numpy()
    rows = []
    for k, name in enumerate(ev.space.targets):
        m = ev.mask[k]
        e = np.where(m, sim[k] - y[k], np.nan)
        ev_ = e[m]
        bias = float(np.mean(ev_))
        d = np.where(m, e - bias, 0.0)
        sd = float(np.std(ev_))
        phi = lag1(d, m)
        # lag: shift of the simulated series (up to 3 h) minimising the de-meaned squared difference
        max_shift = int(min(3 * 3600 / step, len(e) // 4))
        shifts = np.arange(-max_shift, max_shift + 1)
        errs = np.full(len(shifts), np.inf)
        for i, s in enumerate(shifts):
            a = sim[k][max(0, s) : len(e) + min(0, s)]
            b = y[k][max(0, -s) : len(e) - max(0, s)]
            mm = m[max(0, -s) : len(e) - max(0, s)]
            if mm.sum() < 10:
                continue
            diff = (a - b)[mm]
            errs[i] = float(np.mean((diff - diff.mean()) ** 2))
        i = int(np.argmin(errs))
        best_s = float(shifts[i])
        if 0 < i < len(shifts) - 1 and np.all(np.isfinite(errs[i - 1 : i + 2])):  # parabola through the minimum
            den = errs[i - 1] - 2 * errs[i] + errs[i + 1]
            if den > 0:
                best_s += 0.5 * (errs[i - 1] - errs[i + 1]) / den
        hourly = pd.Series(d[m]).groupby(hours[m]).mean()
        amp = float(hourly.max() - hourly.min()) if len(hourly) else 0.0
        var = float(np.mean(d[m] ** 2))
        share = float(np.sum(hourly.reindex(hours[m]).to_numpy() ** 2) / (var * m.sum())) if var > 0 else 0.0
        jump, at = largest_step(times[m], ev_)
        rows.append(
            {
                "target": name,
                "rmse": float(np.sqrt(np.mean(ev_**2))),
                "bias": bias,
                "sd": sd,
                "phi": phi,
                "lag_min": best_s * step / 60.0 + 0.0,
                "daily_amplitude": amp,
                "daily_share": min(share, 1.0),
                "step": jump,
                "step_at": at,
            }
        )
    return pd.DataFrame(rows).set_index("target")


#: :func:`common_step`: the largest steps of two or more temperature targets within this of each other, each beyond
#: half the target's stated accuracy (the sd of a sensor whose accuracy is a 95 % bound), are one event
STEP_TOGETHER = pd.Timedelta("6h")


def common_step(study, residuals: pd.DataFrame) -> str:
    """A sentence naming an event the model does not see, or "": the largest steps (:func:`largest_step`) of two or
    more temperature targets fall within :data:`STEP_TOGETHER` of each other and each exceeds half the target's
    stated accuracy. Sensors that fail on their own do not step together; a change of what the wall sees (a room
    humidified, a heater switched on) that the boundary conditions do not carry shows in every probe at once."""
    rows = []
    for t, r in residuals.iterrows():
        s = study.sensor(t)
        if s.quantity == "temperature" and s.accuracy and r["step_at"] and abs(r["step"]) > 0.5 * s.accuracy:
            rows.append((pd.Timestamp(r["step_at"]), t, float(r["step"])))
    rows.sort()
    best: list = []
    for i in range(len(rows)):
        group = [x for x in rows[i:] if x[0] - rows[i][0] <= STEP_TOGETHER]
        if len(group) > len(best):
            best = group
    if len(best) < 2:
        return ""
    what = ", ".join(f"{t} {v:+.2f} K" for _, t, v in best)
    return (
        f"The residuals of {what} step together between {best[0][0]} and {best[-1][0]} (their daily means, the day "
        "after against the day before): something the model does not see changed then (the room's humidity or "
        "heating, a sensor moved); no candidate extension represents a step, so look at the data around that time."
    )


#: the window on each side of a step in :func:`largest_step` (a day: it averages a daily pattern out), and the
#: share of its samples each side must hold
STEP_WINDOW = pd.Timedelta("1D")
STEP_COVERAGE = 0.9


def largest_step(times: pd.DatetimeIndex, e: np.ndarray) -> tuple[float, str]:
    """The largest change of the mean of ``e`` over :data:`STEP_WINDOW` on either side of a sample: (mean over
    [t, t + window) minus mean over [t - window, t), t as ISO text), at the sample where it is largest in magnitude,
    among those whose two windows each hold at least :data:`STEP_COVERAGE` of the samples a full window holds;
    (nan, "") when none does (a record shorter than about two days)."""
    times = pd.DatetimeIndex(times)
    if len(times) < 4:
        return float("nan"), ""
    t = np.asarray((times - times[0]).total_seconds(), dtype=float)  # [s]
    w = STEP_WINDOW.total_seconds()
    c = np.concatenate([[0.0], np.cumsum(e)])
    i = np.arange(len(t))
    lo = np.searchsorted(t, t - w, side="left")
    hi = np.searchsorted(t, t + w, side="left")
    n_before, n_after = i - lo, hi - i
    dt = float(np.median(np.diff(t)))
    if not dt > 0:
        return float("nan"), ""
    full = STEP_COVERAGE * w / dt  # a part of a day does not average its pattern out
    ok = (n_before >= full) & (n_after >= full)
    if not ok.any():
        return float("nan"), ""
    with np.errstate(invalid="ignore", divide="ignore"):
        step = (c[hi] - c[i]) / n_after - (c[i] - c[lo]) / n_before
    k = int(np.argmax(np.where(ok, np.abs(step), -1.0)))
    return float(step[k]), times[k].isoformat()


# ============================================================================ candidates
@dataclass(frozen=True)
class Extension:
    """One candidate extension of the parameter space.

    Attributes
    ----------
    name : str
        Its parameter name, e.g. ``"depth[T3A]"``.
    kind : str
        ``depth``, ``contact_resistance``, ``conductivity_temperature_coefficient``,
        ``moisture_conductivity_coefficient`` (a moisture study's lambda(w)), ``offset``, ``response_time`` or
        ``face_offset``.
    table : dict
        Its ``[[calibration.parameters]]`` entry as written into the extended study.
    reason : str
        What in the residuals points to it, in words.
    """

    name: str
    kind: str
    table: dict
    reason: str = ""


#: the unit of an error (a difference) of each sensor quantity, as the texts write it
ERROR_UNITS = {"temperature": "K", "heat_flux": "W/m2", "relative_humidity": "RH", "water_content": "kg/m3"}


def unit_label(study, target) -> str:
    return ERROR_UNITS[study.sensor(target).quantity]


def propose(study, space, residuals: pd.DataFrame | None = None, y=None, capabilities=None) -> list[Extension]:
    """Candidate extensions of ``space`` for ``study`` (those already in the space are left out, and those the
    engine cannot represent).

    Parameters
    ----------
    study : Study
    space : ParameterSpace
    residuals : DataFrame, optional
        :func:`residual_analysis` at the calibrated point (for the reasons given).
    y : dict, optional
        Target -> valid measured samples (bounds of a relative-accuracy sensor's offset).
    capabilities : Capabilities, optional
        The engine's (:class:`wallcal.engines.base.Capabilities`): no contact resistance or lambda(T) candidate
        for an engine without them (the ham engine). Default: every kind.
    """
    from .identifiability import sensor_sigma

    wall = study.wall
    have = set(space.names)
    inter = wall.interfaces
    ids = [layer.id for layer in wall.layers]
    res = residuals if residuals is not None else pd.DataFrame()

    def why(t, what):
        if t not in res.index:
            return what
        r = res.loc[t]
        u = unit_label(study, t)
        return (
            f"{what}; {t}: bias {r['bias']:+.3g} {u}, lag {r['lag_min']:+.1f} min, daily pattern "
            f"{r['daily_amplitude']:.3g} {u} peak to peak"
        )

    out: list[Extension] = []
    probes = [t for t in space.targets if study.sensor(t).quantity == "temperature"]
    for t in probes:
        name = f"depth[{t}]"
        if name in have:
            continue
        d = wall.probe(t).depth
        lo, hi = max(0.0, d - DEPTH_RANGE), min(wall.thickness, d + DEPTH_RANGE)
        out.append(
            Extension(
                name,
                "depth",
                {"probe": t, "property": "depth", "bounds": [round(lo, 9), round(hi, 9)], "bounds_kind": "absolute"},
                why(t, f"probe {t} placed off its nominal depth {d:g} m"),
            )
        )
    seen = set()
    contacts = capabilities is None or capabilities.contact_resistance
    laws = capabilities is None or capabilities.conductivity_laws
    for t in probes if contacts else ():
        d = wall.probe(t).depth
        near = np.flatnonzero(np.isclose(inter, d, atol=1e-6, rtol=0))
        if len(near):
            faces = [int(near[0])]
        else:
            li = int(np.searchsorted(inter, d) - 1)
            faces = [li, li + 1]
        for f in faces:
            if f <= 0 or f >= len(wall.layers) or f in seen:
                continue  # the wall's faces have no contact resistance
            seen.add(f)
            li = f - 1  # the contact resistance belongs to the layer on the exterior side
            name = f"contact_resistance[{ids[li]}]"
            if name in have or any(p.property == "contact_resistance" and li in p.layers for p in space.parameters):
                continue
            out.append(
                Extension(
                    name,
                    "contact_resistance",
                    {
                        "layers": [ids[li]],
                        "property": "contact_resistance",
                        "bounds": list(CONTACT_BOUNDS),
                        "bounds_kind": "absolute",
                    },
                    why(t, f"a contact resistance between layers {ids[li]} and {ids[li + 1]}, next to probe {t}"),
                )
            )
    # lambda(T): every insulation layer, grouped as the conductivity parameters group them
    groups: list[tuple[int, ...]] = []
    for p in space.parameters:
        if p.property == "conductivity" and p.layers not in groups:
            groups.append(p.layers)
    for i in range(len(wall.layers)):
        if not any(i in g for g in groups):
            groups.append((i,))
    taken = {i for p in space.parameters if p.property == "conductivity_temperature_coefficient" for i in p.layers}
    eligible = []
    for g in groups if laws else ():
        layers = [wall.layers[i] for i in g]
        if any(
            lay.is_massless
            or lay.conductivity is None
            or lay.conductivity >= INSULATION_LAMBDA
            or lay.conductivity_table is not None
            or i in taken
            for i, lay in zip(g, layers, strict=True)
        ):
            continue
        if len({lay.conductivity_temperature_coefficient for lay in layers}) == 1:
            eligible.append(tuple(g))
    # each group apart, and (with two or more) all of them sharing one coefficient: the coefficient is a property
    # of the insulation's kind (fibre and gas; ISO 10456 gives one per material family), so one shared value is
    # the simplest hypothesis, and the criterion weighs it against separate ones
    shared = [tuple(sorted(i for g in eligible for i in g))] if len(eligible) > 1 else []
    for g in eligible + shared:
        f0s = {wall.layers[i].conductivity_temperature_coefficient for i in g}
        if len(f0s) != 1:
            continue
        f0 = f0s.pop()
        lab = ",".join(ids[i] for i in g)
        what = "sharing one coefficient" if g in shared else "depending on temperature"
        out.append(
            Extension(
                f"conductivity_temperature_coefficient[{lab}]",
                "conductivity_temperature_coefficient",
                {
                    "layers": [ids[i] for i in g],
                    "property": "conductivity_temperature_coefficient",
                    "bounds": [min(f0, 0.0), f0 + COEFFICIENT_RANGE],
                    "bounds_kind": "absolute",
                },
                f"conductivity of insulation layer(s) {lab} {what} (lambda(T))",
            )
        )
    # lambda(w) of each insulation layer of a moisture study (the ham engine computes lambda_dry (1 + b w / rho))
    if study.has_moisture:
        taken_w = {i for p in space.parameters if p.property == "moisture_conductivity_coefficient" for i in p.layers}
        for i, lay in enumerate(wall.layers):
            if i in taken_w or lay.is_massless or lay.conductivity is None or lay.conductivity >= INSULATION_LAMBDA:
                continue
            b0 = lay.moisture_conductivity_coefficient or 0.0
            out.append(
                Extension(
                    f"moisture_conductivity_coefficient[{ids[i]}]",
                    "moisture_conductivity_coefficient",
                    {
                        "layers": [ids[i]],
                        "property": "moisture_conductivity_coefficient",
                        "bounds": [0.0, b0 + MOISTURE_COEFFICIENT_RANGE],
                        "bounds_kind": "absolute",
                    },
                    f"conductivity of insulation layer {ids[i]} depending on its water content (lambda(w))",
                )
            )
    for t in space.targets:
        name = f"offset[{t}]"
        if name in have:
            continue
        yt = np.asarray((y or {}).get(t, [1.0]), dtype=float)
        sig = sensor_sigma(study, t, yt)
        if not np.isfinite(sig) or sig <= 0:
            sig = 0.0
        # a relative accuracy (a heat-flux meter's gain) says little about an offset: at least a quarter of the
        # signal's standard deviation
        half = max(OFFSET_ACCURACIES * sig, OFFSET_SPREAD * float(np.std(yt)))
        half = float(f"{half:.3g}") if half > 0 else 1.0
        out.append(
            Extension(
                name,
                "offset",
                {"sensor": t, "property": "offset", "bounds": [-half, half]},
                why(t, f"a constant offset of sensor {t}"),
            )
        )
    for t in probes:
        name = f"response_time[{t}]"
        if name in have:
            continue
        out.append(
            Extension(
                name,
                "response_time",
                {"sensor": t, "property": "response_time", "bounds": list(RESPONSE_RANGE)},
                why(t, f"probe {t} reading its temperature through a first-order lag"),
            )
        )
    acc = face_accuracy(study, space)
    faces = (study.exterior.type, study.interior.type)
    if acc > 0 and "heat_flux" not in faces and "offset[faces]" not in have:
        half = float(f"{FACE_OFFSET_ACCURACIES * acc:.3g}")
        lead = probes[0] if probes else None
        out.append(
            Extension(
                "offset[faces]",
                "face_offset",
                {"sensor": "faces", "property": "offset", "bounds": [-half, half]},
                why(lead, "one constant offset of both boundary (face) sensors: every temperature moves by it")
                if lead
                else "one constant offset of both boundary (face) sensors",
            )
        )
    return out


def face_accuracy(study, space) -> float:
    """The largest stated accuracy of the temperature targets [K] (0 without any): the face sensors' assumed one."""
    accs = [
        study.sensor(t).accuracy
        for t in space.targets
        if study.sensor(t).quantity == "temperature" and study.sensor(t).accuracy
    ]
    return float(max(accs)) if accs else 0.0


def plausible_range(study, space, p) -> tuple[float, float] | None:
    """The documented plausible range [SI] of an extension's parameter ``p`` (a Parameter), or None (any value in
    its box is plausible: the study's own parameters)."""
    if p.property == "depth":
        d = study.wall.probe(p.probe).depth
        return d - PROBE_TOLERANCE, d + PROBE_TOLERANCE
    if p.property == "conductivity_temperature_coefficient":
        return 0.0, COEFFICIENT_PLAUSIBLE
    if p.property == "contact_resistance":
        return 0.0, CONTACT_PLAUSIBLE
    if p.property == "response_time":
        return 0.0, RESPONSE_PLAUSIBLE
    if p.property == "offset":
        if p.shifts:
            acc = face_accuracy(study, space)
        else:
            acc = study.sensor(p.sensor).accuracy  # a relative accuracy is a gain: only the bound check
        if not acc or not np.isfinite(acc):
            return None
        return -OFFSET_PLAUSIBLE_ACCURACIES * acc, OFFSET_PLAUSIBLE_ACCURACIES * acc
    return None


def plausibility(study, space, x, names, band: float) -> list[str]:
    """Why the values of the extensions ``names`` at ``x`` [SI] are not plausible ([] when they all are): outside
    their documented range (:func:`plausible_range`), or within ``band`` of their range from a bound of the
    candidate's box (a value at a bound is never adopted silently)."""
    out = []
    sides = space.bound_sides(x, band)
    for p, v, side in zip(space.parameters, np.asarray(x, dtype=float), sides, strict=True):
        if p.name not in names:
            continue
        rng = plausible_range(study, space, p)
        if side:
            out.append(f"{p.name} = {v:.4g} at the {side} bound of its box")
        elif rng is not None and not rng[0] - 1e-12 <= v <= rng[1] + 1e-12:
            out.append(f"{p.name} = {v:.4g} outside its plausible range {rng[0]:.4g} .. {rng[1]:.4g}")
    return out

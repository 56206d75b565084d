"""Let the data choose the model structure: ``wallcal diagnose``.

Starting from a calibrated wall, :func:`diagnose` looks at the residuals of each target (bias, lag,
daily pattern), proposes structural extensions of the calibration's parameter space -

- ``depth[P]``: the depth of probe P (a sensor placed a few millimetres off its nominal depth),
- ``contact_resistance[L]``: a contact resistance at each layer interface next to a target probe,
- ``conductivity_temperature_coefficient[L...]``: lambda(T) of each insulation layer or tied group, and of all
  of them sharing one coefficient,
- ``offset[S]``: a constant offset of target sensor S beyond the bias its accuracy allows,

and scores each, and each useful combination, by recalibrating warm-started from the calibrated point
(the study's objective with each target's sensor bias profiled out, :func:`debiased_residuals`; bounded
Levenberg-Marquardt: :func:`refine`; each Jacobian one engine batch). The score is the Bayesian information
criterion on the AR(1) likelihood of the residuals at the recalibrated point, each target's constant sensor bias
integrated out under the posterior's prior N(0, (accuracy/2)^2) (see :func:`ar1_loglike` and
``docs/identifiability.md``, "Choosing the model structure"):

    BIC = -2 sum_k log L_k(AR(1) + bias, phi_k and sigma_k at their maximum) + p ln N

with p the calibration parameters and N the residual pairs over all targets. An extension (or a set) is
adopted when it lowers BIC by at least :data:`ADOPT_DELTA` (10: "very strong" evidence) against the
structure adopted so far (forward selection; the close contenders of each step fitted to convergence first;
extensions within :data:`TIE_DELTA` of the best adopted together), or by :data:`WEAK_DELTA` (2: "positive") while
the structure so far holds some of the study's parameters at a bound of their prior box and the extension frees
one of them: such a structure fails its own check and is no null worth protecting. The extended study
(:attr:`Diagnosis.study`) is the study with the adopted extensions added to its ``[calibration]`` table.
"""

from __future__ import annotations

import copy
import json
import math
import os
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from ..errors import StudyError, WallcalError

__all__ = [
    "ADOPT_DELTA",
    "WEAK_DELTA",
    "Diagnosis",
    "Extension",
    "ar1_loglike",
    "debiased_residuals",
    "diagnose",
    "forward_select",
    "held_at_bounds",
    "node_starts",
    "propose",
    "residual_analysis",
]

#: BIC decrease needed to adopt an extension (Kass and Raftery: > 10 is very strong evidence)
ADOPT_DELTA = 10.0
#: an insulation layer (candidate for lambda(T)) conducts less than this [W/(m K)]
INSULATION_LAMBDA = 0.1
#: half-range of a candidate probe depth [m]
DEPTH_RANGE = 0.01
#: bounds of a candidate contact resistance [m2K/W]
CONTACT_BOUNDS = (0.0, 0.5)
#: range of a candidate conductivity temperature coefficient above its base value [1/K]; an insulation's
#: conductivity rises with temperature (ISO 10456), so the lower bound is min(base, 0)
COEFFICIENT_RANGE = 0.02
#: half-range of a candidate sensor offset: this many times the sensor's accuracy, and at least
#: OFFSET_SPREAD times the standard deviation of its measured signal
OFFSET_ACCURACIES = 2.0
OFFSET_SPREAD = 0.25
#: prior sd of a target's constant sensor bias, integrated out of the criterion, as a share of its stated
#: accuracy (a 95 % bound: its sd is about half of it; the posterior's error model)
BIAS_ACCURACY_SHARE = 0.5
#: BIC decrease that suffices while the structure adopted so far is rejected by its own optimum - one of the study's
#: parameters held at a bound of its prior box (Kass and Raftery: > 2 is "positive" evidence) - and the candidate
#: frees it (see :func:`forward_select`)
WEAK_DELTA = 2.0
#: a parameter whose optimum lies within this share of its range from a bound is held at that bound
BOUND_BAND = 0.005
#: extensions whose criterion lies within this of the best one's are tied: adopted together (Kass and Raftery:
#: a BIC difference below 2 is "not worth more than a bare mention")
TIE_DELTA = 2.0
#: candidates whose criterion lies within this of a step's best are fitted to convergence before they are compared
POLISH_MARGIN = 25.0
#: the base structure's re-polish (and a close contender's) may take this many times the Jacobians of a candidate's
BASE_JACOBIANS = 4
#: Jacobians allowed in each warm-started recalibration
MAX_JACOBIANS = 8
#: a probe depth that starts on a contact's double node is also fitted from this far off it on each side [m]
#: (at most NODE_SHARE of its range; see :func:`node_starts`)
NODE_STEP = 0.001
NODE_SHARE = 0.1
#: relative change of the least-squares cost that ends a recalibration (a BIC change of 1 is about 2 / N)
FTOL = 1e-5
#: after the single candidates, each forward step tries the best few useful ones only
MAX_TRIALS = 3
#: most extensions adopted together
MAX_ADOPTED = 4
CRITERION = "delta_bic"


# ============================================================================ the criterion
def ar1_loglike(e: np.ndarray, mask: np.ndarray, bias_sd: float = 0.0) -> tuple[float, int, float]:
    """Maximised conditional AR(1) Gaussian log-likelihood of one residual series, a constant sensor bias with
    a Gaussian prior integrated out.

    The residuals follow e_t = b + u_t, u_t = phi u_{t-1} + eta_t, eta ~ N(0, s^2), with a constant bias
    b ~ N(0, bias_sd^2) (the posterior's error model: a sensor's bias within its stated accuracy is part of
    the error, not of the structure). Conditioning on the first value of every gap-free run, the m consecutive
    valid pairs give innovations r_t - c b with r_t = e_t - phi e_{t-1} and c = 1 - phi; integrating b out
    exactly,

        log L = -m/2 ln(2 pi s^2) - sum (r_t - c b*)^2 / (2 s^2) - b*^2 / (2 bias_sd^2)
                - 1/2 ln(1 + m c^2 bias_sd^2 / s^2),

    b* = c sum r_t / (m c^2 + s^2 / bias_sd^2) the bias's posterior mean, maximised over phi and s^2 by
    alternating their closed-form updates with b* (this maximises the joint density of phi, s and b; the last
    term's dependence on phi and s is left out of the maximisation, which costs a few thousandths). With
    ``bias_sd`` 0 (no bias: it shows as misfit) this is -m/2 (ln(2 pi s^2) + 1) with
    phi = sum e_t e_{t-1} / sum e_{t-1}^2 and s^2 the mean squared innovation.

    Parameters
    ----------
    e : ndarray, shape (n,)
        Residuals [unit of the signal].
    mask : ndarray of bool, shape (n,)
        Valid samples.
    bias_sd : float
        Prior sd of the sensor's constant bias [unit of the signal]; 0: no bias.

    Returns
    -------
    (log L, m, phi)
    """
    return _ar1_fit(e, mask, bias_sd)[:3]


def _ar1_fit(e, mask, bias_sd=0.0) -> tuple[float, int, float, float, float]:
    """:func:`ar1_loglike` and its innovation sd s and bias b*."""
    e = np.where(mask, e, 0.0)
    pair = mask[1:] & mask[:-1]
    m = int(pair.sum())
    if m < 2:
        return 0.0, 0, 0.0, 1.0, 0.0
    a, p = e[1:][pair], e[:-1][pair]

    def ar(b):
        den = float(np.sum((p - b) ** 2))
        phi = float(np.clip(np.sum((a - b) * (p - b)) / den, -0.999, 0.999)) if den > 0 else 0.0
        s2 = max(float(np.mean(((a - b) - phi * (p - b)) ** 2)), 1e-300)
        return phi, s2

    b = 0.0
    phi, s2 = ar(b)
    if not bias_sd > 0:
        return -0.5 * m * (math.log(2 * math.pi * s2) + 1.0), m, phi, math.sqrt(s2), 0.0
    t2 = float(bias_sd) ** 2
    for _ in range(50):
        c = 1.0 - phi
        b_new = c * float(np.sum(a - phi * p)) / (m * c * c + s2 / t2)
        phi, s2 = ar(b_new)
        done = abs(b_new - b) <= 1e-9 * (abs(b_new) + math.sqrt(s2))
        b = b_new
        if done:
            break
    c = 1.0 - phi
    b = c * float(np.sum(a - phi * p)) / (m * c * c + s2 / t2)
    q = float(np.sum((a - phi * p - c * b) ** 2))
    s2 = max(q / m, 1e-300)
    ll = -0.5 * m * (math.log(2 * math.pi * s2) + 1.0) - 0.5 * b * b / t2 - 0.5 * math.log1p(m * c * c * t2 / s2)
    return ll, m, phi, math.sqrt(s2), b


def ar1_profile(E: np.ndarray, mask: np.ndarray, bias_sd=None) -> tuple[float, int, np.ndarray, np.ndarray]:
    """The AR(1) fit of every target's residuals ``E`` (targets x times), each with its sensor bias of prior sd
    ``bias_sd[k]`` integrated out (None: no bias): (log L summed over the targets, N pairs, phi per target,
    innovation sd per target)."""
    ll, n = 0.0, 0
    phi = np.zeros(E.shape[0])
    sd = np.ones(E.shape[0])
    tau = np.zeros(E.shape[0]) if bias_sd is None else np.asarray(bias_sd, dtype=float)
    for k in range(E.shape[0]):
        lk, mk, phi[k], sk, _ = _ar1_fit(E[k], mask[k], float(tau[k]))
        ll += lk
        n += mk
        if mk:
            sd[k] = sk
    return ll, n, phi, sd


# ============================================================================ residual analysis
def residual_analysis(ev, x, times) -> pd.DataFrame:
    """Bias, lag, daily pattern and autocorrelation of each target's residuals (simulated - measured) at ``x``.

    Columns: ``rmse``, ``bias`` (mean residual), ``sd`` (about the bias), ``phi`` (lag-1 autocorrelation of
    the de-meaned residuals), ``lag_min`` (the shift of the simulated series [min] that best matches the
    measured one; positive: the model is late), ``daily_amplitude`` (peak-to-peak of the mean residual per
    hour of the day) and ``daily_share`` (the part of the residual variance about the bias that the daily
    pattern explains).
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
            }
        )
    return pd.DataFrame(rows).set_index("target")


# ============================================================================ candidates
@dataclass(frozen=True)
class Extension:
    """One candidate extension of the parameter space.

    Attributes
    ----------
    name : str
        Its parameter name, e.g. ``"depth[T3A]"``.
    kind : str
        ``depth``, ``contact_resistance``, ``conductivity_temperature_coefficient`` or ``offset``.
    table : dict
        Its ``[[calibration.parameters]]`` entry as written into the extended study.
    reason : str
        What in the residuals points to it, in words.
    """

    name: str
    kind: str
    table: dict
    reason: str = ""


def _fmt_unit(study, target) -> str:
    return "W/m2" if study.sensor(target).quantity == "heat_flux" else "K"


def propose(study, space, residuals: pd.DataFrame | None = None, y=None) -> list[Extension]:
    """Candidate extensions of ``space`` for ``study`` (those already in the space are left out).

    Parameters
    ----------
    study : Study
    space : ParameterSpace
    residuals : DataFrame, optional
        :func:`residual_analysis` at the calibrated point (for the reasons given).
    y : dict, optional
        Target -> valid measured samples (bounds of a relative-accuracy sensor's offset).
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
        u = _fmt_unit(study, t)
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
    for t in probes:
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
    for g in groups:
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
    return out


# ============================================================================ the result
@dataclass
class Diagnosis:
    """Outcome of :func:`diagnose`.

    Attributes
    ----------
    adopted : list of str
        Names of the adopted extensions ([] when the data support the study's structure).
    candidates : DataFrame
        One row per candidate or combination scored, the columns of ``candidates.csv``: ``extension``
        (names joined by " + "), ``delta_bic`` (BIC change against the study's structure; negative: better),
        ``RMSE <target>`` for every target [its unit], ``adopted`` (the row of the adopted set).
    study : Study
        The study with the adopted extensions added to its ``[calibration]`` table (loadable and runnable
        like :func:`wallcal.load_study`'s; relative paths resolve against the original study's folder).
    residuals : DataFrame
        :func:`residual_analysis` at the calibrated point of the study's structure.
    extensions : list of Extension
        Every candidate proposed.
    x : dict
        Parameter name -> value [SI] at the recalibrated optimum of the adopted structure.
    """

    adopted: list
    candidates: pd.DataFrame
    study: object
    residuals: pd.DataFrame
    extensions: list
    x: dict
    base_study: object
    rmse_base: dict
    bic_base: float
    n_pairs: int
    evaluations: int = 0
    seconds: float = 0.0
    raw: dict = field(default_factory=dict, repr=False)
    notes: list = field(default_factory=list)

    # ------------------------------------------------------------------ words
    def summary(self) -> str:
        """Which structure the data support and by how much, in words."""
        study = self.base_study
        units = {t: _fmt_unit(study, t) for t in self.rmse_base}
        c = self.candidates
        lines = []
        if self.adopted:
            row = c[c["adopted"]].iloc[0]
            rm = ", ".join(f"{t} {self.rmse_base[t]:.3f} -> {row[f'RMSE {t}']:.3f} {units[t]}" for t in self.rmse_base)
            vals = ", ".join(f"{n} = {self.x[n]:.4g}" for n in self.adopted)
            lines.append(
                f"The data support extending the calibration with {' + '.join(self.adopted)}: BIC falls by "
                f"{-row[CRITERION]:.1f} against the study's structure (adoption needs a fall of at least "
                f"{ADOPT_DELTA:g}). RMSE {rm}. Recalibrated values: {vals}."
            )
        else:
            lines.append(
                f"The data support the study's structure: no candidate extension lowers BIC by {ADOPT_DELTA:g} or more."
            )
        single = ~c["extension"].str.contains(r" \+ ", regex=True)
        rest = c[single & ~c["extension"].isin(self.adopted)].sort_values(CRITERION)
        if len(rest):
            best = rest.iloc[0]
            lines.append(
                f"Best candidate left out: {best['extension']} (delta BIC {best[CRITERION]:+.1f} on its own); "
                f"{len(c)} candidates and combinations scored ({self.evaluations} simulations, {self.seconds:.1f} s)."
            )
        r = self.residuals
        feats = []
        for t, row in r.iterrows():
            feats.append(
                f"{t}: RMSE {row['rmse']:.3f} {units.get(t, '')}, bias {row['bias']:+.3f}, lag {row['lag_min']:+.1f} "
                f"min, daily pattern {row['daily_amplitude']:.3f} peak to peak ({100 * row['daily_share']:.0f} % of "
                f"the variance), phi {row['phi']:.3f}"
            )
        lines.append("Residuals of the calibrated study structure: " + "; ".join(feats) + ".")
        lines += self.notes
        return "\n".join(lines)

    def to_json(self) -> dict:
        return {
            "adopted": list(self.adopted),
            "criterion": "BIC on the AR(1) likelihood of the residuals, each target's sensor bias integrated out "
            "(prior sd half its accuracy)",
            "adopt_delta": ADOPT_DELTA,
            "weak_delta": WEAK_DELTA,
            "bic_base": self.bic_base,
            "residual_pairs": self.n_pairs,
            "rmse_base": self.rmse_base,
            "values": self.x,
            "extensions": [
                {"name": e.name, "kind": e.kind, "table": e.table, "reason": e.reason} for e in self.extensions
            ],
            "evaluations": self.evaluations,
            "seconds": self.seconds,
            "summary": self.summary(),
        }

    def study_toml(self, out_dir) -> str:
        """The extended study as TOML, with every relative path rewritten to resolve from ``out_dir``."""
        import tomli_w

        raw = _relocate(self.raw, self.base_study, Path(out_dir))
        src = self.base_study.path or "the study"
        head = (
            f"# wallcal diagnose: {src} with the adopted extensions "
            f"({', '.join(self.adopted) if self.adopted else 'none'}) added to [calibration];\n"
            "# relative paths point to the original study's files.\n"
        )
        return head + tomli_w.dumps(raw)

    def write_into(self, d: Path) -> list[str]:
        """Write ``candidates.csv``, ``study.toml``, ``residuals.csv`` and ``diagnose.json`` into ``d``."""
        from ..study import load_study

        d = Path(d)
        self.candidates.to_csv(d / "candidates.csv", index=False, float_format="%.6g")
        (d / "study.toml").write_text(self.study_toml(d))
        self.residuals.to_csv(d / "residuals.csv", float_format="%.6g")
        (d / "diagnose.json").write_text(json.dumps(self.to_json(), indent=2, default=float))
        load_study(d / "study.toml")  # the written study must load (relative paths resolve)
        return ["candidates.csv", "study.toml", "residuals.csv", "diagnose.json"]

    def write(self, out_dir) -> Path:
        """Write every output atomically into ``out_dir`` (it appears only when complete)."""
        from ..outputs import output_dir
        from ..simulation import manifest_of

        target = Path(out_dir).resolve()
        with output_dir(target, manifest=manifest_of(self.base_study, "diagnose")) as tmp:
            # tmp sits next to target: paths relative to target resolve from tmp too
            self.write_into(Path(tmp))
        return target


def _relocate(raw: dict, study, out_dir: Path) -> dict:
    """A copy of the study's TOML tables with every file path relative to the study made relative to
    ``out_dir`` (data files, wall file, reference wall, a weather file next to the study)."""
    raw = copy.deepcopy(raw)
    base = Path(study.path).resolve().parent if study.path else Path.cwd()
    out_dir = Path(out_dir).resolve()

    def move(value):
        if not isinstance(value, str) or Path(value).is_absolute():
            return value
        target = (base / value).resolve()
        if os.path.commonpath([target, out_dir]) == os.path.sep:
            return str(target)  # nothing in common but the root: an absolute path reads better
        return os.path.relpath(target, out_dir)

    wall = raw.get("wall")
    if isinstance(wall, dict) and "file" in wall:
        wall["file"] = move(wall["file"])
    data = raw.get("data")
    if isinstance(data, dict):
        if "file" in data:
            data["file"] = move(data["file"])
        for f in data.get("files", []) or []:
            if isinstance(f, dict) and "file" in f:
                f["file"] = move(f["file"])
    cal = raw.get("calibration")
    if isinstance(cal, dict) and "reference_wall" in cal:
        cal["reference_wall"] = move(cal["reference_wall"])
    ret = raw.get("retrofit")
    if isinstance(ret, dict) and isinstance(ret.get("weather"), str) and (base / ret["weather"]).is_file():
        ret["weather"] = move(ret["weather"])
    return raw


# ============================================================================ the run
def _values_from_wall(space, wall, study) -> np.ndarray:
    ids = [layer.id for layer in study.wall.layers]
    if [layer.id for layer in wall.layers] != ids:
        raise WallcalError(
            f"the starting wall's layers ({', '.join(layer.id for layer in wall.layers)}) are not the study's "
            f"({', '.join(ids)})"
        )
    depths = {p.name: p.depth for p in wall.probes}
    out = []
    for p in space.parameters:
        if p.sensor is not None:
            out.append(0.0)
        elif p.probe is not None:
            out.append(depths.get(p.probe, p.base))
        else:
            v = getattr(wall.layers[p.layers[0]], p.property)
            out.append(p.base if v is None else float(v))
    return np.array(out, dtype=float)


def start_point(study, space, start, progress) -> tuple[np.ndarray, str]:
    """The calibrated parameter values [SI] to start from, and where they came from."""
    from ..wall import Wall

    if start is None:
        from ..calibration import calibrate

        res = calibrate(study, progress=progress is True, space=space)
        return res.x_opt, f"calibrated now ({res.algorithm}, {res.evaluations} simulations)"
    if hasattr(start, "x_opt") and hasattr(start, "space"):  # a CalibrationResult
        vals = dict(zip(start.space.names, start.x_opt, strict=True))
        x = np.array([vals.get(p.name, p.base) for p in space.parameters], dtype=float)
        return x, "the calibration result given"
    if isinstance(start, Wall):
        return _values_from_wall(space, start, study), "the wall given"
    path = Path(start)
    if path.is_dir():
        from . import load_optimum

        return load_optimum(space, path), f"{path / 'calibration.json'}"
    if path.is_file():
        from ..study import load_wall

        return _values_from_wall(space, load_wall(path), study), str(path)
    raise WallcalError(f"--from {start}: no such calibration output directory or wall file")


def refine(residuals, u0, max_jacobians: int = MAX_JACOBIANS, ftol: float = FTOL, h: float = 1e-6):
    """Warm-started bounded Levenberg-Marquardt in the unit box; every engine call is one batch.

    Each iteration runs one batch of n forward-difference runs (the Jacobian) and one batch of four trial
    steps (damping lambda/10, lambda, 10 lambda, 100 lambda, each clipped to the box; parameters at a bound
    whose gradient points out of the box stay there) and keeps the best trial. The normal equations are
    n x n (no decomposition of the tall Jacobian).

    Parameters
    ----------
    residuals : callable
        ``residuals(U) -> R``, U shape (c, n) in unit coordinates, R shape (c, m).
    u0 : ndarray, shape (n,)
    max_jacobians : int
    ftol : float
        Stop when an accepted step lowers the cost by less than this fraction.

    Returns
    -------
    (u, runs)
        The best point and the number of simulations run.
    """
    u = np.clip(np.asarray(u0, dtype=float), 0.0, 1.0)
    n = len(u)
    r = residuals(u[None])[0]
    cost = float(np.einsum("m,m->", r, r))
    runs = 1
    lam = 1e-3
    for _ in range(max_jacobians):
        step = np.where(u + h > 1.0, -h, h)
        U = np.repeat(u[None], n, axis=0)
        U[np.arange(n), np.arange(n)] += step
        D = (residuals(U) - r[None]) / step[:, None]  # the Jacobian's transpose, (n, m)
        runs += n
        # einsum, not BLAS: on a shared machine a threaded BLAS product of this tall matrix can take 100x longer
        A = np.einsum("im,jm->ij", D, D)
        g = np.einsum("im,m->i", D, r)
        free = ~(((u <= 0.0) & (g > 0)) | ((u >= 1.0) & (g < 0)))
        if not free.any():
            break
        Af, gf = A[np.ix_(free, free)], g[free]
        d = np.diag(Af).copy()
        d[d <= 0] = 1.0
        lams = lam * np.array([0.1, 1.0, 10.0, 100.0])
        trials = []
        for lm in lams:
            try:
                delta = np.linalg.solve(Af + lm * np.diag(d), -gf)
            except np.linalg.LinAlgError:
                delta = -gf / (d * (1 + lm))
            ut = u.copy()
            ut[free] = np.clip(u[free] + delta, 0.0, 1.0)
            trials.append(ut)
        T = np.array(trials)
        R = residuals(T)
        runs += len(T)
        costs = np.einsum("cm,cm->c", R, R)
        costs = np.where(np.isfinite(costs), costs, np.inf)
        k = int(np.argmin(costs))
        if not costs[k] < cost:
            lam *= 1000.0
            if lam > 1e10:
                break
            continue
        gain = (cost - costs[k]) / cost if cost > 0 else 0.0
        u, r, cost, lam = T[k], R[k], float(costs[k]), max(lams[k] / 3.0, 1e-9)
        if gain < ftol:
            break
    return u, runs


def node_starts(space, wall, contact_layers, x) -> list[np.ndarray]:
    """The starts of a recalibration from ``x``: ``x`` itself, and where a probe's depth starts on a contact's
    double node, also just off the node on each side.

    At a contact link the grid has two nodes at one depth (:func:`wallcal.grid.contact_node_depths`); a probe
    on it reads one side or the mean of both, so its reading - and the objective - jumps when the depth moves off
    the node either way. A gradient fit (finite-difference Jacobians) started on the node cannot leave it; started
    :data:`NODE_STEP` (at most :data:`NODE_SHARE` of the range) to either side, inside the bounds, it follows the
    objective on that side. Each such depth gets the three values (on, before and after the node); several such
    depths, every combination.

    Parameters
    ----------
    space : ParameterSpace
    wall : Wall
        The wall the engine builds its grid from.
    contact_layers : set of int
        Layers with a contact link even at zero resistance (the engine input's ``options.contact_layers``).
    x : ndarray, shape (n,)
        Parameter values [SI].

    Returns
    -------
    list of ndarray, shape (n,)
        ``x`` first.
    """
    from ..grid import contact_node_depths, node_tolerance

    x = np.asarray(x, dtype=float)
    nodes = np.array(list(contact_node_depths(wall, contact_layers).values()))
    tol = node_tolerance(wall.thickness)
    starts = [x]
    for j, p in enumerate(space.parameters):
        if p.probe is None or not len(nodes) or np.abs(nodes - x[j]).min() > tol:
            continue
        step = min(NODE_STEP, NODE_SHARE * (p.upper - p.lower))
        values = [v for v in (x[j] - step, x[j] + step) if p.lower <= v <= p.upper]
        more = []
        for s in starts:
            for v in values:
                t = s.copy()
                t[j] = v
                more.append(t)
        starts = starts + more
    return starts


def held_at_bounds(space, x, names=None, band: float = BOUND_BAND) -> frozenset:
    """The parameters of ``space`` (those in ``names``; default all) whose value in ``x`` [SI] lies within
    ``band`` of its range from a bound of the prior box, in the space's unit coordinates."""
    sides = space.bound_sides(x, band)
    return frozenset(n for n, side in zip(space.names, sides, strict=True) if side and (names is None or n in names))


def debiased_residuals(ev, X, bias_sd, noise) -> np.ndarray:
    """The study's least-squares residuals with every target's constant sensor bias profiled out under its
    prior: the objective sum_k w_k (sum_t (e_kt - b_k)^2 + noise_k^2 b_k^2 / bias_sd_k^2), minimised over b_k
    in closed form, b_k = sum_t e_kt / (n_k + noise_k^2 / bias_sd_k^2) (b_k = 0 where bias_sd_k is 0).

    The criterion integrates the same bias out, so the structure it scores is fitted under its own error
    model: fitted on the raw errors, the wall's properties would absorb a sensor's bias.

    Parameters
    ----------
    ev : Evaluator
    X : ndarray, shape (c, n)
        Parameter values [SI].
    bias_sd, noise : ndarray, shape (n_targets,)
        Prior sd of each target's bias and its noise sd [target unit].

    Returns
    -------
    ndarray, shape (c, n_targets * n_times + n_targets)
    """
    from ..calibration.objective import residual_weights

    e = ev.errors(np.atleast_2d(X))
    w = np.sqrt(residual_weights(ev.space.objective, ev.n_valid, ev.weights, ev.scale))
    tau = np.asarray(bias_sd, dtype=float)
    has = tau > 0
    ratio = np.where(has, np.asarray(noise, dtype=float) ** 2 / np.where(has, tau, 1.0) ** 2, np.inf)
    b = np.einsum("ctk->ct", e) / (ev.n_valid + ratio)[None]  # e is 0 at missing samples
    r = np.where(ev.mask[None], e - b[:, :, None], 0.0) * w[None, :, None]
    prior = np.where(has, b * (np.asarray(noise) / np.where(has, tau, 1.0))[None], 0.0) * w[None]
    return np.concatenate([r.reshape(e.shape[0], -1), prior], axis=1)


def forward_select(base, singles: dict, score, polish, compatible, max_adopted: int = MAX_ADOPTED, held=None):
    """Forward selection of extensions by the criterion (the ``bic`` of each fit; lower is better).

    The best single candidate is adopted when it lowers the criterion by at least :data:`ADOPT_DELTA`; then the
    :data:`MAX_TRIALS` best remaining useful candidates (those better than ``base`` alone) are each added to the
    adopted set, and so on, at most ``max_adopted`` extensions. At each step the candidates within
    :data:`POLISH_MARGIN` of the step's best are polished (fitted to convergence) before they are compared, and
    those that end within :data:`TIE_DELTA` of the best are tied: adopted together with it when the set still
    lowers the criterion by the step's threshold (the data cannot choose between them).

    A structure whose optimum holds one of the study's parameters at a bound of its prior box (``held``) fails
    its own check: its parameters compensate for what it lacks, so it is no plausible null, and the strong
    evidence that protects a plausible one does not apply. While it holds some, a step in which no candidate
    reaches :data:`ADOPT_DELTA` adopts the best candidate that lowers the criterion by at least
    :data:`WEAK_DELTA` and frees at least one of them (its optimum leaves it inside the box).

    Parameters
    ----------
    base : fit
        The study's structure: attributes ``names`` (an empty tuple) and ``bic``.
    singles : dict
        Extension name -> its fit alone (attributes ``names``, ``bic``).
    score : callable
        ``score(names, warm) -> fit`` of a set of extensions, warm-started at the fit ``warm``.
    polish : callable
        ``polish(fit) -> fit`` continued to convergence.
    compatible : callable
        ``compatible(names) -> bool``: whether the extensions can be adopted together.
    max_adopted : int
    held : callable, optional
        ``held(fit) -> frozenset`` of the study's parameters held at a bound at the fit's optimum. None: the
        strong threshold only.

    Returns
    -------
    (fit, adopted, tied, weak)
        The adopted set's fit, its names, the tied groups as (names, criterion change against the best one
        alone), and the steps taken on the weaker threshold as (names adopted, criterion change of the step,
        parameters held before, parameters held after).
    """
    useful = [n for n, f in sorted(singles.items(), key=lambda kv: kv[1].bic) if f.bic < base.bic]
    current = base
    adopted: tuple = ()
    tied: list = []
    weak: list = []
    while len(adopted) < max_adopted:
        if not adopted:
            trials = [singles[n] for n in useful]
        else:
            pool = [n for n in useful if n not in adopted and compatible(adopted + (n,))][:MAX_TRIALS]
            trials = [score(adopted + (n,), current) for n in pool]
        if not trials:
            break
        # the close contenders are fitted to convergence before they are compared: a probe depth or a contact
        # link moves slowly in a few Jacobians, and the ranking of near-equals must not depend on that
        first = min(f.bic for f in trials)
        trials = [polish(f) if f.bic <= first + POLISH_MARGIN else f for f in trials]
        best = min(trials, key=lambda f: f.bic)
        threshold = ADOPT_DELTA
        before = frozenset() if held is None else held(current)
        if best.bic > current.bic - ADOPT_DELTA:
            # the structure so far fails its own check (parameters held at bounds): positive evidence suffices for
            # a candidate that frees some of them
            freeing = [f for f in trials if f.bic <= current.bic - WEAK_DELTA and before - held(f)] if before else []
            if not freeing:
                break
            best = min(freeing, key=lambda f: f.bic)
            threshold = WEAK_DELTA
        # extensions that explain the misfit as well as the best one (within TIE_DELTA): the data cannot choose
        # between them, so all are adopted and the posterior averages over them, rather than being conditional on
        # an arbitrary choice
        new = [n for n in best.names if n not in adopted]
        ties = [
            n
            for f in sorted(trials, key=lambda f: f.bic)
            if f is not best and f.bic <= best.bic + TIE_DELTA
            for n in f.names
            if n not in adopted and n not in new
        ]
        ties = [n for n in dict.fromkeys(ties) if compatible(tuple(best.names) + (n,))]
        if ties and len(best.names) + len(ties) <= max_adopted:
            both = score(tuple(best.names) + tuple(ties), best)
            if both.bic <= current.bic - threshold and (threshold == ADOPT_DELTA or before - held(both)):
                tied.append((new + ties, both.bic - best.bic))
                new = new + ties
                best = both
        if threshold != ADOPT_DELTA:
            weak.append((new, best.bic - current.bic, before, held(best)))
        current = best
        adopted = tuple(best.names)
    return current, adopted, tied, weak


class _Say:
    def __init__(self, progress):
        from ..calibration.algorithms import Progress

        self.fn = progress if callable(progress) else None
        self.bar = Progress("diagnose", enabled=progress is True)

    def __call__(self, text: str, force: bool = False):
        if self.fn is not None:
            self.fn(text)
        self.bar.update(text, force=force)

    def close(self, text: str):
        if self.fn is not None:
            self.fn(text)
        self.bar.close(text)


@dataclass
class _Fit:
    names: tuple
    x: np.ndarray  # SI, of the space of this structure
    space: object
    bic: float
    rmse: np.ndarray
    ll: float


def _extended_raw(study, tables: list[dict]) -> dict:
    raw = copy.deepcopy(study.raw)
    cal = raw.setdefault("calibration", {})
    params = cal.get("parameters")
    cal["parameters"] = list(params or []) + [copy.deepcopy(t) for t in tables]
    return raw


def diagnose(
    study,
    *,
    start=None,
    progress: bool | Callable[[str], None] | None = None,
    prepared=None,
    max_jacobians: int = MAX_JACOBIANS,
    max_adopted: int = MAX_ADOPTED,
    kinds: tuple[str, ...] | None = None,
) -> Diagnosis:
    """Which extensions of the calibration's structure the data support.

    Parameters
    ----------
    study : Study
        With a ``[calibration]`` table.
    start : path, Wall or CalibrationResult, optional
        The calibrated point: a ``wallcal calibrate`` output directory (its ``calibration.json``), a wall
        file or :class:`~wallcal.wall.Wall`, or a calibration result. None: calibrate the study first.
    progress : bool or callable, optional
        True: a progress line on stderr; a callable receives each progress message; None/False: quiet.
    prepared : Prepared, optional
        The study's data prepared for batches (:func:`wallcal.simulation.prepare`).
    max_jacobians : int
        Jacobians allowed in each warm-started recalibration.
    max_adopted : int
        Most extensions adopted together.
    kinds : tuple of str, optional
        Candidate kinds to consider (default all: depth, contact_resistance,
        conductivity_temperature_coefficient, offset).

    Returns
    -------
    Diagnosis

    Raises
    ------
    StudyError, WallcalError
        The study has no ``[calibration]`` table, the start does not fit the study, ...
    """
    from ..calibration.objective import Evaluator
    from ..calibration.space import parse_space, space_of
    from ..simulation import BATCH_NEEDS, prepare
    from ..study import parse_study
    from .identifiability import sensor_sigma

    t0 = time.perf_counter()
    space = space_of(study)
    all_kinds = ("depth", "contact_resistance", "conductivity_temperature_coefficient", "offset")
    if kinds is not None:
        bad = [k for k in kinds if k not in all_kinds]
        if bad:
            raise StudyError([f"kinds: unknown extension kind(s) {', '.join(map(repr, bad))}; valid: {all_kinds}"])
    say = _Say(progress)
    prepared = prepared or prepare(study, needs=BATCH_NEEDS, purpose="the structure diagnosis")
    x0, origin = start_point(study, space, start, progress)
    x0 = np.clip(np.asarray(x0, dtype=float), space.lower, space.upper)
    evaluations = 0
    evaluators: dict[tuple, Evaluator] = {}

    def evaluator(sp):
        key = tuple(sp.names)
        if key not in evaluators:
            evaluators[key] = Evaluator(prepared, sp)
        return evaluators[key]

    def fit(tables: list[dict], names: tuple, starts: list, jacobians=None) -> _Fit:
        """Recalibrate a structure from each of ``starts`` (the study's objective with the sensor biases profiled
        out, warm-started) and score it by its AR(1) log-likelihood (biases integrated out), the best of the starts.
        ``starts``: (x_start, ll_before) pairs, ``x_start`` a dict of parameter values (the structure it extends;
        the new parameters at their base values); the score of a fit from it is ``ll_before`` plus the fit's gain
        over its starting point - a contact link or the lambda(T) path changes the discrete model slightly even at
        the base value, and that change is no evidence for the extension. ``ll_before`` None: the
        log-likelihood at the fit."""
        nonlocal evaluations
        sp = space if not tables else parse_space(study, _extended_raw(study, tables)["calibration"])
        ev = evaluator(sp)
        best = None
        for x_start, ll_before in starts:
            xs = np.array([x_start.get(n, p.base) for n, p in zip(sp.names, sp.parameters, strict=True)])
            xs = np.clip(xs, sp.lower, sp.upper)
            ll0 = ar1_profile(ev.errors(xs[None])[0], ev.mask, tau)[0] if ll_before is not None else 0.0
            # a probe depth starting on a contact's double node is also fitted from just off it (node_starts)
            for s in node_starts(sp, ev.inp.wall, ev.inp.options.contact_layers, xs):
                u, n_runs = refine(
                    lambda U: debiased_residuals(ev, sp.from_unit(U), tau, noise),
                    sp.to_unit(s),
                    jacobians or max_jacobians,
                    FTOL,
                )
                x = sp.from_unit(u)
                E = ev.errors(x[None])[0]
                evaluations += n_runs + 2
                ll, n, _, _ = ar1_profile(E, ev.mask, tau)
                if ll_before is not None:
                    ll = ll_before + (ll - ll0)
                if best is None or ll > best[0]:
                    best = (ll, n, x, E)
        ll, n, x, E = best
        rmse = np.sqrt(np.einsum("tk,tk->t", E, E) / ev.n_valid)
        return _Fit(names, x, sp, -2.0 * ll + sp.n * math.log(max(n, 2)), rmse, ll)

    # every target's constant sensor bias is part of the error model, as in the posterior: prior sd half the
    # stated accuracy (a 95 % bound), integrated out of the criterion
    ev_study = evaluator(space)
    tau = np.array(
        [
            BIAS_ACCURACY_SHARE * sensor_sigma(study, t, ev_study.y[k][ev_study.mask[k]])
            for k, t in enumerate(space.targets)
        ]
    )
    tau = np.where(np.isfinite(tau) & (tau > 0), tau, 0.0)
    E0 = ev_study.errors(x0[None])[0]
    noise = np.array([float(np.std(E0[k][ev_study.mask[k]])) for k in range(len(tau))])
    noise = np.where(np.isfinite(noise) & (noise > 0), noise, 1.0)
    say("recalibrating the study's structure (warm start)", force=True)
    # the start is the optimum of the study's objective, which counts a sensor's bias as misfit: the base structure
    # is re-polished to convergence under the criterion's error model, so that no candidate gains from that alone
    base = fit([], (), [(dict(zip(space.names, x0, strict=True)), None)], jacobians=BASE_JACOBIANS * max_jacobians)
    ev0 = evaluator(space)
    _, n_pairs, _, _ = ar1_profile(ev0.errors(base.x[None])[0], ev0.mask, tau)
    resid = residual_analysis(ev0, base.x, prepared.times)
    y = {t: ev0.y[k][ev0.mask[k]] for k, t in enumerate(space.targets)}
    exts = [e for e in propose(study, space, resid, y) if kinds is None or e.kind in kinds]
    by_name = {e.name: e for e in exts}
    fits: dict[tuple, _Fit] = {}

    def compatible(names) -> bool:
        """No layer's lambda(T) twice (a group and the shared coefficient overlap)."""
        seen: set = set()
        for n in names:
            t = by_name[n].table
            if t.get("property") != "conductivity_temperature_coefficient":
                continue
            if seen & set(t["layers"]):
                return False
            seen |= set(t["layers"])
        return True

    def score(names: tuple, warm: _Fit) -> _Fit:
        """Fit and score a structure, warm-started from ``warm`` and from every other scored structure it extends
        by one extension: a combination's optimum can lie far from one parent's (on the ``all`` campaign of
        ``bench/posterior_coverage.py``, lambda(T) + contact + depth fitted from the lambda(T) + contact optimum,
        whose contact absorbs the probe's offset, stayed in that valley or left it depending on the engine's
        round-off; see docs/identifiability.md, step 4)."""
        key = tuple(sorted(names))
        if key not in fits:
            say(f"scoring {' + '.join(names)} ({len(fits) + 1} scored, {evaluations} simulations)")
            parents = [warm] + [
                f for k, f in fits.items() if len(k) == len(key) - 1 and set(k) < set(key) and f is not warm
            ]
            fits[key] = fit(
                [by_name[n].table for n in names],
                names,
                [(dict(zip(p.space.names, p.x, strict=True)), p.ll) for p in parents],
            )
        return fits[key]

    polished: set = set()

    def polish(f: _Fit) -> _Fit:
        key = tuple(sorted(f.names))
        if key in polished:
            return fits[key]
        polished.add(key)
        say(f"polishing {' + '.join(f.names)} ({evaluations} simulations)")
        fits[key] = fit(
            [by_name[n].table for n in f.names],
            f.names,
            [(dict(zip(f.space.names, f.x, strict=True)), f.ll)],
            jacobians=BASE_JACOBIANS * max_jacobians,
        )
        return fits[key]

    own = set(space.names)

    def held(f: _Fit) -> frozenset:
        """The study's own parameters at a bound of their prior box at the fit's optimum."""
        return held_at_bounds(f.space, f.x, own)

    singles = {e.name: score((e.name,), base) for e in exts}
    current, adopted, tied, weak = forward_select(base, singles, score, polish, compatible, max_adopted, held)
    rows = []
    for key, f in fits.items():
        rows.append(
            {
                "extension": " + ".join(f.names),
                CRITERION: f.bic - base.bic,
                **{f"RMSE {t}": float(r) for t, r in zip(space.targets, f.rmse, strict=True)},
                "adopted": bool(adopted) and key == tuple(sorted(adopted)),
                "held_at_bounds": ", ".join(sorted(held(f))),
            }
        )
    cols = ["extension", CRITERION] + [f"RMSE {t}" for t in space.targets] + ["adopted", "held_at_bounds"]
    cand = pd.DataFrame(rows, columns=cols)
    if len(cand):
        cand["n"] = cand["extension"].str.count(r" \+ ")
        cand = cand.sort_values(["n", CRITERION], kind="stable").drop(columns="n").reset_index(drop=True)
    cand["adopted"] = cand["adopted"].astype(bool)
    raw = _extended_raw(study, [by_name[n].table for n in adopted]) if adopted else copy.deepcopy(study.raw)
    base_dir = Path(study.path).resolve().parent if study.path else None
    ext_study = parse_study(raw, base_dir=base_dir, source=str(study.path) if study.path else None)
    ext_study = ext_study.replace(path=study.path)
    seconds = time.perf_counter() - t0
    say.close(
        f"{len(fits)} candidates and combinations scored, {evaluations} simulations, {seconds:.1f} s; adopted: "
        + (", ".join(adopted) if adopted else "none")
    )
    notes = [f"Started from {origin}."]
    for names, cost in tied:
        notes.append(
            f"{' and '.join(names)} explain the misfit equally well (criterion within {TIE_DELTA:g}): the data cannot "
            f"choose between them, so both are adopted (criterion {cost:+.1f} against one alone) and the posterior "
            "averages over them."
        )
    for names, cost, before, after in weak:
        notes.append(
            f"{' + '.join(names)} adopted on positive evidence (criterion {cost:+.1f}; {WEAK_DELTA:g} suffices): the "
            f"structure without it holds {', '.join(sorted(before))} at a bound of the prior box (a structure its own "
            "optimum rejects); with it "
            + (", ".join(sorted(after)) if after else "none of the study's parameters")
            + " sit(s) at a bound."
        )
    if held(current):
        notes.append(
            f"At the chosen structure's optimum {', '.join(sorted(held(current)))} sit(s) at a bound of the prior "
            "box: the data want a value the bounds forbid (or do not identify it), and no candidate frees it with "
            "positive evidence."
        )
    if prepared.note:
        notes.append(prepared.note)
    return Diagnosis(
        adopted=list(adopted),
        candidates=cand,
        study=ext_study,
        residuals=resid,
        extensions=exts,
        x=dict(zip(current.space.names, map(float, current.x), strict=True)),
        base_study=study,
        rmse_base=dict(zip(space.targets, map(float, base.rmse), strict=True)),
        bic_base=base.bic,
        n_pairs=n_pairs,
        evaluations=evaluations,
        seconds=seconds,
        raw=raw,
        notes=notes,
    )

"""Structural and practical identifiability of the calibration parameters.

Two facts hold before any data are looked at:

- within a layer, density rho and specific heat c enter the heat equation only
  through the volumetric heat capacity rho*c, so only their product can be found;
- with measured temperatures imposed on both faces (Dirichlet boundaries),
  multiplying every conductivity lambda and every rho*c by one common factor k
  leaves every temperature unchanged (the equation divided by k is the same;
  wallcal's grid depends on the diffusivities only). Temperatures alone can
  therefore never fix absolute conductivities, resistances or heat capacities:
  only ratios and diffusivities. A heat-flux sensor in the objective (the flux
  scales with k) or an informative prior fixes the scale.

:func:`identifiability` finds such flat directions numerically: the Jacobian of
the scaled residuals with respect to the log-parameters is built from one
engine batch (central differences, 2n simulations), its singular values below
``rtol`` times the largest are structural null directions; those are matched
against the known directions above and named in words, the rest described by
their loadings. Residuals are divided by each target's sigma (sensor accuracy
by default) and down-weighted by the effective-sample-size factor
(1 - phi) / (1 + phi) of an AR(1) error with the lag-1 autocorrelation phi of the
residuals at the linearisation point, so that the predicted standard deviations
1 / s_k are honest about the strongly autocorrelated 5-minute residuals.
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

#: singular values below RTOL * s_max are structural null directions
RTOL = 1e-6
#: posterior/prior standard deviation ratios for the verdicts
IDENTIFIED_RATIO = 0.5
WEAK_RATIO = 0.9

_SYMBOL = {
    "conductivity": "lambda",
    "density": "rho",
    "specific_heat": "c",
    "contact_resistance": "Rc",
    "conductivity_temperature_coefficient": "fT",
    "depth": "depth",
}


def verdict(ratio: float) -> str:
    """Plain verdict from a posterior/prior standard deviation ratio."""
    if not np.isfinite(ratio) or ratio >= WEAK_RATIO:
        return "not identified"
    return "identified" if ratio < IDENTIFIED_RATIO else "weakly identified"


# ============================================================================ coordinates
def log_coordinates(space) -> np.ndarray:
    """True for parameters analysed in log coordinates (positive over the box), False for unit coordinates."""
    return np.array([p.lower > 0 for p in space.parameters])


def to_z(space, X):
    """Absolute values -> analysis coordinates (log for positive parameters, unit otherwise)."""
    X = np.asarray(X, dtype=float)
    lg = log_coordinates(space)
    return np.where(lg, np.log(np.where(lg, X, 1.0)), space.to_unit(X))


def from_z(space, Z):
    Z = np.asarray(Z, dtype=float)
    lg = log_coordinates(space)
    return np.where(lg, np.exp(np.where(lg, Z, 0.0)), space.from_unit(Z))


def prior_sd_z(space) -> np.ndarray:
    """Standard deviation of the uniform prior on the bounds, per parameter, in analysis coordinates."""
    lg = log_coordinates(space)
    lo, hi = space.lower, space.upper
    w = np.where(lg, np.log(np.where(lg, hi, 2.0) / np.where(lg, lo, 1.0)), 1.0)
    return w / np.sqrt(12.0)


# ============================================================================ known directions
def _groups(space, wall):
    """Layer groups: layers tuple -> {property: parameter index}."""
    g: dict[tuple, dict[str, int]] = {}
    for j, p in enumerate(space.parameters):
        if p.layers:
            g.setdefault(p.layers, {})[p.property] = j
    return g


def capacity_pairs(space) -> list[tuple[int, int]]:
    """The (density, specific heat) parameter pairs of one layer group, both in log coordinates: the model sees
    only their product rho*c (list of (index of rho, index of c))."""
    lg = log_coordinates(space)
    pairs = []
    for props in _groups(space, None).values():
        if "density" in props and "specific_heat" in props and lg[props["density"]] and lg[props["specific_heat"]]:
            pairs.append((props["density"], props["specific_heat"]))
    return pairs


def group_label(wall, layers) -> str:
    return ",".join(wall.layers[i].id for i in layers)


def structural_directions(space, wall, with_flux: bool = False) -> list[tuple[str, str, np.ndarray]]:
    """Known flat directions of the model in analysis coordinates.

    Returns
    -------
    list of (key, words, unit vector)
    """
    lg = log_coordinates(space)
    out = []
    groups = _groups(space, wall)
    for j_rho, j_c in capacity_pairs(space):
        d = np.zeros(space.n)
        d[j_rho], d[j_c] = 1.0, -1.0
        lab = group_label(wall, space.parameters[j_rho].layers)
        out.append(
            (
                f"rho_c[{lab}]",
                f"layer {lab}: density and specific heat act only through their product "
                f"rho*c (raising one and lowering the other changes nothing)",
                d / np.linalg.norm(d),
            )
        )
    if with_flux:
        return out
    # common scale of every lambda and every rho*c (needs every massive layer's lambda and rho*c free)
    d = np.zeros(space.n)
    covered_l, covered_c = set(), set()
    for layers, props in groups.items():
        if "conductivity" in props and lg[props["conductivity"]]:
            d[props["conductivity"]] = 1.0
            covered_l.update(layers)
        caps = [props[k] for k in ("density", "specific_heat") if k in props and lg[props[k]]]
        for j in caps:
            d[j] = 1.0 / len(caps)
        if caps:
            covered_c.update(layers)
        if "contact_resistance" in props and lg[props["contact_resistance"]]:
            d[props["contact_resistance"]] = -1.0
    massive = {i for i, layer in enumerate(wall.layers) if not layer.is_massless}
    if massive <= covered_l and massive <= covered_c:
        out.append(
            (
                "common_scale",
                "multiplying every conductivity and every volumetric heat capacity rho*c by one "
                "common factor leaves every temperature unchanged (both faces imposed): temperatures fix "
                "only conductivity ratios and diffusivities, never absolute conductivities",
                d / np.linalg.norm(d),
            )
        )
    return out


def monomial(space, v: np.ndarray, cutoff: float = 0.15, terms: int = 4) -> str:
    """A direction in log coordinates as a product of powers, e.g. ``lambda[3]^1 * (rho c)...``."""
    v = np.asarray(v, dtype=float)
    if np.max(np.abs(v)) == 0:
        return "-"
    v = v / v[np.argmax(np.abs(v))]
    out = []
    for j in np.argsort(-np.abs(v)):
        if abs(v[j]) < cutoff:
            break
        out.append(f"{space.names[j]}^{v[j]:+.2f}")
    more = int(np.sum(np.abs(v) >= cutoff)) - terms
    return " * ".join(out[:terms]) + (f" * ({more} more)" if more > 0 else "")


def combinations(space, wall, x0) -> list[tuple[str, np.ndarray]]:
    """Physically meaningful combinations as gradients in log coordinates (linearised at ``x0``).

    Per layer group: rho*c, diffusivity lambda/(rho c), thermal resistance d/lambda, ratios to the first
    group's conductivity and rho*c; and the total thermal resistance of the layers.
    """
    lg = log_coordinates(space)
    groups = [
        (layers, props)
        for layers, props in _groups(space, wall).items()
        if "conductivity" in props and lg[props["conductivity"]]
    ]
    out = []
    ref = groups[0] if groups else None
    for layers, props in groups:
        lab = group_label(wall, layers)
        caps = [props[k] for k in ("density", "specific_heat") if k in props and lg[props[k]]]
        jl = props["conductivity"]
        g = np.zeros(space.n)
        g[jl] = -1.0
        out.append((f"R[{lab}] = d/lambda", g.copy()))
        if caps:
            c = np.zeros(space.n)
            c[caps] = 1.0
            out.append((f"(rho c)[{lab}]", c.copy()))
            a = -c
            a[jl] = 1.0
            out.append((f"alpha[{lab}] = lambda/(rho c)", a))
        if ref is not None and layers != ref[0]:
            rl = np.zeros(space.n)
            rl[jl], rl[ref[1]["conductivity"]] = 1.0, -1.0
            out.append((f"lambda[{lab}]/lambda[{group_label(wall, ref[0])}]", rl))
            rcaps = [ref[1][k] for k in ("density", "specific_heat") if k in ref[1] and lg[ref[1][k]]]
            if caps and rcaps:
                rc = np.zeros(space.n)
                rc[caps] += 1.0
                rc[rcaps] -= 1.0
                out.append((f"(rho c)[{lab}]/(rho c)[{group_label(wall, ref[0])}]", rc))
    # total resistance of the layers: d log R_tot / d log lambda_i = -R_i / R_tot
    w = space.wall_at(wall, x0)
    R = np.array(
        [
            layer.thickness / layer.conductivity
            if not layer.is_massless and layer.conductivity
            else (getattr(layer, "resistance", 0.0) or 0.0)
            for layer in w.layers
        ]
    )
    if R.sum() > 0 and groups:
        g = np.zeros(space.n)
        for layers, props in groups:
            g[props["conductivity"]] = -R[list(layers)].sum() / R.sum()
        out.append(("R_total (all layers)", g))
    return out


# ============================================================================ the analysis
@dataclass
class TargetAnalysis:
    """Identifiability for one set of targets.

    Attributes
    ----------
    targets : tuple of str
    singular : DataFrame
        One row per singular value: ``s``, ``relative``, ``sd_log`` (predicted posterior sd along that
        direction, analysis coordinates), ``prior_sd``, ``verdict``, ``direction`` (in words).
    flat : DataFrame
        The structural flat directions, named.
    parameters : DataFrame
        Per parameter: null-space share, linearised sd, prior sd, verdict.
    combos : DataFrame
        Per physical combination: null-space share, sd (relative, for log coordinates), verdict.
    rank : int
        Numerical rank (number of identifiable directions).
    """

    targets: tuple
    singular: pd.DataFrame
    flat: pd.DataFrame
    parameters: pd.DataFrame
    combos: pd.DataFrame
    rank: int
    n: int
    sigma: dict
    phi: dict
    scale_gain: float | None = None

    @property
    def smallest_nonzero(self) -> float:
        s = self.singular["relative"].to_numpy()
        return float(s[self.rank - 1]) if self.rank else float("nan")


@dataclass
class IdentifiabilityResult:
    """Outcome of :func:`identifiability`: the requested targets first, then variants with heat fluxes added."""

    study: object
    space: object
    x0: np.ndarray
    at: str
    analyses: list = field(default_factory=list)
    demo: pd.DataFrame | None = None
    notes: list = field(default_factory=list)

    @property
    def main(self) -> TargetAnalysis:
        return self.analyses[0]

    def comparison(self) -> pd.DataFrame:
        rows = []
        for a in self.analyses:
            rows.append(
                {
                    "targets": "+".join(a.targets),
                    "rank": f"{a.rank} of {a.n}",
                    "smallest s/s_max": a.smallest_nonzero,
                    "flat directions": len(a.flat),
                    "common scale gain": a.scale_gain if a.scale_gain is not None else np.nan,
                    "sd of common scale %": (100.0 / a.scale_gain if a.scale_gain else np.inf)
                    if a.scale_gain is not None
                    else np.nan,
                    "identified params": int((a.parameters["verdict"] == "identified").sum()),
                }
            )
        return pd.DataFrame(rows).set_index("targets")

    def to_json(self) -> dict:
        return {
            "at": self.at,
            "x0": dict(zip(self.space.names, map(float, self.x0), strict=True)),
            "analyses": [
                {
                    "targets": list(a.targets),
                    "rank": a.rank,
                    "n": a.n,
                    "sigma": a.sigma,
                    "phi": a.phi,
                    "singular_values": a.singular["s"].tolist(),
                    "flat_directions": a.flat.reset_index().to_dict(orient="records"),
                    "common_scale_gain": a.scale_gain,
                }
                for a in self.analyses
            ],
            "notes": self.notes,
        }

    def write_into(self, d: Path) -> None:
        d = Path(d)
        (d / "identifiability.json").write_text(json.dumps(self.to_json(), indent=2, default=float))
        self.comparison().to_csv(d / "targets_comparison.csv", float_format="%.6g")
        for a in self.analyses:
            tag = "_".join(a.targets)
            a.singular.to_csv(d / f"singular_values_{tag}.csv", float_format="%.6g")
            a.parameters.to_csv(d / f"parameters_{tag}.csv", float_format="%.6g")
            a.combos.to_csv(d / f"combinations_{tag}.csv", float_format="%.6g")
        if self.demo is not None:
            self.demo.to_csv(d / "flat_direction_demo.csv", float_format="%.6g")
        from .plots import plot_singular_values

        plot_singular_values(self, d / "singular_values.png", RTOL)


def _phi(e: np.ndarray) -> float:
    den = float(np.sum(e * e))
    return float(np.clip(np.sum(e[1:] * e[:-1]) / den, 0.0, 0.999)) if den > 0 else 0.0


def sensor_sigma(study, name: str, y: np.ndarray) -> float:
    """A sensor's error standard deviation from its stated accuracy [its unit]."""
    s = study.sensor(name)
    if s.accuracy is not None:
        return float(s.accuracy)
    if s.accuracy_relative is not None:
        return float(s.accuracy_relative * np.sqrt(np.mean(y[np.isfinite(y)] ** 2)))
    return float("nan")


def identifiability(
    study,
    *,
    x0=None,
    at: str = "base case",
    targets=None,
    add_fluxes: bool = True,
    sigma: str = "accuracy",
    h: float = 1e-3,
    prepared=None,
) -> IdentifiabilityResult:
    """Local identifiability of the calibration parameters at ``x0``.

    Parameters
    ----------
    study : Study
    x0 : ndarray, optional
        Parameter values [SI]; default the base case.
    at : str
        Label of ``x0`` for the report.
    targets : list of str, optional
        Target sensors; default the study's ``calibration.targets``.
    add_fluxes : bool
        Also analyse the targets plus each heat-flux sensor the study has (and all of them).
    sigma : {"accuracy", "residual"}
        Per-target error sd: the sensor accuracy, or the RMSE of the residuals at ``x0``.
    h : float
        Central-difference step in analysis coordinates (relative step 1e-3 for log coordinates).
    prepared : Prepared, optional

    Returns
    -------
    IdentifiabilityResult
    """
    from ..calibration.objective import Evaluator
    from ..calibration.space import parse_space
    from ..simulation import BATCH_NEEDS, prepare
    from . import space_with_targets

    space = space_with_targets(study, parse_space(study), targets)
    x0 = space.base if x0 is None else np.asarray(x0, dtype=float)
    fluxes = [s.name for s in study.sensors if s.quantity == "heat_flux" and s.name not in space.targets]
    sets = [tuple(space.targets)]
    if add_fluxes and fluxes:
        sets += [tuple(space.targets) + (f,) for f in fluxes]
        if len(fluxes) > 1:
            sets.append(tuple(space.targets) + tuple(fluxes))
    union = tuple(dict.fromkeys(t for s in sets for t in s))
    prepared = prepared or prepare(study, needs=BATCH_NEEDS, purpose="the identifiability analysis")
    ev = Evaluator(prepared, dataclasses.replace(space, targets=union))
    n = space.n
    z0 = to_z(space, x0)
    # the stencil stays inside the box (one-sided at a bound): outside it a property may have no meaning (a
    # vapour resistance factor below 1) and the engine refuses it
    zlo, zhi = to_z(space, space.lower), to_z(space, space.upper)
    Zp = np.minimum(z0[None] + h * np.eye(n), zhi[None])
    Zm = np.maximum(z0[None] - h * np.eye(n), zlo[None])
    X = np.clip(from_z(space, np.vstack([Zp, Zm])), space.lower, space.upper)  # no round-off past a bound
    E = ev.errors(np.vstack([x0[None], X]))  # one batch, 2n+1 runs
    D = (E[1 : n + 1] - E[n + 1 :]) / (Zp - Zm)[np.arange(n), np.arange(n)][:, None, None]
    sig, phi, blocks = {}, {}, {}
    for k, name in enumerate(union):
        m = ev.mask[k]
        e0 = E[0, k][m]
        phi[name] = _phi(e0)
        y = ev.y[k][m]
        sig[name] = float(np.sqrt(np.mean(e0**2))) if sigma == "residual" else sensor_sigma(study, name, y)
        neff = (1 - phi[name]) / (1 + phi[name])
        blocks[name] = D[:, k, :][:, m].T * np.sqrt(neff) / sig[name]
    res = IdentifiabilityResult(study=study, space=space, x0=x0, at=at)
    if prepared.note:
        res.notes.append(prepared.note)
    for tset in sets:
        J = np.concatenate([blocks[t] for t in tset], axis=0)
        with_flux = any(study.sensor(t).quantity == "heat_flux" for t in tset)
        res.analyses.append(_analyse(space, study.wall, x0, J, tset, with_flux, sig, phi))
    # demonstration: move along the common-scale direction (exact in the model) and report the RMSEs
    known = dict((k, v) for k, _, v in structural_directions(space, study.wall, with_flux=False))
    if "common_scale" in known:
        d = known["common_scale"] / np.max(np.abs(known["common_scale"]))
        ks = [0.9, 0.95, 1.0, 1.05, 1.1]
        Z = np.array([z0 + np.log(k) * d for k in ks])
        Xd = from_z(space, Z)
        _, rmse = ev.per_target(Xd)
        df = pd.DataFrame(rmse, columns=[f"RMSE {t}" for t in union])
        df.insert(0, "factor k", ks)
        inside = np.all((Xd >= space.lower - 1e-12) & (Xd <= space.upper + 1e-12), axis=1)
        df["inside bounds"] = inside
        res.demo = df.set_index("factor k")
    return res


def _analyse(space, wall, x0, J, tset, with_flux, sig, phi) -> TargetAnalysis:
    n = space.n
    _, s, Vt = np.linalg.svd(J, full_matrices=False)
    smax = s[0] if s[0] > 0 else 1.0
    null = s < RTOL * smax
    rank = int((~null).sum())
    N = Vt[null].T  # n x m
    Vr, sr = Vt[~null].T, s[~null]
    psd = prior_sd_z(space)
    # linearised posterior covariance with the prior as a Gaussian of the same sd; used only for quantities
    # orthogonal to the structural null space (along it the box prior, not the data, would decide)
    cov = np.linalg.inv(J.T @ J + np.diag(1.0 / psd**2))
    del Vr, sr

    def prior_sd_dir(v):
        return float(np.sqrt(np.sum((v * psd) ** 2)))

    # name the null space
    known = structural_directions(space, wall, with_flux=with_flux)
    flat_rows = []
    matched = []
    for key, words, d in known:
        share = float(np.linalg.norm(N.T @ d)) if N.size else 0.0
        if share > 0.99:
            flat_rows.append({"direction": key, "in words": words, "share in null space": share})
            matched.append(d)
    if N.size:
        rest = N - (np.array(matched).T @ (np.array(matched) @ N) if matched else 0.0)
        u, sv, _ = np.linalg.svd(rest, full_matrices=False)
        for i in np.flatnonzero(sv > 0.5):
            flat_rows.append(
                {
                    "direction": f"other_{i + 1}",
                    "in words": "unnamed flat direction: " + monomial(space, u[:, i]) + " = const",
                    "share in null space": float(sv[i]),
                }
            )
    flat = pd.DataFrame(flat_rows, columns=["direction", "in words", "share in null space"]).set_index("direction")
    words = {tuple(np.round(d, 6)): key for key, _, d in known}
    srows = []
    for i in range(len(s)):
        v = Vt[i]
        if null[i]:
            desc = "flat (structural)"
            for key, _, d in known:
                if abs(v @ d) > 0.9:
                    desc = f"flat: {key}"
        else:
            desc = monomial(space, v)
        sd = 1.0 / s[i] if s[i] > RTOL * smax else np.inf
        pr = prior_sd_dir(v)
        srows.append(
            {
                "s": s[i],
                "relative": s[i] / smax,
                "sd_log": sd,
                "prior_sd": pr,
                "verdict": "structurally flat" if null[i] else verdict(sd / pr),
                "direction": desc,
            }
        )
    singular = pd.DataFrame(srows)
    singular.index = pd.RangeIndex(1, len(s) + 1, name="k")
    del words
    prow = []
    for j, p in enumerate(space.parameters):
        share = float(np.linalg.norm(N[j])) if N.size else 0.0
        sd = float(np.sqrt(max(cov[j, j], 0.0)))
        if share > 0.05:
            v, sd = "not identifiable (structural)", np.inf
        else:
            v = verdict(sd / psd[j])
        prow.append(
            {"parameter": p.name, "value": x0[j], "null share": share, "sd_log": sd, "prior_sd": psd[j], "verdict": v}
        )
    params = pd.DataFrame(prow).set_index("parameter")
    crow = []
    for name, g in combinations(space, wall, x0):
        gn = g / np.linalg.norm(g)
        share = float(np.linalg.norm(N.T @ gn)) if N.size else 0.0
        sd = float(np.sqrt(max(g @ cov @ g, 0.0)))
        pr = prior_sd_dir(g)
        if share > 0.05:
            v, sd = "not identifiable (structural)", np.inf
        else:
            v = verdict(sd / pr)
        crow.append({"combination": name, "null share": share, "sd %": 100 * sd, "prior sd %": 100 * pr, "verdict": v})
    combos = pd.DataFrame(crow, columns=["combination", "null share", "sd %", "prior sd %", "verdict"])
    combos = combos.set_index("combination")  # a space may have no combination (one hygric property)
    # how strongly the data pin the common scale (sensitivity of the scaled residuals to log k)
    scale = [d for key, _, d in structural_directions(space, wall, with_flux=False) if key == "common_scale"]
    gain = None
    if scale:
        d = scale[0] / np.max(np.abs(scale[0]))
        gain = float(np.linalg.norm(J @ d))
        gain = gain if gain > RTOL * smax else 0.0
    return TargetAnalysis(
        targets=tuple(tset),
        singular=singular,
        flat=flat,
        parameters=params,
        combos=combos,
        rank=rank,
        n=n,
        sigma={t: sig[t] for t in tset},
        phi={t: phi[t] for t in tset},
        scale_gain=gain,
    )

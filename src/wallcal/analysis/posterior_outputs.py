"""The posterior's outputs (:mod:`wallcal.analysis.posterior`): :class:`PosteriorResult`, its report and its
output folder (``wallcal posterior``; format version in :mod:`wallcal.outputs`), written by
:meth:`PosteriorResult.write_into` and read back by :func:`load_samples`.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

nan = float("nan")

#: effective samples the default chain runs for: the Monte-Carlo sd of a 2.5 % tail probability estimated from
#: n independent draws is sqrt(0.025 x 0.975 / n), 0.7 % at 500
DEFAULT_EFFECTIVE_SAMPLES = 500


# ============================================================================ result
@dataclass
class PosteriorResult:
    """Outcome of :func:`posterior`.

    Attributes
    ----------
    chain : ndarray, shape (steps, walkers, n)
        Unit coordinates (the split of each rho*c pair drawn from its conditional, see :class:`LogCoordinates`).
    log_prob : ndarray, shape (steps, walkers)
        Log posterior density of each chain entry, up to a constant, in the sampling coordinates
        (:class:`LogCoordinates`).
    samples : ndarray, shape (m, n)
        Post-burn-in, thinned samples [SI].
    summary : DataFrame
        Per parameter: mean, sd, q2.5, q97.5 [SI], bounds, sd ratio to the prior, verdict, truth, inside.
    correlation : DataFrame
    combinations : DataFrame
        Derived quantities (R = d/lambda, rho*c, diffusivity, ratios, R_total) with the same columns.
    nonunique : DataFrame
        Distinct posterior parameter sets whose RMSEs all sit within the sensor accuracy.
    tempering : dict
        ``kind`` ("sandwich" or "none"), ``weight`` w of the tempered likelihood L^w and, for "sandwich", the
        measured ``inflation``, ``directions``, ``bandwidth`` (see :func:`sandwich_weight`).
    checks : DataFrame
        Posterior predictive residuals per target (:func:`residual_checks`).
    structure : dict
        The self-checks' verdict (:func:`structure_verdict`): ``rejected``, ``reasons``, ``statement``.
    tau : ndarray
        Integrated autocorrelation time per parameter over the chain after burn-in [steps].
    acceptance : float
    effective_samples : float
        Walkers x steps after burn-in / the largest autocorrelation time.
    adequate : bool
        Whether the chain is adequate (:func:`chain_diagnostics`): ``target_effective_samples`` effective samples,
        long enough for its autocorrelation time and that time no longer growing with the chain.
    """

    study: object
    space: object
    chain: np.ndarray
    log_prob: np.ndarray
    samples: np.ndarray
    summary: pd.DataFrame
    correlation: pd.DataFrame
    combinations: pd.DataFrame
    nonunique: pd.DataFrame
    tau: np.ndarray
    acceptance: float
    burn: int
    thin: int
    sigma: dict
    phi: dict
    sigma_kind: str
    evaluations: int  # walkers x steps: the chain's proposals
    seconds: float
    status: str = "complete"
    warnings: list = field(default_factory=list)
    #: the posterior predictive band (:class:`~wallcal.analysis.posterior_predictive.Predictive`) or None
    predictive: object = None
    #: whether ``predictive`` is of the study's validation window (written as validation.csv)
    predicted_validation: bool = False
    truth: np.ndarray | None = None
    tempering: dict = field(default_factory=lambda: {"kind": "none", "weight": 1.0})
    checks: pd.DataFrame = field(default_factory=pd.DataFrame)
    structure: dict = field(default_factory=lambda: {"rejected": False, "reasons": [], "statement": ""})
    effective_samples: float = nan
    adequate: bool = False
    target_effective_samples: float = DEFAULT_EFFECTIVE_SAMPLES
    simulations: int | None = None

    def coverage(self) -> tuple[int, int]:
        """(identified parameters whose 95 % interval holds the truth, identified parameters with a truth)."""
        s = self.summary
        sel = s["verdict"].str.startswith("identified") & s["truth"].notna()
        return int(s.loc[sel, "inside 95%"].sum()), int(sel.sum())

    def combination_coverage(self) -> dict:
        """Coverage of the identifiable combinations (verdict identified or weakly identified) with a truth:
        ``n`` and the numbers inside the 50 % and 95 % intervals (``inside 50%``, ``inside 95%``)."""
        c = self.combinations
        if "truth" not in c:
            return {"n": 0, "inside 50%": 0, "inside 95%": 0}
        sel = ~c["verdict"].str.startswith("not") & c["truth"].notna()
        return {
            "n": int(sel.sum()),
            "inside 50%": int(c.loc[sel, "inside 50%"].sum()),
            "inside 95%": int(c.loc[sel, "inside 95%"].sum()),
        }

    def _pairs_line(self) -> str:
        from .identifiability import capacity_pairs

        k = len(capacity_pairs(self.space))
        if not k:
            return ""
        return (
            f"; {self.space.n - k} sampled coordinates: the density and specific heat of {k} layer "
            f"group{'s' if k > 1 else ''} as their product rho*c (the split drawn from the prior)"
        )

    def report(self) -> str:
        lines = [
            f"posterior ({self.status}): {self.chain.shape[1]} walkers x {self.chain.shape[0]} steps = "
            f"{self.evaluations} proposals{self._simulated()} in {self.seconds:.1f} s; burn-in {self.burn}, "
            f"thin {self.thin}, "
            f"{len(self.samples)} samples{self._pairs_line()}",
            f"error model AR(1) per target + constant sensor bias integrated out, sigma {self.sigma_kind}: "
            + ", ".join(
                f"{k} sigma {self.sigma[k]:.3g} phi {self.phi[k]:.3f} (n_eff factor "
                f"{(1 - self.phi[k]) / (1 + self.phi[k]):.3f})"
                for k in self.sigma
            ),
            f"acceptance fraction {self.acceptance:.2f}; integrated autocorrelation time "
            + (
                f"{np.nanmin(self.tau):.0f}..{np.nanmax(self.tau):.0f} steps"
                if np.isfinite(self.tau).any()
                else "not estimated (chain too short)"
            )
            + f"; {self.effective_samples:.0f} effective samples (target {self.target_effective_samples:.0f}): chain "
            + ("adequate" if self.adequate else "NOT adequate"),
            self.tempering_line(),
        ]
        lines += [f"warning: {w}" for w in self.warnings]
        if len(self.checks):
            lines.append(
                "posterior predictive residuals: "
                + "; ".join(
                    f"{t} RMSE {r['RMSE']:.3g} ({r['RMSE / accuracy']:.2f} x accuracy), model error "
                    f"{r['model error']:.3g}, white noise {r['white noise']:.3g}: {r['verdict']}"
                    for t, r in self.checks.iterrows()
                )
            )
        if self.structure.get("statement"):
            lines.append(("STRUCTURE REJECTED. " if self.structure["rejected"] else "") + self.structure["statement"])
        if self.predictive is not None:
            w = self.predictive.window
            lines.append(
                f"posterior predictive {w[0]} .. {w[1]}"
                + (" (the held-out window)" if self.predicted_validation else "")
                + f", {self.predictive.draws} draws: "
                + "; ".join(
                    f"{r['sensor']} RMSE {r['rmse']:.3g}, 95 % band covers {100 * r['coverage_95']:.0f} % "
                    f"(width {r['band_width_95']:.3g})"
                    for _, r in self.predictive.table.iterrows()
                )
            )
        if self.truth is not None:
            k, n = self.coverage()
            lines.append(f"truth (reference wall) inside the 95 % interval for {k} of {n} identified parameters")
            c = self.combination_coverage()
            lines.append(
                f"truth inside the 95 % interval for {c['inside 95%']} of {c['n']} identifiable combinations, "
                f"inside the 50 % interval for {c['inside 50%']}"
            )
        return "\n".join(lines)

    def _simulated(self) -> str:
        if self.simulations is None:
            return ""
        return f" ({self.simulations} simulated; the others fell outside the prior box and cost no simulation)"

    def tempering_line(self) -> str:
        t = self.tempering
        if t.get("kind") != "sandwich":
            return "likelihood not tempered (w = 1)"
        return (
            f"likelihood tempered by the sandwich rule: the score of the residuals varies {t['inflation']:.2f} x what "
            f"the AR(1) model expects (Newey-West over {t['window_s'] / 3600:.0f} h, {t['directions']} identifiable "
            f"directions), w = {t['weight']:.3f}: intervals {1 / np.sqrt(t['weight']):.2f} x as wide as untempered"
        )

    def to_json(self) -> dict:
        return {
            "status": self.status,
            "evaluations": self.evaluations,
            "simulations": self.simulations,
            "seconds": self.seconds,
            "walkers": self.chain.shape[1],
            "steps": self.chain.shape[0],
            "burn": self.burn,
            "thin": self.thin,
            "acceptance_fraction": self.acceptance,
            "tau": dict(zip(self.space.names, self.tau.tolist(), strict=True)),
            "effective_samples": self.effective_samples,
            "target_effective_samples": self.target_effective_samples,
            "adequate": self.adequate,
            "sigma": self.sigma,
            "phi": self.phi,
            "sigma_kind": self.sigma_kind,
            "warnings": self.warnings,
            "coverage": list(self.coverage()) if self.truth is not None else None,
            "combination_coverage": self.combination_coverage() if self.truth is not None else None,
            "tempering": self.tempering,
            "structure": self.structure,
            "checks": self.checks.reset_index().to_dict(orient="records"),
            "summary": self.summary.reset_index().to_dict(orient="records"),
            "predictive": None
            if self.predictive is None
            else {
                "window": [str(t) for t in self.predictive.window],
                "validation_window": self.predicted_validation,
                "draws": self.predictive.draws,
                "table": self.predictive.table.to_dict(orient="records"),
            },
        }

    def write_into(self, d: Path) -> None:
        d = Path(d)
        self.summary.to_csv(d / "posterior_summary.csv", float_format="%.6g")
        self.correlation.to_csv(d / "posterior_correlation.csv", float_format="%.4f")
        self.combinations.to_csv(d / "posterior_combinations.csv", float_format="%.6g")
        self.nonunique.to_csv(d / "non_uniqueness.csv", float_format="%.6g")
        self.checks.to_csv(d / "posterior_checks.csv", float_format="%.6g")
        if self.predictive is not None:
            self.predictive.bands.to_csv(d / "predictive.csv", index=False, float_format="%.6g")
            name = "validation.csv" if self.predicted_validation else "predictive_summary.csv"
            self.predictive.table.to_csv(d / name, index=False, float_format="%.6g")
        write_chain(d, self.chain, self.log_prob, self.space)
        (d / "posterior.json").write_text(json.dumps(self.to_json(), indent=2, default=float))
        from .plots import plot_corner, plot_trace

        comb = self.combination_samples()
        keys = [k for k in comb if k.startswith(("R[", "(rho c)["))]
        truth = self.combination_truth()
        plot_corner(
            np.column_stack([comb[k] for k in keys]),
            keys,
            d / "corner.png",
            truth=None if truth is None else np.array([truth[k] for k in keys]),
        )
        plot_corner(self.samples, self.space.names, d / "corner_parameters.png", truth=self.truth)
        plot_trace(self.chain, self.space.names, d / "trace.png")

    # derived quantities
    def combination_samples(self, X=None) -> dict:
        return derived(self.space, self.study.wall, self.samples if X is None else X)

    def combination_truth(self):
        return (
            None
            if self.truth is None
            else {k: float(v[0]) for k, v in self.combination_samples(self.truth[None]).items()}
        )


def derived(space, wall, X) -> dict:
    """Physically meaningful combinations of parameter samples ``X`` [SI]: R = d/lambda [m2K/W], rho*c [J/(m3K)],
    diffusivity lambda/(rho c) [m2/s], conductivity ratios to the first group [-], R_total [m2K/W]."""
    X = np.atleast_2d(X)
    props, _ = space.properties(wall, X)
    lam, C = props.conductivity, props.volumetric_heat_capacity
    groups: dict[tuple, set] = {}
    for p in space.parameters:
        if p.layers:
            groups.setdefault(p.layers, set()).add(p.property)
    out = {}
    first = None
    for layers, ps in groups.items():
        lab = ",".join(wall.layers[i].id for i in layers)
        li = list(layers)
        d = np.array([wall.layers[i].thickness for i in li])
        if "conductivity" in ps:
            out[f"R[{lab}]"] = (d[None] / lam[:, li]).sum(axis=1)
        if ps & {"density", "specific_heat"}:
            out[f"(rho c)[{lab}]"] = C[:, li[0]]
        if "conductivity" in ps and ps & {"density", "specific_heat"}:
            out[f"alpha[{lab}]"] = lam[:, li[0]] / C[:, li[0]]
        if "conductivity" in ps:
            if first is None:
                first = (lab, li[0])
            else:
                out[f"lambda[{lab}]/lambda[{first[0]}]"] = lam[:, li[0]] / lam[:, first[1]]
    thick = np.array([layer.thickness for layer in wall.layers])
    massive = np.array([not layer.is_massless for layer in wall.layers])
    with np.errstate(divide="ignore"):
        out["R_total"] = (np.where(massive[None], thick[None] / lam, 0.0)).sum(axis=1)
    return out


# ============================================================================ the output folder, read back
#: The command whose output :meth:`PosteriorResult.write_into` writes (its format version: :mod:`wallcal.outputs`).
COMMAND = "posterior"


@dataclass
class Samples:
    """Posterior draws applied to a base wall: ``walls`` (one per draw), ``values`` (draw x parameter, SI),
    ``names`` (parameter names as the posterior wrote them), ``point`` (the posterior-median wall)."""

    walls: list
    values: np.ndarray
    names: list[str]
    point: object
    source: str


def apply_named(wall, names: list[str], x: np.ndarray):
    """Apply parameter values named like the calibration space's ('conductivity[5,8]'); probe depths skip."""
    for name, v in zip(names, x, strict=True):
        prop, _, ids = name.partition("[")
        if prop == "depth":
            continue
        for lid in ids.rstrip("]").split(","):
            wall = wall.replace_layer(lid, **{prop: float(v)})
    return wall


def write_chain(d: Path, chain: np.ndarray, log_prob: np.ndarray, space) -> None:
    """``chain.npz``: the chain in unit coordinates of ``space``'s box, shape (steps, walkers, parameters), its log
    posterior (steps, walkers), the parameter names and the box."""
    np.savez_compressed(
        Path(d) / "chain.npz",
        chain=chain,
        log_prob=log_prob,
        names=np.array(space.names),
        lower=space.lower,
        upper=space.upper,
    )


def write_samples(d: Path, space, chain: np.ndarray, burn: int = 0, thin: int = 1) -> Path:
    """A posterior output holding what :func:`load_samples` reads (``chain.npz``, ``posterior.json`` with the
    burn-in and thinning, the manifest of this format): samples made elsewhere (another sampler, a test, a
    benchmark) for ``wallcal retrofit --from`` and ``wallcal building --from``. ``chain`` in unit coordinates of
    ``space``'s box, shape (steps, walkers, parameters). Returns ``d`` (created)."""
    from ..outputs import format_entries

    d = Path(d)
    d.mkdir(parents=True, exist_ok=True)
    write_chain(d, chain, np.zeros(chain.shape[:2]), space)
    (d / "posterior.json").write_text(json.dumps({"burn": int(burn), "thin": int(thin)}))
    (d / "manifest.json").write_text(json.dumps({"command": COMMAND, **format_entries(COMMAND)}))
    return d


def load_samples(from_dir: Path, wall, n_max: int) -> Samples:
    """Posterior samples from a ``wallcal posterior`` output (``chain.npz``, ``posterior.json``) of the format
    this wallcal writes: the chain after its burn-in, thinned as the posterior did, at most ``n_max`` draws
    evenly spread, applied to ``wall``.

    Raises
    ------
    OutputFormatError
        A folder of another format version, or without one (:func:`wallcal.outputs.check_format`).
    DataError
        Unreadable files, a chain of the wrong shape, no draw after the burn-in.
    StudyError
        A parameter naming a layer ``wall`` does not have.
    """
    from ..errors import DataError, StudyError
    from ..outputs import check_format

    from_dir = Path(from_dir)
    check_format(from_dir, COMMAND)
    chain_f, info_f = from_dir / "chain.npz", from_dir / "posterior.json"
    try:
        with np.load(chain_f, allow_pickle=False) as z:
            chain, names, lower, upper = z["chain"], [str(s) for s in z["names"]], z["lower"], z["upper"]
        info = json.loads(info_f.read_text())
        burn, thin = int(info.get("burn", 0)), max(1, int(info.get("thin", 1)))
    except (OSError, KeyError, ValueError) as exc:
        raise DataError(f"{from_dir}: not a readable posterior output (chain.npz, posterior.json): {exc}") from exc
    if chain.ndim != 3 or chain.shape[2] != len(names):
        raise DataError(f"{chain_f}: chain has shape {chain.shape}, expected (steps, walkers, {len(names)})")
    flat = chain[burn::thin].reshape(-1, chain.shape[2])
    if len(flat) == 0:
        raise DataError(f"{from_dir}: no posterior draw after the burn-in")
    X = lower + flat * (upper - lower)
    ids = {layer.id for layer in wall.layers}
    for name in names:
        prop, _, lids = name.partition("[")
        if prop != "depth":
            bad = [i for i in lids.rstrip("]").split(",") if i not in ids]
            if bad:
                raise StudyError(
                    [f"{chain_f}: parameter {name!r} names layer(s) {', '.join(bad)} that the wall does not have"]
                )
    pick = np.unique(np.linspace(0, len(X) - 1, min(n_max, len(X))).round().astype(int))
    Xs = X[pick]
    walls = [apply_named(wall, names, x) for x in Xs]
    point = apply_named(wall, names, np.median(X, axis=0))
    return Samples(walls=walls, values=Xs, names=names, point=point, source=str(from_dir))

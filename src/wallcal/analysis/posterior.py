"""Bayesian posterior of the calibration parameters (emcee), with an AR(1) error model.

Model: for each target k the errors e_t = s_t(theta) - y_t follow a stationary AR(1)
process e_t = phi_k e_{t-1} + eta_t with marginal standard deviation sigma_k. The 5-minute
residuals of a wall model are strongly autocorrelated (phi ~ 0.9-0.99): treating them as
independent would count every sample as new information and give intervals 5-20 times
too narrow. The exact AR(1) log-likelihood (gaps restart the process) is

    log L = sum_k [ -1/2 sum_pairs (e_t - phi e_{t-1})^2 / (sigma^2 (1 - phi^2)) - 1/2 sum_starts e_t^2 / sigma^2 ]

(constants dropped). phi_k and sigma_k are fixed before sampling: phi_k is the lag-1
autocorrelation of the residuals at the starting point (the calibrated optimum);
sigma_k is either the RMSE of those residuals (``sigma="estimated"``, default: it
includes model error) or the sensor's stated accuracy (``sigma="accuracy"``).

Priors are uniform on the calibration bounds; sampling happens in the unit box
(the prior is flat there). emcee runs with ``vectorize=True``: each half-step of the
ensemble is one engine batch. The chain is checkpointed atomically (``.npz``) every
few seconds and on Ctrl-C, so an interruption loses nothing and ``resume=True``
continues.
"""

from __future__ import annotations

import json
import os
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from .identifiability import verdict

DEFAULT_STEPS = 1500
nan = float("nan")


# ============================================================================ likelihood
class AR1Likelihood:
    """Vectorised AR(1) Gaussian log-likelihood over the unit box.

    Parameters
    ----------
    ev : Evaluator
    sigma, phi : ndarray, shape (n_targets,)
        Marginal error sd [target unit] and lag-1 autocorrelation [-].
    """

    def __init__(self, ev, sigma, phi, bias_sd=None):
        self.ev = ev
        self.sigma = np.asarray(sigma, dtype=float)
        self.phi = np.asarray(phi, dtype=float)
        self.tau = np.zeros_like(self.sigma) if bias_sd is None else np.asarray(bias_sd, dtype=float)
        m = ev.mask
        self.pairs = m[:, 1:] & m[:, :-1]
        self.starts = m & ~np.concatenate([np.zeros((m.shape[0], 1), bool), m[:, :-1]], axis=1)
        self.q11 = self.quad(np.ones((1,) + m.shape), np.ones((1,) + m.shape))[0]
        self.calls = 0

    def quad(self, A, B):
        """AR(1) quadratic form a' Sigma^-1 b per candidate and target (gaps restart the process)."""
        phi = self.phi[None, :, None]
        ia = A[:, :, 1:] - phi * A[:, :, :-1]
        ib = B[:, :, 1:] - phi * B[:, :, :-1]
        a = np.einsum("ctk,tk->ct", ia * ib, self.pairs.astype(float)) / (1 - self.phi**2)[None]
        b = np.einsum("ctk,tk->ct", A * B, self.starts.astype(float))
        return (a + b) / (self.sigma**2)[None]

    def loglike_errors(self, E):
        """Log-likelihood per candidate; a constant sensor bias N(0, tau^2) per target is integrated out
        analytically (Sherman-Morrison on Sigma + tau^2 1 1')."""
        qee = self.quad(E, E)
        if np.any(self.tau > 0):
            q1e = self.quad(np.ones_like(E[:1]), E)
            t2 = (self.tau**2)[None]
            qee = qee - t2 * q1e**2 / (1.0 + t2 * self.q11[None])
        return -0.5 * qee.sum(axis=1)

    def __call__(self, U):
        U = np.atleast_2d(U)
        out = np.full(len(U), -np.inf)
        inside = np.all((U >= 0) & (U <= 1), axis=1)
        if inside.any():
            E = self.ev.errors(self.ev.space.from_unit(U[inside]))
            ll = self.loglike_errors(E)
            out[inside] = np.where(np.isfinite(ll), ll, -np.inf)
        self.calls += 1
        return out


def lag1(e: np.ndarray, mask: np.ndarray) -> float:
    """Lag-1 autocorrelation of an error series about zero (valid consecutive pairs only)."""
    p = mask[1:] & mask[:-1]
    den = float(np.sum(np.where(mask, e, 0.0) ** 2))
    return float(np.clip(np.sum(np.where(p, e[1:] * e[:-1], 0.0)) / den, 0.0, 0.995)) if den > 0 else 0.0


# ============================================================================ result
@dataclass
class PosteriorResult:
    """Outcome of :func:`posterior`.

    Attributes
    ----------
    chain : ndarray, shape (steps, walkers, n)
        Unit coordinates.
    samples : ndarray, shape (m, n)
        Post-burn-in, thinned samples [SI].
    summary : DataFrame
        Per parameter: mean, sd, q2.5, q97.5 [SI], bounds, sd ratio to the prior, verdict, truth, inside.
    correlation : DataFrame
    combinations : DataFrame
        Derived quantities (R = d/lambda, rho*c, diffusivity, ratios, R_total) with the same columns.
    nonunique : DataFrame
        Distinct posterior parameter sets whose RMSEs all sit within the sensor accuracy.
    tau : ndarray
        Integrated autocorrelation time per parameter [steps].
    acceptance : float
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
    evaluations: int
    seconds: float
    status: str = "complete"
    warnings: list = field(default_factory=list)
    truth: np.ndarray | None = None

    def coverage(self) -> tuple[int, int]:
        """(identified parameters whose 95 % interval holds the truth, identified parameters with a truth)."""
        s = self.summary
        sel = s["verdict"].str.startswith("identified") & s["truth"].notna()
        return int(s.loc[sel, "inside 95%"].sum()), int(sel.sum())

    def report(self) -> str:
        lines = [
            f"posterior ({self.status}): {self.chain.shape[1]} walkers x {self.chain.shape[0]} steps = "
            f"{self.evaluations} simulations in {self.seconds:.1f} s; burn-in {self.burn}, thin {self.thin}, "
            f"{len(self.samples)} samples",
            f"error model AR(1) per target + constant sensor bias integrated out, sigma {self.sigma_kind}: "
            + ", ".join(
                f"{k} sigma {self.sigma[k]:.3g} phi {self.phi[k]:.3f} (n_eff factor "
                f"{(1 - self.phi[k]) / (1 + self.phi[k]):.3f})"
                for k in self.sigma
            ),
            f"acceptance fraction {self.acceptance:.2f}; integrated autocorrelation time "
            f"{np.nanmin(self.tau):.0f}..{np.nanmax(self.tau):.0f} steps",
        ]
        lines += [f"warning: {w}" for w in self.warnings]
        if self.truth is not None:
            k, n = self.coverage()
            lines.append(f"truth (reference wall) inside the 95 % interval for {k} of {n} identified parameters")
        return "\n".join(lines)

    def to_json(self) -> dict:
        return {
            "status": self.status,
            "evaluations": self.evaluations,
            "seconds": self.seconds,
            "walkers": self.chain.shape[1],
            "steps": self.chain.shape[0],
            "burn": self.burn,
            "thin": self.thin,
            "acceptance_fraction": self.acceptance,
            "tau": dict(zip(self.space.names, self.tau.tolist(), strict=True)),
            "sigma": self.sigma,
            "phi": self.phi,
            "sigma_kind": self.sigma_kind,
            "warnings": self.warnings,
            "coverage": list(self.coverage()) if self.truth is not None else None,
            "summary": self.summary.reset_index().to_dict(orient="records"),
        }

    def write_into(self, d: Path) -> None:
        d = Path(d)
        self.summary.to_csv(d / "posterior_summary.csv", float_format="%.6g")
        self.correlation.to_csv(d / "posterior_correlation.csv", float_format="%.4f")
        self.combinations.to_csv(d / "posterior_combinations.csv", float_format="%.6g")
        self.nonunique.to_csv(d / "non_uniqueness.csv", float_format="%.6g")
        np.savez_compressed(
            d / "chain.npz",
            chain=self.chain,
            log_prob=self.log_prob,
            names=np.array(self.space.names),
            lower=self.space.lower,
            upper=self.space.upper,
        )
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


def _stats(samples: np.ndarray, prior: np.ndarray, truth=None) -> dict:
    lo, hi = np.percentile(samples, [2.5, 97.5])
    sd = float(np.std(samples))
    psd = float(np.std(prior))
    row = {
        "mean": float(np.mean(samples)),
        "sd": sd,
        "q2.5": lo,
        "q97.5": hi,
        "sd/prior sd": sd / psd,
        "verdict": verdict(sd / psd),
    }
    if truth is not None:
        row["truth"] = truth
        row["inside 95%"] = bool(lo <= truth <= hi) if np.isfinite(truth) else False
    return row


# ============================================================================ the run
def initial_walkers(study, space, x_start, nw, spread, rng):
    """Walkers around ``x_start`` (unit coordinates), spread along the known structural flat directions.

    Along a flat direction only the prior box limits the posterior; walkers started in a tiny ball would
    need thousands of steps to diffuse along it, so they start spread over +-15 % of it.
    """
    from .identifiability import log_coordinates, structural_directions

    with_flux = any(study.sensor(t).quantity == "heat_flux" for t in space.targets)
    dirs = [d for _, _, d in structural_directions(space, study.wall, with_flux=with_flux)]
    z0 = np.where(log_coordinates(space), np.log(np.abs(x_start) + 1e-300), 0.0)
    Z = np.repeat(z0[None], nw, axis=0)
    for d in dirs:
        d = d / np.max(np.abs(d))
        Z += rng.uniform(-0.15, 0.15, size=(nw, 1)) * d[None]
    X = np.where(log_coordinates(space)[None], np.exp(Z), x_start[None])
    U = space.to_unit(X) + spread * rng.standard_normal((nw, space.n))
    return np.clip(U, 1e-3, 1 - 1e-3)


def checkpoint_path(out_dir) -> Path | None:
    if out_dir is None:
        return None
    out_dir = Path(out_dir).resolve()
    out_dir.parent.mkdir(parents=True, exist_ok=True)
    return out_dir.parent / f".{out_dir.name}.posterior-checkpoint.npz"


def _save(path, chain, logp, meta):
    if path is None:
        return
    tmp = path.with_name(path.name + ".tmp.npz")
    np.savez(tmp, chain=chain, log_prob=logp, meta=json.dumps(meta))
    os.replace(tmp, path)


def posterior(
    study,
    *,
    x_start=None,
    targets=None,
    sigma: str = "estimated",
    walkers: int | None = None,
    steps: int = DEFAULT_STEPS,
    seed: int = 1,
    init_spread: float = 0.02,
    out_dir=None,
    resume: bool = False,
    progress: bool = True,
    prepared=None,
    max_evaluations: int | None = None,
    nonunique_candidates: int = 256,
    bias: bool = True,
) -> PosteriorResult:
    """Sample the posterior of the calibration parameters.

    Parameters
    ----------
    study : Study
    x_start : ndarray, optional
        Starting point [SI] (the calibrated optimum); default the base case.
    targets : list of str, optional
        Default the study's ``calibration.targets``.
    sigma : {"estimated", "accuracy"}
        Error sd per target: the residual RMSE at ``x_start``, or the sensor's stated accuracy.
    walkers : int, optional
        Default 4 n (even).
    steps : int
        Ensemble steps (simulations = walkers x steps).
    seed : int
    init_spread : float
        Initial ball around ``x_start`` in unit coordinates.
    out_dir : path, optional
        The checkpoint ``.<name>.posterior-checkpoint.npz`` is kept next to it.
    resume : bool
        Continue from that checkpoint.
    max_evaluations : int, optional
        Cap on simulations (steps are reduced to fit).
    bias : bool
        Integrate out a constant bias per sensor with sd = half the stated accuracy (accuracy read as a 95 %
        bound); without it a thermocouple's offset is fitted by the wall properties and the intervals miss
        the truth.
    nonunique_candidates : int
        Posterior samples re-simulated to show distinct sets with RMSEs within the sensor accuracy.

    Returns
    -------
    PosteriorResult
    """
    from ..calibration.algorithms import Progress
    from ..calibration.objective import Evaluator
    from ..calibration.space import parse_space
    from ..errors import WallcalError, require
    from ..simulation import BATCH_NEEDS, prepare
    from . import reference_values, space_with_targets
    from .identifiability import sensor_sigma

    require("emcee", "analysis")  # a clear error when the analysis extra is missing
    space = space_with_targets(study, parse_space(study), targets)
    x_start = space.base if x_start is None else np.asarray(x_start, dtype=float)
    prepared = prepared or prepare(study, needs=BATCH_NEEDS, purpose="the posterior sampling")
    ev = Evaluator(prepared, space)
    n = space.n
    nw = int(walkers or max(4 * n, 16))
    nw += nw % 2
    if max_evaluations:
        steps = min(steps, max(1, int(max_evaluations) // nw))
    e0 = ev.errors(x_start[None])[0]
    sig, ph, tau = {}, {}, {}
    for k, t in enumerate(space.targets):
        m = ev.mask[k]
        ek = np.where(m, e0[k] - e0[k][m].mean(), 0.0)  # the constant part is the sensor bias, modelled apart
        ph[t] = lag1(ek, m)
        sig[t] = float(np.sqrt(np.mean(ek[m] ** 2))) if sigma == "estimated" else sensor_sigma(study, t, ev.y[k][m])
        tau[t] = (0.5 * sensor_sigma(study, t, ev.y[k][m])) if bias else 0.0
    like = AR1Likelihood(
        ev, [sig[t] for t in space.targets], [ph[t] for t in space.targets], [tau[t] for t in space.targets]
    )
    ckpt = checkpoint_path(out_dir)
    meta = {
        "names": space.names,
        "targets": list(space.targets),
        "sigma": sig,
        "phi": ph,
        "walkers": nw,
        "study_sha256": study.sha256,
    }
    rng = np.random.default_rng(seed)
    prev_chain = np.zeros((0, nw, n))
    prev_lp = np.zeros((0, nw))
    if resume:
        if ckpt is None or not ckpt.exists():
            raise WallcalError(f"nothing to resume: no checkpoint {ckpt} (run without --resume)")
        data = np.load(ckpt)
        old = json.loads(str(data["meta"]))
        for key in ("names", "targets", "walkers", "study_sha256"):
            if old.get(key) != meta[key]:
                raise WallcalError(f"{ckpt}: made with another {key}; run without --resume")
        prev_chain, prev_lp = data["chain"], data["log_prob"]
        sig, ph = old["sigma"], old["phi"]
        like = AR1Likelihood(
            ev, [sig[t] for t in space.targets], [ph[t] for t in space.targets], [tau[t] for t in space.targets]
        )
        meta.update(sigma=sig, phi=ph)
        p0 = prev_chain[-1]
        steps = max(0, steps - len(prev_chain))
    else:
        p0 = initial_walkers(study, space, x_start, nw, init_spread, rng)
    sampler = ensemble_sampler(like, nw, n, seed)
    prog = Progress("posterior (emcee)", enabled=progress)
    t0 = time.perf_counter()
    status = "complete"
    last = time.perf_counter()
    done = 0
    try:
        if steps > 0:
            for _ in sampler.sample(p0, iterations=steps):
                done += 1
                if time.perf_counter() - last > 10.0:
                    _save(
                        ckpt,
                        np.concatenate([prev_chain, sampler.get_chain()]),
                        np.concatenate([prev_lp, sampler.get_log_prob()]),
                        meta,
                    )
                    last = time.perf_counter()
                prog.update(
                    f"step {len(prev_chain) + done}/{len(prev_chain) + steps}, "
                    f"{ev.evaluations} simulations, acceptance {np.mean(sampler.acceptance_fraction):.2f}"
                )
    except KeyboardInterrupt:
        status = "interrupted"
    chain = np.concatenate([prev_chain, sampler.get_chain()]) if done else prev_chain
    logp = np.concatenate([prev_lp, sampler.get_log_prob()]) if done else prev_lp
    _save(ckpt, chain, logp, meta)
    seconds = time.perf_counter() - t0
    prog.close(f"{len(chain)} steps, {ev.evaluations} simulations, {seconds:.1f} s ({status})")
    if len(chain) < 4:
        raise WallcalError("the chain is too short to summarise (interrupted at once); continue with --resume")
    res = summarise(
        study,
        space,
        chain,
        logp,
        ev,
        sig,
        ph,
        sigma,
        seconds,
        status,
        acceptance=float(np.mean(sampler.acceptance_fraction)) if done else float("nan"),
        truth=reference_values(study, space),
        nonunique_candidates=nonunique_candidates,
        seed=seed,
    )
    if prepared.note:
        res.warnings.insert(0, prepared.note)
    if status == "complete" and ckpt is not None and ckpt.exists():
        ckpt.unlink()
    return res


def ensemble_sampler(like, walkers: int, n: int, seed: int):
    """The emcee ensemble sampler of :func:`posterior`: vectorised log-probability ``like`` (unit coordinates),
    differential-evolution moves (80 % DE, 20 % DE snooker), seeded."""
    import emcee

    sampler = emcee.EnsembleSampler(
        walkers, n, like, vectorize=True, moves=[(emcee.moves.DEMove(), 0.8), (emcee.moves.DESnookerMove(), 0.2)]
    )
    sampler.random_state = np.random.RandomState(seed).get_state()
    return sampler


def burn_and_thin(chain: np.ndarray, acceptance: float = nan) -> tuple[np.ndarray, int, int, list]:
    """Integrated autocorrelation time per parameter [steps], burn-in and thinning of a chain (steps, walkers, n),
    and the warnings on its length and acceptance."""
    import emcee

    nsteps = chain.shape[0]
    warnings = []
    tau = emcee.autocorr.integrated_time(chain, quiet=True, tol=50) if nsteps > 10 else np.full(chain.shape[2], nan)
    tau = np.asarray(tau, dtype=float)
    tmax = float(np.nanmax(tau)) if np.isfinite(tau).any() else float(nsteps)
    if nsteps < 50 * tmax:
        warnings.append(
            f"chain too short for reliable intervals: {nsteps} steps < 50 x the largest integrated "
            f"autocorrelation time ({tmax:.0f} steps); run longer (--steps) or --resume"
        )
    if np.isfinite(acceptance) and not 0.1 <= acceptance <= 0.7:
        warnings.append(f"acceptance fraction {acceptance:.2f} is outside 0.1..0.7")
    burn = int(min(max(2 * tmax, nsteps // 3), nsteps // 2))
    thin = max(1, int(0.5 * np.nanmin(tau))) if np.isfinite(tau).any() else 1
    return tau, burn, thin, warnings


def summarise(
    study,
    space,
    chain,
    logp,
    ev,
    sig,
    ph,
    sigma_kind,
    seconds,
    status,
    acceptance,
    truth=None,
    nonunique_candidates=256,
    seed=1,
) -> PosteriorResult:
    """Burn-in, thinning, diagnostics, per-parameter and derived summaries, non-uniqueness demonstration."""
    tau, burn, thin, warnings = burn_and_thin(chain, acceptance)
    flat_u = chain[burn::thin].reshape(-1, chain.shape[2])
    X = space.from_unit(flat_u)
    rng = np.random.default_rng(seed)
    prior_u = rng.random((20000, space.n))
    prior_X = space.from_unit(prior_u)
    rows = []
    for j, p in enumerate(space.parameters):
        r = {
            "parameter": p.name,
            **_stats(X[:, j], prior_X[:, j], None if truth is None else truth[j]),
            "lower": p.lower,
            "upper": p.upper,
        }
        rows.append(r)
    summary = pd.DataFrame(rows).set_index("parameter")
    # structural facts override the marginal widths: a lone rho or c is never identified (only rho*c is; its
    # marginal is narrowed by the bounds of its partner), and without a heat flux the absolute scale of the
    # conductivities comes from the bounds of the other layers, not from the data
    from .identifiability import structural_directions

    with_flux = any(study.sensor(t).quantity == "heat_flux" for t in space.targets)
    for key, _, d in structural_directions(space, study.wall, with_flux=with_flux):
        for j in np.flatnonzero(np.abs(d) > 0.05):
            name = space.names[j]
            if key.startswith("rho_c"):
                summary.loc[name, "verdict"] = "not identified (only rho*c)"
            elif summary.loc[name, "verdict"] != "not identified" and "rho*c" not in summary.loc[name, "verdict"]:
                summary.loc[name, "verdict"] += " (scale from the bounds)"
    corr = pd.DataFrame(np.corrcoef(X.T), index=space.names, columns=space.names)
    dpost = derived(space, study.wall, X)
    dprior = derived(space, study.wall, prior_X)
    dtruth = derived(space, study.wall, truth[None]) if truth is not None else None
    crow = [
        {"combination": k, **_stats(dpost[k], dprior[k], None if dtruth is None else float(dtruth[k][0]))}
        for k in dpost
    ]
    comb = pd.DataFrame(crow).set_index("combination").sort_values("sd/prior sd")
    # non-uniqueness: distinct posterior sets, all RMSEs within the sensor accuracy
    pick = rng.choice(len(X), size=min(nonunique_candidates, len(X)), replace=False)
    Xc = X[pick]
    _, rmse = ev.per_target(Xc)
    acc = np.array([_accuracy(study, t, ev.y[k][ev.mask[k]]) for k, t in enumerate(space.targets)])
    ok = np.all(rmse <= acc[None], axis=1)
    chosen = []
    if ok.any():
        Uc = space.to_unit(Xc[ok])
        idx = [int(np.argmin(rmse[ok].sum(axis=1)))]
        while len(idx) < min(5, len(Uc)):
            dmin = np.min(np.linalg.norm(Uc[:, None] - Uc[idx][None], axis=2), axis=1)
            idx.append(int(np.argmax(dmin)))
        chosen = np.flatnonzero(ok)[idx]
    nonunique = pd.DataFrame(Xc[chosen], columns=space.names)
    for k, t in enumerate(space.targets):
        nonunique[f"RMSE {t}"] = rmse[chosen, k]
    nonunique.index = pd.Index([f"set {i + 1}" for i in range(len(chosen))], name="set")
    return PosteriorResult(
        study=study,
        space=space,
        chain=chain,
        log_prob=logp,
        samples=X,
        summary=summary,
        correlation=corr,
        combinations=comb,
        nonunique=nonunique,
        tau=tau,
        acceptance=acceptance,
        burn=burn,
        thin=thin,
        sigma=sig,
        phi=ph,
        sigma_kind=sigma_kind,
        evaluations=int(chain.shape[0] * chain.shape[1]),
        seconds=seconds,
        status=status,
        warnings=warnings,
        truth=truth,
    )


def _accuracy(study, name, y) -> float:
    from .identifiability import sensor_sigma

    return sensor_sigma(study, name, y)

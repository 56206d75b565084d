"""Sequential Monte Carlo on the posterior of the linear 22-parameter space (issue 19: a sampler that mixes).

A measurement, not a sampler of wallcal: it builds the target exactly as ``wallcal.analysis.posterior.posterior``
does (AR(1) likelihood with the sensor biases integrated out, tempered by the sandwich rule, uniform prior on the
bounds, log coordinates) and samples it by SMC with adaptive tempering (Del Moral, Doucet and Jasra 2006; Chopin
and Papaspiliopoulos 2020): particles drawn from the prior; the next temperature where the effective sample size
of the incremental weights falls to N/2; systematic resampling; every particle mutated by random-walk Metropolis
with the particles' covariance (scaled towards an acceptance of 0.234), all particles one engine batch per
mutation step, until each particle has moved with probability 0.99 (at most 40 steps). It prints the stages, the
simulations and the time, the identifiable combinations whose 95 % and 50 % intervals hold the truth, and, with
two or more seeds, how far the runs' posterior means lie apart: with n effective samples per run the difference of
two means is N(0, 2/n) posterior variances, so n ~ 0.91 / median(d^2) over the parameters (0.455, the median of a
chi-square with one degree of freedom, times 2).

    nice -n 19 .venv/bin/python bench/posterior_smc.py --workdir cov19 --particles 1000 --seeds 1 2
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np
from posterior_coverage import CAMPAIGNS, LINEAR_22, make_campaign

import wallcal
from wallcal.analysis import reference_values, space_with_targets
from wallcal.analysis.identifiability import to_z, verdict
from wallcal.analysis.posterior import AR1Likelihood, LogCoordinates, derived, error_model, linearise, sandwich_weight
from wallcal.calibration import calibrate
from wallcal.calibration.objective import Evaluator
from wallcal.calibration.space import parse_space
from wallcal.simulation import BATCH_NEEDS, prepare


def target(study, prep, x):
    """The posterior's likelihood and sampling coordinates at the optimum ``x`` [SI], as posterior() makes them."""
    space = space_with_targets(study, parse_space(study), None)
    ev = Evaluator(prep, space)
    sig, ph, tau = error_model(study, space, ev, x)
    lin = linearise(ev, space, x, sig, ph, tau)
    w = sandwich_weight(ev, space, x, sig, ph, lin=lin)["weight"]
    like = AR1Likelihood(
        ev, *([d[t] for t in space.targets] for d in (sig, ph, tau)), weight=w
    )  # sigma, phi, bias sd per target
    return space, ev, LogCoordinates(like, space), w


def smc(space, ev, coords, particles: int, seed: int, log=print):
    """Particles (z coordinates) of the posterior, and the stages run."""
    rng = np.random.default_rng(seed)
    n = coords.dim  # the sampled coordinates (a layer's rho and c as one, ln(rho c))

    def split(Z):
        """Log-prior (-inf outside the box) and log-likelihood (-inf outside: not simulated)."""
        U = coords.to_unit(Z)
        inside = np.all((U >= 0) & (U <= 1), axis=1)
        lp = np.where(inside, coords.log_prior(Z), -np.inf)
        ll = np.full(len(Z), -np.inf)
        if inside.any():
            ll[inside] = coords.like(U[inside])
        return lp, ll

    Z = coords.from_unit(rng.random((particles, space.n)))
    LP, LL = split(Z)
    beta, stage, scale = 0.0, 0, 2.38 / np.sqrt(n)
    t0, sims0 = time.perf_counter(), ev.evaluations

    def ess(b):
        a = (b - beta) * LL
        wgt = np.exp(a - a.max())
        return wgt.sum() ** 2 / (wgt**2).sum()

    while beta < 1.0:
        stage += 1
        if ess(1.0) >= particles / 2:
            nb = 1.0
        else:
            lo, hi = beta, 1.0
            for _ in range(60):
                mid = 0.5 * (lo + hi)
                lo, hi = (mid, hi) if ess(mid) >= particles / 2 else (lo, mid)
            nb = lo
        a = (nb - beta) * LL
        W = np.exp(a - a.max())
        W /= W.sum()
        mean = W @ Z
        C = ((Z - mean) * W[:, None]).T @ (Z - mean)
        beta = nb
        idx = np.minimum(
            np.searchsorted(np.cumsum(W), (rng.random() + np.arange(particles)) / particles), particles - 1
        )
        Z, LP, LL = Z[idx], LP[idx], LL[idx]
        chol = np.linalg.cholesky(C + 1e-12 * np.eye(n))
        accs = []
        for _ in range(40):
            P = Z + scale * rng.standard_normal((particles, n)) @ chol.T
            lp, ll = split(P)
            ok = np.log(rng.random(particles)) < (lp + beta * ll) - (LP + beta * LL)
            Z[ok], LP[ok], LL[ok] = P[ok], lp[ok], ll[ok]
            accs.append(ok.mean())
            if len(accs) >= 2 and np.prod(1.0 - np.array(accs)) < 0.01:
                break
        scale *= np.exp(np.mean(accs) - 0.234)
        log(
            f"  stage {stage}: temperature {beta:.4g}, {len(accs)} mutation steps, acceptance {np.mean(accs):.3f}, "
            f"{ev.evaluations - sims0} simulations, {time.perf_counter() - t0:.1f} s"
        )
    return Z, stage


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--campaign", choices=tuple(CAMPAIGNS), default="offset")
    ap.add_argument("--particles", type=int, default=1000)
    ap.add_argument("--seeds", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--workdir", help="keep the synthetic campaign here (default: a temporary folder)")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        workdir = Path(args.workdir or tmp)
        folder = "speed-linear" if args.campaign == "all" else f"speed-{args.campaign}-linear"
        path = make_campaign(CAMPAIGNS[args.campaign], workdir / folder)
        path.write_text(path.read_text() + LINEAR_22)
        study = wallcal.load_study(path)
        prep = prepare(study, needs=BATCH_NEEDS)
        x = calibrate(study, progress=False, prepared=prep).x_opt
        space, ev, coords, w = target(study, prep, x)
        truth = reference_values(study, space)
        prior = space.from_unit(np.random.default_rng(0).random((20000, space.n)))
        runs = []
        for seed in args.seeds:
            t, sims = time.perf_counter(), ev.evaluations
            Z, stages = smc(space, ev, coords, args.particles, seed)
            dt, sims = time.perf_counter() - t, ev.evaluations - sims
            X = space.from_unit(coords.draw_unit(Z, np.random.default_rng(seed)))
            runs.append(to_z(space, X))
            post, pri, tru = (derived(space, study.wall, v) for v in (X, prior, truth[None]))
            held95 = held50 = k = 0
            for name in post:
                if verdict(np.std(post[name]) / np.std(pri[name])).startswith("not"):
                    continue
                lo, q25, q75, hi = np.percentile(post[name], [2.5, 25, 75, 97.5])
                k += 1
                held95 += bool(lo <= tru[name][0] <= hi)
                held50 += bool(q25 <= tru[name][0] <= q75)
            print(
                f"SMC, {args.particles} particles, seed {seed} ({space.n} parameters, campaign {args.campaign}, "
                f"w = {w:.3f}): {stages} stages, {sims} simulations in {dt:.1f} s ({sims / dt:.0f}/s); truth inside "
                f"the 95 % interval for {held95} of {k} identifiable combinations, the 50 % for {held50}",
                flush=True,
            )
        for i in range(1, len(runs)):
            a, b = runs[0], runs[i]
            d = (a.mean(axis=0) - b.mean(axis=0)) / np.sqrt(0.5 * (a.var(axis=0) + b.var(axis=0)))
            print(
                f"seeds {args.seeds[0]} and {args.seeds[i]}: posterior means apart by a median "
                f"{np.median(np.abs(d)):.3f} posterior sd (largest {np.abs(d).max():.3f}): about "
                f"{0.91 / np.median(d**2):.0f} effective samples per run"
            )


if __name__ == "__main__":
    main()

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

When the residuals carry more than the AR(1) model expects (a model error: smooth, correlated across
targets and over a day), the likelihood is tempered, L^w with 0 < w <= 1, by the sandwich rule
(:func:`sandwich_weight`): w is the inverse of the mean variance inflation of the score that a
heteroskedasticity-and-autocorrelation-consistent (Newey-West, one-day window) estimate finds over the
identifiable directions. Under a correct error model w = 1 (within its sampling error, capped at 1).

The posterior checks itself (:func:`residual_checks`, :func:`structure_verdict`): posterior predictive
residuals against the sensors' stated accuracy, posterior mass piled up at the edges of the prior box, and
(when given) the extensions that ``wallcal diagnose`` found the data support but the sampled structure lacks.
When any of them fires, the report says plainly that the intervals are conditional on a structure the data
reject.

Priors are uniform on the calibration bounds. The ensemble samples the log of each positive parameter
(:class:`LogCoordinates`; the prior's Jacobian added), where the structural flat directions are straight, and
one coordinate, ln(rho c), for a layer's density and specific heat (the model sees only their product; the split
is drawn from the prior's conditional afterwards),
and starts from the Laplace approximation of the posterior at the optimum (:func:`initial_walkers`), so that
it spans the posterior's flat valleys from the first step. emcee runs with ``vectorize=True``: each half-step
of the ensemble is one engine batch (proposals outside the prior box cost no simulation). By default the chain
runs until it is adequate (:func:`chain_diagnostics`): enough effective samples, and an autocorrelation time that
no longer grows with the chain (a chain shorter than its autocorrelation time gives an estimate capped by its
length, and effective samples that count its length, not its mixing). The chain is checkpointed atomically
(``.npz``) every few seconds and on Ctrl-C, so an interruption loses nothing and ``resume=True`` continues.

This module is the sampler (the run, the chain's diagnostics and summary); beside it,
:mod:`.posterior_likelihood` (the AR(1) likelihood, the sampling coordinates, the tempering),
:mod:`.posterior_checks` (the self-checks) and :mod:`.posterior_outputs` (the result, its output folder and
the reader of that folder). Their names are importable from here.
"""

from __future__ import annotations

import dataclasses
import json
import os
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from ..errors import interrupted
from .identifiability import verdict

# the likelihood, the self-checks and the outputs live beside this module (the sampler); their names are
# importable from here as before
from .posterior_checks import (  # noqa: F401
    PILE_BAND,
    PILE_FRACTION,
    PILES_SHOWN,
    missing_from_diagnosis,
    piled_up,
    residual_checks,
    structure_verdict,
)
from .posterior_likelihood import (  # noqa: F401
    AR1Likelihood,
    Linearisation,
    LogCoordinates,
    error_model,
    hac,
    lag1,
    linearise,
    sandwich_inflation,
    sandwich_weight,
    whiten,
)
from .posterior_outputs import (  # noqa: F401
    COMMAND,
    DEFAULT_EFFECTIVE_SAMPLES,
    PosteriorResult,
    Samples,
    apply_named,
    derived,
    load_samples,
)

nan = float("nan")

#: the default chain stops here even when it is not yet adequate (it says so)
DEFAULT_MAX_STEPS = 5000
#: the default chain is first checked at this many steps, then whenever it has grown by ADAPTIVE_GROWTH (at least
#: ADAPTIVE_EVERY steps): a check costs ~1 s per 2000 steps on two cores, so the checks stay a few % of the run
ADAPTIVE_FIRST_CHECK = 100
ADAPTIVE_EVERY = 25
ADAPTIVE_GROWTH = 0.2
#: an adequate chain is at least this many autocorrelation times long after its burn-in
MIN_TAU_MULTIPLE = 10
#: ... and its autocorrelation time no longer grows with the chain: the estimate over the whole chain after burn-in
#: at most this factor times the one over its first STABLE_SHARE (an estimate that is capped by the chain's length
#: grows in proportion to it: by 1 / STABLE_SHARE = 2)
STABLE_RATIO = 1.2
STABLE_SHARE = 0.5
#: the ensemble's median log-probability, averaged over windows of this many steps, tells the start's transient
BURN_WINDOW = 10


def _stats(samples: np.ndarray, prior: np.ndarray, truth=None) -> dict:
    lo, q25, q75, hi = np.percentile(samples, [2.5, 25.0, 75.0, 97.5])
    sd = float(np.std(samples))
    psd = float(np.std(prior))
    at_lo, at_hi = piled_up(samples, prior)
    row = {
        "mean": float(np.mean(samples)),
        "sd": sd,
        "q2.5": lo,
        "q25": q25,
        "q75": q75,
        "q97.5": hi,
        "sd/prior sd": sd / psd,
        "verdict": verdict(sd / psd),
        "at lower edge": at_lo,
        "at upper edge": at_hi,
    }
    if truth is not None:
        row["truth"] = truth
        row["inside 50%"] = bool(q25 <= truth <= q75) if np.isfinite(truth) else False
        row["inside 95%"] = bool(lo <= truth <= hi) if np.isfinite(truth) else False
    return row


# ============================================================================ the run
def initial_walkers(space, x_start, nw, rng, information, weight: float = 1.0, tries: int = 100):
    """Walkers drawn from the Laplace approximation of the posterior at ``x_start`` (unit coordinates).

    The approximation is Gaussian in the analysis coordinates z (log of each positive parameter, else the unit
    coordinate): mean z(``x_start``), precision ``weight`` x the likelihood's information plus the precision of
    a Gaussian with the uniform prior's variance (which bounds the structural and the nearly flat directions).
    Draws outside the prior box are drawn again (at most ``tries`` times, then clipped into it).

    The ensemble then starts with the posterior's spread and orientation, along its flat valleys too: the
    ensemble moves propose along differences between walkers, so walkers started in a small ball only creep
    along a valley that spans the prior box (on the ``offset`` campaign of ``bench/posterior_coverage.py`` the
    autocorrelation time grew from ~130 to ~500 steps as a chain so started spread over it).

    Parameters
    ----------
    space : ParameterSpace
    x_start : ndarray
        [SI] (the calibrated optimum).
    nw : int
        Walkers.
    rng : numpy Generator
    information : ndarray, shape (n, n)
        Fisher information about the unit coordinates at ``x_start`` (:attr:`Linearisation.information`).
    weight : float
        Power w of the tempered likelihood.

    Returns
    -------
    ndarray, shape (nw, n)
        Unit coordinates inside the box.
    """
    from .identifiability import from_z, log_coordinates, prior_sd_z, to_z

    x_start = np.asarray(x_start, dtype=float)
    lg = log_coordinates(space)
    # du/dz: a log coordinate z = ln x moves u = (x - lo) / (hi - lo) by x / (hi - lo)
    dudz = np.where(lg, x_start / (space.upper - space.lower), 1.0)
    precision = weight * np.asarray(information) * np.outer(dudz, dudz) + np.diag(prior_sd_z(space) ** -2.0)
    L = np.linalg.cholesky(precision)
    z0 = to_z(space, x_start[None])[0]
    U = np.full((nw, space.n), np.nan)
    todo = np.arange(nw)
    for _ in range(tries):
        Z = z0[None] + np.linalg.solve(L.T, rng.standard_normal((space.n, len(todo)))).T
        Ui = space.to_unit(from_z(space, Z))
        ok = np.all((Ui > 0.0) & (Ui < 1.0), axis=1)
        U[todo[ok]] = Ui[ok]
        todo = todo[~ok]
        if not len(todo):
            break
    if len(todo):
        U[todo] = np.clip(Ui[~ok], 1e-3, 1 - 1e-3)
    return U


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
    steps: int | None = None,
    seed: int = 1,
    out_dir=None,
    resume: bool = False,
    progress: bool = True,
    prepared=None,
    max_evaluations: int | None = None,
    nonunique_candidates: int = 256,
    bias: bool = True,
    tempering: str = "sandwich",
    missing_extensions=(),
    effective_samples: float | None = None,
    max_steps: int | None = None,
    predict=None,
    predictive_draws: int | None = None,
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
        Default 4 per sampled coordinate (:class:`LogCoordinates`; even), at least 16.
    steps : int, optional
        Ensemble steps (simulations = walkers x steps). Default: run until the chain is adequate
        (:func:`chain_diagnostics`: ``effective_samples`` effective samples, at least ``MIN_TAU_MULTIPLE``
        autocorrelation times after burn-in, the autocorrelation time no longer growing), checked whenever the
        chain has grown by 20 % (at least 25 steps), at most ``max_steps``.
    seed : int
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
        Posterior samples re-simulated to show distinct sets with RMSEs within the sensor accuracy (and for the
        posterior predictive residual checks).
    tempering : {"sandwich", "none"}
        Temper the likelihood by the sandwich rule (:func:`sandwich_weight`; one extra batch of 2n + 1 runs), or
        not.
    missing_extensions : sequence of str
        Structure extensions that ``wallcal diagnose`` adopted for this study but the sampled structure lacks;
        any makes the self-check say that the data reject the structure.

    effective_samples : float, optional
        Effective samples an adequate chain holds (default :data:`DEFAULT_EFFECTIVE_SAMPLES`).
    max_steps : int, optional
        Longest default chain (when ``steps`` is not given) [steps] (default :data:`DEFAULT_MAX_STEPS`).
    predict : (start, end), optional
        Predict this period of the study's data from the draws plus their out-of-sample errors over the fitted
        period (:func:`~wallcal.analysis.posterior_predictive.predictive`; ``predictive.csv``); default the study's
        validation window, if any (then also ``validation.csv`` with ``coverage_95`` and ``band_width_95``).
    predictive_draws : int, optional
        Posterior draws simulated for the predictive band (default
        :data:`~wallcal.analysis.posterior_predictive.PREDICTIVE_DRAWS`).

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

    require("emcee", "analysis")  # a clear error when the analysis extra is missing
    space = space_with_targets(study, parse_space(study), targets)
    x_start = space.base if x_start is None else np.asarray(x_start, dtype=float)
    prepared = prepared or prepare(study, needs=BATCH_NEEDS, purpose="the posterior sampling")
    ev = Evaluator(prepared, space)
    n = space.n
    coords = LogCoordinates(None, space)  # the sampled coordinates (the likelihood is set below)
    dim = coords.dim
    nw = int(walkers or max(4 * dim, 16))
    nw += nw % 2
    adaptive = steps is None
    check_positive({"steps": steps, "max_steps": max_steps, "effective_samples": effective_samples})
    effective_samples = DEFAULT_EFFECTIVE_SAMPLES if effective_samples is None else effective_samples
    max_steps = DEFAULT_MAX_STEPS if max_steps is None else max_steps
    steps = int(max_steps if adaptive else steps)
    if max_evaluations:
        steps = min(steps, max(1, int(max_evaluations) // nw))
    sig, ph, tau = error_model(study, space, ev, x_start, sigma, bias)
    if tempering not in ("sandwich", "none"):
        raise WallcalError(f"tempering: {tempering!r} is not one of 'sandwich', 'none'")
    temp = {"kind": "none", "weight": 1.0}
    lin = None if resume else linearise(ev, space, x_start, sig, ph, tau)
    if tempering == "sandwich" and not resume:
        temp = {"kind": "sandwich", **sandwich_weight(ev, space, x_start, sig, ph, lin=lin)}
    like = AR1Likelihood(
        ev,
        [sig[t] for t in space.targets],
        [ph[t] for t in space.targets],
        [tau[t] for t in space.targets],
        weight=temp["weight"],
    )
    ckpt = checkpoint_path(out_dir)
    meta = {
        "names": space.names,
        "targets": list(space.targets),
        "sigma": sig,
        "phi": ph,
        "walkers": nw,
        "sampled_coordinates": coords.names,
        "study_sha256": study.sha256,
        "tempering": temp,
    }
    rng = np.random.default_rng(seed)
    prev_chain = np.zeros((0, nw, dim))  # the chain of the sampled coordinates
    prev_lp = np.zeros((0, nw))
    if resume:
        if ckpt is None or not ckpt.exists():
            raise WallcalError(f"nothing to resume: no checkpoint {ckpt} (run without --resume)")
        data = np.load(ckpt)
        old = json.loads(str(data["meta"]))
        for key in ("names", "targets", "walkers", "sampled_coordinates", "study_sha256"):
            if old.get(key) != meta[key]:
                raise WallcalError(f"{ckpt}: made with another {key.replace('_', ' ')}; run without --resume")
        prev_chain, prev_lp = data["chain"], data["log_prob"]
        sig, ph = old["sigma"], old["phi"]
        temp = old.get("tempering", {"kind": "none", "weight": 1.0})
        like = AR1Likelihood(
            ev,
            [sig[t] for t in space.targets],
            [ph[t] for t in space.targets],
            [tau[t] for t in space.targets],
            weight=temp["weight"],
        )
        meta.update(sigma=sig, phi=ph, tempering=temp)
        p0 = prev_chain[-1]
        steps = max(0, steps - len(prev_chain))
    else:
        p0 = coords.from_unit(initial_walkers(space, x_start, nw, rng, lin.information, temp["weight"]))
    coords.like = like
    sampler = ensemble_sampler(coords, nw, dim, seed)

    prog = Progress("posterior (emcee)", enabled=progress)
    runs0 = ev.evaluations
    t0 = time.perf_counter()
    status = "complete"
    last = time.perf_counter()
    done = 0
    next_check = max(ADAPTIVE_FIRST_CHECK, len(prev_chain))
    ess = ""
    final = None  # the diagnostics of the chain as it ends, when the adequacy check computed them
    if adaptive and len(prev_chain) >= ADAPTIVE_FIRST_CHECK:
        d = chain_diagnostics(prev_chain, prev_lp, effective_samples)
        if d.adequate:
            steps = 0  # the resumed chain is adequate already
            final = d
    try:
        if steps > 0:
            for _ in sampler.sample(p0, iterations=steps):
                done += 1
                if adaptive and len(prev_chain) + done >= next_check:
                    d = chain_diagnostics(
                        np.concatenate([prev_chain, sampler.get_chain()]),
                        np.concatenate([prev_lp, sampler.get_log_prob()]),
                        effective_samples,
                    )
                    if d.adequate:
                        final = d
                        break
                    length = len(prev_chain) + done
                    next_check = length + max(ADAPTIVE_EVERY, int(ADAPTIVE_GROWTH * length))
                    ess = f", {d.effective_samples:.0f} effective samples" + (
                        "" if d.stable else " (tau still growing)"
                    )
                if time.perf_counter() - last > 10.0:
                    _save(
                        ckpt,
                        np.concatenate([prev_chain, sampler.get_chain()]),
                        np.concatenate([prev_lp, sampler.get_log_prob()]),
                        meta,
                    )
                    last = time.perf_counter()
                prog.update(
                    f"step {len(prev_chain) + done}/{'at most ' if adaptive else ''}{len(prev_chain) + steps}, "
                    f"{ev.evaluations} simulations, acceptance {np.mean(sampler.acceptance_fraction):.2f}{ess}"
                )
    except (KeyboardInterrupt, SystemError) as exc:  # (a Ctrl-C inside a numba kernel: a SystemError)
        if not interrupted(exc):
            raise
        status = "interrupted"
    chain = np.concatenate([prev_chain, sampler.get_chain()]) if done else prev_chain
    logp = np.concatenate([prev_lp, sampler.get_log_prob()]) if done else prev_lp
    _save(ckpt, chain, logp, meta)
    seconds = time.perf_counter() - t0
    simulated = ev.evaluations - runs0
    prog.close(f"{len(chain)} steps, {ev.evaluations} simulations, {seconds:.1f} s ({status})")
    if len(chain) < 4:
        raise WallcalError("the chain is too short to summarise (interrupted at once); continue with --resume")
    # the diagnostics belong to the Markov chain (the sampled coordinates); the summary reads the chain of every
    # parameter, each rho*c split drawn from its conditional
    final = final or chain_diagnostics(chain, logp, effective_samples)
    final = dataclasses.replace(final, tau=coords.full_tau(final.tau))
    split_rng = np.random.default_rng([seed, 1])
    unit = coords.draw_unit(chain.reshape(-1, dim), split_rng).reshape(chain.shape[:2] + (n,))
    res = summarise(
        study,
        space,
        unit,
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
        tempering=temp,
        missing_extensions=missing_extensions,
        effective_samples=effective_samples,
        diagnostics=final,
    )
    res.simulations = simulated if not resume else None  # a resumed chain's earlier part is not counted
    from .posterior_predictive import PREDICTIVE_DRAWS, predictive

    res.predictive = predictive(
        study,
        space,
        res.samples,
        ev,
        window=predict,
        draws=predictive_draws or PREDICTIVE_DRAWS,
        seed=seed,
    )
    res.predicted_validation = predict is None and res.predictive is not None
    if prepared.note:
        res.warnings.insert(0, prepared.note)
    if status == "complete" and ckpt is not None and ckpt.exists():
        ckpt.unlink()
    return res


def ensemble_sampler(like, walkers: int, n: int, seed: int):
    """The emcee ensemble sampler of :func:`posterior`: vectorised log-probability ``like`` (over the sampling
    coordinates), differential-evolution moves (80 % DE, 20 % DE snooker), seeded."""
    import emcee

    sampler = emcee.EnsembleSampler(
        walkers, n, like, vectorize=True, moves=[(emcee.moves.DEMove(), 0.8), (emcee.moves.DESnookerMove(), 0.2)]
    )
    sampler.random_state = np.random.RandomState(seed).get_state()
    return sampler


def check_positive(settings: dict) -> None:
    """Raise :class:`WallcalError` naming the first of ``settings`` (name -> value; None: not given) that is not
    positive (the chain's length settings; the command line checks its flags with it before calibrating)."""
    from ..errors import WallcalError

    for name, value in settings.items():
        if value is not None and not value > 0:
            raise WallcalError(f"{name}: must be positive, got {value!r}")


@dataclass
class ChainDiagnostics:
    """What a chain (steps, walkers, n) says about itself (:func:`chain_diagnostics`).

    Attributes
    ----------
    tau : ndarray, shape (n,)
        Integrated autocorrelation time per parameter over the chain after burn-in [steps].
    tau_early : float
        The largest autocorrelation time over the first ``STABLE_SHARE`` of the chain after burn-in [steps].
    burn : int
        Burn-in [steps].
    effective_samples : float
        Walkers x steps after burn-in / the largest autocorrelation time.
    stable : bool
        The autocorrelation time no longer grows with the chain (``tau.max() <= STABLE_RATIO x tau_early``).
    adequate : bool
        At least ``target`` effective samples, ``MIN_TAU_MULTIPLE`` autocorrelation times after burn-in, stable.
    reasons : list of str
        Why not adequate (empty when adequate).
    """

    tau: np.ndarray
    tau_early: float
    burn: int
    effective_samples: float
    stable: bool
    adequate: bool
    reasons: list


def integrated_time(chain: np.ndarray, c: float = 5.0) -> np.ndarray:
    """Integrated autocorrelation time per parameter of a chain (steps, walkers, n) [steps]: emcee's estimate
    (``emcee.autocorr.integrated_time``: the autocorrelation function of each walker's series averaged over the
    walkers, summed over Sokal's automatic window with ``c``), with the FFTs of all walkers at once; nan for a
    parameter in which a walker never moved."""
    from scipy import fft

    nsteps = chain.shape[0]
    if nsteps <= 10:
        return np.full(chain.shape[2], nan)
    size = fft.next_fast_len(2 * nsteps - 1, real=True)  # zero-padded: the circular correlation is the linear one
    out = np.empty(chain.shape[2])
    lag = np.arange(nsteps)
    for j in range(chain.shape[2]):
        x = chain[:, :, j] - chain[:, :, j].mean(axis=0, keepdims=True)
        f = fft.rfft(x, n=size, axis=0, workers=-1)
        acf = fft.irfft(f * np.conjugate(f), n=size, axis=0, workers=-1)[:nsteps]
        with np.errstate(invalid="ignore", divide="ignore"):
            rho = (acf / acf[0][None]).mean(axis=1)
        taus = 2.0 * np.cumsum(rho) - 1.0
        short = lag < c * taus
        out[j] = taus[int(np.argmin(short))] if short.any() else taus[-1]
    return out


def transient_end(log_prob: np.ndarray) -> int:
    """The step at which the ensemble's median log-probability (averaged over ``BURN_WINDOW`` steps) first reaches
    its level over the second half of the chain: from a start narrower than the posterior it falls to it, from one
    wider or off the mode it climbs to it."""
    m = np.median(np.asarray(log_prob, dtype=float), axis=1)
    n = len(m) // BURN_WINDOW
    if n < 4:
        return 0
    w = m[: n * BURN_WINDOW].reshape(n, BURN_WINDOW).mean(axis=1)
    level = float(np.median(m[len(m) // 2 :]))
    side = np.sign(w[0] - level)
    crossed = np.flatnonzero(np.sign(w - level) != side)
    return int(crossed[0] * BURN_WINDOW) if len(crossed) else len(m) // 2


def chain_diagnostics(chain: np.ndarray, log_prob=None, target: float = DEFAULT_EFFECTIVE_SAMPLES) -> ChainDiagnostics:
    """Burn-in, autocorrelation time and effective samples of a chain (steps, walkers, n), and whether it is adequate.

    Burn-in: the end of the start's transient in the log-probability (:func:`transient_end`), and at least one
    autocorrelation time, at most half the chain; without ``log_prob``, two autocorrelation times. The
    autocorrelation time is estimated on the chain after burn-in (emcee's windowed estimator, averaged over the
    walkers). A chain too short for it gives an estimate capped by its length, which grows in proportion to the
    chain: so an adequate chain also has an estimate that no longer grows (over the whole chain after burn-in at
    most ``STABLE_RATIO`` x the one over its first ``STABLE_SHARE``), is at least ``MIN_TAU_MULTIPLE``
    autocorrelation times long after burn-in, and holds ``target`` effective samples.
    """
    nsteps, walkers = chain.shape[:2]
    start = max(transient_end(log_prob), 1) if log_prob is not None and len(log_prob) == nsteps else 0
    start = min(start, nsteps // 2)
    tau = integrated_time(chain[start:])
    t = float(np.nanmax(tau)) if np.isfinite(tau).any() else float(nsteps)
    burn = int(min(max(start, int(np.ceil(t))) if start else int(np.ceil(2 * t)), nsteps // 2))
    post = chain[burn:]
    if burn != start:
        tau = integrated_time(post)
    tmax = float(np.nanmax(tau)) if np.isfinite(tau).any() else float(nsteps)
    early = integrated_time(post[: int(STABLE_SHARE * len(post))])
    tau_early = float(np.nanmax(early)) if np.isfinite(early).any() else nan
    ess = walkers * len(post) / tmax if tmax > 0 else 0.0
    stable = bool(np.isfinite(tau_early) and tmax <= STABLE_RATIO * tau_early)
    reasons = []
    if ess < target:
        reasons.append(f"{ess:.0f} effective samples < {target:.0f}")
    if len(post) < MIN_TAU_MULTIPLE * tmax:
        reasons.append(
            f"{len(post)} steps after burn-in < {MIN_TAU_MULTIPLE} x the largest autocorrelation time "
            f"({tmax:.0f} steps)"
        )
    if not stable:
        reasons.append(
            f"the autocorrelation time still grows with the chain ({tau_early:.0f} steps over the first "
            f"{STABLE_SHARE:.0%} after burn-in, {tmax:.0f} over all): it is a lower bound, the effective samples an "
            "upper one"
        )
    return ChainDiagnostics(
        tau=tau,
        tau_early=tau_early,
        burn=burn,
        effective_samples=float(ess),
        stable=stable,
        adequate=not reasons,
        reasons=reasons,
    )


def burn_and_thin(d: ChainDiagnostics, acceptance: float = nan) -> tuple[np.ndarray, int, int, list]:
    """Integrated autocorrelation time per parameter [steps], burn-in and thinning of a chain, from its
    :func:`chain_diagnostics` ``d``, and the warnings on its adequacy and acceptance."""
    warnings = []
    if not d.adequate:
        warnings.append(
            "chain not adequate for reliable intervals: " + "; ".join(d.reasons) + "; run longer (--steps) or --resume"
        )
    if np.isfinite(acceptance) and not 0.1 <= acceptance <= 0.7:
        warnings.append(f"acceptance fraction {acceptance:.2f} is outside 0.1..0.7")
    thin = max(1, int(0.5 * np.nanmin(d.tau))) if np.isfinite(d.tau).any() else 1
    return d.tau, d.burn, thin, warnings


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
    tempering=None,
    missing_extensions=(),
    effective_samples: float = DEFAULT_EFFECTIVE_SAMPLES,
    diagnostics: ChainDiagnostics | None = None,
) -> PosteriorResult:
    """Burn-in, thinning, diagnostics, per-parameter and derived summaries, non-uniqueness demonstration,
    posterior predictive checks and the structure verdict. ``diagnostics``: those of this very chain
    (:func:`chain_diagnostics` with ``effective_samples``), when the caller has them already."""
    diag = diagnostics or chain_diagnostics(chain, logp, effective_samples)
    tau, burn, thin, warnings = burn_and_thin(diag, acceptance)
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
    E = ev.errors(Xc)
    rmse = np.sqrt(np.einsum("ctk,ctk->ct", E, E) / ev.n_valid[None])
    checks = residual_checks(study, space, ev, E)
    structure = structure_verdict(checks, summary, comb, missing_extensions)
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
        tempering=tempering or {"kind": "none", "weight": 1.0},
        checks=checks,
        structure=structure,
        effective_samples=diag.effective_samples,
        adequate=diag.adequate,
        target_effective_samples=float(effective_samples),
    )


def _accuracy(study, name, y) -> float:
    from .identifiability import sensor_sigma

    return sensor_sigma(study, name, y)

"""Ensemble slice sampling with the differential move (Karamanis and Beutler 2021), batched over the walkers.

Each walker of one half of the ensemble takes a univariate slice-sampling step (Neal 2003: stepping out, then
shrinking) along the difference of two walkers drawn from the other half, scaled by ``mu``. The step never
rejects: a point outside the prior box has log-probability -inf and only shrinks the slice. All walkers of a half
step out and shrink together, so every round of the procedure is one call of the vectorised log-probability (one
engine batch). ``mu`` is tuned during the first steps so that expansions and contractions balance (Karamanis and
Beutler's Robbins-Monro rule); the tuning stops after ``patience`` steps within ``tolerance`` of the balance, and
the kernel is then fixed.

This is the algorithm of ``zeus`` (Karamanis, Beutler and Peacock 2021, "zeus: a Python implementation of Ensemble
Slice Sampling for efficient Bayesian parameter inference", MNRAS 508), written here with its own seeded random
generator (zeus draws from numpy's and Python's global generators and resets the root logger's handlers when it is
constructed: process-wide side effects a library cannot have).
"""

from __future__ import annotations

import numpy as np


class EnsembleSliceSampler:
    """Ensemble slice sampler (differential move) over a vectorised log-probability.

    Parameters
    ----------
    log_prob : callable
        Shape (m, n) -> (m,), -inf where the density is zero.
    walkers : int
        Even, at least 4.
    n : int
        Dimension.
    seed : int
    mu : float
        Initial scale of the directions (tuned while ``tune``).
    tune : bool
    tolerance, patience :
        Tuning stops after more than ``patience`` steps whose share of expansions is within ``tolerance`` of 1/2.
    max_steps_out : int
        Most expansions of one slice (both ends together; a point outside the box stops it anyway).
    light : bool
        Once tuned, widen ``mu`` by the last step's expansions per walker and stop stepping out (zeus's
        ``light_mode``: fewer evaluations, for nearly Gaussian targets).

    Attributes
    ----------
    evaluations : int
        Points whose log-probability was asked for (inside and outside the box).
    expansions, contractions : int
        Over all steps.
    """

    def __init__(
        self,
        log_prob,
        walkers: int,
        n: int,
        seed: int = 1,
        *,
        mu: float = 1.0,
        tune: bool = True,
        tolerance: float = 0.05,
        patience: int = 5,
        max_steps_out: int = 10000,
        max_rounds: int = 10000,
        light: bool = False,
    ):
        if walkers < 4 or walkers % 2:
            raise ValueError(f"walkers: an even number >= 4 is needed, got {walkers}")
        self.log_prob = log_prob
        self.walkers, self.n = int(walkers), int(n)
        self.rng = np.random.default_rng(seed)
        self.mu = float(mu)
        self.tune = bool(tune)
        self.tolerance, self.patience = float(tolerance), int(patience)
        self.max_steps_out, self.max_rounds = int(max_steps_out), int(max_rounds)
        self.light = bool(light)
        self.evaluations = 0
        self.expansions = 0
        self.contractions = 0
        self._within = 0
        self._chain: list = []
        self._lp: list = []

    # -------------------------------------------------------------- emcee-like access
    def get_chain(self) -> np.ndarray:
        """The chain so far, shape (steps, walkers, n)."""
        return np.array(self._chain).reshape(len(self._chain), self.walkers, self.n)

    def get_log_prob(self) -> np.ndarray:
        """Log-probability of each chain entry, shape (steps, walkers)."""
        return np.array(self._lp).reshape(len(self._lp), self.walkers)

    @property
    def acceptance_fraction(self) -> np.ndarray:
        """1 for every walker: a slice step always moves (kept for the emcee interface)."""
        return np.ones(self.walkers)

    @property
    def expansion_share(self) -> float:
        """Expansions / (expansions + contractions) over the run (about 1/2 once ``mu`` is tuned)."""
        total = self.expansions + self.contractions
        return self.expansions / total if total else float("nan")

    def _lp_of(self, X):
        self.evaluations += len(X)
        out = np.asarray(self.log_prob(X), dtype=float)
        if np.any(np.isnan(out)):
            raise ValueError("the log-probability returned NaN")
        return out

    # -------------------------------------------------------------- the step
    def _directions(self, other: np.ndarray, m: int) -> np.ndarray:
        """``m`` directions 2 mu (x_j - x_k), (j, k) distinct ordered pairs of the other half, drawn without
        replacement."""
        k = len(other)
        pick = self.rng.choice(k * (k - 1), size=m, replace=k * (k - 1) < m)
        j = pick // (k - 1)
        i = pick % (k - 1)
        i = i + (i >= j)
        return 2.0 * self.mu * (other[j] - other[i])

    def _half(self, X, Z, active, inactive) -> tuple[int, int]:
        x0 = X[active]
        m = len(active)
        d = self._directions(X[inactive], m)
        level = Z[active] - self.rng.exponential(size=m)
        left = -self.rng.random(m)
        right = left + 1.0
        j = np.floor(self.max_steps_out * self.rng.random(m))
        k = (self.max_steps_out - 1) - j
        go_l, go_r = j >= 1, k >= 1
        nexp = ncon = 0
        rounds = 0
        while go_l.any() or go_r.any():
            rounds += 1
            if rounds > self.max_rounds:
                raise RuntimeError("ensemble slice sampler: the slice kept expanding (is the density proper?)")
            pts = np.concatenate([x0[go_l] + d[go_l] * left[go_l, None], x0[go_r] + d[go_r] * right[go_r, None]])
            z = self._lp_of(pts)
            zl, zr = z[: go_l.sum()], z[go_l.sum() :]
            il, ir = np.flatnonzero(go_l), np.flatnonzero(go_r)
            up_l, up_r = zl > level[il], zr > level[ir]
            left[il[up_l]] -= 1.0
            right[ir[up_r]] += 1.0
            j[il[up_l]] -= 1
            k[ir[up_r]] -= 1
            nexp += int(up_l.sum() + up_r.sum())
            go_l[il[~up_l]] = False
            go_r[ir[~up_r]] = False
            go_l &= j >= 1
            go_r &= k >= 1
        todo = np.ones(m, dtype=bool)
        xn = np.empty_like(x0)
        zn = np.empty(m)
        rounds = 0
        while todo.any():
            rounds += 1
            if rounds > self.max_rounds:
                raise RuntimeError("ensemble slice sampler: the slice kept shrinking (is the density proper?)")
            it = np.flatnonzero(todo)
            w = left[it] + self.rng.random(len(it)) * (right[it] - left[it])
            pts = x0[it] + d[it] * w[:, None]
            z = self._lp_of(pts)
            ok = z > level[it]
            xn[it[ok]], zn[it[ok]] = pts[ok], z[ok]
            todo[it[ok]] = False
            bad = it[~ok]
            wb = w[~ok]
            left[bad] = np.where(wb < 0.0, wb, left[bad])
            right[bad] = np.where(wb > 0.0, wb, right[bad])
            ncon += int(np.count_nonzero(wb != 0.0))
        X[active], Z[active] = xn, zn
        return nexp, ncon

    def sample(self, start, iterations: int, log_prob0=None):
        """Advance the ensemble ``iterations`` steps from ``start`` (walkers, n); yields (X, Z) after each step."""
        X = np.array(start, dtype=float, copy=True)
        if X.shape != (self.walkers, self.n):
            raise ValueError(f"start: shape {(self.walkers, self.n)} expected, got {X.shape}")
        Z = self._lp_of(X) if log_prob0 is None else np.array(log_prob0, dtype=float)
        if not np.all(np.isfinite(Z)):
            raise ValueError("start: every walker needs a finite log-probability")
        half = self.walkers // 2
        for _ in range(int(iterations)):
            order = self.rng.permutation(self.walkers)
            a, b = order[:half], order[half:]
            nexp = ncon = 0
            for active, inactive in ((a, b), (b, a)):
                e, c = self._half(X, Z, active, inactive)
                nexp, ncon = nexp + e, ncon + c
            self.expansions += nexp
            self.contractions += ncon
            if self.tune:
                share = max(1, nexp) / (max(1, nexp) + ncon)
                self.mu *= 2.0 * share
                if abs(nexp / max(1, nexp + ncon) - 0.5) < self.tolerance:
                    self._within += 1
                if self._within > self.patience:
                    self.tune = False
                    if self.light:  # no stepping out from now on: the tuned slice, widened by the expansions
                        self.mu *= 1.0 + nexp / self.walkers
                        self.max_steps_out = 1
            self._chain.append(X.copy())
            self._lp.append(Z.copy())
            yield X, Z

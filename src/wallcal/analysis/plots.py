"""Figures of the analyses: grid study (Fig. 4), sensitivity bars, singular values, posterior corner plot."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402


def plot_grid_study(res, path):
    """RMSE of each target versus the time step, one curve per grid constant C (the paper's Fig. 4)."""
    targets = res.targets
    ncol = min(3, len(targets))
    nrow = int(np.ceil(len(targets) / ncol))
    fig, axes = plt.subplots(nrow, ncol, figsize=(4.2 * ncol, 3.3 * nrow), squeeze=False, layout="constrained")
    for ax, t in zip(axes.ravel(), targets, strict=False):
        d = res.table[res.table.target == t]
        for C, g in d.groupby("grid_constant"):
            g = g.sort_values("time_step")
            ax.plot(g.time_step / 60.0, g.rmse, marker="o", label=f"C = {C:g}")
        ax.set_xlabel("time step [min]")
        ax.set_ylabel(f"RMSE {t} [{res.units[t]}]")
        ax.set_title(t)
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=8)
    for ax in axes.ravel()[len(targets) :]:
        ax.set_visible(False)
    rec = f"; recommended dt = {res.recommended[0]:g} s, C = {res.recommended[1]:g}" if res.recommended else ""
    fig.suptitle(f"Grid sensitivity (tolerance {res.tolerance:g}{rec})")
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_sensitivity(res, path):
    """Horizontal bars of the ranking measure per parameter."""
    r = res.ranking
    col = res.measure
    fig, ax = plt.subplots(figsize=(7.5, 0.35 * len(r) + 1.5), layout="constrained")
    y = np.arange(len(r))[::-1]
    ax.barh(y, r[col].to_numpy(), color="tab:blue", alpha=0.8, label=col)
    if res.method == "sobol" and "S1" in r:
        ax.barh(y, r["S1"].to_numpy(), height=0.4, color="tab:orange", label="S1")
        if "ST_conf" in r:
            ax.errorbar(r["ST"].to_numpy(), y, xerr=r["ST_conf"].to_numpy(), fmt="none", ecolor="k", lw=0.8)
    ax.set_yticks(y)
    ax.set_yticklabels(r.index)
    ax.set_xlabel(col)
    ax.set_title(f"Sensitivity ({res.method}) of the objective over the calibration space")
    ax.grid(True, axis="x", alpha=0.3)
    ax.legend()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_singular_values(res, path, threshold: float):
    """Relative singular values of the scaled Jacobian for each target set; ``threshold``: the structural one."""
    fig, ax = plt.subplots(figsize=(7, 4), layout="constrained")
    for a in res.analyses:
        s = a.singular["relative"].to_numpy()
        ax.semilogy(
            np.arange(1, len(s) + 1),
            np.maximum(s, 1e-18),
            marker="o",
            label="+".join(a.targets) + f" (rank {a.rank}/{a.n})",
        )
    ax.axhline(threshold, color="0.4", ls="--", lw=1, label="structural threshold")
    ax.set_xlabel("k")
    ax.set_ylabel("s_k / s_1")
    ax.set_title(f"Singular values of the residual Jacobian ({res.at})")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_corner(samples, labels, path, truth=None, max_points: int = 3000):
    """A corner plot (pairwise scatter, marginal histograms) of posterior samples."""
    samples = np.asarray(samples)
    n = samples.shape[1]
    rng = np.random.default_rng(0)
    sub = samples[rng.choice(len(samples), size=min(max_points, len(samples)), replace=False)]
    size = max(1.3 * n, 6)
    fig, axes = plt.subplots(n, n, figsize=(size, size), squeeze=False)
    for i in range(n):
        for j in range(n):
            ax = axes[i, j]
            if j > i:
                ax.set_visible(False)
                continue
            if i == j:
                ax.hist(samples[:, i], bins=30, color="tab:blue", alpha=0.7)
                if truth is not None and np.isfinite(truth[i]):
                    ax.axvline(truth[i], color="tab:red", lw=1)
            else:
                ax.plot(sub[:, j], sub[:, i], ",", color="tab:blue", alpha=0.4)
                if truth is not None:
                    ax.plot(truth[j], truth[i], "+", color="tab:red", ms=6)
            ax.tick_params(labelsize=5)
            if i < n - 1:
                ax.set_xticklabels([])
            else:
                ax.set_xlabel(labels[j], fontsize=6)
            if j > 0 or i == 0:
                ax.set_yticklabels([])
            else:
                ax.set_ylabel(labels[i], fontsize=6)
    fig.subplots_adjust(wspace=0.05, hspace=0.05)
    fig.savefig(path, dpi=90)
    plt.close(fig)


def plot_trace(chain, labels, path):
    """Walker traces of every parameter (unit coordinates)."""
    nsteps, nw, n = chain.shape
    fig, axes = plt.subplots(n, 1, figsize=(8, 0.9 * n + 1), sharex=True, squeeze=False, layout="constrained")
    for k in range(n):
        axes[k, 0].plot(chain[:, :, k], color="k", alpha=0.15, lw=0.5)
        axes[k, 0].set_ylabel(labels[k], fontsize=6, rotation=0, ha="right")
        axes[k, 0].set_ylim(0, 1)
        axes[k, 0].tick_params(labelsize=6)
    axes[-1, 0].set_xlabel("step")
    fig.savefig(path, dpi=90)
    plt.close(fig)

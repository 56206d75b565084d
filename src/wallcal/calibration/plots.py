"""Figures of a calibration: convergence and measured vs base vs calibrated (the paper's Fig. 5)."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402


def plot_convergence(res, path):
    h = np.array([(e, f) for e, _, f in res.history], dtype=float) if res.history else np.zeros((0, 2))
    fig, ax = plt.subplots(figsize=(7, 4), layout="constrained")
    if len(h):
        ax.semilogy(h[:, 0], h[:, 1] - 0 if res.f_opt <= 0 else h[:, 1], lw=1.5, label="best objective")
    ax.axhline(res.f_base, color="0.5", ls="--", lw=1, label=f"base case {res.f_base:.4g}")
    ax.set_xlabel("simulations")
    ax.set_ylabel(f"objective ({res.space.objective})")
    ax.set_title(
        f"{res.algorithm}: {res.f_base:.4g} -> {res.f_opt:.4g} in {res.evaluations} simulations, {res.seconds:.1f} s"
    )
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_fit(res, path):
    targets = list(res.space.targets)
    fig, axes = plt.subplots(
        len(targets), 1, figsize=(10, 2.6 * len(targets)), sharex=True, squeeze=False, layout="constrained"
    )
    met = res.metrics.set_index(["case", "signal"])["rmse"]
    for ax, name in zip(axes[:, 0], targets, strict=True):
        s = res.study.sensor(name)
        unit = "W/m2" if s.quantity == "heat_flux" else "degC"
        y = res.measured[name]
        ax.plot(y.index, y.to_numpy(), color="k", lw=0.8, label="measured")
        ax.plot(
            y.index,
            res.simulated["base"][name].to_numpy(),
            color="tab:blue",
            lw=0.9,
            label=f"base case (RMSE {met[('base', name)]:.3f})",
        )
        ax.plot(
            y.index,
            res.simulated["calibrated"][name].to_numpy(),
            color="tab:red",
            lw=0.9,
            label=f"calibrated (RMSE {met[('calibrated', name)]:.3f})",
        )
        ax.set_ylabel(f"{name} [{unit}]")
        ax.legend(loc="upper right", fontsize=8)
        ax.grid(alpha=0.3)
    axes[-1, 0].set_xlabel("time (local standard time)")
    fig.suptitle("Measured vs base case vs calibrated")
    fig.savefig(path, dpi=110)
    plt.close(fig)

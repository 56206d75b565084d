"""Figures of the verification cases (matplotlib, Agg backend, PNG)."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from .cases import CaseRun  # noqa: E402


def plot_case(run: CaseRun, path) -> str:
    """Profiles of temperature, relative humidity and water content at each output time, the reference
    limits as error bars, and the run's balance errors in the title."""
    res = run.result
    fig, axes = plt.subplots(1, 3, figsize=(13, 4.2), layout="constrained")
    x_mm = res.x * 1000.0
    for k, t in enumerate(res.times):
        day = t / 86400.0
        label = f"{day:g} d" if day >= 1 else f"{t / 3600:g} h"
        axes[0].plot(x_mm, res.temperature[k], lw=1.2, label=label)
        axes[1].plot(x_mm, res.relative_humidity[k], lw=1.2, label=label)
        axes[2].plot(x_mm, res.water_content[k], lw=1.2, label=label)
    ref = run.checks[run.checks["x_m"].notna()]
    for q, ax in (("temperature", axes[0]), ("relative_humidity", axes[1]), ("water_content", axes[2])):
        r = ref[ref["quantity"].isin([q, f"refinement_{q}"])]  # reference limits, or the refinement band
        if len(r):
            mid = 0.5 * (r["lower"] + r["upper"])
            ax.errorbar(
                r["x_m"] * 1000.0,
                mid,
                yerr=0.5 * (r["upper"] - r["lower"]),
                fmt="none",
                ecolor="k",
                capsize=3,
                lw=0.8,
                label="reference limits" if (r["quantity"] == q).any() else "twice-refined run +- tolerance",
            )
    if run.name == "en15026":
        axes[0].set_xlim(0, 5200)
        axes[1].set_xlim(0, 150)
        axes[2].set_xlim(0, 150)
    else:
        for ax in axes:
            ax.set_xlim(0, x_mm[-1] + 0.5 * res.dx[-1] * 1000.0)
    if run.name == "hamstad5":  # the moisture gathers at the mortar and insulation
        axes[1].set_xlim(340, 420)
        axes[2].set_xlim(340, 420)
    for ax, lab in zip(axes, ("temperature [degC]", "relative humidity [-]", "water content [kg/m3]"), strict=True):
        ax.set_xlabel("depth from the exterior face [mm]")
        ax.set_ylabel(lab)
        ax.grid(alpha=0.3)
    axes[2].legend(fontsize=8)
    fig.suptitle(
        f"{run.name}: max relative balance error, mass {np.max(res.mass_balance_error):.1e}, "
        f"energy {np.max(res.energy_balance_error):.1e}; {res.stats['steps']} steps, {run.seconds:.2f} s"
    )
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return str(path)

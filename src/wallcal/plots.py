"""Figures shared by commands and the report (matplotlib, Agg backend, PNG files)."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import pandas as pd  # noqa: E402


def plot_measurements(study, frame: pd.DataFrame, path, start=None, end=None):
    """Measured probe temperatures (left axis) and heat fluxes (right axis) over the period (the paper's Fig. 3)."""
    start = pd.Timestamp(start or study.period.start)
    end = pd.Timestamp(end or study.period.end)
    f = frame.loc[(frame.index >= start) & (frame.index <= end)]
    fig, (ax1, ax3) = plt.subplots(
        2, 1, figsize=(11, 6.5), sharex=True, layout="constrained", gridspec_kw={"height_ratios": [2, 1.2]}
    )
    temps = [s for s in study.sensors if s.quantity == "temperature"]
    fluxes = [s for s in study.sensors if s.quantity == "heat_flux"]
    for s in temps:
        ax1.plot(f.index, f[s.name], lw=0.9, label=f"{s.name} ({study.wall.probe(s.name).depth * 1000:.1f} mm)")
    if fluxes:
        ax2 = ax1.twinx()
        for s in fluxes:
            ax2.plot(f.index, f[s.name], lw=0.7, ls="--", label=f"{s.name} ({s.face} face)")
        ax2.set_ylabel("heat flux density [W/m2] (towards the interior)")
        ax2.legend(loc="upper right", fontsize=8)
    ax1.set_ylabel("temperature [degC]")
    ax1.legend(loc="upper left", fontsize=8)
    ax1.grid(alpha=0.3)
    ax1.set_title(f"{study.name}: measured signals over the comparison period")
    for face, b in (("exterior", study.exterior), ("interior", study.interior)):
        unit = "W/m2" if b.type == "heat_flux" else "degC"
        ax3.plot(f.index, f[face], lw=0.9, label=f"{b.column} ({face} boundary, {b.type.replace('_', ' ')}) [{unit}]")
    ax3.set_ylabel("boundary")
    ax3.legend(loc="upper left", fontsize=8)
    ax3.grid(alpha=0.3)
    ax3.set_xlabel("time (local standard time)")
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path

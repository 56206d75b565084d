"""Figures of a retrofit run (matplotlib, Agg; one PNG each)."""

from __future__ import annotations

import calendar
from pathlib import Path

import numpy as np


def _plt():
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    return plt


def plot_annual_loss(res, path: Path) -> None:
    """Annual loss per variant, with the 5-95 % interval of the posterior draws when there are any."""
    plt = _plt()
    tab = res.table()
    fig, ax = plt.subplots(figsize=(7.5, 0.6 + 0.55 * len(tab)))
    y = np.arange(len(tab))[::-1]
    ax.barh(y, tab["annual_loss_kWh_m2"], color="#6a8fc7", height=0.6)
    if tab["annual_loss_p05"].notna().any():
        lo = tab["annual_loss_kWh_m2"] - tab["annual_loss_p05"]
        hi = tab["annual_loss_p95"] - tab["annual_loss_kWh_m2"]
        ax.errorbar(
            tab["annual_loss_kWh_m2"],
            y,
            xerr=[lo, hi],
            fmt="none",
            ecolor="k",
            capsize=4,
        )
    right = tab["annual_loss_p95"].fillna(tab["annual_loss_kWh_m2"]).to_numpy()
    for yi, val, r, u in zip(y, tab["annual_loss_kWh_m2"], right, tab["U"], strict=True):
        ax.text(max(val, r), yi, f"  {val:.1f} (U {u:.3f})", va="center", fontsize=8)
    ax.set_yticks(y, tab["variant"])
    xl = "annual heat loss through the wall [kWh/m2] (net)"
    if tab["annual_loss_p05"].notna().any():
        xl += "\nwhiskers: 5-95 % of the annual loss over the posterior draws"
    ax.set_xlabel(xl, fontsize=9)
    ax.set_xlim(0, max(1e-9, float(np.nanmax(tab[["annual_loss_kWh_m2", "annual_loss_p95"]].to_numpy()))) * 1.45)
    ax.set_title(f"Annual loss per variant ({res.weather.name.removesuffix('.epw')})", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_glaser(res, path: Path) -> None:
    """Glaser diagram (p_sat and p against the cumulative s_d) of each variant's worst month."""
    plt = _plt()
    vs = [v for v in res.variants if v.glaser is not None]
    ncol = min(3, len(vs))
    nrow = -(-len(vs) // ncol)
    fig, axes = plt.subplots(nrow, ncol, figsize=(3.8 * ncol, 3.3 * nrow), squeeze=False)
    for ax in axes.flat[len(vs) :]:
        ax.set_visible(False)
    for ax, v in zip(axes.flat, vs, strict=False):
        g = v.glaser
        pr = g.profiles[g.worst_month]
        ax.plot(pr.s, pr.p_sat, "r-", lw=1.2, label="p_sat")
        ax.plot(pr.s, pr.p, "b-", lw=1.2, label="p")
        cond = pr.rate > 0
        ax.plot(pr.s[cond], pr.p[cond], "ko", ms=4, label="condensation")
        for i in g.sub.first_interface[1:-1]:
            ax.axvline(pr.s[i], color="0.85", lw=0.8, zorder=0)
        ax.set_xlabel("s_d from the exterior [m]", fontsize=8)
        ax.set_title(f"{v.spec.name}\n{calendar.month_abbr[g.worst_month]}: {g.verdict}", fontsize=9)
    for row in axes:
        row[0].set_ylabel("vapour pressure [Pa]")
    axes[0][0].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_accumulation(res, path: Path) -> None:
    """Accumulated condensate month by month (ISO 13788), each variant."""
    plt = _plt()
    fig, ax = plt.subplots(figsize=(7.5, 3.6))
    for v in res.variants:
        if v.glaser is None:
            continue
        t = v.glaser.table.sort_index()
        x = t.index.to_numpy()
        ax.plot(
            x, 1e3 * t["accumulated_kg_m2"].to_numpy(), marker="o", ms=3, label=f"{v.spec.name} ({v.glaser.verdict})"
        )
        ax.set_xticks(x, [calendar.month_abbr[m] for m in x])
    ax.set_ylabel("accumulated condensate [g/m2]")
    ax.set_xlabel("month (end-of-month amount)")
    ax.legend(fontsize=7)
    ax.set_title("ISO 13788 monthly method: accumulation", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def write_figures(res, d: Path) -> list[str]:
    files = ["annual_loss.png"]
    plot_annual_loss(res, d / "annual_loss.png")
    if any(v.glaser is not None for v in res.variants):
        plot_glaser(res, d / "glaser_worst_month.png")
        plot_accumulation(res, d / "accumulation.png")
        files += ["glaser_worst_month.png", "accumulation.png"]
    return files

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


def _grid(n: int, w: float = 4.2, h: float = 2.8):
    plt = _plt()
    ncol = min(2, n)
    nrow = -(-n // ncol)
    fig, axes = plt.subplots(nrow, ncol, figsize=(w * ncol, h * nrow), squeeze=False)
    for ax in axes.flat[n:]:
        ax.set_visible(False)
    return plt, fig, axes


def plot_moisture_critical(res, path: Path) -> None:
    """Hourly RH and mould index at each variant's critical interface over the last (periodic) year."""
    from .moisture_risk import DRY_RH, MOULD_LIMIT

    vs = [v for v in res.variants if v.hygro is not None and v.hygro.critical is not None]
    plt, fig, axes = _grid(len(vs))
    for ax, v in zip(axes.flat, vs, strict=False):
        h = v.hygro
        k = h.critical
        days = np.arange(h.rh.shape[1]) / 24.0
        ax.plot(days, 100 * h.rh[k], color="#3b6fb6", lw=0.6, label="RH [%]")
        ax.axhline(100 * DRY_RH, color="#3b6fb6", ls=":", lw=0.8)
        ax.set_ylim(0, 105)
        ax.set_ylabel("RH [%]", fontsize=8, color="#3b6fb6")
        ax2 = ax.twinx()
        ax2.plot(days[1:], h.mould[k], color="#c0392b", lw=1.2, label="mould index")
        ax2.axhline(MOULD_LIMIT, color="#c0392b", ls=":", lw=0.8)
        ax2.set_ylim(0, max(2.0, 1.1 * float(h.mould[k].max())))
        ax2.set_ylabel("mould index M", fontsize=8, color="#c0392b")
        ax.set_xlabel("day of the periodic year", fontsize=8)
        ax.set_title(f"{v.spec.name}: {h.critical_name} ({h.verdict})", fontsize=9)
    fig.suptitle("Critical interface: hourly RH (blue, dotted 80 %) and mould index (red, dotted M = 1)", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_water_by_year(res, path: Path) -> None:
    """Water per layer [kg/m2] at the start of each year until the run is periodic, each variant."""
    vs = [v for v in res.variants if v.hygro is not None]
    plt, fig, axes = _grid(len(vs), h=2.6)
    for ax, v in zip(axes.flat, vs, strict=False):
        h = v.hygro
        years = np.arange(h.layer_water.shape[0])
        for j, lid in enumerate(h.layer_ids):
            ax.plot(years, h.layer_water[:, j], marker="o", ms=3, label=lid)
        ax.set_xlabel("year (0 = start)", fontsize=8)
        ax.set_ylabel("water [kg/m2]", fontsize=8)
        ax.set_xticks(years)
        ax.set_title(f"{v.spec.name}: {h.years} years" + ("" if h.periodic else " (not periodic)"), fontsize=9)
        ax.legend(fontsize=6, ncol=2)
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
    if any(v.hygro is not None and v.hygro.critical is not None for v in res.variants):
        plot_moisture_critical(res, d / "moisture_critical.png")
        files.append("moisture_critical.png")
    if any(v.hygro is not None for v in res.variants):
        plot_water_by_year(res, d / "water_by_year.png")
        files.append("water_by_year.png")
    return files

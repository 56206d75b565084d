"""The HTML report of ``wallcal run``: one self-contained ``index.html`` (figures embedded).

Readable by a building physicist who did not run the study: a summary first (what
was measured, how well the base case fits, what calibration changed, how well each
property is identified, the U-value and dynamic figures before and after), then one
section per stage with its tables and figures, and where its machine-readable results are.
"""

from __future__ import annotations

import base64
import html
import math
import time
from pathlib import Path

import numpy as np
import pandas as pd

CSS = """
body{font-family:system-ui,-apple-system,Segoe UI,Roboto,sans-serif;margin:0;color:#1d2329;background:#f6f7f9}
header{background:#233044;color:#fff;padding:18px 32px}
header h1{margin:0 0 4px 0;font-size:24px} header p{margin:2px 0;color:#c9d3e0;font-size:13px}
main{max-width:1180px;margin:0 auto;padding:16px 32px 48px}
nav{background:#fff;border:1px solid #dde2e8;border-radius:6px;padding:10px 16px;margin:14px 0}
nav a{margin-right:14px;color:#2457a6;text-decoration:none;font-size:14px}
section{background:#fff;border:1px solid #dde2e8;border-radius:6px;padding:14px 22px;margin:16px 0}
h2{font-size:19px;margin:6px 0 10px} h3{font-size:15px;margin:14px 0 6px;color:#33414f}
table{border-collapse:collapse;font-size:13px;margin:6px 0 12px}
th,td{border-bottom:1px solid #e5e8ec;padding:3px 9px;text-align:right;white-space:nowrap}
th{background:#f0f3f6;font-weight:600} td.l,th.l{text-align:left}
figure{margin:8px 0 16px} figure img{max-width:100%;border:1px solid #e5e8ec}
figcaption{font-size:13px;color:#4a5562;margin-top:4px}
.status{display:inline-block;font-size:12px;padding:1px 8px;border-radius:10px;margin-left:8px;vertical-align:middle}
.ok{background:#dff3e4;color:#1d6b35} .failed{background:#fbe1df;color:#9b2317}
.skipped{background:#eceff3;color:#4a5562}
.summary li{margin:5px 0} .files{font-size:12px;color:#5a6570} .note{color:#7a4a00}
"""


def _fmt(v) -> str:
    if isinstance(v, (bool, np.bool_)):
        return "yes" if v else "no"
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    if isinstance(v, (float, np.floating)):
        v = float(v)
        if math.isnan(v):
            return "-"
        if v != 0 and (abs(v) >= 1e5 or abs(v) < 1e-3):
            return f"{v:.3e}"
        if abs(v) >= 100:
            return f"{v:.1f}"
        return f"{v:.4g}"
    return html.escape(str(v))


def table_html(df: pd.DataFrame, percent: tuple[str, ...] = ()) -> str:
    idx_names = [n for n in (df.index.names or []) if n] or [""]
    head = "".join(f'<th class="l">{html.escape(str(n))}</th>' for n in idx_names)
    head += "".join(f"<th>{html.escape(str(c))}{' %' if c in percent else ''}</th>" for c in df.columns)
    rows = []
    for tup in df.itertuples(index=True, name=None):  # keeps each column's own type (counts stay integers)
        idx, values = tup[0], tup[1:]
        idx_t = idx if isinstance(idx, tuple) else (idx,)
        cells = "".join(f'<td class="l">{html.escape(str(i))}</td>' for i in idx_t)
        for c, v in zip(df.columns, values, strict=True):
            if c in percent and isinstance(v, (float, np.floating)) and not math.isnan(v):
                cells += f"<td>{100 * float(v):.1f}</td>"
            else:
                cells += f"<td>{_fmt(v)}</td>"
        rows.append(f"<tr>{cells}</tr>")
    return f"<table><thead><tr>{head}</tr></thead><tbody>{''.join(rows)}</tbody></table>"


def figure_html(title: str, path: Path) -> str:
    path = Path(path)
    if not path.exists():
        return f'<p class="note">Figure missing: {html.escape(path.name)}</p>'
    data = base64.b64encode(path.read_bytes()).decode()
    return (
        f'<figure><img alt="{html.escape(title)}" src="data:image/png;base64,{data}">'
        f"<figcaption>{html.escape(title)}</figcaption></figure>"
    )


def moisture_figures(study, d: Path, result=None, engine: str | None = None) -> list[tuple[str, Path]]:
    """The moisture figures of a ``ham`` study: measured vs simulated relative humidity at each humidity
    sensor (``moisture_rh.png``) and the water content and RH profiles across the wall at six times of the
    comparison period (``moisture_profiles.png``, from the engine's cell states: ``profiles`` requested).

    Parameters
    ----------
    study : Study
        A moisture study (``study.has_moisture``).
    d : Path
        Where the PNG files go.
    result : SimulationResult, optional
        A run of the study with its engine; run again here when it holds no profiles.
    engine : str, optional
        The engine that ran ``result`` (and runs it again); default the study's.
    """
    import dataclasses

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from .simulation import simulate

    if result is None or result.profiles is None:
        study_p = dataclasses.replace(study, simulation=dataclasses.replace(study.simulation, profiles=True))
        result = simulate(study_p, engine=engine or study.simulation.engine)
    d = Path(d)
    figs = []
    rh = [s for s in study.sensors if s.quantity == "relative_humidity"]
    if rh:
        fig, ax = plt.subplots(figsize=(11, 4.5), layout="constrained")
        for k, s in enumerate(rh):
            c = f"C{k}"
            ax.plot(result.measured.index, result.measured[s.name], color=c, lw=0.8, label=f"{s.name} measured")
            ax.plot(result.simulated.index, result.simulated[s.name], color=c, lw=1.2, ls="--", label="simulated")
        ax.set_ylabel("relative humidity [-]")
        ax.set_xlabel("time (local standard time)")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8, ncol=2)
        ax.set_title(f"{study.name}: measured vs simulated relative humidity")
        fig.savefig(d / "moisture_rh.png", dpi=100)
        plt.close(fig)
        figs.append(("Measured (solid) vs simulated (dashed) relative humidity", d / "moisture_rh.png"))
    prof = result.profiles
    if prof is not None and len(prof):
        times = np.unique(prof["time_s"].to_numpy())
        pick = times[np.linspace(0, len(times) - 1, 6).round().astype(int)]
        t0 = pd.Timestamp(result.simulated.index[0]) - pd.Timedelta(seconds=float(times[0]))
        fig, (aw, ar) = plt.subplots(1, 2, figsize=(11, 4.2), layout="constrained")
        for k, t in enumerate(pick):
            p = prof[prof["time_s"] == t]
            label = f"{t0 + pd.Timedelta(seconds=float(t)):%Y-%m-%d %H:%M}"
            aw.plot(p["x_m"] * 1000, p["water_content"], color=f"C{k}", label=label)
            ar.plot(p["x_m"] * 1000, p["relative_humidity"], color=f"C{k}", label=label)
        for li, x in enumerate(np.cumsum([layer.thickness for layer in study.wall.layers])[:-1]):
            for ax in (aw, ar):
                ax.axvline(x * 1000, color="0.6", lw=0.7, ls=":", label="layer interface" if li == 0 else None)
        aw.set_ylabel("water content [kg/m3]")
        ar.set_ylabel("relative humidity [-]")
        for ax in (aw, ar):
            ax.set_xlabel("x from the exterior face [mm]")
            ax.grid(alpha=0.3)
        aw.legend(fontsize=8)
        fig.suptitle(f"{study.name}: profiles across the wall (ham engine's cell states)")
        fig.savefig(d / "moisture_profiles.png", dpi=100)
        plt.close(fig)
        figs.append(("Water content and relative humidity across the wall at six times", d / "moisture_profiles.png"))
    return figs


#: title of the calibration stage's table of the fitted period beside the held-out window
HELD_OUT_TITLE = "RMSE per sensor: fitted period and held-out validation window (no fit saw it)"


def held_out_table(fitted_rmse: pd.Series, validation: pd.DataFrame) -> pd.DataFrame:
    """The fitted period's RMSE beside the held-out window's (``validation.csv``: rmse, mbe, n), one row per
    sensor."""
    v = validation.set_index("sensor")
    out = pd.DataFrame({"fitted RMSE": fitted_rmse.reindex(v.index)})
    out["held-out RMSE"] = v["rmse"]
    out["held-out MBE"] = v["mbe"]
    out["held-out n"] = v["n"].astype(int)
    out.index.name = "sensor"
    return out


def _held_out_summary(study, stage) -> str | None:
    """The summary's sentence on the held-out window, from the calibration stage's table (None without one)."""
    t = next((df for title, df, _ in stage.tables if title == HELD_OUT_TITLE), None)
    if t is None or study.period.validation is None:
        return None
    vs, ve = study.period.validation
    parts = "; ".join(f"{sig} {r['fitted RMSE']:.3f} -> {r['held-out RMSE']:.3f}" for sig, r in t.iterrows())
    return (
        f"<b>Held-out window</b> {html.escape(str(vs))} to {html.escape(str(ve))} (no fit saw it). RMSE fitted "
        f"period -&gt; held-out window: {html.escape(parts)}."
    )


def _summary(study, outputs) -> str:
    by = {o.name: o for o in outputs}
    items = []
    d = by.get("data")
    if d and d.status == "ok" and d.tables:
        summ = d.tables[0][1]
        temps = [s.name for s in study.sensors if s.quantity == "temperature"]
        rng = ", ".join(
            f"{t} {summ.loc[t, 'min']:.1f}..{summ.loc[t, 'max']:.1f} degC" for t in temps if t in summ.index
        )
        items.append(
            f"<b>Measured.</b> {html.escape(study.wall.name or 'The wall')}: {len(study.wall.layers)} layers, "
            f"{study.wall.thickness * 100:.1f} cm; probes {html.escape(rng)}; period {study.period.start} to "
            f"{study.period.end}"
            + (
                f", of which {study.period.validation[0]} to {study.period.validation[1]} held out for validation."
                if study.period.validation is not None
                else "."
            )
        )
    e = by.get("engines")
    if e and e.status == "ok" and e.text:
        items.append("<b>Base case.</b> " + html.escape(e.text[0]))
    c = by.get("calibration")
    if c and c.status == "ok":
        items.append("<b>Calibration.</b> " + html.escape(c.text[0] if c.text else ""))
        rm = c.tables[1][1]
        parts = []
        for sig, r in rm.iterrows():
            floor = r.get("noise floor (reference wall)", float("nan"))
            parts.append(
                f"{sig} {r['base']:.3f} -> {r['calibrated']:.3f}"
                + (f" (floor {floor:.3f})" if isinstance(floor, float) and not math.isnan(floor) else "")
            )
        items.append("<b>RMSE before -> after.</b> " + html.escape("; ".join(parts)) + ".")
        held = _held_out_summary(study, c)
        if held:
            items.append(held)
    g = by.get("diagnose")
    if g and g.status == "ok" and g.text:
        items.append("<b>Model structure.</b> " + html.escape(g.text[0]))
    i = by.get("identifiability")
    if i and i.status == "ok" and i.text:
        items.append("<b>Identifiability.</b> " + html.escape(i.text[0]))
    elif i:
        items.append("<b>Identifiability.</b> not evaluated (" + html.escape(i.message or i.status) + ").")
    s = by.get("standards")
    if s and s.status == "ok" and s.tables:
        wf = s.tables[0][1]
        u = wf.loc[[r for r in wf.index if r.startswith("U ")][0]]
        shift = wf.loc["time shift [h]"]
        f = wf.loc["decrement factor [-]"]
        txt = "; ".join(
            f"{col}: U {u[col]:.3f} W/(m2K), decrement factor {f[col]:.3f}, time shift {shift[col]:.1f} h"
            for col in wf.columns
        )
        caveat = ""
        if i and i.status == "ok" and i.text and "common_scale" in i.text[0]:
            caveat = (
                " The calibrated U rests on a direction the temperatures cannot fix (the common scale of all "
                "conductivities and heat capacities): add a heat-flux sensor to the targets to identify it."
            )
        items.append("<b>Wall figures.</b> " + html.escape(txt + "." + caveat))
    r = by.get("retrofit")
    if r and r.status == "ok" and r.tables:
        vt = r.tables[0][1]
        items.append(
            "<b>Retrofit.</b> "
            + html.escape(
                "; ".join(
                    f"{name}: U {row['U']:.3f} W/(m2K), {row['annual_loss_kWh_m2']:.1f} kWh/m2 a year"
                    + (
                        f" (5-95 %: {row['annual_loss_p05']:.1f}..{row['annual_loss_p95']:.1f})"
                        if row["annual_loss_p05"] == row["annual_loss_p05"]
                        else ""
                    )
                    + ", "
                    f"condensation {row['condensation_verdict'] or 'not checked'}"
                    + (
                        f", moisture {row['moisture_verdict']} (mould index {row['mould_index_max']:.2f} at "
                        f"{row['critical_interface']})"
                        if row.get("moisture_verdict", "")
                        else ""
                    )
                    for name, row in vt.iterrows()
                )
                + "."
            )
        )
    b = by.get("building")
    if b and b.status == "ok" and b.tables:
        bt = b.tables[0][1]
        items.append(
            "<b>Building.</b> "
            + html.escape(
                "; ".join(
                    f"{name}: heating {row['heating_kWh_m2']:.1f}, cooling {row['cooling_kWh_m2']:.1f} kWh/m2"
                    for name, row in bt.head(3).iterrows()
                )
                + (f" (and {len(bt) - 3} more walls)" if len(bt) > 3 else "")
                + "."
            )
        )
    failed = [o for o in outputs if o.status == "failed"]
    if failed:
        items.append(
            '<span class="note"><b>Stages that failed:</b> '
            + html.escape("; ".join(f"{o.title}: {o.message}" for o in failed))
            + "</span>"
        )
    return "<ul class='summary'>" + "".join(f"<li>{x}</li>" for x in items) + "</ul>"


def write_report(study, outputs, path: Path, seconds: float | None = None) -> Path:
    """Write the self-contained HTML report."""
    from . import __version__

    nav = "".join(f'<a href="#{o.name}">{html.escape(o.title)}</a>' for o in outputs)
    secs = []
    for o in outputs:
        body = [f'<h2 id="{o.name}">{html.escape(o.title)}<span class="status {o.status}">{o.status}</span></h2>']
        if o.message:
            body.append(f'<p class="note">{html.escape(o.message)}</p>')
        body += [f"<p>{html.escape(t)}</p>" for t in o.text]
        for title, df, pct in o.tables:
            body.append(f"<h3>{html.escape(title)}</h3>{table_html(df, pct)}")
        body += [figure_html(t, p) for t, p in o.figures]
        if o.files:
            body.append(
                f'<p class="files">Machine-readable results: {html.escape(o.name)}/'
                + ", ".join(html.escape(f) for f in o.files)
                + f" ({o.seconds:.1f} s)</p>"
            )
        secs.append(f"<section>{''.join(body)}</section>")
    when = time.strftime("%Y-%m-%d %H:%M")
    doc = f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><meta name="viewport" content="width=device-width, initial-scale=1">
<title>wallcal report: {html.escape(study.name)}</title><style>{CSS}</style></head>
<body><header><h1>{html.escape(study.name or "wallcal study")}</h1>
<p>{html.escape(study.description)}</p>
<p>wallcal {html.escape(__version__)} &middot; {when} &middot; study {html.escape(str(study.path or ""))}
(sha256 {html.escape(study.sha256[:12])})
{f"&middot; {seconds:.0f} s" if seconds is not None else ""}</p></header>
<main><nav>{nav}</nav>
<section id="summary"><h2>Summary</h2>{_summary(study, outputs)}</section>
{"".join(secs)}
</main></body></html>
"""
    Path(path).write_text(doc, encoding="utf-8")
    return Path(path)

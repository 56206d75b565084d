"""Plain-text numbers and tables (the terminal's tables, the text of verdicts and summaries).

A library module: the CLI (``commands/``) and library modules alike use it.
"""

from __future__ import annotations

import math

import pandas as pd


def fmt(v, digits: int = 4) -> str:
    """A number as a table shows it: ``digits`` significant digits, scientific notation when tiny or
    huge, ``-`` for NaN, ``yes``/``no`` for booleans."""
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return "-"
        if v != 0 and (abs(v) >= 1e5 or abs(v) < 1e-3):
            return f"{v:.{digits - 1}e}"
        return f"{v:.{digits}g}" if abs(v) >= 1 else f"{v:.{digits - 1}f}".rstrip("0").rstrip(".") or "0"
    return str(v)


def table(df: pd.DataFrame, title: str | None = None, index: bool = True, percent: tuple[str, ...] = ()) -> str:
    """Render a DataFrame as an aligned text table; ``percent`` columns are shown as %."""
    cols = list(df.columns)
    head = ([df.index.name or ""] if index else []) + [str(c) + (" %" if c in percent else "") for c in cols]
    rows = []
    for idx, r in df.iterrows():
        cells = [str(idx)] if index else []
        for c in cols:
            v = r[c]
            if c in percent and isinstance(v, float) and not math.isnan(v):
                cells.append(f"{100 * v:.1f}")
            else:
                cells.append(fmt(v.item() if hasattr(v, "item") else v))
        rows.append(cells)
    widths = [max(len(h), *(len(r[i]) for r in rows)) if rows else len(h) for i, h in enumerate(head)]
    lines = []
    if title:
        lines.append(title)
    lines.append("  ".join(h.rjust(w) for h, w in zip(head, widths, strict=True)))
    lines.append("  ".join("-" * w for w in widths))
    for r in rows:
        lines.append("  ".join(c.rjust(w) for c, w in zip(r, widths, strict=True)))
    return "\n".join(lines)

"""Issue 38's classic case (examples/retrofit_classic/): a solid brick wall (0.365 m `solid brick`, 0.015 m
`lime plaster`) given with --wall, the bundled example's [retrofit] settings and the shipped Chicago weather file,
with four retrofit variants (80 mm mineral wool + plasterboard inside, the same with a vapour control layer, 60 mm
calcium silicate board inside, 100 mm EPS outside). Runs `wallcal retrofit` and prints the moisture columns of
variants.csv.

Usage: python bench/retrofit_classic.py [--interior-climate "constant" | "EN 15026 normal" | "EN 15026 high"]
[--set 'KEY = VALUE' ...]

``--interior-climate`` replaces the example's ``moisture_interior_climate``; ``--set`` adds (or replaces) a line
of the ``[retrofit]`` table, e.g. ``--set 'mould_sensitivity = { plaster = "sensitive" }'`` or ``--set
'driving_rain_factor = 2.0'`` (the sensitivity columns of docs/retrofit.md). About 20 s each.
"""

from __future__ import annotations

import argparse
import re
import tempfile
from pathlib import Path

import pandas as pd

REPO = Path(__file__).resolve().parents[1]
EXAMPLE = REPO / "src" / "wallcal" / "examples" / "campaign_a" / "study.toml"

#: the wall and its variants, shipped as an example
CLASSIC = REPO / "examples" / "retrofit_classic"

COLUMNS = [
    "condensation_verdict",
    "critical_interface",
    "max_relative_humidity_critical",
    "mould_index_max",
    "water_content_trend_kg_m2_per_year",
    "moisture_years",
    "moisture_verdict",
]


def write_classic(tmp: Path, interior_climate: str | None = None, lines: tuple[str, ...] = ()) -> tuple[Path, Path]:
    """The classic case's study and wall files in ``tmp``: the bundled example's ``[retrofit]`` settings (its
    ``moisture_interior_climate`` replaced by ``interior_climate``, ``lines`` added or replacing theirs) and
    the classic variants. Returns (study, wall)."""
    text = EXAMPLE.read_text()
    head, _, rest = text.partition("\n[retrofit]\n")
    settings = rest.partition("[[retrofit.variants]]")[0]
    if interior_climate is not None:
        settings = re.sub(r"(?m)^moisture_interior_climate = .*$", "", settings)
        settings += f"moisture_interior_climate = {interior_climate!r}\n".replace("'", '"')
    for line in lines:
        key = line.partition("=")[0].strip()
        settings = re.sub(rf"(?m)^{re.escape(key)} = .*$", "", settings) + line + "\n"
    head = head.replace('file = "measured.csv"', f'file = "{(EXAMPLE.parent / "measured.csv").as_posix()}"')
    head = head.replace('reference_wall = "true_wall.toml"', "")
    variants = (CLASSIC / "variants.toml").read_text()
    (tmp / "study.toml").write_text(head + "\n[retrofit]\n" + settings + variants)
    (tmp / "brick.toml").write_text((CLASSIC / "brick_wall.toml").read_text())
    return tmp / "study.toml", tmp / "brick.toml"


def main() -> None:
    from wallcal.cli import main as wallcal

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--interior-climate", help="replaces the example's [retrofit] moisture_interior_climate")
    ap.add_argument("--set", action="append", default=[], metavar="'KEY = VALUE'", help="a [retrofit] line")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        study, wall = write_classic(tmp, args.interior_climate, tuple(args.set))
        code = wallcal(["retrofit", str(study), "--wall", str(wall), "--out", str(tmp / "out")])
        if code != 0:
            raise SystemExit(code)
        tab = pd.read_csv(tmp / "out" / "variants.csv").set_index("variant")
        pd.set_option("display.width", 200)
        print(tab[[c for c in COLUMNS if c in tab.columns]].to_string())


if __name__ == "__main__":
    main()

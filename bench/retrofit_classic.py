"""Issue 38's classic case: a solid brick wall (0.365 m `solid brick`, 0.015 m `lime plaster`) given with --wall,
the bundled example's [retrofit] settings and the shipped Chicago weather file, with four retrofit variants
(80 mm mineral wool + plasterboard inside, the same with a vapour control layer, 60 mm calcium silicate board
inside, 100 mm EPS outside). Runs `wallcal retrofit` and prints the moisture columns of variants.csv.

Usage: python bench/retrofit_classic.py   (a few minutes: the vapour control layer variant alone takes ~100 s)
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import pandas as pd

REPO = Path(__file__).resolve().parents[1]
EXAMPLE = REPO / "src" / "wallcal" / "examples" / "campaign_a" / "study.toml"

BRICK_WALL = """
[wall]
name = "solid brick wall"

[[wall.layers]]
id = "brick"
material = "solid brick"
thickness = 0.365

[[wall.layers]]
id = "plaster"
material = "lime plaster"
thickness = 0.015
"""

VARIANTS = """
[[retrofit.variants]]
name = "as built"

[[retrofit.variants]]
name = "wool 80 + board"
add_interior = [{ material = "mineral wool", thickness = 0.08 },
                { material = "gypsum plasterboard", thickness = 0.0125 }]

[[retrofit.variants]]
name = "wool 80 + VCL + board"
add_interior = [{ material = "mineral wool", thickness = 0.08 },
                { material = "vapour control layer", thickness = 0.0002 },
                { material = "gypsum plasterboard", thickness = 0.0125 }]

[[retrofit.variants]]
name = "calcium silicate 60"
add_interior = [{ material = "calcium silicate board", thickness = 0.06 }]

[[retrofit.variants]]
name = "EPS 100 outside"
add_exterior = [{ material = "EPS", thickness = 0.10 }]
"""

COLUMNS = [
    "critical_interface",
    "max_relative_humidity_critical",
    "mould_index_max",
    "water_content_trend_kg_m2_per_year",
    "moisture_years",
    "moisture_verdict",
]


def main() -> None:
    from wallcal.cli import main as wallcal

    text = EXAMPLE.read_text()
    head, _, rest = text.partition("\n[retrofit]\n")
    settings = rest.partition("[[retrofit.variants]]")[0]
    head = head.replace('file = "measured.csv"', f'file = "{(EXAMPLE.parent / "measured.csv").as_posix()}"')
    head = head.replace('reference_wall = "true_wall.toml"', "")
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        (tmp / "study.toml").write_text(head + "\n[retrofit]\n" + settings + VARIANTS)
        (tmp / "brick.toml").write_text(BRICK_WALL)
        code = wallcal(
            ["retrofit", str(tmp / "study.toml"), "--wall", str(tmp / "brick.toml"), "--out", str(tmp / "out")]
        )
        if code != 0:
            raise SystemExit(code)
        tab = pd.read_csv(tmp / "out" / "variants.csv").set_index("variant")
        print(tab[[c for c in COLUMNS if c in tab.columns]].to_string())


if __name__ == "__main__":
    main()

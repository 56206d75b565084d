"""Short copies of the bundled example for the executor tests: 1 day at 180 s, a 2-parameter calibration."""

from __future__ import annotations

import re
import shutil
from pathlib import Path

from conftest import EXAMPLE

PERIOD = "warmup_start = 2025-05-23T00:00:00\nstart = 2025-05-30T00:00:00\nend = 2025-06-07T00:00:00"

SMALL_CALIBRATION = """[calibration]
targets = ["T3A", "T2A", "T1A"]
objective = "cse"
algorithm = "pso-hj"
seed = {seed}

[calibration.settings]
particles = 6
generations = 3
step_reductions = 1
polish = false

[[calibration.parameters]]
layers = ["3"]
property = "conductivity"
bounds = [-0.2, 0.2]

[[calibration.parameters]]
layers = ["7"]
property = "conductivity"
bounds = [-0.5, 2.0]
"""


def short_study(dest: Path, name: str = "short", *, days: int = 1, engine: str = "fd-cn", seed: int = 1) -> Path:
    """``dest/name.toml``: the example over ``days`` days from 30 May at 180 s steps with a small calibration
    (layer 3 and layer 7 conductivities), its data copied beside it (``dest`` is created once)."""
    if not dest.exists():
        shutil.copytree(EXAMPLE.parent, dest)
    text = (EXAMPLE.parent / "study.toml").read_text()
    assert PERIOD in text
    end = f"2025-05-{30 + days:02d}T00:00:00" if days <= 1 else f"2025-06-{days - 1:02d}T00:00:00"
    text = text.replace(PERIOD, f"warmup_start = 2025-05-29T00:00:00\nstart = 2025-05-30T00:00:00\nend = {end}")
    text = text.replace("time_step = 60 ", "time_step = 180 ")
    text = text.replace('engine = "fd-cn"', f'engine = "{engine}"')
    head, rest = text.split("[calibration]", 1)
    tail = rest[rest.index("[retrofit]") :] if "[retrofit]" in rest else ""
    text = head + SMALL_CALIBRATION.format(seed=seed) + "\n" + tail
    text = re.sub(r'reference_wall = "true_wall.toml".*\n', "", text)
    path = dest / f"{name}.toml"
    path.write_text(text)
    return path

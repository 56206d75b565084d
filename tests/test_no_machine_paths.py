"""No tracked file carries a path of one machine (a home folder, a work folder, a temporary folder).

Paths in the repository are relative (to the repository root or to a study file); a path that only exists on
the machine of whoever wrote it breaks on every other. The patterns below are assembled from pieces so this
file does not match itself. A legitimate use (an example in a doc of what not to write, a system device) goes
into :data:`ALLOWED` as (file, text on the line).
"""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SEP = "/"
#: Absolute paths of one machine: home folders, a work folder, a temporary folder used as a project path,
#: Windows user folders.
PATTERNS = [
    re.compile(r"(?<![\w.~-])" + SEP + name + SEP + r"[\w.~-]")
    for name in ("home", "Users", "work", "tmp", "root", "mnt", "srv")
] + [re.compile(r"\b[A-Za-z]:\\{1,2}" + "Users" + r"\\{1,2}", re.IGNORECASE)]
#: (file relative to the repository root, text on the offending line) pairs that are legitimate.
ALLOWED: set[tuple[str, str]] = set()
TEXT_SUFFIXES = {
    ".py", ".md", ".toml", ".txt", ".cfg", ".ini", ".yml", ".yaml", ".json", ".csv", ".html", ".js", ".css",
    ".sh", ".rst", ".idf", ".tsv", "",
}  # fmt: skip


def _tracked() -> list[str]:
    try:
        out = subprocess.run(["git", "ls-files", "-z"], cwd=ROOT, capture_output=True, check=True, text=True).stdout
    except (OSError, subprocess.CalledProcessError):
        pytest.skip("not a git checkout")
    return [f for f in out.split("\0") if f]


def offending(text: str, rel: str) -> list[str]:
    """The lines of ``text`` (file ``rel``) with a machine path, as ``rel:line: text``."""
    out = []
    for i, line in enumerate(text.splitlines(), 1):
        if any(p.search(line) for p in PATTERNS) and not any(f == rel and snippet in line for f, snippet in ALLOWED):
            out.append(f"{rel}:{i}: {line.strip()[:160]}")
    return out


def test_patterns_catch_machine_paths_and_spare_system_ones():
    bad = [
        "see " + SEP + "home" + SEP + "ann/x.csv",
        "--workdir " + SEP + "work" + SEP + "tmp/a",
        "C:" + "\\" + "Users" + "\\" + "ann",
        "cd " + SEP + "tmp" + SEP + "run1",
        SEP + "Users" + SEP + "bob/d",
    ]
    good = ["dd if=/dev/zero", "/proc/self/status", "../shared/data/campaign_a", "bench/tmp/x", "a/homework/b"]
    assert all(offending(b, "x") for b in bad)
    assert not any(offending(g, "x") for g in good)


def test_no_tracked_file_has_a_machine_path():
    hits = []
    for rel in _tracked():
        path = ROOT / rel
        if path.suffix.lower() not in TEXT_SUFFIXES or not path.is_file():
            continue
        try:
            text = path.read_text(encoding="utf-8")
        except (UnicodeDecodeError, OSError):
            continue
        hits += offending(text, rel)
    assert not hits, "machine paths in tracked files (make them relative):\n" + "\n".join(hits)

"""Mutation testing of wallcal's core modules with mutmut 3, one module at a time (``make mutate``).

Usage::

    python tools/mutate.py [MODULE ...]       # e.g. src/wallcal/metrics.py; default: every module of TESTS
    python tools/mutate.py --report            # summarise the last runs only
    python tools/mutate.py --recheck MODULE    # only re-run the mutants mutmut left "suspicious"

Each module is mutated in its own scratch copy ``.mutate/<module>/`` (the repository's src/, tests/ and
pyproject.toml plus a ``setup.cfg`` naming the module and its tests), with only the tests that exercise that
module (:data:`TESTS`), so a run costs minutes rather than hours. The scratch copy sits next to a ``shared``
link, so that the tests find ``../shared`` as they do in the repository. mutmut runs one worker under
``nice`` (the machine is shared). The summary (killed / total per module, and every mutant that survived,
timed out or was not covered) is written to ``.mutate/summary.txt`` and printed.

Numba-jitted functions (``@njit``) are not mutated: mutmut skips every decorated function, and a mutant of a
jitted function could not be switched on by mutmut's trampolines anyway (the compiled kernel never calls
back into Python). Those kernels are covered by the reference tests (EnergyPlus, analytic solutions).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
from collections import Counter
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
WORK = REPO / ".mutate"

#: module -> the test files that exercise it (the fastest relevant subset)
TESTS: dict[str, list[str]] = {
    "src/wallcal/metrics.py": ["tests/test_metrics.py"],
    "src/wallcal/wall.py": ["tests/test_wall.py", "tests/test_iso6946.py"],
    "src/wallcal/calibration/objective.py": ["tests/test_objective_reference.py", "tests/test_flux_at_depth.py"],
    "src/wallcal/standards/iso6946.py": ["tests/test_iso6946.py"],
    "src/wallcal/standards/iso10456.py": ["tests/test_iso10456.py"],
    "src/wallcal/standards/iso13786.py": ["tests/test_iso13786.py"],
    "src/wallcal/standards/iso9869.py": ["tests/test_iso9869.py"],
    "src/wallcal/standards/insitu.py": ["tests/test_cli_standards.py", "tests/test_insitu.py"],
    "src/wallcal/grid.py": ["tests/test_grid.py", "tests/test_reference_physics.py"],
    "src/wallcal/engines/operator.py": [
        "tests/test_theta_rule.py",
        "tests/test_extreme_walls.py",
        "tests/test_reference_engine.py",
    ],
}

STATUS = {1: "killed", 3: "killed", 0: "survived", 5: "no tests", 33: "no tests", 34: "skipped", 36: "timeout"}
STATUS.update({-24: "timeout", 24: "timeout", 152: "timeout", 255: "timeout", 37: "caught by type check"})


def slug(module: str) -> str:
    return module.removeprefix("src/wallcal/").removesuffix(".py").replace("/", ".")


def setup_cfg(module: str, tests: list[str]) -> str:
    lines = ["[mutmut]", "source_paths = src", f"only_mutate = {module}", "pytest_add_cli_args_test_selection ="]
    lines += [f"    {t}" for t in tests]
    lines += ["pytest_add_cli_args =", "    -q", "    -x", "    -p", "    no:cacheprovider"]
    # mutmut limits each mutant's CPU time (not wall time, so a load spike on the shared host does not count) to
    # 2 x multiplier x (the tests' estimated time + constant): about 2 min for these subsets, so that a mutant
    # that loops for ever (two of iso13786) is stopped and counted as detected
    lines += ["timeout_multiplier = 4", "timeout_constant = 15"]
    return "\n".join(lines) + "\n"


def prepare(module: str) -> Path:
    d = WORK / slug(module)
    tests = [t for t in TESTS[module] if (REPO / t).exists()]
    if not tests:
        raise SystemExit(f"{module}: none of its tests exist ({TESTS[module]})")
    d.mkdir(parents=True, exist_ok=True)
    for sub in ("src", "tests"):
        if (d / sub).exists():
            shutil.rmtree(d / sub)
        shutil.copytree(REPO / sub, d / sub, ignore=shutil.ignore_patterns("__pycache__", "*.nbi", "*.nbc"))
    shutil.copy2(REPO / "pyproject.toml", d / "pyproject.toml")
    (d / "setup.cfg").write_text(setup_cfg(module, tests))
    if (d / "mutants").exists():
        shutil.rmtree(d / "mutants")
    # the tests find ../shared next to the repository; the mutants run in d/mutants, so d/shared must exist
    shared = REPO.parent / "shared"
    link = d / "shared"
    if shared.exists() and not link.exists():
        link.symlink_to(shared.resolve())
    return d


def run(module: str) -> None:
    d = prepare(module)
    mutmut = Path(sys.executable).with_name("mutmut")
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "CI")}
    env["NUMBA_NUM_THREADS"] = "1"
    print(f"== {module}: mutmut in {d.relative_to(REPO)} with {TESTS[module]}", flush=True)
    subprocess.run(["nice", "-n", "15", str(mutmut), "run", "--max-children", "1"], cwd=d, env=env, check=False)


def results(module: str) -> dict:
    """Status of every mutant: mutmut's, with the plain-pytest re-runs of :func:`recheck` in place of its
    "suspicious" and "not checked" ones."""
    meta = WORK / slug(module) / "mutants" / (module + ".meta")
    if not meta.exists():
        return {}
    codes = json.loads(meta.read_text())["exit_code_by_key"]
    out = {k: STATUS.get(v, "not checked" if v is None else "suspicious") for k, v in codes.items()}
    rechecked = WORK / slug(module) / "recheck.json"
    if rechecked.exists():
        out.update({k: v for k, v in json.loads(rechecked.read_text()).items() if k in out})
    return out


def recheck(module: str) -> None:
    """Re-run every mutant that mutmut left "suspicious" (its forked worker ended by a signal: on this host
    mutmut's workers were sometimes sent SIGTERM a second after they started) or "not checked", one at a
    time with plain pytest in a fresh process (``MUTANT_UNDER_TEST`` switches the mutant on): exit status 0
    is a survivor, 1 a kill, 5 no tests. Results go to ``recheck.json`` next to the run."""
    d = WORK / slug(module)
    todo = sorted(k for k, v in results(module).items() if v in ("suspicious", "not checked"))
    if not todo:
        return
    path = d / "recheck.json"
    done = json.loads(path.read_text()) if path.exists() else {}
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "CI")}
    env.update(NUMBA_NUM_THREADS="1", PYTHONPATH="src")
    tests = [t for t in TESTS[module] if (REPO / t).exists()]
    print(f"== {module}: {len(todo)} mutants re-run with plain pytest", flush=True)
    for i, key in enumerate(todo):
        cmd = ["nice", "-n", "15", sys.executable, "-m", "pytest", "-x", "-q", "-p", "no:cacheprovider", *tests]
        try:
            code = subprocess.run(
                cmd, cwd=d / "mutants", env={**env, "MUTANT_UNDER_TEST": key}, capture_output=True, timeout=60
            ).returncode
        except subprocess.TimeoutExpired:
            code = 24
        done[key] = {0: "survived", 1: "killed", 5: "no tests"}.get(code, "timeout" if code == 24 else "suspicious")
        path.write_text(json.dumps(done, indent=0))  # progress is kept: an interrupted re-check resumes
        print(f"   {i + 1}/{len(todo)} {key.rpartition('.')[2]}: {done[key]}", flush=True)


def mutant_diffs(module: str) -> dict[str, str]:
    """The changed line of every mutant of ``module`` (``-old`` / ``+new``), read from mutmut's mutated file."""
    import ast
    import difflib

    path = WORK / slug(module) / "mutants" / module
    if not path.exists():
        return {}
    src = path.read_text()
    lines = src.split("\n")
    funcs = {}
    for node in ast.walk(ast.parse(src)):
        if isinstance(node, ast.FunctionDef) and "__mutmut_" in node.name:
            funcs[node.name] = lines[node.lineno : node.end_lineno]
    prefix = module.removeprefix("src/").removesuffix(".py").replace("/", ".")
    out = {}
    for name, body in funcs.items():
        base, _, k = name.rpartition("__mutmut_")
        if k == "orig" or f"{base}__mutmut_orig" not in funcs:
            continue
        old = funcs[f"{base}__mutmut_orig"]
        if len(old) == len(body):  # the usual case: one line changed
            d = [x for a, b in zip(old, body, strict=True) if a != b for x in ("-" + a, "+" + b)]
        else:
            d = [
                ln
                for ln in difflib.unified_diff(old, body, lineterm="", n=0)
                if ln[:1] in "-+" and ln[:3] not in ("---", "+++")
            ]
        out[f"{prefix}.{name}"] = " / ".join(" ".join(ln.split()) for ln in d)[:200]
    return out


def report(modules: list[str]) -> str:
    out = []
    tk = tn = 0
    for m in modules:
        r = results(m)
        if not r:
            out.append(f"{m}: not run")
            continue
        c = Counter(r.values())
        killed = c["killed"] + c["caught by type check"] + c["timeout"]  # a mutant that hangs the tests is detected
        tk, tn = tk + killed, tn + len(r)
        out.append(f"{m}: {killed}/{len(r)} killed ({100 * killed / len(r):.1f} %) " + dict(c).__repr__())
        diffs = mutant_diffs(m)
        for k, v in sorted(r.items()):
            if v not in ("killed", "caught by type check", "timeout"):
                out.append(f"    {v:10s} {k.rpartition('.')[2]}: {diffs.get(k, '?')}")
    if tn:
        out.append(f"all: {tk}/{tn} killed ({100 * tk / tn:.1f} %)")
    return "\n".join(out)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("modules", nargs="*", help="source files (default: every module of TESTS)")
    ap.add_argument("--report", action="store_true", help="only summarise the last runs")
    ap.add_argument("--recheck", action="store_true", help="only re-run the suspicious mutants of the last runs")
    a = ap.parse_args(argv)
    modules = a.modules or list(TESTS)
    unknown = [m for m in modules if m not in TESTS]
    if unknown:
        ap.error(f"no test selection for {unknown}; add them to TESTS in tools/mutate.py")
    if a.recheck:
        for m in modules:
            recheck(m)
    elif not a.report:
        for m in modules:
            run(m)
            recheck(m)
    text = report(modules)
    WORK.mkdir(exist_ok=True)
    (WORK / "summary.txt").write_text(text + "\n")
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())

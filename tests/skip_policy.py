"""Skip policy of the test suite: no test may stop running silently.

- With the environment variable ``CI`` set (to anything non-empty), a test that is skipped, xfailed or
  xpassed is turned into a failure unless it is on :data:`ALLOWED` below, matched by its node id and its
  reason. Each entry says why the skip is acceptable. The list is short on purpose: missing data, a
  missing browser or a missing optional package is not a reason (CI installs them; ``.ci/run``).
- Without ``CI`` (a developer's ``make test``), skips stay skips, but the end of the run lists which
  groups of tests did not run and why, so a green run that skipped the browser tests says so.

The hooks are imported by ``tests/conftest.py``; docs/testing.md describes the policy.
"""

from __future__ import annotations

import fnmatch
import os
from collections import defaultdict
from dataclasses import dataclass

import pytest


@dataclass(frozen=True)
class Allowed:
    """A skip CI accepts: ``nodeid`` (fnmatch pattern on the test's node id), ``reason`` (a substring of the
    skip/xfail reason) and ``why`` it is acceptable."""

    nodeid: str
    reason: str
    why: str


#: The allow-list. Keep it short; every entry needs its reason.
ALLOWED: tuple[Allowed, ...] = (
    Allowed(
        nodeid="*tests/test_reproducibility.py::*agrees_across_thread_counts*",
        reason="needs 2 numba threads",
        why="a runner with one CPU cannot start two numba threads; the same-thread determinism tests still run",
    ),
)

#: markers that name a group of tests (reported per group at the end of a run)
GROUP_MARKERS = ("browser", "energyplus", "slow")


def in_ci() -> bool:
    return bool(os.environ.get("CI", "").strip())


def skip_reason(report) -> str:
    """The reason of a skipped/xfailed/xpassed report, without pytest's "Skipped: " prefix."""
    if hasattr(report, "wasxfail"):
        return str(report.wasxfail) or "(xfail without a reason)"
    lr = report.longrepr
    text = lr[2] if isinstance(lr, tuple) and len(lr) == 3 else str(lr)
    return text.removeprefix("Skipped: ").strip() or "(skip without a reason)"


def allowed(nodeid: str, reason: str) -> Allowed | None:
    for a in ALLOWED:
        if fnmatch.fnmatchcase(nodeid, a.nodeid) and a.reason in reason:
            return a
    return None


def _kind(report) -> str | None:
    if hasattr(report, "wasxfail"):
        return "xfailed" if report.skipped else "xpassed"
    return "skipped" if report.skipped else None


def _enforce(report) -> None:
    kind = _kind(report)
    if kind is None or (kind == "xpassed" and report.failed):  # a strict XPASS already fails
        return
    reason = skip_reason(report)
    a = allowed(report.nodeid, reason)
    report.did_not_run = (kind, reason, a.why if a else None)
    if in_ci() and a is None:
        report.outcome = "failed"
        report.longrepr = (
            f"{kind} under CI: {reason}\n"
            "CI treats a skip, xfail or xpass as a failure unless it is on the allow-list in "
            "tests/skip_policy.py (with its reason); install what the test needs, fix the bug, or add an entry."
        )
        if hasattr(report, "wasxfail"):
            del report.wasxfail


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item, call):
    outcome = yield
    _enforce(outcome.get_result())


@pytest.hookimpl(hookwrapper=True)
def pytest_make_collect_report(collector):
    outcome = yield
    _enforce(outcome.get_result())


def _group(report) -> str:
    path = report.nodeid.split("::")[0]
    marks = [m for m in GROUP_MARKERS if m in getattr(report, "keywords", {})]
    return f"{path} [{','.join(marks)}]" if marks else path


def pytest_terminal_summary(terminalreporter, exitstatus, config):
    """At the end of every run: the groups of tests that did not run (skipped/xfailed/xpassed), and why."""
    groups: dict[tuple, int] = defaultdict(int)
    for key in ("skipped", "xfailed", "xpassed", "failed", "error"):
        for rep in terminalreporter.stats.get(key, []):
            if not hasattr(rep, "did_not_run"):
                continue
            kind, reason, why = rep.did_not_run
            groups[(_group(rep), kind, reason, why)] += 1
    if not groups:
        return
    tr = terminalreporter
    tr.section("tests that did not run" + (" (CI: failures unless allow-listed)" if in_ci() else ""))
    for (group, kind, reason, why), n in sorted(groups.items()):
        status = f"allowed in CI: {why}" if why else ("FAILED in CI" if in_ci() else "would fail under CI")
        tr.write_line(f"{n:4d} {kind:8s} {group}: {reason}  -- {status}")

"""The skip policy (tests/skip_policy.py): under CI a skip, xfail or xpass fails unless allow-listed."""

from __future__ import annotations

import pytest

import skip_policy

pytest_plugins = ["pytester"]

INNER = """
import pytest

def test_runs():
    pass

@pytest.mark.skipif(True, reason="needs a frobnicator")
def test_skipped():
    pass

@pytest.mark.xfail(reason="known bug", strict=True)
def test_xfailed():
    assert False

def test_skipped_inside():
    pytest.skip("no data")
"""


def _run(pytester, monkeypatch, ci: str | None, allow=()):
    if ci is None:
        monkeypatch.delenv("CI", raising=False)
    else:
        monkeypatch.setenv("CI", ci)
    monkeypatch.setattr(skip_policy, "ALLOWED", tuple(allow))
    pytester.makeconftest(
        "from skip_policy import pytest_make_collect_report, pytest_runtest_makereport, pytest_terminal_summary\n"
    )
    pytester.makepyfile(test_inner=INNER)
    return pytester.runpytest_inprocess("-p", "no:cacheprovider")


def test_without_ci_skips_stay_skips_and_are_listed(pytester, monkeypatch):
    r = _run(pytester, monkeypatch, None)
    r.assert_outcomes(passed=1, skipped=2, xfailed=1)
    out = r.stdout.str()
    assert "tests that did not run" in out
    assert "needs a frobnicator" in out and "would fail under CI" in out and "known bug" in out


def test_under_ci_every_unlisted_skip_fails(pytester, monkeypatch):
    r = _run(pytester, monkeypatch, "true")
    assert r.ret != 0
    out = r.stdout.str()
    # the skipif is evaluated in setup (an error), the others in the call (failures)
    r.assert_outcomes(passed=1, failed=2, errors=1)
    assert "skipped under CI: needs a frobnicator" in out
    assert "xfailed under CI: known bug" in out
    assert "FAILED in CI" in out


def test_under_ci_an_allow_listed_skip_passes_and_the_reason_must_match(pytester, monkeypatch):
    allow = [
        skip_policy.Allowed("*test_inner.py::test_skipped", "frobnicator", "no frobnicator on this platform"),
        skip_policy.Allowed("*test_inner.py::test_xfailed", "known bug", "documented"),
        # an entry for one reason does not excuse the same test skipping for another
        skip_policy.Allowed("*test_inner.py::test_skipped_inside", "another reason", "-"),
    ]
    r = _run(pytester, monkeypatch, "1", allow)
    r.assert_outcomes(passed=1, skipped=1, xfailed=1, failed=1)
    out = r.stdout.str()
    assert "allowed in CI: no frobnicator on this platform" in out
    assert "skipped under CI: no data" in out


def test_every_allow_list_entry_has_a_reason():
    for a in skip_policy.ALLOWED:
        assert a.nodeid and a.reason and len(a.why) > 20, a
    assert len(skip_policy.ALLOWED) <= 5  # short on purpose


@pytest.mark.parametrize("empty", ["", "  "])
def test_an_empty_ci_variable_is_not_ci(monkeypatch, empty):
    monkeypatch.setenv("CI", empty)
    assert not skip_policy.in_ci()


def test_the_allow_list_is_documented():
    from conftest import REPO

    doc = (REPO / "docs" / "testing.md").read_text()
    for a in skip_policy.ALLOWED:
        assert a.nodeid.lstrip("*") in doc and a.reason in doc and a.why in doc, a

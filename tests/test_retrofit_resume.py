"""``wallcal retrofit --from POSTERIOR``: the posterior draws run in chunks saved to a checkpoint beside --out, an
interrupted run continues with --resume to the outputs of an uninterrupted one, a checkpoint of other inputs is
refused in one line, and a progress line shows the draws."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from retrofit_helpers import study_with_retrofit, write_epw
from wallcal import load_study
from wallcal.cli import main
from wallcal.cluster import ClusterError
from wallcal.retrofitting import moisture_risk as mr
from wallcal.retrofitting import run as rr

SAMPLES = 4
REAL_DRAW = mr.draw_task
#: two variants, the example wall (hygric data) and an exterior board; two days of weather, at most 3 moisture years
BODY = (
    '[retrofit]\nweather = "w.epw"\nmoisture_max_years = 3\n'
    '[[retrofit.variants]]\nname = "as built"\n'
    '[[retrofit.variants]]\nname = "EPS"\nadd_exterior = [{ material = "EPS", thickness = 0.1 }]\n'
)


@pytest.fixture
def case(tmp_path, monkeypatch):
    """A small study with a [retrofit] table, its weather and a posterior output; chunks of 2 moisture draws."""
    from wallcal.analysis.posterior_outputs import write_samples
    from wallcal.calibration import parse_space

    h = np.arange(48)
    write_epw(tmp_path / "w.epw", 6.0 * np.sin(2 * np.pi * h / 24), rh=np.full(h.size, 85.0))
    study = study_with_retrofit(tmp_path, BODY)
    sp = parse_space(load_study(study))
    d = write_samples(tmp_path / "post", sp, np.random.default_rng(3).random((6, 4, sp.n)), burn=2)
    monkeypatch.setattr(rr, "DRAW_CHUNK_PER_WORKER", 2)
    return tmp_path, study, d


def _args(study, post, out, *extra):
    return ["retrofit", str(study), "--from", str(post), "--out", str(out), "--samples", str(SAMPLES), *extra]


def _count_draws(monkeypatch, stop_at=None, error=KeyboardInterrupt):
    """Count the moisture draws run (``calls[0]``); raise ``error`` at draw ``stop_at`` (1-based)."""
    calls = [0]

    def task(t):
        calls[0] += 1
        if calls[0] == stop_at:
            raise error("stopped by the test")
        return REAL_DRAW(t)

    monkeypatch.setattr(mr, "draw_task", task)
    return calls


def _interrupt(case, monkeypatch, capsys, out, stop_at=3):
    """Run and stop at moisture draw ``stop_at`` (3: the first draw of the first variant's second chunk)."""
    _, study, post = case
    _count_draws(monkeypatch, stop_at)
    code = main(_args(study, post, out, "--quiet"))
    monkeypatch.setattr(mr, "draw_task", REAL_DRAW)
    return code, capsys.readouterr()


def test_interrupted_run_resumes_to_the_uninterrupted_outputs(case, monkeypatch, capsys):
    """Ctrl-C at the first draw of the second chunk: exit 130, nothing in OUT, the first chunk in the checkpoint and
    the --resume command on stderr; --resume runs only the draws not done and writes the uninterrupted outputs
    exactly (each draw is deterministic), then removes the checkpoint."""
    tmp, study, post = case
    ref = tmp / "ref"
    calls = _count_draws(monkeypatch)
    assert main(_args(study, post, ref, "--quiet")) == 0
    assert calls[0] == 2 * SAMPLES
    capsys.readouterr()

    out = tmp / "out"
    ckpt = rr.checkpoint_path(out)
    assert ckpt == tmp / ".out.retrofit-checkpoint.npz"
    _count_draws(monkeypatch, stop_at=3)
    code = main(_args(study, post, out, "--quiet"))
    err = capsys.readouterr().err
    assert code == 130, err
    assert not out.exists()  # nothing partial where the results go
    assert sorted(p.name for p in tmp.glob(".out*")) == [ckpt.name]  # no temporary directory or file beside it
    assert str(ckpt) in err and "--resume" in err and f"--out {out}" in err, err
    with np.load(ckpt) as z:
        assert z["moisture_0"].shape == (2, 4)  # the first chunk of the first variant
        assert z["losses_0"].shape == (SAMPLES,) and "moisture_1" not in z.files and "losses_1" not in z.files

    calls = _count_draws(monkeypatch)
    batches = []
    real_year = rr.periodic_year

    def year(walls, *a, **k):
        batches.append(len(walls))
        return real_year(walls, *a, **k)

    monkeypatch.setattr(rr, "periodic_year", year)
    assert main(_args(study, post, out, "--quiet", "--resume")) == 0
    assert calls[0] == 2 * SAMPLES - 2  # the first chunk is not run again
    assert batches.count(1 + SAMPLES) == 1  # nor the first variant's thermal draws
    assert not ckpt.exists() and not list(tmp.glob(".out.*"))
    for name in ("variants.csv", "sample_losses.csv"):
        pd.testing.assert_frame_equal(pd.read_csv(out / name), pd.read_csv(ref / name), check_exact=True)
    got = pd.read_csv(out / "variants.csv")
    assert got["mould_index_max_p95"].notna().all()


def test_resume_of_a_complete_run_and_without_checkpoint(case, monkeypatch, capsys):
    """--resume without a checkpoint runs from the start (and says so); once complete, --resume says there is
    nothing to resume. A run without --resume replaces an earlier run's checkpoint."""
    tmp, study, post = case
    out = tmp / "out"
    assert main(_args(study, post, out, "--quiet", "--resume")) == 0
    assert "running from the start" in capsys.readouterr().err
    assert main(_args(study, post, out, "--quiet", "--resume")) == 0
    assert capsys.readouterr().out.startswith("nothing to resume:")

    out2 = tmp / "second"
    assert _interrupt(case, monkeypatch, capsys, out2)[0] == 130
    assert rr.checkpoint_path(out2).exists()
    assert main(_args(study, post, out2)) == 0  # afresh
    assert "replacing the checkpoint" in capsys.readouterr().err
    assert not rr.checkpoint_path(out2).exists()
    pd.testing.assert_frame_equal(pd.read_csv(out2 / "variants.csv"), pd.read_csv(out / "variants.csv"))


@pytest.mark.parametrize(
    "change, problem",
    [
        ("samples", "another number of draws"),
        ("weather", "another weather file"),
        ("damaged", "not a retrofit checkpoint"),
        ("study", "another study file"),
    ],
)
def test_checkpoint_that_does_not_fit_is_refused(case, monkeypatch, capsys, change, problem):
    """Exit 2, one line naming the checkpoint, the problem and how to start afresh; the checkpoint is left as it was
    and nothing is written to OUT."""
    tmp, study, post = case
    out = tmp / "out"
    assert _interrupt(case, monkeypatch, capsys, out)[0] == 130
    ckpt = rr.checkpoint_path(out)
    args = _args(study, post, out, "--quiet", "--resume")
    if change == "samples":
        args[args.index("--samples") + 1] = str(SAMPLES - 1)
    elif change == "weather":
        h = np.arange(48)
        write_epw(tmp / "w.epw", 5.0 * np.sin(2 * np.pi * h / 24), rh=np.full(h.size, 85.0))
    elif change == "damaged":
        ckpt.write_bytes(ckpt.read_bytes()[:100])
    elif change == "study":
        study.write_text(study.read_text().replace("moisture_max_years = 3", "moisture_max_years = 2"))
    before = ckpt.read_bytes()
    code = main(args)
    err = capsys.readouterr().err.strip()
    assert code == 2, err
    assert err.startswith("wallcal: error:") and "\n" not in err and len(err) <= 300, err
    assert ckpt.name in err and problem in err and "rerun without --resume" in err, err
    assert ckpt.read_bytes() == before and not out.exists()


def test_lost_cluster_keeps_the_draws_done(case, monkeypatch, capsys):
    """A task failing for good (a lost cluster, a killed worker): the error, then where the draws are and the
    --resume command; resuming completes."""
    tmp, study, post = case
    out = tmp / "out"
    _count_draws(monkeypatch, stop_at=4, error=ClusterError)
    assert main(_args(study, post, out, "--quiet")) == 2
    err = capsys.readouterr().err
    assert "stopped by the test" in err and "continue with:" in err and "--resume" in err, err
    calls = _count_draws(monkeypatch)
    assert main(_args(study, post, out, "--quiet", "--resume")) == 0
    assert calls[0] == 2 * SAMPLES - 2
    assert (out / "variants.csv").exists() and not rr.checkpoint_path(out).exists()


def test_progress_line_and_quiet(case, capsys):
    """While the draws run: draws done of the variant's, elapsed, estimated remaining, on stderr; none with --quiet."""
    tmp, study, post = case
    assert main(_args(study, post, tmp / "a")) == 0
    err = capsys.readouterr().err
    assert f"'as built' (1/2): moisture draws 0/{SAMPLES}" in err, err
    assert f"'EPS' (2/2): moisture draws {SAMPLES}/{SAMPLES}" in err, err
    assert " s left" in err, err
    assert main(_args(study, post, tmp / "b", "--quiet")) == 0
    assert "moisture draws" not in capsys.readouterr().err


def test_run_draws_skips_the_rows_done_and_reports_each_chunk(monkeypatch):
    """``run_draws(done=..., chunk=..., on_chunk=...)``: only the draws after ``done`` run, in chunks, and each chunk
    hands over every row so far."""
    ran = []

    def task(t):
        ran.append(t[0])
        return (float(t[0]), 0.0, 1, 0.0)

    monkeypatch.setattr(mr, "draw_task", task)
    seen = []
    done = np.array([[0.0, 0.0, 1, 0.0], [1.0, 0.0, 1, 0.0]])
    out = mr.run_draws(list(range(7)), None, None, done=done, chunk=2, on_chunk=lambda rows: seen.append(len(rows)))
    assert ran == [2, 3, 4, 5, 6]
    assert seen == [4, 6, 7]
    np.testing.assert_array_equal(out[:, 0], np.arange(7))


def test_ctrl_c_inside_a_numba_kernel_is_an_interruption(case, monkeypatch, capsys):
    """Ctrl-C while a numba kernel runs surfaces as a SystemError caused by the KeyboardInterrupt: the same exit 130
    and --resume command as a plain Ctrl-C, no traceback."""
    tmp, study, post = case
    out = tmp / "out"

    def kernel_interrupt(message):
        exc = SystemError(f"CPUDispatcher(run_ham) returned a result with an exception set ({message})")
        exc.__cause__ = KeyboardInterrupt()
        return exc

    _count_draws(monkeypatch, stop_at=3, error=kernel_interrupt)
    code = main(_args(study, post, out, "--quiet"))
    err = capsys.readouterr().err
    assert code == 130, err
    assert err.startswith("wallcal: interrupted;") and "--resume" in err and "Traceback" not in err, err
    assert rr.checkpoint_path(out).exists() and not out.exists()

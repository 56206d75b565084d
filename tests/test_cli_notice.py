"""The command line says when numba compiles the engine's kernels (the silent ~10 s of a first run after
installing), once, and says nothing for short compilations, loads from the cache or with --quiet."""

import io
import time

from numba.core import event

from wallcal import cli
from wallcal.commands import calibrate as calibrate_command


def _compile(seconds, nested=0.0):
    """numba's compile events around a pause (a compilation, nested ones inside it)."""
    event.start_event(cli.COMPILE_EVENT)
    if nested:
        event.start_event(cli.COMPILE_EVENT)
        time.sleep(nested)
        event.end_event(cli.COMPILE_EVENT)
    time.sleep(seconds)
    event.end_event(cli.COMPILE_EVENT)


def _said(notice, *compilations):
    with event.install_listener(cli.COMPILE_EVENT, notice):
        for c in compilations:
            _compile(*c)
        time.sleep(0.15 if notice.after < 0.15 else notice.after + 0.1)  # a timer left running would fire here
    notice.close()
    return notice.stream.getvalue()


def test_a_long_compilation_is_announced_once():
    out = _said(cli.CompileNotice(io.StringIO(), after=0.05), (0.8, 0.1), (0.8,))
    assert out == cli.CompileNotice.MESSAGE + "\n"


def test_short_compilations_say_nothing():
    assert _said(cli.CompileNotice(io.StringIO(), after=1.0), (0.02,), (0.02, 0.02), (0.02,)) == ""


def test_the_wait_counts_from_the_outermost_compilation():
    # a nested compilation shorter than `after`, inside one longer than it: announced
    assert _said(cli.CompileNotice(io.StringIO(), after=0.1), (0.8, 0.05)) == cli.CompileNotice.MESSAGE + "\n"


def test_the_command_line_announces_a_compilation_unless_quiet(monkeypatch, capsys, tmp_path):
    def fake_calibrate(args):
        _compile(0.8)
        return 0

    monkeypatch.setattr(calibrate_command, "run_calibrate", fake_calibrate)
    monkeypatch.setattr(cli.CompileNotice.__init__, "__defaults__", (None, 0.05))
    study = str(tmp_path / "study.toml")
    assert cli.main(["calibrate", study]) == 0
    assert cli.CompileNotice.MESSAGE in capsys.readouterr().err
    assert cli.main(["calibrate", study, "--quiet"]) == 0
    assert capsys.readouterr().err == ""

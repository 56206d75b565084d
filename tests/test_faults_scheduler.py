"""Scheduler addresses that are not a dask scheduler (issue 36): each ends in one line, exit 2, within 30 s,
with no traceback (not even from ``Client.__del__`` at exit).

The command is run as a subprocess (``wallcal compare STUDY --scheduler ADDRESS``: it connects to the scheduler
before anything else, and a ``__del__`` traceback would only show at the interpreter's exit) against loopback
listeners started here: a silent one, an HTTP server, one that sends random bytes, one that announces a huge
message, one that closes at once; ``tls://`` without certificates, with certificates to a listener that speaks no
TLS, with a missing certificate file, and a real TLS scheduler that must pass. Last, a killed worker's scratch
directory is removed by the next building run.
"""

from __future__ import annotations

import os
import shutil
import socket
import struct
import subprocess
import sys
import threading
import time
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path

import pytest

from conftest import EXAMPLE, REPO

pytest.importorskip("distributed")


class Listener:
    """A loopback TCP listener whose accepted connections get ``behaviour(conn)`` in a thread."""

    def __init__(self, behaviour):
        self.sock = socket.create_server(("127.0.0.1", 0))
        self.address = f"tcp://127.0.0.1:{self.sock.getsockname()[1]}"
        self.behaviour = behaviour
        self.conns = []
        threading.Thread(target=self._run, daemon=True).start()

    def _run(self):
        while True:
            try:
                conn, _ = self.sock.accept()
            except OSError:
                return
            self.conns.append(conn)
            threading.Thread(target=self.behaviour, args=(conn,), daemon=True).start()

    def close(self):
        self.sock.close()
        for c in self.conns:
            c.close()


def silent(conn):
    pass  # accepts and never sends a byte


def random_bytes(conn):
    conn.sendall(os.urandom(4096))


def huge_length(conn):
    conn.sendall(b"\xff" * 8 + os.urandom(64))  # the "3 EiB" message: a length distributed would allocate


def plausible_then_stall(conn):
    conn.sendall(struct.pack("<Q", 2**31))  # 2 GiB announced, nothing follows


def close_at_once(conn):
    conn.close()


@pytest.fixture
def listener():
    made = []

    def make(behaviour):
        made.append(Listener(behaviour))
        return made[-1].address

    yield make
    for x in made:
        x.close()


@pytest.fixture
def http_server():
    class Quiet(BaseHTTPRequestHandler):
        def log_message(self, *args):
            pass

    httpd = ThreadingHTTPServer(("127.0.0.1", 0), Quiet)
    threading.Thread(target=httpd.serve_forever, daemon=True).start()
    yield f"tcp://127.0.0.1:{httpd.server_address[1]}"
    httpd.shutdown()
    httpd.server_close()


def wallcal(tmp_path, *args, env_extra=None):
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(REPO / "src"), env.get("PYTHONPATH", "")])
    env.pop("WALLCAL_SCHEDULER", None)
    env.pop("WALLCAL_SCHEDULER_TIMEOUT", None)
    env["DASK_CONFIG"] = str(tmp_path / "no-dask-config")  # no user configuration (TLS certificates) applies
    env.update(env_extra or {})
    t = time.perf_counter()
    proc = subprocess.run(
        [sys.executable, "-m", "wallcal.cli", *map(str, args)],
        env=env,
        capture_output=True,
        text=True,
        timeout=60,
        cwd=tmp_path,
    )
    return proc, time.perf_counter() - t


def assert_one_line(proc, elapsed, *words):
    err = proc.stderr
    assert proc.returncode == 2, (proc.returncode, err[-2000:])
    assert "Traceback" not in err and "Exception ignored" not in err, err[-2000:]
    lines = err.strip().splitlines()
    assert len(lines) == 1, err[-2000:]
    assert lines[0].startswith("wallcal: error: ") and len(lines[0]) <= 300, lines[0]
    for w in words:
        assert w in lines[0], lines[0]
    assert elapsed < 30, elapsed
    return lines[0]


def compare(tmp_path, address, *extra, env_extra=None):
    return wallcal(tmp_path, "compare", EXAMPLE, "--scheduler", address, *extra, env_extra=env_extra)


@pytest.mark.slow
def test_a_silent_listener_fails_after_the_stated_default_of_10_s(tmp_path, listener):
    address = listener(silent)
    proc, elapsed = compare(tmp_path, address)
    line = assert_one_line(proc, elapsed, address, "no dask handshake within 10 s", "WALLCAL_SCHEDULER_TIMEOUT")
    assert elapsed >= 10, (elapsed, line)


@pytest.mark.parametrize(
    "behaviour, words",
    [
        (silent, "no dask handshake within 2 s"),
        (random_bytes, "not a dask handshake"),
        (huge_length, "not a dask handshake"),
        (plausible_then_stall, "not a dask handshake"),
        (close_at_once, "not a dask scheduler"),
    ],
    ids=["silent", "random", "huge-length", "2-GiB-announced", "closes"],
)
def test_a_listener_that_is_not_a_dask_scheduler_is_one_line(tmp_path, listener, behaviour, words):
    address = listener(behaviour)
    proc, elapsed = compare(tmp_path, address, "--scheduler-timeout", "2")
    assert_one_line(proc, elapsed, address, words)


def test_an_http_server_is_not_a_scheduler(tmp_path, http_server):
    proc, elapsed = compare(tmp_path, http_server, env_extra={"WALLCAL_SCHEDULER_TIMEOUT": "2"})
    assert_one_line(proc, elapsed, http_server, "no dask handshake within 2 s")


def test_the_environment_variable_gets_the_same_checks(tmp_path, listener):
    address = listener(random_bytes)
    proc, elapsed = wallcal(tmp_path, "compare", EXAMPLE, env_extra={"WALLCAL_SCHEDULER": address})
    assert_one_line(proc, elapsed, address, "not a dask handshake")


def test_tls_without_certificates_is_one_line(tmp_path, listener):
    address = listener(random_bytes).replace("tcp://", "tls://")
    proc, elapsed = compare(tmp_path, address)
    assert_one_line(proc, elapsed, address, "needs the client's certificates", "distributed.comm.tls.ca-file")


@pytest.mark.parametrize(
    "address, words",
    [
        ("foo", "not an address"),
        ("tcp://no-such-host.invalid:8786", "unknown host"),
        ("ucx://127.0.0.1:8786", "cannot connect to the dask scheduler"),  # a Client that fails to start
    ],
)
def test_a_garbage_address_is_one_line(tmp_path, address, words):
    proc, elapsed = compare(tmp_path, address)
    assert_one_line(proc, elapsed, words)


@pytest.mark.parametrize(
    "address, words",
    [
        ("tcp://", "not an address"),
        ("tcp://127.0.0.1", "not an address"),
        ("127.0.0.1:8786:1", "not an address"),
        ("http://127.0.0.1:80", "http:// is not supported"),
        ("tcp://127.0.0.1:0", "port 0 is not in 1..65535"),
        ("127.0.0.1:70000", "port 70000 is not in 1..65535"),
        ("tcp://127.0.0.1:1", "cannot reach the dask scheduler"),
    ],
)
def test_an_address_is_checked_before_any_connection(tmp_path, capsys, address, words):
    from wallcal.cli import main

    assert main(["compare", str(EXAMPLE), "--scheduler", address]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and len(err[0]) <= 300 and words in err[0], err


@pytest.mark.parametrize("value", ["0", "-1", "nan", "soon", "1e9"])
def test_a_bad_scheduler_timeout_is_one_line(capsys, value):
    from wallcal.cli import main

    assert main(["compare", str(EXAMPLE), "--scheduler", "tcp://127.0.0.1:1", "--scheduler-timeout", value]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "must be a number of seconds in (0, 3600]" in err[0], err


def test_the_timeout_comes_from_the_argument_else_the_environment_else_10_s(monkeypatch):
    from wallcal.cluster import CONNECT_TIMEOUT_S, Executor

    monkeypatch.delenv("WALLCAL_SCHEDULER_TIMEOUT", raising=False)
    assert CONNECT_TIMEOUT_S == 10.0 and Executor("tcp://h:1").connect_timeout == 10.0
    monkeypatch.setenv("WALLCAL_SCHEDULER_TIMEOUT", "3.5")
    assert Executor("tcp://h:1").connect_timeout == 3.5
    assert Executor("tcp://h:1", connect_timeout=7).connect_timeout == 7.0


# ----------------------------------------------------------------------------- a killed worker's scratch directory
def test_a_killed_workers_scratch_directory_is_removed_by_the_next_run(tmp_path):
    from wallcal.building.run import clean_stale_scratch, scratch_dir

    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(REPO / "src"), os.environ.get("PYTHONPATH", "")]))
    code = (
        "import sys, time\nfrom wallcal.building.run import scratch_dir\n"
        "d = scratch_dir(sys.argv[1]); (d / 'eplusout.err').write_text('running'); print(d, flush=True)\n"
        "time.sleep(120)\n"
    )
    worker = subprocess.Popen([sys.executable, "-c", code, str(tmp_path)], stdout=subprocess.PIPE, text=True, env=env)
    try:
        left = Path(worker.stdout.readline().strip())
        assert left.parent == tmp_path and (left / "eplusout.err").exists()
        assert clean_stale_scratch(tmp_path) == [] and left.is_dir()  # a live run's directory stays
    finally:
        worker.kill()  # SIGKILL: the run's own clean-up never happens
        worker.wait(10)
        worker.stdout.close()
    assert left.is_dir()
    another_host = tmp_path / f"wallcal_building_{worker.pid}@another-host_x1"
    unrelated = tmp_path / "wallcal_building_no_pid"
    mine = scratch_dir(tmp_path)  # this process's own, made now
    reused = tmp_path / f"wallcal_building_{os.getpid()}@{mine.name.split('@')[1].split('_')[0]}_old"
    for d in (another_host, unrelated, reused):
        d.mkdir()
    os.utime(reused, (time.time() - 3600, time.time() - 3600))  # this pid's, but older than this process
    new = scratch_dir(tmp_path)
    assert not left.exists() and not reused.exists()
    assert new.is_dir() and mine.is_dir() and another_host.is_dir() and unrelated.is_dir()


def tls_env(tmp_path) -> dict:
    """A self-signed certificate as the client's TLS configuration (dask's environment variables)."""
    if shutil.which("openssl") is None:
        pytest.skip("needs the openssl command to make a certificate")
    cert, key = tmp_path / "cert.pem", tmp_path / "key.pem"
    subprocess.run(
        ["openssl", "req", "-x509", "-newkey", "rsa:2048", "-nodes", "-days", "1", "-subj", "/CN=127.0.0.1"]
        + ["-keyout", str(key), "-out", str(cert)],
        check=True,
        capture_output=True,
        timeout=60,
    )
    return {
        "DASK_DISTRIBUTED__COMM__TLS__CA_FILE": str(cert),
        "DASK_DISTRIBUTED__COMM__TLS__CLIENT__CERT": str(cert),
        "DASK_DISTRIBUTED__COMM__TLS__CLIENT__KEY": str(key),
    }


@pytest.mark.parametrize(
    "behaviour, words", [(random_bytes, "the TLS handshake failed"), (silent, "no dask handshake within 2 s")]
)
def test_tls_with_certificates_to_a_listener_that_speaks_no_tls_is_one_line(tmp_path, listener, behaviour, words):
    env = tls_env(tmp_path) | {"WALLCAL_SCHEDULER_TIMEOUT": "2"}
    address = listener(behaviour).replace("tcp://", "tls://")
    proc, elapsed = compare(tmp_path, address, env_extra=env)
    assert_one_line(proc, elapsed, address, words)


def test_tls_with_a_missing_certificate_file_is_one_line(tmp_path, listener):
    env = tls_env(tmp_path)
    env["DASK_DISTRIBUTED__COMM__TLS__CLIENT__CERT"] = str(tmp_path / "missing.pem")
    address = listener(silent).replace("tcp://", "tls://")
    proc, elapsed = compare(tmp_path, address, env_extra=env)
    assert_one_line(proc, elapsed, address, "the dask TLS configuration cannot be used")


def test_a_real_tls_scheduler_passes_the_probe(tmp_path):
    """The probe's TLS handshake is the one dask makes: a scheduler with the same certificates is accepted."""
    import dask
    import distributed
    from distributed.security import Security

    from wallcal.cluster import Executor

    env = tls_env(tmp_path)
    cert, key = env["DASK_DISTRIBUTED__COMM__TLS__CLIENT__CERT"], env["DASK_DISTRIBUTED__COMM__TLS__CLIENT__KEY"]
    tls = "distributed.comm.tls."
    config = {tls + "ca-file": cert, tls + "client.cert": cert, tls + "client.key": key}
    for role in ("scheduler", "worker"):
        config |= {f"{tls}{role}.cert": cert, f"{tls}{role}.key": key}
    with dask.config.set(config):
        with distributed.LocalCluster(
            n_workers=1,
            processes=False,
            protocol="tls://",
            host="127.0.0.1",
            security=Security(),
            dashboard_address=None,
        ) as lc:
            assert lc.scheduler_address.startswith("tls://")
            with Executor(lc.scheduler_address, progress=False, connect_timeout=10) as ex:
                assert ex.map(abs, [-3, 4]) == [3, 4]

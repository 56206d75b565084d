"""Scheduler addresses that are not a dask scheduler (issue 36): each ends in one line, exit 2, within 30 s,
with no traceback (not even from ``Client.__del__`` at exit).

The command is run as a subprocess (``wallcal compare STUDY --scheduler ADDRESS``: it connects to the scheduler
before anything else, and a ``__del__`` traceback would only show at the interpreter's exit) against loopback
listeners started here: a silent one, an HTTP server, one that sends random bytes, one that announces a huge
message, one that closes at once.
"""

from __future__ import annotations

import os
import socket
import struct
import subprocess
import sys
import threading
import time
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

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
        ("tcp://", "not an address"),
        ("tcp://127.0.0.1", "not an address"),
        ("http://127.0.0.1:80", "http:// is not supported"),
        ("tcp://127.0.0.1:0", "port 0 is not in 1..65535"),
        ("127.0.0.1:70000", "port 70000 is not in 1..65535"),
        ("tcp://no-such-host.invalid:8786", "unknown host"),
        ("tcp://127.0.0.1:1", "cannot reach the dask scheduler"),
        ("ucx://127.0.0.1:8786", "cannot connect to the dask scheduler"),
    ],
)
def test_a_garbage_address_is_one_line(tmp_path, address, words):
    proc, elapsed = compare(tmp_path, address)
    assert_one_line(proc, elapsed, words)


@pytest.mark.parametrize("value", ["0", "-1", "nan", "soon", "1e9"])
def test_a_bad_scheduler_timeout_is_one_line(tmp_path, value):
    proc, elapsed = compare(tmp_path, "tcp://127.0.0.1:1", "--scheduler-timeout", value)
    assert_one_line(proc, elapsed, "must be a number of seconds in (0, 3600]")

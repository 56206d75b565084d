"""``wallcal serve`` refuses other origins and never overwrites a file (issue 18).

The server runs in a thread on a free port; requests are written byte by byte on raw sockets so
that every header (Host, Origin, Content-Type, Content-Length) is exactly what an attacker sends.
"""

from __future__ import annotations

import json
import shutil
import socket
import threading
import time

import pytest

from conftest import EXAMPLE

TIMEOUT = 3.0  # the test server's per-connection time limit [s]


@pytest.fixture(scope="module")
def live(tmp_path_factory):
    from wallcal.web.server import serve

    d = tmp_path_factory.mktemp("live")
    for f in ("measured.csv", "true_wall.toml"):
        shutil.copy(EXAMPLE.parent / f, d)
    shutil.copy(EXAMPLE, d / "study.toml")
    box = {}
    th = threading.Thread(
        target=serve,
        args=(d / "study.toml",),
        kwargs={"port": 0, "timeout": TIMEOUT, "ready": lambda h: box.update(httpd=h)},
        daemon=True,
    )
    th.start()
    t0 = time.time()
    while "httpd" not in box:
        assert th.is_alive() and time.time() - t0 < 180, "the server did not start"
        time.sleep(0.05)
    httpd = box["httpd"]
    yield httpd, d
    httpd.shutdown()


def snapshot(d):
    """Every file of the study folder and its bytes."""
    return {p.name: p.read_bytes() for p in sorted(d.iterdir())}


def raw(httpd, data: bytes, read_timeout: float = 10.0, close_write: bool = False):
    """Send ``data`` on a new connection; the status and the JSON (or text) answer."""
    with socket.create_connection(httpd.server_address[:2], timeout=read_timeout) as s:
        s.sendall(data)
        if close_write:
            s.shutdown(socket.SHUT_WR)
        chunks = []
        while chunk := s.recv(65536):
            chunks.append(chunk)
    answer = b"".join(chunks)
    head, _, body = answer.partition(b"\r\n\r\n")
    status = int(head.split(b" ", 2)[1])
    headers = dict(
        (k.strip().lower(), v.strip()) for k, _, v in (line.partition(":") for line in head.decode().split("\r\n")[1:])
    )
    try:
        body = json.loads(body)
    except ValueError:
        body = body.decode()
    return status, body, headers


def request(httpd, method, path, body=None, *, token=True, host=None, ctype="application/json", headers=None):
    """One HTTP/1.1 request as a browser (or an attacker) would send it."""
    port = httpd.server_address[1]
    h = {"Host": host or f"127.0.0.1:{port}"}
    if token:
        h["X-Wallcal-Token"] = httpd.token if token is True else token
    if body is not None:
        data = body if isinstance(body, bytes) else json.dumps(body).encode()
        if ctype:
            h["Content-Type"] = ctype
        h["Content-Length"] = str(len(data))
    else:
        data = b""
    h["Connection"] = "close"
    h.update(headers or {})
    head = f"{method} {path} HTTP/1.1\r\n" + "".join(f"{k}: {v}\r\n" for k, v in h.items()) + "\r\n"
    return raw(httpd, head.encode() + data)


def still_serving(httpd):
    status, body, _ = request(httpd, "GET", "/api/study")
    assert status == 200 and body["layers"], body


# ----------------------------------------------------------------------------- the attack of the issue
def test_cross_origin_text_plain_save_is_refused_and_the_study_is_unchanged(live):
    """A page of another origin posts {"file": "study.toml"} as text/plain (no preflight), without the token."""
    httpd, d = live
    before = snapshot(d)
    status, body, headers = request(
        httpd,
        "POST",
        "/api/save",
        b'{"file": "study.toml"}',
        token=False,
        ctype="text/plain;charset=UTF-8",
        headers={"Origin": "http://evil.example", "Sec-Fetch-Site": "cross-site", "Sec-Fetch-Mode": "no-cors"},
    )
    assert status == 403, body
    assert "refused" in body["error"]
    assert not any(k.startswith("access-control") for k in headers)
    assert snapshot(d) == before  # the study file byte for byte, and no new file


@pytest.mark.parametrize(
    "headers",
    [
        {},  # no Origin (a form post from a file:// page, a curl): the token and content type still stop it
        {"Origin": "null"},
        {"Origin": "http://evil.example"},
    ],
)
def test_the_attack_without_the_token_is_refused_whatever_the_origin(live, headers):
    httpd, d = live
    before = snapshot(d)
    status, body, _ = request(
        httpd, "POST", "/api/save", b'{"file": "study.toml"}', token=False, ctype="text/plain", headers=headers
    )
    assert status in (403, 415), body
    assert snapshot(d) == before


def test_the_attack_with_the_token_but_text_plain_is_refused(live):
    httpd, d = live
    before = snapshot(d)
    status, body, _ = request(httpd, "POST", "/api/save", b'{"file": "study.toml"}', ctype="text/plain")
    assert status == 415, body
    assert "application/json" in body["error"]
    assert snapshot(d) == before


# ----------------------------------------------------------------------------- who may call
@pytest.mark.parametrize("host", ["evil.example:{port}", "evil.example", "127.0.0.1.nip.io:{port}", "127.0.0.1:1"])
def test_a_foreign_host_is_refused(live, host):
    """DNS rebinding: a remote page whose name now resolves to 127.0.0.1 reads /api/study."""
    httpd, _ = live
    status, body, _ = request(httpd, "GET", "/api/study", host=host.format(port=httpd.server_address[1]))
    assert status == 403, body
    assert "Host" in body["error"]
    assert "layers" not in body
    status, body, _ = request(httpd, "GET", "/", host=host.format(port=httpd.server_address[1]))
    assert status == 403


@pytest.mark.parametrize("host", ["127.0.0.1:{port}", "localhost:{port}", "LOCALHOST:{port}"])
def test_the_bound_address_and_localhost_are_served(live, host):
    httpd, _ = live
    status, body, _ = request(httpd, "GET", "/api/study", host=host.format(port=httpd.server_address[1]))
    assert status == 200, body


def test_a_request_without_host_is_refused(live):
    httpd, _ = live
    status, body, _ = raw(httpd, f"GET /api/study HTTP/1.0\r\nX-Wallcal-Token: {httpd.token}\r\n\r\n".encode())
    assert status == 403, body


@pytest.mark.parametrize("token", [False, "", "wrong", "x" * 43, "TOKEN_WITH_ONE_CHANGE", "TOKEN\u00e9"])
@pytest.mark.parametrize("method,path", [("GET", "/api/study"), ("POST", "/api/simulate"), ("POST", "/api/save")])
def test_a_missing_or_wrong_token_is_refused(live, token, method, path):
    httpd, d = live
    before = snapshot(d)
    if isinstance(token, str):
        token = token.replace("TOKEN_WITH_ONE_CHANGE", httpd.token[:-1] + ("A" if httpd.token[-1] != "A" else "B"))
        token = token.replace("TOKEN", httpd.token)
    body = {} if method == "POST" else None
    status, answer, _ = request(httpd, method, path, body, token=token)
    assert status == 403, answer
    assert "token" in answer["error"]
    assert snapshot(d) == before


def test_the_token_is_not_accepted_in_the_query_string_of_the_api(live):
    httpd, _ = live
    status, _, _ = request(httpd, "GET", f"/api/study?token={httpd.token}", token=False)
    assert status == 403


@pytest.mark.parametrize(
    "headers",
    [
        {"Origin": "http://evil.example"},
        {"Origin": "null"},
        {"Origin": "http://localhost:1"},
        {"Sec-Fetch-Site": "cross-site"},
        {"Sec-Fetch-Site": "same-site"},
    ],
)
def test_a_foreign_origin_is_refused_even_with_the_token(live, headers):
    httpd, d = live
    before = snapshot(d)
    status, body, _ = request(httpd, "POST", "/api/save", {}, headers=headers)
    assert status == 403, body
    assert snapshot(d) == before


def test_the_pages_own_origin_is_served(live):
    httpd, _ = live
    port = httpd.server_address[1]
    headers = {"Origin": f"http://127.0.0.1:{port}", "Sec-Fetch-Site": "same-origin"}
    status, body, _ = request(
        httpd, "POST", "/api/simulate", {"layers": {"3": {"conductivity": 0.04}}}, headers=headers
    )
    assert status == 200, body
    assert body["metrics"]


def test_a_preflight_gets_no_cors_permission(live):
    httpd, _ = live
    status, _, headers = request(
        httpd,
        "OPTIONS",
        "/api/save",
        token=False,
        headers={"Origin": "http://evil.example", "Access-Control-Request-Method": "POST"},
    )
    assert status == 403
    assert not any(k.startswith("access-control") for k in headers)


@pytest.mark.parametrize(
    "ctype",
    [
        None,
        "text/plain",
        "application/x-www-form-urlencoded",
        "multipart/form-data; boundary=x",
        "application/jsonx",
        "text/json",
    ],
)
def test_a_wrong_content_type_is_refused(live, ctype):
    httpd, d = live
    before = snapshot(d)
    status, body, _ = request(httpd, "POST", "/api/save", b"{}", ctype=ctype)
    assert status == 415, body
    assert snapshot(d) == before


def test_json_with_a_charset_is_accepted(live):
    httpd, _ = live
    status, body, _ = request(httpd, "POST", "/api/simulate", b"{}", ctype="application/json; charset=utf-8")
    assert status == 200, body


def test_the_page_is_served_with_its_protections(live):
    httpd, _ = live
    status, body, headers = request(httpd, "GET", "/?token=whatever", token=False)
    assert status == 200 and "wallcal" in body
    csp = headers["content-security-policy"]
    assert "frame-ancestors 'none'" in csp and "script-src 'sha256-" in csp and "unsafe-eval" not in csp
    assert headers["x-frame-options"] == "DENY"
    assert headers["referrer-policy"] == "no-referrer"
    assert httpd.url == f"http://127.0.0.1:{httpd.server_address[1]}/?token={httpd.token}"
    assert len(httpd.token) >= 40  # 32 random bytes


# ----------------------------------------------------------------------------- hostile bodies
def _nested(n):
    return ("[" * n + "]" * n).encode()


@pytest.mark.parametrize(
    "body,status,words",
    [
        (b"not json", 400, "not valid JSON"),
        (b"", 400, "not valid JSON"),
        (b"\xff\xfe{}", 400, "UTF-8"),
        (b'{"layers": {"3": {"conductivity": NaN}}}', 400, "finite"),
        (b'{"layers": {"3": {"conductivity": Infinity}}}', 400, "finite"),
        (b'{"layers": {"3": {"conductivity": -Infinity}}}', 400, "finite"),
        (b'{"layers": {"3": {"conductivity": 1e999}}}', 400, "finite"),
        (b'{"layers": {"3": {"conductivity": ' + b"9" * 400 + b"}}}", 400, "finite"),
        (b'{"layers": {"3": {"conductivity": ' + b"9" * 5000 + b"}}}", 400, "JSON"),
        (_nested(10), 400, "nested"),
        (_nested(30_000), 400, "nested"),
        (b'{"a": ' * 9 + b"1" + b"}" * 9, 400, "nested"),
        (b"[]", 400, "JSON object"),
        (b'"study.toml"', 400, "JSON object"),
        (b'{"layers": []}', 400, "JSON object"),
        (b'{"layers": {"3": 0.04}}', 400, "JSON object"),
        (b'{"layers": {"3": {"conductivity": -0.04}}}', 400, "outside the possible range"),
        (b'{"layers": {"3": {"conductivity": 0}}}', 400, "outside the possible range"),
        (b'{"layers": {"3": {"conductivity": 1e300}}}', 400, "outside the possible range"),
        (b'{"layers": {"3": {"density": -500}}}', 400, "outside the possible range"),
        (b'{"layers": {"3": {"density": 1e9}}}', 400, "outside the possible range"),
        (b'{"layers": {"3": {"specific_heat": 1e-9}}}', 400, "outside the possible range"),
        (b'{"layers": {"3": {"contact_resistance": -1}}}', 400, "outside the possible range"),
        (b'{"layers": {"3": {"conductivity_temperature_coefficient": 5}}}', 400, "outside the possible range"),
        (b'{"layers": {"3": {"conductivity": "0.04"}}}', 400, "must be a number"),
        (b'{"layers": {"3": {"conductivity": true}}}', 400, "must be a number"),
        (b'{"layers": {"3": {"conductivity": null}}}', 400, "must be a number"),
        (b'{"layers": {"3": {"thickness": 1}}}', 400, "not an editable property"),
        (b'{"layers": {"../study": {"conductivity": 0.04}}}', 400, "not a layer id"),
        (b'{"probes": {"T3A": -1}}', 400, "outside the wall"),
        (b'{"probes": {"T3A": 1e308}}', 400, "outside the wall"),
        (b'{"probes": {"nope": 0.01}}', 400, "not a probe"),
        (b'{"path": "/etc/passwd"}', 400, "unknown key"),
    ],
)
@pytest.mark.parametrize("path", ["/api/simulate", "/api/save"])
def test_a_hostile_body_gets_a_clear_4xx_and_the_server_goes_on(live, capfd, body, status, words, path):
    httpd, d = live
    before = snapshot(d)
    got, answer, _ = request(httpd, "POST", path, body)
    assert got == status, answer
    assert words in answer["error"], answer
    assert "Traceback" not in answer["error"] and len(answer["error"]) < 400
    assert snapshot(d) == before
    still_serving(httpd)
    assert "Traceback" not in capfd.readouterr().err


@pytest.mark.parametrize(
    "body",
    [
        b'"' + b'\\"' * 30_000,
        b'{"a": "' + b"[" * 60_000 + b'"}',
        b"[" * 60_000,
        b'{"layers": {' + b'"3": {}, ' * 6000 + b"}}",
    ],
)
def test_a_body_made_to_be_slow_to_check_is_answered_at_once(live, body):
    httpd, _ = live
    t = time.perf_counter()
    status, answer, _ = request(httpd, "POST", "/api/simulate", body)
    assert status == 400, answer
    assert time.perf_counter() - t < 2.0  # one linear pass over at most 64 KiB
    still_serving(httpd)


def test_a_huge_body_is_refused_with_413(live):
    httpd, d = live
    before = snapshot(d)
    big = b'{"layers": {}, "pad": "' + b"x" * 2_000_000 + b'"}'
    status, body, _ = request(httpd, "POST", "/api/save", big)
    assert status == 413, body
    assert "larger than" in body["error"]
    assert snapshot(d) == before
    still_serving(httpd)


def test_an_absurd_content_length_is_refused_before_reading(live):
    httpd, _ = live
    port = httpd.server_address[1]
    for n, status in ((10**12, 413), ("9" * 5000, 400), ("-5", 400), ("\u00b2", 400)):
        head = (
            f"POST /api/simulate HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nX-Wallcal-Token: {httpd.token}\r\n"
            f"Content-Type: application/json\r\nContent-Length: {n}\r\n\r\n"
        )
        got, body, _ = raw(httpd, head.encode("latin-1") + b"{}")
        assert got == status, (n, body)
    head = (
        f"POST /api/simulate HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nX-Wallcal-Token: {httpd.token}\r\n"
        f"Content-Type: application/json\r\nTransfer-Encoding: chunked\r\n\r\n2\r\n{{}}\r\n0\r\n\r\n"
    )
    assert raw(httpd, head.encode())[0] == 411
    still_serving(httpd)


def test_a_body_shorter_than_announced_is_refused(live):
    httpd, _ = live
    port = httpd.server_address[1]
    head = (
        f"POST /api/simulate HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nX-Wallcal-Token: {httpd.token}\r\n"
        f"Content-Type: application/json\r\nContent-Length: 100\r\n\r\n"
    )
    status, body, _ = raw(httpd, head.encode() + b'{"layers": {}}', close_write=True)
    assert status == 400 and "ended after 14 of the 100 bytes" in body["error"], body


def test_a_request_that_never_finishes_gets_408_and_does_not_block_others(live):
    httpd, d = live
    port = httpd.server_address[1]
    head = (
        f"POST /api/save HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nX-Wallcal-Token: {httpd.token}\r\n"
        f"Content-Type: application/json\r\nContent-Length: 100\r\n\r\n"
    )
    before = snapshot(d)
    box = {}

    def slow():
        box["t0"] = time.perf_counter()
        box["answer"] = raw(httpd, head.encode() + b'{"layers": ', read_timeout=4 * TIMEOUT)
        box["t1"] = time.perf_counter()

    stalled = [socket.create_connection(httpd.server_address[:2]) for _ in range(8)]
    try:
        for i, s in enumerate(stalled):  # request lines and headers that never end, bodies that never come
            s.sendall(head.encode()[: 20 + 10 * i] if i % 2 else head.encode() + b"{")
        th = threading.Thread(target=slow)
        th.start()
        time.sleep(0.2)
        t = time.perf_counter()
        still_serving(httpd)  # the page is served while nine clients hang
        status, body, _ = request(httpd, "POST", "/api/simulate", {"layers": {"3": {"conductivity": 0.04}}})
        assert status == 200, body
        assert th.is_alive(), "the slow client was answered before the others: nothing shows they ran concurrently"
        assert time.perf_counter() - t < TIMEOUT
        th.join(4 * TIMEOUT)
    finally:
        for s in stalled:
            s.close()
    status, body, _ = box["answer"]
    assert status == 408, body
    assert "did not arrive" in body["error"]
    assert TIMEOUT * 0.9 <= box["t1"] - box["t0"] < 3 * TIMEOUT
    assert snapshot(d) == before


# ----------------------------------------------------------------------------- save never overwrites
def test_save_writes_only_new_files(live):
    from wallcal import load_wall

    httpd, d = live
    for f in d.glob("manual_wall*.toml"):
        f.unlink()
    mine = d / "manual_wall.toml"
    mine.write_text("# the user's own notes, not a wall\n")
    before = snapshot(d)
    status, body, _ = request(httpd, "POST", "/api/save", {"layers": {"3": {"conductivity": 0.045}}})
    assert status == 200, body
    assert body["path"] == str(d / "manual_wall-2.toml") and body["file"] == "manual_wall-2.toml"
    assert snapshot(d) == before | {"manual_wall-2.toml": (d / "manual_wall-2.toml").read_bytes()}
    assert mine.read_text() == "# the user's own notes, not a wall\n"
    assert load_wall(d / "manual_wall-2.toml").layers[0].conductivity == 0.045
    assert (d / "manual_wall-2.toml").read_text() == body["toml"]
    status, body, _ = request(httpd, "POST", "/api/save", {})
    assert body["file"] == "manual_wall-3.toml"
    for f in ("manual_wall.toml", "manual_wall-2.toml", "manual_wall-3.toml"):
        (d / f).unlink()


@pytest.mark.parametrize(
    "name,expected",
    [
        ("study.toml", "study-2.toml"),
        ("true_wall.toml", "true_wall-2.toml"),
        ("measured.csv", "measured.csv.toml"),
        ("../../outside.toml", "outside.toml"),
        ("/etc/passwd", "passwd.toml"),
        ("..\\..\\win.toml", "win.toml"),
        ("..", "manual_wall.toml"),
        ("", "manual_wall.toml"),
        (".hidden", "hidden.toml"),
        ("my wall; rm -rf ~", "my_wall_rm_-rf.toml"),
        ("a" * 300, "a" * 64 + ".toml"),
    ],
)
def test_save_names_are_sanitised_and_stay_in_the_study_folder(live, name, expected):
    httpd, d = live
    before = snapshot(d)
    status, body, _ = request(httpd, "POST", "/api/save", {"file": name})
    assert status == 200, body
    assert body["path"] == str(d / expected)
    new = snapshot(d)
    assert {k: v for k, v in new.items() if k != expected} == before
    (d / expected).unlink()


@pytest.mark.parametrize("name", [["study.toml"], {"name": "study.toml"}, 1, True])
def test_a_save_name_that_is_not_a_string_is_refused(live, name):
    httpd, d = live
    before = snapshot(d)
    status, body, _ = request(httpd, "POST", "/api/save", {"file": name})
    assert status == 400 and "file: must be a string" in body["error"], body
    assert snapshot(d) == before


def test_save_does_not_follow_a_planted_symbolic_link(live, tmp_path):
    httpd, d = live
    victim = tmp_path / "victim.txt"
    victim.write_text("precious")
    link = d / "manual_wall.toml"
    link.symlink_to(victim)
    try:
        status, body, _ = request(httpd, "POST", "/api/save", {})
        assert status == 200 and body["file"] == "manual_wall-2.toml", body
        assert victim.read_text() == "precious"
    finally:
        link.unlink()
        (d / "manual_wall-2.toml").unlink(missing_ok=True)


def test_concurrent_saves_each_get_their_own_complete_file(live):
    from wallcal import load_wall

    httpd, d = live
    answers = []
    threads = [
        threading.Thread(
            target=lambda k=k: answers.append(
                request(httpd, "POST", "/api/save", {"layers": {"3": {"conductivity": 0.03 + k / 1000}}})
            )
        )
        for k in range(8)
    ]
    for th in threads:
        th.start()
    for th in threads:
        th.join(60)
    files = sorted(a[1]["file"] for a in answers)
    assert [a[0] for a in answers] == [200] * 8
    assert len(set(files)) == 8
    assert sorted(round(load_wall(d / f).layers[0].conductivity, 6) for f in files) == [
        round(0.03 + k / 1000, 6) for k in range(8)
    ]
    assert not list(d.glob(".*.tmp"))
    for f in files:
        (d / f).unlink()


def test_write_text_new_never_replaces(tmp_path):
    from wallcal.outputs import write_text_new

    (tmp_path / "w.toml").write_text("old")
    (tmp_path / "w-2.toml").write_text("old 2")
    assert write_text_new(tmp_path, "w", "new") == tmp_path / "w-3.toml"
    assert (tmp_path / "w.toml").read_text() == "old" and (tmp_path / "w-2.toml").read_text() == "old 2"
    assert (tmp_path / "w-3.toml").read_text() == "new"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["w-2.toml", "w-3.toml", "w.toml"]


def test_write_text_new_without_hard_links_creates_exclusively(tmp_path, monkeypatch):
    import os

    from wallcal.outputs import write_text_new

    def no_link(*a, **k):
        raise PermissionError(1, "Operation not permitted")

    monkeypatch.setattr(os, "link", no_link)
    (tmp_path / "w.toml").write_text("old")
    assert write_text_new(tmp_path, "w", "new") == tmp_path / "w-2.toml"
    assert (tmp_path / "w.toml").read_text() == "old" and (tmp_path / "w-2.toml").read_text() == "new"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["w-2.toml", "w.toml"]


# ----------------------------------------------------------------------------- binding
def test_a_non_loopback_host_needs_allow_remote():
    from wallcal.errors import WallcalError
    from wallcal.web.server import serve

    with pytest.raises(WallcalError, match="allow-remote"):
        serve(EXAMPLE, host="0.0.0.0", port=0)


def test_the_command_refuses_a_remote_host_and_warns_when_allowed(monkeypatch, capsys):
    from wallcal import cli
    from wallcal.web import server

    assert cli.main(["serve", str(EXAMPLE), "--host", "0.0.0.0", "--port", "0"]) == 2
    err = capsys.readouterr().err
    assert "--allow-remote" in err and "Traceback" not in err

    calls = []
    monkeypatch.setattr(server, "serve", lambda *a, **k: calls.append((a, k)))
    assert cli.main(["serve", str(EXAMPLE), "--host", "0.0.0.0", "--port", "0", "--allow-remote"]) == 0
    assert calls[0][1]["allow_remote"] is True
    err = capsys.readouterr().err
    assert "WARNING" in err and "token" in err

    calls.clear()
    assert cli.main(["serve", str(EXAMPLE), "--port", "0"]) == 0
    assert calls[0][1]["host"] == "127.0.0.1" and calls[0][1]["allow_remote"] is False
    assert "WARNING" not in capsys.readouterr().err


def test_a_token_is_drawn_at_every_start(live, monkeypatch):
    """Two starts of the server (on the already-loaded study) print different tokens."""
    from wallcal.web import server

    httpd, _ = live
    monkeypatch.setattr(server, "ManualCalibration", lambda path: httpd.app)
    urls = []
    for _ in range(2):
        box = {}
        th = threading.Thread(
            target=server.serve,
            args=(EXAMPLE,),
            kwargs={"port": 0, "ready": lambda h, box=box: box.update(h=h)},
            daemon=True,
        )
        th.start()
        while "h" not in box:
            time.sleep(0.01)
        urls.append(box["h"].url)
        status, _, _ = request(box["h"], "GET", "/api/study", token=httpd.token)
        assert status == 403  # another start's token does not open this one
        box["h"].shutdown()
        th.join(10)
    assert urls[0].split("token=")[1] != urls[1].split("token=")[1] != httpd.token


@pytest.mark.parametrize("study", ["campaign_a", "trh"])
def test_the_pages_sliders_stay_inside_the_accepted_ranges(study):
    """The page's sliders span 0.5x .. 2x of each value: for the bundled walls every value they can
    send is accepted (the limits refuse only the absurd)."""
    import wallcal
    from wallcal.web.server import LIMITS

    wall = wallcal.load_study(EXAMPLE.parent.parent / study / "study.toml").wall
    for layer in wall.layers:
        if layer.is_massless:
            continue
        for prop in ("conductivity", "density", "specific_heat"):
            v = getattr(layer, prop)
            if v is not None:
                lo, hi, _ = LIMITS[prop]
                assert lo <= 0.5 * v and 2 * v <= hi, (study, layer.id, prop, v)

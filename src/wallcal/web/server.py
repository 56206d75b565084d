"""``wallcal serve``: a local web page for manual calibration.

A small standard-library HTTP server (bound to 127.0.0.1 by default) that serves
one page (``page.html``, no external assets: it works offline) and three JSON
end points, all built on wallcal's public API only (``load_study``, ``prepare``,
``simulate``, ``Wall.replace_layer``, ``dump_wall``, ``Study.calibration``):

- ``GET /api/study``: the wall, the calibration parameters, the sensors, the
  measured series and the base-case simulation;
- ``POST /api/simulate``: ``{"layers": {id: {property: value}}, "probes": {name: depth}}``
  -> simulated series and metrics (one engine run on prepared data: milliseconds);
- ``POST /api/save``: the same body (and an optional ``"file"`` name) -> the wall
  written as a new TOML file next to the study (``manual_wall.toml``, else
  ``manual_wall-2.toml``, ...; never an existing file), its path and its text.

Only the user's own page may call the API (see docs/live-page.md):

- a random token per server start, in the printed URL (``/?token=...``); the page
  sends it in the ``X-Wallcal-Token`` header of every API call, compared in
  constant time; missing or wrong: 403;
- the ``Host`` header must name the bound address or ``localhost`` (DNS
  rebinding), an ``Origin`` header must be the page's own, a ``Sec-Fetch-Site``
  header must say ``same-origin``: 403 otherwise;
- ``POST`` bodies: ``Content-Type: application/json`` only (415), one
  ``Content-Length`` (411, 400 for two) of at most ``MAX_BODY`` bytes (413), sent within the
  connection's time limit (408), UTF-8 JSON of finite numbers, nested at most
  ``MAX_DEPTH`` deep, in the shape above, with physically possible values (400);
- every answer, refusals included (the standard library's own: ``send_error``), carries
  the security headers, and every refusal is one line of JSON.

Under load (:class:`LiveServer`): one loop reads each request without a thread (a deadline,
a head limit, at most ``MAX_PENDING`` waiting connections), ``HANDLER_THREADS`` threads answer
complete ones, and at most ``SIMULATIONS`` simulations run or wait at once (503 with
``Retry-After`` beyond), so slow, stalled or numerous clients never hold up the page.
"""

from __future__ import annotations

import base64
import errno
import hashlib
import hmac
import io
import ipaddress
import json
import math
import re
import secrets
import socket
import sys
import threading
import time
from http.server import BaseHTTPRequestHandler, HTTPServer
from pathlib import Path, PurePosixPath
from urllib.parse import urlsplit

import numpy as np

import wallcal
from wallcal.errors import WallcalError

PAGE = Path(__file__).with_name("page.html")
EDITABLE = ("conductivity", "density", "specific_heat", "conductivity_temperature_coefficient", "contact_resistance")
#: The range the page accepts for each editable property (SI units): any building material with the sliders'
#: factor-2 margin (vacuum panels and still air to metals; an air layer's 1.2 kg/m3 to lead; phase-change
#: materials' apparent heat capacity), and the study file's temperature-coefficient bounds. Anything outside
#: is refused as absurd.
LIMITS = {
    "conductivity": (1e-4, 1e4, "W/(m K)"),
    "density": (0.01, 1e5, "kg/m3"),
    "specific_heat": (1.0, 1e6, "J/(kg K)"),
    "conductivity_temperature_coefficient": (-0.2, 0.2, "1/K"),
    "contact_resistance": (0.0, 100.0, "m2K/W"),
}
MAX_BODY = 64 * 1024  # bytes; the page's bodies are a few hundred bytes
MAX_DEPTH = 8  # JSON nesting; the page's bodies are 3 deep
TIMEOUT = 10.0  # seconds a connection may take to send its request
TOKEN_HEADER = "X-Wallcal-Token"
SAVE_STEM = "manual_wall"
#: Names Windows reserves for devices, whatever the extension and case (``CON.toml``, ``nul.backup.toml``).
WINDOWS_RESERVED = frozenset(["CON", "PRN", "AUX", "NUL"] + [f"{d}{i}" for d in ("COM", "LPT") for i in range(10)])


def _clean(values) -> list:
    return [None if (v is None or not math.isfinite(v)) else round(float(v), 5) for v in values]


def _number(v, where: str) -> float:
    """A JSON number as a finite float, or a WallcalError naming ``where``."""
    if isinstance(v, bool) or not isinstance(v, int | float):
        raise WallcalError(f"{where}: must be a number, got {type(v).__name__} {json.dumps(v)[:40]}")
    try:
        x = float(v)
    except OverflowError:
        x = math.inf
    if not math.isfinite(x):
        raise WallcalError(f"{where}: must be a finite number, got {str(v)[:40]}")
    return x


def _object(v, where: str) -> dict:
    if not isinstance(v, dict):
        raise WallcalError(f"{where}: must be a JSON object, got {type(v).__name__}")
    return v


def _safe_stem(name) -> str:
    """The file name a save may use: the base name only, letters, digits, ``.``, ``_``, ``-``, no ``.toml``."""
    if name is None:
        return SAVE_STEM
    if not isinstance(name, str):
        raise WallcalError(f"file: must be a string, got {type(name).__name__}")
    stem = PurePosixPath(name.replace("\\", "/")).name
    if stem.lower().endswith(".toml"):
        stem = stem[:-5]
    stem = re.sub(r"[^A-Za-z0-9._-]+", "_", stem).strip("._-")[:64]
    if stem.split(".")[0].upper() in WINDOWS_RESERVED:
        raise WallcalError(
            f"file: {stem[:40]!r} is a device name on Windows (CON, PRN, AUX, NUL, COM0-9, LPT0-9, with any "
            "extension), not a file name; choose another"
        )
    return stem or SAVE_STEM


def is_loopback(host: str) -> bool:
    """True for ``localhost`` and loopback addresses (127.0.0.0/8, ::1)."""
    if host.lower() == "localhost":
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False


class ManualCalibration:
    """The state behind the page: a study, its prepared data and the base case."""

    def __init__(self, study_path: str | Path):
        self.study_path = Path(study_path).resolve()
        self.study = wallcal.load_study(self.study_path)
        self.prepared = wallcal.prepare(self.study, needs=("batches",), purpose="the live page")
        self.base = wallcal.simulate(self.study, prepared=self.prepared)
        self.lock = threading.Lock()
        self.slots = threading.BoundedSemaphore(SIMULATIONS)  # simulations running or waiting for the lock
        self.params = []
        if self.study.calibration:  # validated by load_study
            self.params = [
                {
                    "name": p.name,
                    "property": p.property,
                    "layers": [self.study.wall.layers[i].id for i in p.layers],
                    "probe": p.probe,
                    "base": p.base,
                    "lower": p.lower,
                    "upper": p.upper,
                }
                for p in self.study.calibration.parameters
            ]

    # ------------------------------------------------------------------ API
    def state(self) -> dict:
        s = self.study
        layers = []
        for layer in s.wall.layers:
            d = {
                "id": layer.id,
                "material": layer.material,
                "thickness": layer.thickness,
                "massless": layer.is_massless,
            }
            for prop in EDITABLE:
                v = getattr(layer, prop)
                d[prop] = None if v is None else float(v)
            layers.append(d)
        sensors = [
            {
                "name": x.name,
                "quantity": x.quantity,
                "unit": "W/m2" if x.quantity == "heat_flux" else "degC",
                "accuracy": x.accuracy,
                "accuracy_relative": x.accuracy_relative,
            }
            for x in s.sensors
        ]
        times = [int(t.value // 1_000_000) for t in self.base.measured.index]  # ms since epoch (naive local)
        return {
            "name": s.name,
            "wall": s.wall.name,
            "study": str(self.study_path),
            "layers": layers,
            "probes": [{"name": p.name, "depth": p.depth} for p in s.wall.probes],
            "parameters": self.params,
            "sensors": sensors,
            "times": times,
            "measured": {x.name: _clean(self.base.measured[x.name].to_numpy()) for x in s.sensors},
            "base": self._payload(self.base, 0.0),
        }

    def wall_from(self, body: dict):
        """The study's wall with the body's edits, every value checked (WallcalError names the bad one)."""
        body = _object(body, "body")
        unknown = sorted(set(body) - {"layers", "probes", "file"})
        if unknown:
            raise WallcalError(f"body: unknown key {unknown[0]!r} (expected layers, probes, file)")
        wall = self.study.wall
        layers = {layer.id: layer for layer in wall.layers}
        for lid, props in _object({} if body.get("layers") is None else body["layers"], "layers").items():
            if lid not in layers:
                raise WallcalError(f"layers: {lid[:40]!r} is not a layer id (the wall has {', '.join(layers)})")
            layer = layers[lid]
            changes = {}
            for prop, v in _object(props, f"layers.{lid}").items():
                where = f"layers.{lid}.{prop[:40]}"
                if prop not in EDITABLE:
                    raise WallcalError(f"{where}: not an editable property (editable: {', '.join(EDITABLE)})")
                if layer.is_massless and prop != "contact_resistance":
                    raise WallcalError(f"{where}: layer {lid} is a no-mass layer (thermal_resistance only)")
                if prop == "conductivity_temperature_coefficient" and layer.conductivity_table is not None:
                    raise WallcalError(f"{where}: layer {lid} has a conductivity_table, not a coefficient")
                v = _number(v, where)
                lo, hi, unit = LIMITS[prop]
                if not lo <= v <= hi:
                    raise WallcalError(f"{where}: {v:g} {unit} is outside the possible range {lo:g} .. {hi:g} {unit}")
                changes[prop] = v
            wall = wall.replace_layer(lid, **changes)
        probes = {p.name for p in wall.probes}
        for name, depth in _object({} if body.get("probes") is None else body["probes"], "probes").items():
            if name not in probes:
                raise WallcalError(f"probes: {name[:40]!r} is not a probe of the wall")
            depth = _number(depth, f"probes.{name}")
            if not 0 <= depth <= wall.thickness:
                raise WallcalError(f"probes.{name}: depth {depth:g} m is outside the wall (0 .. {wall.thickness:g} m)")
            wall = wall.replace_probe(name, depth=depth)
        return wall

    def simulate(self, body: dict) -> dict:
        wall = self.wall_from(body)
        if not self.slots.acquire(timeout=SIMULATION_WAIT):
            raise _Refused(
                503,
                f"busy: {SIMULATIONS} simulations are running or waiting; retry in {RETRY_AFTER} s",
                {"Retry-After": str(RETRY_AFTER)},
            )
        try:
            t = time.perf_counter()
            with self.lock:
                res = wallcal.simulate(self.study, prepared=self.prepared, wall=wall)
        finally:
            self.slots.release()
        return self._payload(res, (time.perf_counter() - t) * 1000, wall)

    def save(self, body: dict) -> dict:
        """Write the edited wall to a new TOML file in the study's folder (never an existing file)."""
        from wallcal.outputs import write_text_new
        from wallcal.study import dump_wall

        wall = self.wall_from(body)
        stem = _safe_stem(body.get("file"))
        text = dump_wall(
            wall.replace(name=(wall.name or "wall") + " (manual calibration)"),
            f"saved by wallcal serve from {self.study_path.name}",
        )
        path = write_text_new(self.study_path.parent, stem, text)
        return {"path": str(path), "file": path.name, "toml": text}

    def _payload(self, res, ms: float, wall=None) -> dict:
        met = res.metrics.replace({np.nan: None})
        wall = wall or self.study.wall
        return {
            "simulated": {c: _clean(res.simulated[c].to_numpy()) for c in res.simulated.columns},
            "metrics": met.to_dict(orient="records"),
            "ms": round(ms, 2),
            "R": wall.resistance,
            "U": wall.u_value(),
        }


class _Refused(Exception):
    """A request answered with a 4xx status and a one-line message."""

    def __init__(self, status: int, message: str, headers: dict | None = None):
        super().__init__(message)
        self.status = status
        self.headers = headers


def _depth(text: str) -> int:
    """Deepest nesting of JSON arrays and objects in ``text`` (strings skipped): one linear pass."""
    depth = deepest = 0
    in_string = escaped = False
    for c in text:
        if in_string:
            if escaped:
                escaped = False
            elif c == "\\":
                escaped = True
            elif c == '"':
                in_string = False
        elif c == '"':
            in_string = True
        elif c in "[{":
            depth += 1
            deepest = max(deepest, depth)
        elif c in "]}":
            depth -= 1
    return deepest


def _no_constant(name: str):
    raise ValueError(f"{name} is not a number JSON allows (numbers must be finite)")


def _finite_float(s: str) -> float:
    x = float(s)
    if not math.isfinite(x):
        raise ValueError(f"{s[:40]} is out of range (numbers must be finite)")
    return x


def parse_body(raw: bytes):
    """The JSON value of a request body, or _Refused(400) saying what is wrong with it."""
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise _Refused(400, f"the body is not UTF-8 text ({exc.reason} at byte {exc.start})") from None
    if _depth(text) > MAX_DEPTH:
        raise _Refused(400, f"the body is nested more than {MAX_DEPTH} levels deep")
    try:
        return json.loads(text, parse_constant=_no_constant, parse_float=_finite_float)
    except (ValueError, RecursionError) as exc:
        raise _Refused(400, f"the body is not valid JSON: {exc}") from None


def _page_csp(page: bytes) -> str:
    """A content security policy for the page: its own inline script only (by hash), no other resource."""
    scripts = re.findall(rb"<script>(.*?)</script>", page, flags=re.S)
    hashes = " ".join("'sha256-" + base64.b64encode(hashlib.sha256(s).digest()).decode() + "'" for s in scripts)
    return (
        f"default-src 'none'; script-src {hashes}; style-src 'unsafe-inline'; connect-src 'self'; "
        "img-src 'self'; base-uri 'none'; form-action 'none'; frame-ancestors 'none'"
    )


#: Pending connections (still sending their request) kept open at most; a new connection beyond this closes
#: the oldest pending one. A page a few browser tabs use opens a handful at a time.
MAX_PENDING = 256
#: Threads answering complete requests (the only threads the server starts besides its own loop).
HANDLER_THREADS = 16
#: Complete requests waiting for a thread beyond which a new one is answered 503.
MAX_QUEUED = 64
#: Simulations running or waiting for the engine at once; one more waits ``SIMULATION_WAIT`` s, then gets 503.
SIMULATIONS = 8
SIMULATION_WAIT = 2.0  # s
RETRY_AFTER = 1  # s, in the Retry-After header of a 503
MAX_HEAD = 16 * 1024  # bytes: request line and headers (the page's are under 1 KiB)
BACKLOG = 128  # connections the kernel queues before the server accepts them
_END_OF_HEAD = re.compile(rb"\r?\n\r?\n")
_CONTENT_LENGTH = re.compile(rb"^content-length[ \t]*:[ \t]*([^\r\n]*?)[ \t]*\r?$", re.I | re.M)
_TRANSFER_ENCODING = re.compile(rb"^transfer-encoding[ \t]*:", re.I | re.M)


def answer_bytes(code: int, body: bytes, ctype: str, extra: dict | None = None, head_only: bool = False) -> bytes:
    """A complete HTTP/1.0 answer with the page's security headers (every answer of the server has them)."""
    from http import HTTPStatus

    try:
        reason = HTTPStatus(code).phrase
    except ValueError:
        reason = ""
    headers = {
        "Server": "wallcal",
        "Content-Type": ctype,
        "Content-Length": str(len(body)),
        "Cache-Control": "no-store",
        "X-Content-Type-Options": "nosniff",
        "Referrer-Policy": "no-referrer",
        "X-Frame-Options": "DENY",
        "Connection": "close",
        **(extra or {}),
    }
    head = f"HTTP/1.0 {code} {reason}\r\n" + "".join(f"{k}: {v}\r\n" for k, v in headers.items()) + "\r\n"
    return head.encode("latin-1") + (b"" if head_only else body)


def error_bytes(code: int, message: str, extra: dict | None = None) -> bytes:
    """A refusal: one line of JSON ``{"error": message}``."""
    return answer_bytes(code, json.dumps({"error": message}).encode(), "application/json", extra)


class _Conn:
    """A connection the server's loop reads until its request is complete (no thread meanwhile)."""

    __slots__ = ("sock", "addr", "buf", "deadline", "need", "draining")

    def __init__(self, sock, addr, deadline: float):
        self.sock, self.addr, self.buf, self.deadline = sock, addr, bytearray(), deadline
        self.need = None  # bytes of head + body once the head is complete
        self.draining = False  # answered by the loop: input is read and dropped until EOF or the deadline


class LiveServer(HTTPServer):
    """The HTTP server of ``wallcal serve``.

    One loop (``serve_forever``'s thread) accepts connections and reads each request, head and body,
    without a thread: a connection must send its whole request within ``timeout`` seconds (408
    otherwise), its head within ``MAX_HEAD`` bytes (414, 431); at most ``MAX_PENDING`` connections
    wait for their request (a new one closes the oldest). Complete requests go to a pool of
    ``HANDLER_THREADS`` threads (``MAX_QUEUED`` waiting at most: 503 beyond). So a thousand clients
    trickling bytes hold no thread and cannot keep the page from being served.

    Attributes: ``app`` (the ManualCalibration), ``token`` (this start's secret), ``url``
    (the page's address with the token), ``allowed_hosts`` (host names accepted in the
    ``Host`` header; None: any, for a wildcard address with ``allow_remote``).
    """

    request_queue_size = BACKLOG

    def __init__(self, address, handler, app, token: str, allow_any_host: bool = False, timeout: float = TIMEOUT):
        from collections import OrderedDict
        from concurrent.futures import ThreadPoolExecutor

        host = address[0]
        self.address_family = socket.AF_INET6 if ":" in host else socket.AF_INET
        super().__init__(address, handler)
        self.app = app
        self.token = token
        self.request_timeout = float(timeout)
        port = self.server_address[1]
        names = {"localhost", host.lower(), f"[{host.lower()}]" if ":" in host else host.lower()}
        if host.lower() == "localhost":
            names.add("127.0.0.1")
        self.allowed_hosts = None if allow_any_host else names
        shown = {"0.0.0.0": "127.0.0.1", "::": "[::1]", "": "127.0.0.1"}.get(host, f"[{host}]" if ":" in host else host)
        self.url = f"http://{shown}:{port}/?token={token}"
        self._pending: OrderedDict[int, _Conn] = OrderedDict()  # by fd, oldest first
        self._pool = ThreadPoolExecutor(HANDLER_THREADS, thread_name_prefix="wallcal-serve")
        self._queued = 0  # requests given to the pool and not finished
        self._queued_lock = threading.Lock()
        self._prefix: dict[int, bytes] = {}  # request bytes read by the loop, by the socket's id
        self._stop = threading.Event()
        self._stopped = threading.Event()
        self._stopped.set()

    # ------------------------------------------------------------------ the loop
    def serve_forever(self, poll_interval: float = 0.2) -> None:
        import selectors

        self._stop.clear()
        self._stopped.clear()
        sel = selectors.DefaultSelector()
        self._sel = sel
        self.socket.setblocking(False)
        sel.register(self.socket, selectors.EVENT_READ, None)
        try:
            while not self._stop.is_set():
                for key, _ in sel.select(poll_interval):
                    if key.data is None:
                        self._accept()
                    else:
                        self._receive(key.data)
                now = time.monotonic()
                while self._pending:
                    conn = next(iter(self._pending.values()))
                    if conn.deadline > now:
                        break
                    self._expire(conn)
        finally:
            for conn in list(self._pending.values()):
                self._close(conn)
            sel.close()
            self._stopped.set()

    def shutdown(self) -> None:
        """Stop ``serve_forever`` and wait until it has returned (from another thread)."""
        self._stop.set()
        self._stopped.wait()

    def server_close(self) -> None:
        super().server_close()
        self._pool.shutdown(wait=False, cancel_futures=True)

    def _accept(self) -> None:
        import selectors

        for _ in range(64):  # then let the loop serve the others
            try:
                sock, addr = self.socket.accept()
            except BlockingIOError:
                return
            except OSError as exc:
                if exc.errno in (errno.EMFILE, errno.ENFILE, errno.ENOBUFS, errno.ENOMEM):
                    if self._pending:  # out of file descriptors: make room, the next round accepts
                        self._close(next(iter(self._pending.values())))
                    else:
                        time.sleep(0.05)
                    return
                continue  # a connection reset before it was accepted
            while len(self._pending) >= MAX_PENDING:
                self._close(next(iter(self._pending.values())))
            sock.setblocking(False)
            conn = _Conn(sock, addr, time.monotonic() + self.request_timeout)
            self._pending[sock.fileno()] = conn
            self._sel.register(sock, selectors.EVENT_READ, conn)

    def _receive(self, conn: _Conn) -> None:
        try:
            chunk = conn.sock.recv(65536)
        except (BlockingIOError, InterruptedError):
            return
        except OSError:
            self._close(conn)
            return
        if conn.draining:
            if not chunk:
                self._close(conn)
            return
        if not chunk:  # the client stopped sending: answer what came (a short body is a 400)
            if conn.buf:
                self._dispatch(conn)
            else:
                self._close(conn)
            return
        old = len(conn.buf)
        conn.buf += chunk
        if conn.need is None:
            end = _END_OF_HEAD.search(conn.buf, max(0, old - 3))
            head = len(conn.buf) if end is None else end.end()
            if head > MAX_HEAD:
                line = conn.buf.find(b"\n", 0, MAX_HEAD + 1) >= 0
                code, what = (431, "the request headers are") if line else (414, "the request line is")
                self._refuse(conn, code, f"{what} longer than the {MAX_HEAD} bytes the server accepts")
                return
            if end is None:
                return
            conn.need = end.end() + self._body_length(bytes(conn.buf[: end.end()]))
        if len(conn.buf) >= conn.need:
            self._dispatch(conn)

    @staticmethod
    def _body_length(head: bytes) -> int:
        """The body bytes to read before answering: the one valid Content-Length up to MAX_BODY, else 0 (the
        handler refuses the request without reading its body)."""
        lengths = _CONTENT_LENGTH.findall(head)
        if len(lengths) != 1 or _TRANSFER_ENCODING.search(head) or not re.fullmatch(rb"[0-9]{1,15}", lengths[0]):
            return 0
        n = int(lengths[0])
        return n if n <= MAX_BODY else 0

    def _expire(self, conn: _Conn) -> None:
        if conn.draining:
            self._close(conn)
            return
        t = self.request_timeout
        if conn.need is None:
            self._refuse(conn, 408, f"the request did not arrive within {t:g} s ({len(conn.buf)} bytes came)")
        else:
            head = conn.need - self._body_length(bytes(conn.buf[: conn.need]))
            got, n = len(conn.buf) - head, conn.need - head
            self._refuse(conn, 408, f"the body did not arrive within {t:g} s ({got} of {n} bytes)")

    def _refuse(self, conn: _Conn, code: int, message: str, extra: dict | None = None) -> None:
        """Answer from the loop, then read and drop what the client still sends for 2 s (so that closing does not
        reset the connection before the client has read the answer)."""
        try:
            conn.sock.send(error_bytes(code, message, extra))  # a few hundred bytes: fits the empty send buffer
            conn.sock.shutdown(socket.SHUT_WR)
        except OSError:
            self._close(conn)
            return
        conn.draining = True
        conn.deadline = time.monotonic() + 2.0
        self._pending.move_to_end(conn.sock.fileno())

    def _close(self, conn: _Conn) -> None:
        self._forget(conn)
        conn.sock.close()

    def _forget(self, conn: _Conn) -> None:
        self._pending.pop(conn.sock.fileno(), None)
        try:
            self._sel.unregister(conn.sock)
        except (KeyError, ValueError):
            pass

    def _dispatch(self, conn: _Conn) -> None:
        """Give a complete request to the pool (503 when too many wait)."""
        with self._queued_lock:
            busy = self._queued >= HANDLER_THREADS + MAX_QUEUED
            if not busy:
                self._queued += 1
        if busy:
            self._refuse(conn, 503, "the server is busy; retry in a moment", {"Retry-After": str(RETRY_AFTER)})
            return
        self._forget(conn)
        conn.sock.setblocking(True)
        conn.sock.settimeout(self.request_timeout)
        self._prefix[id(conn.sock)] = bytes(conn.buf)
        self._pool.submit(self._answer, conn.sock, conn.addr)

    def _answer(self, sock, addr) -> None:
        try:
            self.finish_request(sock, addr)
        except Exception:
            self.handle_error(sock, addr)
        finally:
            self._prefix.pop(id(sock), None)
            self.shutdown_request(sock)
            with self._queued_lock:
                self._queued -= 1

    def take_prefix(self, sock) -> bytes:
        """The request bytes the loop read from ``sock``."""
        return self._prefix.pop(id(sock), b"")

    def handle_error(self, request, client_address):
        """One line on stderr instead of a traceback; a client that went away is not an error."""
        exc = sys.exc_info()[1]
        if isinstance(exc, OSError):
            return
        print(f"wallcal serve: error answering {client_address[0]}: {type(exc).__name__}: {exc}", file=sys.stderr)


def make_handler(app: ManualCalibration, timeout: float = TIMEOUT):
    page = PAGE.read_bytes()
    csp = _page_csp(page)
    routes = {"/api/study": ("GET", lambda body: app.state()), "/api/simulate": ("POST", app.simulate)}
    routes["/api/save"] = ("POST", app.save)

    class Handler(BaseHTTPRequestHandler):
        def setup(self):
            self.timeout = timeout  # socket time-out of this connection (read by StreamRequestHandler.setup)
            super().setup()
            self.rfile.close()  # not the socket: the request was read by the server's loop
            self.rfile = io.BytesIO(self.server.take_prefix(self.request))  # the request, read by the server's loop
            self._body_read = False

        def log_message(self, fmt, *args):  # quiet
            pass

        # ---------------------------------------------------------------- answering
        def version_string(self):
            return "wallcal"

        def send_error(self, code, message=None, explain=None):
            """The standard library's own refusals (a bad request line, too many headers, an unknown method) as
            one line of JSON with the security headers, like every other answer."""
            self.close_connection = True
            if code == 501:
                text = f"method {str(self.command)[:20]!r} is not supported (GET, POST, HEAD)"
            elif code == 431:
                text = "too many request headers"
            elif code == 414:
                text = "the request line is too long"
            else:
                text = f"bad request: {message or code}"
            self._json(code, {"error": text[:200]})

        def _send(self, code: int, body: bytes, ctype: str, extra: dict | None = None):
            self.wfile.write(answer_bytes(code, body, ctype, extra, head_only=self.command == "HEAD"))
            self.close_connection = True
            headers = getattr(self, "headers", None) or {}
            announced = headers.get("Content-Length", "").strip() not in ("", "0")
            if not self._body_read and (announced or headers.get("Transfer-Encoding")):
                self._linger()

        def _json(self, code: int, obj, extra: dict | None = None):
            self._send(code, json.dumps(obj, allow_nan=False).encode(), "application/json", extra)

        def _linger(self):
            """After answering a request whose body was not read: stop sending, then read and drop what the
            client still sends (at most 2 s, 16 MiB), so that closing the socket does not reset the
            connection before the client has read the answer."""
            try:
                self.wfile.flush()
                self.connection.shutdown(socket.SHUT_WR)
                self.connection.settimeout(0.5)
                deadline, dropped = time.monotonic() + 2.0, 0
                while time.monotonic() < deadline and dropped < 16 << 20:
                    chunk = self.connection.recv(1 << 16)
                    if not chunk:
                        break
                    dropped += len(chunk)
            except OSError:
                pass

        def _read(self, n: int) -> bytes:
            """The ``n`` body bytes (the server's loop waited for them, or for the client to stop sending)."""
            data = self.rfile.read(n)
            if len(data) < n:
                raise _Refused(400, f"the body ended after {len(data)} of the {n} bytes announced")
            return data

        # ---------------------------------------------------------------- checks
        def _check_host(self):
            allowed = self.server.allowed_hosts
            host = (self.headers.get("Host") or "").strip().lower()
            if not host:
                raise _Refused(403, "refused: no Host header")
            name, _, port = host.rpartition(":") if not host.endswith("]") else (host, "", "")
            if not name or (port and not re.fullmatch(r"[0-9]{1,5}", port)):
                name, port = host, ""
            if port and int(port) != self.server.server_address[1]:
                raise _Refused(403, f"refused: Host {host!r} names another port")
            if allowed is not None and name not in allowed:
                raise _Refused(403, f"refused: Host {host!r} is not this server (only {', '.join(sorted(allowed))})")

        def _check_caller(self):
            """The API's checks: same origin, the token."""
            origin = self.headers.get("Origin")
            if origin is not None and origin.lower() != f"http://{self.headers['Host'].strip().lower()}":
                raise _Refused(403, f"refused: requests from {origin[:100]!r} may not use this page's API")
            site = self.headers.get("Sec-Fetch-Site")
            if site is not None and site not in ("same-origin", "none"):
                raise _Refused(403, f"refused: a {site} request may not use this page's API")
            given = self.headers.get(TOKEN_HEADER)
            if not given:
                raise _Refused(
                    403, f"refused: no token (header {TOKEN_HEADER}); open the page from the URL wallcal serve printed"
                )
            if not hmac.compare_digest(given.encode("utf-8", "surrogateescape"), self.server.token.encode()):
                raise _Refused(403, "refused: wrong token; open the page from the URL this wallcal serve printed")

        def _json_body(self):
            ctype = self.headers.get("Content-Type") or ""
            if ctype.split(";")[0].strip().lower() != "application/json":
                raise _Refused(415, f"the API accepts Content-Type: application/json only, got {ctype[:60]!r}")
            if self.headers.get("Transfer-Encoding"):
                raise _Refused(411, "send the body with a Content-Length (no Transfer-Encoding)")
            if len(self.headers.get_all("Content-Length") or ()) > 1:
                raise _Refused(400, "more than one Content-Length header")
            n = (self.headers.get("Content-Length") or "").strip()
            if not n:
                raise _Refused(411, "a Content-Length header is required")
            if not re.fullmatch(r"[0-9]{1,15}", n):
                raise _Refused(400, f"bad Content-Length {n[:40]!r}")
            if int(n) > MAX_BODY:
                raise _Refused(413, f"the body ({int(n)} bytes) is larger than the {MAX_BODY} bytes the API accepts")
            raw = self._read(int(n))
            self._body_read = True
            return parse_body(raw)

        # ---------------------------------------------------------------- dispatch
        def _handle(self):
            extra = None
            try:
                self._check_host()
                path = urlsplit(self.path).path
                if path in ("/", "/index.html"):
                    if self.command not in ("GET", "HEAD"):
                        raise _Refused(405, f"{self.command} is not allowed on the page")
                    self._send(200, page, "text/html; charset=utf-8", {"Content-Security-Policy": csp})
                    return
                if path == "/favicon.ico":
                    self._send(204, b"", "image/x-icon")
                    return
                if path not in routes:
                    raise _Refused(404, f"no such page: {path[:100]}")
                self._check_caller()
                method, action = routes[path]
                if self.command != method:
                    raise _Refused(405, f"{path} takes {method}, not {self.command}")
                answer = action(self._json_body() if method == "POST" else None)
                code, extra = 200, None
            except _Refused as exc:
                code, answer, extra = exc.status, {"error": str(exc)}, exc.headers
            except WallcalError as exc:
                code, answer = 400, {"error": str(exc)}
            except Exception as exc:  # a bug: answer without a traceback, say it on the terminal
                print(
                    f"wallcal serve: internal error on {self.path[:100]}: {type(exc).__name__}: {exc}", file=sys.stderr
                )
                code, answer = 500, {"error": f"internal error ({type(exc).__name__}); see the terminal"}
            self._json(code, answer, extra)

        do_GET = do_POST = do_HEAD = do_PUT = do_DELETE = do_PATCH = do_OPTIONS = _handle

    return Handler


def serve(
    study_path,
    host: str = "127.0.0.1",
    port: int = 8765,
    ready=None,
    *,
    allow_remote: bool = False,
    token: str | None = None,
    timeout: float = TIMEOUT,
):
    """Serve the manual-calibration page until interrupted (or ``shutdown()``).

    Parameters
    ----------
    study_path : path
    host : str
        Interface to bind (127.0.0.1 by default: the page is for this machine only). Another
        address needs ``allow_remote=True``: the token is then the page's only protection.
    port : int
        TCP port (0: any free port).
    ready : callable, optional
        Called with the server once it listens; ``server.url`` is the page's address with
        its token (tests use it, the command prints it).
    allow_remote : bool
        Allow a ``host`` that is not a loopback address.
    token : str, optional
        The API token (default: 32 random bytes, new at every start).
    timeout : float
        Seconds a connection may take to send its request [s].
    """
    if not is_loopback(host) and not allow_remote:
        raise WallcalError(
            f"--host {host}: not a loopback address; the page would be reachable from other machines "
            "with only its token to protect it. Pass --allow-remote (allow_remote=True) if that is what you want"
        )
    app = ManualCalibration(study_path)
    wildcard = host in ("", "0.0.0.0", "::")
    httpd = LiveServer(
        (host, port), make_handler(app, timeout), app, token or secrets.token_urlsafe(32), wildcard, timeout
    )
    if ready is not None:
        ready(httpd)
    try:
        httpd.serve_forever(poll_interval=0.2)
    finally:
        httpd.server_close()
    return httpd

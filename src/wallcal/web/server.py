"""``wallcal serve``: a local web page for manual calibration.

A small standard-library HTTP server (bound to 127.0.0.1 by default) that serves
one page (``page.html``, no external assets: it works offline) and three JSON
end points, all built on wallcal's public API only (``load_study``, ``prepare``,
``simulate``, ``Wall.replace_layer``, ``dump_wall``, ``calibration.parse_space``):

- ``GET /api/study``: the wall, the calibration parameters, the sensors, the
  measured series and the base-case simulation;
- ``POST /api/simulate``: ``{"layers": {id: {property: value}}, "probes": {name: depth}}``
  -> simulated series and metrics (one engine run on prepared data: milliseconds);
- ``POST /api/save``: the same body -> the wall written as TOML next to the study
  (``manual_wall.toml``, or ``{"file": name}``), and its text.
"""

from __future__ import annotations

import json
import math
import threading
import time
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path

import numpy as np

import wallcal
from wallcal.errors import WallcalError

PAGE = Path(__file__).with_name("page.html")
EDITABLE = ("conductivity", "density", "specific_heat", "conductivity_temperature_coefficient", "contact_resistance")


def _clean(values) -> list:
    return [None if (v is None or not math.isfinite(v)) else round(float(v), 5) for v in values]


class ManualCalibration:
    """The state behind the page: a study, its prepared data and the base case."""

    def __init__(self, study_path: str | Path):
        self.study_path = Path(study_path).resolve()
        self.study = wallcal.load_study(self.study_path)
        self.prepared = wallcal.prepare(self.study, needs=("batches",), purpose="the live page")
        self.base = wallcal.simulate(self.study, prepared=self.prepared)
        self.lock = threading.Lock()
        self.params = []
        if self.study.calibration:
            from wallcal.calibration import parse_space

            try:
                space = parse_space(self.study)
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
                    for p in space.parameters
                ]
            except WallcalError:
                self.params = []

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
        wall = self.study.wall
        ids = {layer.id for layer in wall.layers}
        for lid, props in (body.get("layers") or {}).items():
            if lid not in ids:
                raise WallcalError(f"layers: {lid!r} is not a layer id")
            changes = {}
            for prop, v in props.items():
                if prop not in EDITABLE:
                    raise WallcalError(f"layers.{lid}.{prop}: not an editable property")
                v = float(v)
                if (
                    not math.isfinite(v)
                    or (prop in ("conductivity", "density", "specific_heat") and v <= 0)
                    or (prop == "contact_resistance" and v < 0)
                ):
                    raise WallcalError(f"layers.{lid}.{prop}: invalid value {v}")
                changes[prop] = v
            wall = wall.replace_layer(lid, **changes)
        for name, depth in (body.get("probes") or {}).items():
            depth = float(depth)
            if not 0 <= depth <= wall.thickness:
                raise WallcalError(f"probes.{name}: depth {depth} m is outside the wall")
            wall = wall.replace_probe(name, depth=depth)
        return wall

    def simulate(self, body: dict) -> dict:
        wall = self.wall_from(body)
        t = time.perf_counter()
        with self.lock:
            res = wallcal.simulate(self.study, prepared=self.prepared, wall=wall)
        return self._payload(res, (time.perf_counter() - t) * 1000, wall)

    def save(self, body: dict) -> dict:
        from wallcal.outputs import write_text_atomic
        from wallcal.study import dump_wall

        wall = self.wall_from(body)
        name = Path(str(body.get("file") or "manual_wall.toml")).name
        if not name.endswith(".toml"):
            name += ".toml"
        text = dump_wall(
            wall.replace(name=(wall.name or "wall") + " (manual calibration)"),
            f"saved by wallcal serve from {self.study_path.name}",
        )
        path = write_text_atomic(self.study_path.parent / name, text)
        return {"path": str(path), "toml": text}

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


def make_handler(app: ManualCalibration):
    page = PAGE.read_bytes()

    class Handler(BaseHTTPRequestHandler):
        def log_message(self, fmt, *args):  # quiet
            pass

        def _send(self, code: int, body: bytes, ctype: str):
            self.send_response(code)
            self.send_header("Content-Type", ctype)
            self.send_header("Content-Length", str(len(body)))
            self.send_header("Cache-Control", "no-store")
            self.end_headers()
            self.wfile.write(body)

        def _json(self, code: int, obj):
            self._send(code, json.dumps(obj, allow_nan=False).encode(), "application/json")

        def do_GET(self):
            if self.path in ("/", "/index.html"):
                self._send(200, page, "text/html; charset=utf-8")
            elif self.path == "/api/study":
                self._json(200, app.state())
            elif self.path == "/favicon.ico":
                self._send(204, b"", "image/x-icon")
            else:
                self._json(404, {"error": f"no such page: {self.path}"})

        def do_POST(self):
            n = int(self.headers.get("Content-Length") or 0)
            if n > 1_000_000:
                self._json(413, {"error": "request too large"})
                return
            try:
                body = json.loads(self.rfile.read(n) or b"{}")
                if self.path == "/api/simulate":
                    self._json(200, app.simulate(body))
                elif self.path == "/api/save":
                    self._json(200, app.save(body))
                else:
                    self._json(404, {"error": f"no such end point: {self.path}"})
            except (WallcalError, ValueError, TypeError) as exc:
                self._json(400, {"error": str(exc)})

    return Handler


def serve(study_path, host: str = "127.0.0.1", port: int = 8765, ready=None):
    """Serve the manual-calibration page until interrupted.

    Parameters
    ----------
    study_path : path
    host : str
        Interface to bind (127.0.0.1 by default: the page is for this machine only).
    port : int
        TCP port (0: any free port).
    ready : callable, optional
        Called with the server once it listens (tests use it to learn the port).
    """
    app = ManualCalibration(study_path)
    httpd = ThreadingHTTPServer((host, port), make_handler(app))
    httpd.daemon_threads = True
    if ready is not None:
        ready(httpd)
    try:
        httpd.serve_forever(poll_interval=0.2)
    finally:
        httpd.server_close()
    return httpd

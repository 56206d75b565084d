"""``wallcal serve STUDY``: a local web page for manual calibration."""

from __future__ import annotations


def register(sub) -> None:
    p = sub.add_parser(
        "serve",
        help="a local web page for manual calibration",
        description="Serve a page with one control per layer property (and the calibration "
        "parameters), a live plot of measured vs simulated for every sensor and the "
        "metrics table; a button saves the current wall as TOML next to the study.",
    )
    p.add_argument("study")
    p.add_argument("--port", type=int, default=8765)
    p.add_argument("--host", default="127.0.0.1", help="interface to bind (default 127.0.0.1: this machine only)")
    p.set_defaults(func=run)


def run(args) -> int:
    from ..web.server import serve

    def ready(httpd):
        host, port = httpd.server_address[:2]
        print(f"wallcal serve: http://{host}:{port}/  (Ctrl-C to stop)", flush=True)

    try:
        serve(args.study, host=args.host, port=args.port, ready=ready)
    except OSError as exc:
        from ..errors import WallcalError

        raise WallcalError(f"cannot listen on {args.host}:{args.port}: {exc.strerror}; try another --port") from exc
    except KeyboardInterrupt:
        print("\nstopped")
    return 0

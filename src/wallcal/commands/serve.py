"""``wallcal serve STUDY``: a local web page for manual calibration."""

from __future__ import annotations

import sys


def register(sub) -> None:
    p = sub.add_parser(
        "serve",
        help="a local web page for manual calibration",
        description="Serve a page with one control per layer property (and the calibration "
        "parameters), a live plot of measured vs simulated for every sensor and the "
        "metrics table; a button saves the current wall as a new TOML file next to the study "
        "(manual_wall.toml, manual_wall-2.toml, ...: never an existing file). Open the page from "
        "the printed URL: its token, new at every start, is required by the page's API.",
    )
    p.add_argument("study")
    p.add_argument("--port", type=int, default=8765, help="TCP port (default 8765; 0: any free port)")
    p.add_argument("--host", default="127.0.0.1", help="interface to bind (default 127.0.0.1: this machine only)")
    p.add_argument(
        "--allow-remote",
        action="store_true",
        help="allow a --host that is not a loopback address (the page is then protected by its token only)",
    )
    p.set_defaults(func=run)


def run(args) -> int:
    from ..errors import WallcalError
    from ..web.server import is_loopback, serve

    if args.allow_remote and not is_loopback(args.host):
        print(
            f"wallcal serve: WARNING: listening on {args.host}: any machine that can reach this port can open "
            "the page; its only protection is the token in the URL, which travels unencrypted (plain HTTP). "
            "Share the URL with no one and stop the server when done.",
            file=sys.stderr,
            flush=True,
        )

    def ready(httpd):
        print(f"wallcal serve: {httpd.url}  (Ctrl-C to stop)", flush=True)

    try:
        serve(args.study, host=args.host, port=args.port, ready=ready, allow_remote=args.allow_remote)
    except OSError as exc:
        raise WallcalError(f"cannot listen on {args.host}:{args.port}: {exc.strerror}; try another --port") from exc
    except KeyboardInterrupt:
        print("\nstopped")
    return 0

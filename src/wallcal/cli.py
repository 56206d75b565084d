"""Command-line interface: a thin layer over the library API.

Each command module registers its sub-parser through ``register(subparsers)``
and sets ``func(args) -> int``. Errors raised as :class:`WallcalError` are
printed on one line (``wallcal: error: ...``) with exit status 2; ``--debug``
shows the traceback instead. Ctrl-C exits with status 130 and a message.
"""

from __future__ import annotations

import argparse
import importlib
import sys

from .errors import WallcalError

#: Modules that add commands (each has ``register(subparsers)``).
COMMAND_MODULES = (
    "wallcal.commands.simulate",
    "wallcal.commands.calibrate",
    "wallcal.commands.run",
    "wallcal.commands.serve",
    "wallcal.commands.standards",
    "wallcal.commands.energyplus",
    "wallcal.commands.analysis",
    "wallcal.commands.diagnose",
    "wallcal.commands.retrofit",
    "wallcal.commands.building",
)


def build_parser() -> argparse.ArgumentParser:
    from . import __version__

    parser = argparse.ArgumentParser(
        prog="wallcal",
        description="Calibrate the thermal model of a building wall against in-situ monitoring data.",
    )
    parser.add_argument("--version", action="version", version=f"wallcal {__version__}")
    parser.add_argument("--debug", action="store_true", help="show the full traceback on errors")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for mod in COMMAND_MODULES:
        importlib.import_module(mod).register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 1
    try:
        return int(args.func(args) or 0)
    except WallcalError as exc:
        if args.debug:
            raise
        msg = str(exc)
        print(f"wallcal: error: {msg}", file=sys.stderr)
        return 2
    except BrokenPipeError:  # output piped into a command that stopped reading (e.g. head)
        sys.stderr.close()
        return 0
    except KeyboardInterrupt:
        if args.debug:
            raise
        print("wallcal: interrupted; no partial output was left in place", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())

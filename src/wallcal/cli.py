"""Command-line interface: a thin layer over the library API.

Each command module registers its sub-parser through ``register(subparsers)``
and sets ``func(args) -> int``. Errors raised as :class:`WallcalError` are
printed on one line (``wallcal: error: ...``; :func:`wallcal.errors.format_message`: lines of at most
300 characters, control characters escaped) with exit status 2; ``--debug``
shows the traceback instead. Ctrl-C exits with status 130 and a message.
When numba has to compile the engine's kernels (the first run after installing
or upgrading, or with an empty ``NUMBA_CACHE_DIR``), a command says so on stderr
(:class:`CompileNotice`), unless it was given ``--quiet``.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import sys
import threading

from numba.core import event

from .errors import WallcalError, format_message, interrupted

#: numba's event of one compilation (its documented event API; a load from the kernel cache sends none)
COMPILE_EVENT = "numba:compile"

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
    "wallcal.commands.verify",
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


class CompileNotice(event.Listener):
    """Says once, on ``stream``, that the engine's kernels are being compiled, when a compilation has been running
    for ``after`` seconds: otherwise the first run after installing is silent for the ~10 s numba takes before any
    progress line. Compilations that finish sooner, and loads from the cache, say nothing."""

    MESSAGE = (
        "wallcal: compiling the engine's kernels (once after installing or upgrading; later runs load them "
        "from numba's cache)"
    )

    def __init__(self, stream=None, after: float = 2.0):
        self.stream = stream or sys.stderr
        self.after = after
        self.depth = 0  # compilations under way (numba compiles a kernel's callees inside it)
        self.said = False
        self.timer: threading.Timer | None = None
        self.lock = threading.Lock()

    def on_start(self, ev):
        with self.lock:
            self.depth += 1
            if self.depth == 1 and not self.said:
                self.timer = threading.Timer(self.after, self._say)
                self.timer.daemon = True
                self.timer.start()

    def on_end(self, ev):
        with self.lock:
            self.depth -= 1
            if self.depth == 0:
                self._cancel()

    def _say(self):
        with self.lock:
            if self.depth == 0 or self.said:
                return
            self.said = True
        print(self.MESSAGE, file=self.stream, flush=True)

    def close(self):
        with self.lock:
            self._cancel()

    def _cancel(self):  # (under the lock)
        if self.timer is not None:
            self.timer.cancel()
            self.timer = None


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 1
    notice = None if getattr(args, "quiet", False) else CompileNotice()
    listening = contextlib.nullcontext() if notice is None else event.install_listener(COMPILE_EVENT, notice)
    try:
        with listening:
            return int(args.func(args) or 0)
    except WallcalError as exc:
        if args.debug:
            raise
        print(format_message(str(exc), "wallcal: error: "), file=sys.stderr)
        return 2
    except BrokenPipeError:  # output piped into a command that stopped reading (e.g. head)
        sys.stderr.close()
        return 0
    except (KeyboardInterrupt, SystemError) as exc:  # (a Ctrl-C inside a numba kernel: a SystemError)
        if args.debug or not interrupted(exc):
            raise
        print("wallcal: interrupted; no partial output was left in place", file=sys.stderr)
        return 130
    finally:
        if notice is not None:
            notice.close()


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())

"""The ``imubench`` command line: one subcommand per module in :mod:`imubench.commands`.

Each command module exposes ``register(subparsers)`` (adds its parser and sets ``func``)
and a ``run(args) -> int``. :func:`main` is the one place that turns outcomes into exit
statuses (docs/cli.md):

======  ===============================================================================
status  meaning
======  ===============================================================================
0       success
1       a check ran and failed (a command's verdict, e.g. a jig FAIL); never an error
2       usage or input error: bad options (argparse), an invalid configuration,
        recording, model or source, a file that cannot be read or written; one line
        per problem, ``imubench COMMAND: error: ...``
70      internal error (a bug): the traceback is printed, please report it
130     interrupted by SIGINT (Ctrl-C); 143: by SIGTERM. One line on stderr; what was
        written so far is flushed and closed (both raise KeyboardInterrupt in the
        command, so one clean-up path serves both; a second signal exits at once)
141     stdout was closed by its reader (``imubench allan ... | head -1``): no
        message, as a tool killed by SIGPIPE
======  ===============================================================================

``imubench run`` ends with 0 after SIGINT/SIGTERM: that is how a daemon is stopped.
``-v``/``-vv`` and ``--progress`` are accepted before or after the subcommand.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import os
import signal
import sys
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from types import FrameType
from typing import Any

from imubench import __version__

COMMANDS: tuple[str, ...] = (
    "run", "convert", "allan", "acquire", "sim", "fit", "model", "report", "gap", "jig", "tilt",
    "view", "fleet",
)

EXIT_OK = 0
EXIT_CHECK_FAILED = 1
EXIT_USAGE = 2
EXIT_SOFTWARE = 70
EXIT_SIGINT = 128 + signal.SIGINT
EXIT_SIGPIPE = 128 + signal.SIGPIPE
EXIT_SIGTERM = 128 + signal.SIGTERM


def _add_common_options(parser: argparse.ArgumentParser, *, sub: bool) -> None:
    """``-v`` and ``--progress``; on a subcommand they go to their own ``*_sub`` dests
    (argparse would otherwise let the subcommand's default overwrite the main value)."""
    suffix = "_sub" if sub else ""
    parser.add_argument("-v", "--verbose", action="count", default=0, dest="verbose" + suffix,
                        help="more log output: -v info, -vv debug (before or after COMMAND)")
    parser.add_argument("--progress", choices=("auto", "on", "off"), default=None,
                        dest="progress" + suffix,
                        help="progress bars on stderr: auto (when stderr is a terminal, "
                        "the default), on, off")


def build_parser(only: str | None = None) -> argparse.ArgumentParser:
    """The parser with every command, or with ``only`` that one (a command's module may
    import heavy libraries: ``imubench run`` must start in well under a second)."""
    parser = argparse.ArgumentParser(
        prog="imubench",
        description="Live acquisition and Allan-family noise analysis for ST LSM6DS IMUs.",
        epilog="Exit status: 0 ok, 1 a check failed, 2 usage or input error, 130 "
        "interrupted (Ctrl-C), 143 terminated, 141 output pipe closed, 70 internal error.",
    )
    parser.add_argument("--version", action="version", version=f"imubench {__version__}",
                        help="print the version and exit")
    _add_common_options(parser, sub=False)
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name in COMMANDS if only is None else (only,):
        importlib.import_module(f"imubench.commands.{name}").register(sub)
    for subparser in sub.choices.values():
        _add_common_options(subparser, sub=True)
    return parser


# -- signals -----------------------------------------------------------------------------


def _exit_now(signum: int, frame: FrameType | None) -> None:
    os.write(2, b"imubench: signalled again: exiting without finishing the clean-up\n")
    os._exit(128 + signum)


_received: list[int] = []
"""The signal that raised the KeyboardInterrupt being handled (SIGINT or SIGTERM)."""


def _on_signal(signum: int, frame: FrameType | None) -> None:
    # the first signal unwinds the command (its clean-up closes what it wrote); a second
    # one while that runs exits at once
    _note_signal(signum, frame)
    raise KeyboardInterrupt


def _note_signal(signum: int, frame: FrameType | None) -> None:
    signal.signal(signal.SIGINT, _exit_now)
    signal.signal(signal.SIGTERM, _exit_now)
    _received.append(signum)


@contextmanager
def _signals(*, defer: bool = False) -> Iterator[None]:
    """SIGINT and SIGTERM raise KeyboardInterrupt while a command runs, so one clean-up
    path (``except KeyboardInterrupt``, ``finally``) serves both; with ``defer`` they are
    only noted (:data:`_received`), for the imports of start-up, where an exception raised
    inside C code turns into an ImportError. Main thread only; the previous handlers come
    back afterwards."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    _received.clear()
    old = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    for s in old:
        signal.signal(s, _note_signal if defer else _on_signal)
    try:
        yield
    finally:
        for s, handler in old.items():
            signal.signal(s, handler)


def _stdout_gone() -> int:
    """stdout's reader went away: point fd 1 at /dev/null so the interpreter's final
    flush cannot fail again (Python docs, "Note on SIGPIPE")."""
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, sys.stdout.fileno())
    os.close(devnull)
    return EXIT_SIGPIPE


def _error_lines(exc: BaseException) -> list[str]:
    if isinstance(exc, OSError) and exc.strerror:
        where = exc.filename if exc.filename is not None else ""
        return [f"{where}: {exc.strerror}" if where else exc.strerror]
    return str(exc).splitlines() or [type(exc).__name__]


def _signalled(who: str, note: str = "", *, daemon: bool = False) -> int:
    """The one-line message and exit status of the signal received (SIGINT or SIGTERM);
    0 for the daemon (``daemon``), which a signal stops, also in its first moments,
    before its own handlers are in place (an outside reviewer: a SIGTERM 0.6 s after the
    start gave 143, which a service manager reads as a failure)."""
    if daemon:
        name = "SIGTERM" if _received and _received[0] == signal.SIGTERM else "Ctrl-C"
        print(f"{who}: stopped ({name})", file=sys.stderr, flush=True)
        return 0
    if _received and _received[0] == signal.SIGTERM:
        print(f"{who}: terminated (SIGTERM){note}", file=sys.stderr, flush=True)
        return EXIT_SIGTERM
    print(f"{who}: interrupted (Ctrl-C){note}", file=sys.stderr, flush=True)
    return EXIT_SIGINT


def _run_command(func: Callable[[argparse.Namespace], Any], args: argparse.Namespace,
                 command: str) -> int:
    from imubench.errors import USER_ERRORS

    input_errors: tuple[type[Exception], ...] = (*USER_ERRORS, OSError)

    def say(line: str) -> None:
        print(f"imubench {command}: {line}", file=sys.stderr, flush=True)

    def signalled() -> int:
        # a conversion is all or nothing: its partial output is removed (an outside
        # reviewer read "output written so far is kept" over a CSV that was not there)
        note = ("; the partial output is removed" if command == "convert"
                else "; output written so far is kept")
        return _signalled(f"imubench {command}", note, daemon=command == "run")

    try:
        with _signals():
            status = int(func(args) or 0)
            sys.stdout.flush()
            return status
    except BrokenPipeError:
        return _stdout_gone()
    except KeyboardInterrupt:
        return signalled()
    except input_errors as exc:
        if _received:  # an error the signal caused (an interrupted file operation)
            return signalled()
        for line in _error_lines(exc):
            say(f"error: {line}")
        return EXIT_USAGE
    except Exception:
        if _received:  # e.g. an import interrupted inside C code surfaces as ImportError
            return signalled()
        import traceback

        traceback.print_exc()
        say("internal error (a bug; the traceback above tells where): please report it")
        return EXIT_SOFTWARE


def _command_of(argv: list[str]) -> str | None:
    """The command named in ``argv`` (None: none or unknown; the parser then has them all
    and reports it)."""
    takes_value = {"--progress"}
    skip = False
    for arg in argv:
        if skip:
            skip = False
        elif arg in takes_value:
            skip = True
        elif not arg.startswith("-"):
            return arg if arg in COMMANDS else None
    return None


def main(argv: list[str] | None = None) -> int:
    """Parse ``argv``, set up logging and progress bars, run the command; the exit status
    (see the module docstring)."""
    try:
        return _main(argv)
    except KeyboardInterrupt:  # between Python's own handler and ours
        args_in = sys.argv[1:] if argv is None else argv
        return _signalled("imubench", daemon=_command_of(args_in) == "run")


def _main(argv: list[str] | None) -> int:
    args_in = sys.argv[1:] if argv is None else argv
    with _signals(defer=True):  # the command's module and its libraries are imported
        args = build_parser(_command_of(args_in)).parse_args(args_in)
    if _received:
        return _signalled("imubench", daemon=args.command == "run")
    from imubench import progress
    from imubench.logs import remove_logging, setup_logging

    progress.set_mode(args.progress_sub or args.progress or "auto")
    handler = setup_logging(args.verbose + args.verbose_sub)
    logging.getLogger("imubench.cli").debug("imubench %s, Python %s: %s", __version__,
                                            sys.version.split()[0], " ".join(sys.argv))
    try:
        return _run_command(args.func, args, args.command)
    finally:
        remove_logging(handler)


if __name__ == "__main__":
    sys.exit(main())

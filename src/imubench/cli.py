"""The ``imubench`` command line: one subcommand per module in :mod:`imubench.commands`.

Each command module exposes ``register(subparsers)`` (adds its parser and sets
``func``) and a ``run(args) -> int``. Errors of the imubench family are printed on one
line per problem (``imubench: <message>``) with exit status 2; nothing else is caught.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import sys

from imubench import __version__
from imubench.errors import USER_ERRORS

COMMANDS: tuple[str, ...] = (
    "run", "convert", "allan", "acquire", "sim", "fit", "model", "report", "gap",
)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="imubench",
        description="Live acquisition and Allan-family noise analysis for ST LSM6DS IMUs.",
    )
    parser.add_argument("--version", action="version", version=f"imubench {__version__}")
    parser.add_argument("-v", "--verbose", action="count", default=0,
                        help="more log output (repeatable)")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name in COMMANDS:
        try:
            module = importlib.import_module(f"imubench.commands.{name}")
        except ModuleNotFoundError as exc:
            if exc.name == f"imubench.commands.{name}":
                continue  # command not installed in this version
            raise
        module.register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    level = logging.WARNING - 10 * min(args.verbose, 2)
    logging.basicConfig(level=level, format="%(levelname)s %(name)s: %(message)s")
    try:
        return int(args.func(args) or 0)
    except USER_ERRORS as exc:
        for line in str(exc).splitlines() or [type(exc).__name__]:
            print(f"imubench {args.command}: error: {line}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    sys.exit(main())

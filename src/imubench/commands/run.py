"""``imubench run --config FILE``: the acquisition and analysis daemon."""

from __future__ import annotations

import argparse

from imubench.config import load_config, reference_markdown


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "run", help="run the daemon (source -> recording + live Allan -> MQTT)",
        description="Read the configured source, log every sample, keep the Allan "
        "deviations up to date and publish them over MQTT until SIGINT/SIGTERM.",
    )
    p.add_argument("--config", metavar="FILE", help="TOML configuration (see README)")
    p.add_argument("--check", action="store_true",
                   help="validate the configuration and exit")
    p.add_argument("--config-reference", action="store_true",
                   help="print every configuration key with default, unit and description")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    if args.config_reference:
        print(reference_markdown())
        return 0
    config = load_config(args.config)
    if args.check:
        print(f"{args.config or '(defaults)'}: configuration is valid")
        return 0
    from imubench.daemon import run_daemon

    return run_daemon(config, args.config)

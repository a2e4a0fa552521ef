"""``imubench run [--config FILE]``: the acquisition and analysis daemon.

Without ``--config`` it runs the shipped quick-start configuration (a simulated LSM6DSL,
``imubench run --print-quickstart`` shows it). ``--check`` validates every value and exits
(status 0 valid, 2 refused, one line per problem). Under systemd see docs/service.md.
"""

from __future__ import annotations

import argparse
import logging

from imubench.config import Config, load_config, quickstart_file, reference_markdown

log = logging.getLogger(__name__)


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "run", help="run the daemon (source -> recording + live Allan -> MQTT)",
        description="Read the configured source, log every sample, keep the Allan "
        "deviations up to date and publish them over MQTT until SIGINT/SIGTERM. "
        "Without --config: the shipped quick-start configuration.",
    )
    p.add_argument("--config", metavar="FILE",
                   help="TOML configuration (README, Configuration reference); default: "
                   "the shipped quick start")
    p.add_argument("--check", action="store_true",
                   help="validate the configuration (every value) and exit")
    p.add_argument("--config-reference", action="store_true",
                   help="print every configuration key with default, unit and description")
    p.add_argument("--print-quickstart", action="store_true",
                   help="print the shipped quick-start configuration (a file to start from)")
    p.set_defaults(func=run)


def _check_calibrations(config: Config) -> None:
    """Each sensor's calibration file against its source's chip and full scales, as the
    start does (``--check`` passed a calibration for another chip that ``run`` then
    refused); no device is opened."""
    from imubench.calibration import Calibration
    from imubench.sources.registry import open_source

    for spec in config.sensor_specs():
        if spec.calibration is None:
            continue
        info = open_source(spec.uri).info
        Calibration.load(spec.calibration).check_data(
            info.chip, info.fs_dps, info.fs_g, None, f"sensor {spec.name}: source {spec.uri}")


def run(args: argparse.Namespace) -> int:
    if args.config_reference:
        print(reference_markdown())
        return 0
    if args.print_quickstart:
        print(quickstart_file().read_text(encoding="utf-8"), end="")
        return 0
    source = args.config if args.config is not None else quickstart_file()
    config = load_config(source)
    if args.check:
        _check_calibrations(config)
        print(f"{args.config or 'shipped quick start'}: configuration is valid")
        return 0
    log.info("configuration %s", args.config or "shipped quick start")
    from imubench.daemon import run_daemon

    return run_daemon(config, args.config)

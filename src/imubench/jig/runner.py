"""``imubench jig run``: check the station, run the suite through pytest, write the
report, keep the run under the board's serial number, publish the result.

Exit status: 0 every measurement passed, 1 a measurement or a test failed, 3 no failure
but an inconclusive measurement, 2 a usage error (bad station or limits file, DUT URI,
serial number, a manual fixture without a terminal, user tests that do not collect).
"""

from __future__ import annotations

import datetime as dt
import json
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from imubench.jig.dut import resolve_uri_paths
from imubench.jig.errors import JigError
from imubench.jig.limits import load_limits
from imubench.jig.report import build_result, write_report, write_result
from imubench.jig.session import MEASUREMENTS_FILE
from imubench.jig.station import load_station
from imubench.jig.store import append_history, check_serial, new_run_dir
from imubench.sources.registry import check_source_uri

SUITE_DIR = Path(__file__).resolve().parent / "suite"
USAGE = 2
PYTEST_USAGE_CODES = {2: "interrupted", 3: "internal error", 4: "usage error",
                      5: "no tests collected"}


@dataclass(frozen=True)
class JigRun:
    exit_status: int
    run_dir: Path
    result: dict[str, Any]
    published_topic: str | None
    publish_error: str | None


INCOMPLETE_JUNIT = "junit.incomplete.xml"
"""The JUnit XML of a run that did not finish: renamed so that a line system reading
``junit.xml`` never takes it for a result (an interrupted run's file said 37 tests, no
failure and no error, of a suite of 47)."""


def _set_aside_junit(run_dir: Path) -> None:
    junit = run_dir / "junit.xml"
    if junit.exists():
        junit.replace(run_dir / INCOMPLETE_JUNIT)


def _now() -> str:
    return dt.datetime.now(dt.UTC).isoformat(timespec="seconds")


def pytest_args(station_path: Path, uri: str, serial: str, run_dir: Path,
                extra: list[Path], select: str | None, suite: bool, capture: bool) -> list[str]:
    """The argument list ``imubench jig run`` gives ``pytest.main``: an empty ini file in
    the run directory and the jig package as rootdir (the project's pytest settings and
    conftests stay out), no cache, the jig plugin, JUnit XML into the run directory."""
    ini = run_dir / "pytest.ini"
    ini.write_text("[pytest]\n", encoding="utf-8")
    args = ["-c", str(ini), "--rootdir", str(SUITE_DIR.parent), "-p", "no:cacheprovider",
            "-p", "imubench.jig.plugin", "--junitxml", str(run_dir / "junit.xml"),
            "-o", "junit_suite_name=imubench-jig", "-rfEs",
            "--jig-station", str(station_path), "--jig-dut", uri,
            "--jig-serial", serial, "--jig-out", str(run_dir)]
    if not capture:
        args.append("-s")
    if select:
        args += ["-k", select]
    if suite:
        args.append(str(SUITE_DIR))
    args += [str(p) for p in extra]
    return args


def run_jig(station_path: str | Path, report_dir: str | Path, *, dut: str | None = None,
            serial: str | None = None) -> JigRun:
    """Run the station's suite on one board; see the module docstring."""
    station = load_station(station_path)
    uri = dut or resolve_uri_paths(station.dut.uri, Path(station_path).resolve().parent)
    parsed = check_source_uri(uri)
    sn = serial or station.dut.serial
    if not sn:
        raise JigError("no serial number: pass --serial SN or set dut.serial in"
                       f" {station_path}")
    check_serial(sn)
    limits = load_limits(station.resolve(station.station.limits))
    # the chip the URI names (the device tells otherwise, and the session checks it)
    chip = parsed.params.get("chip") or (parsed.target if parsed.scheme == "sim" else None)
    if chip is not None and chip != limits.chip:
        raise JigError(f"{limits.path}: limits are for {limits.chip}, the DUT URI names an "
                       f"{chip}; use config/limits-{chip}.toml")
    extra = [station.resolve(t) for t in station.station.tests]
    for t in extra:
        if not t.exists():
            raise JigError(f"{station_path}: station.tests entry {t} does not exist")
    if not station.station.suite and not extra:
        raise JigError(f"{station_path}: station.suite = false and no station.tests: nothing"
                       " to run")
    manual = station.fixture.kind == "manual"
    if manual and not (sys.stdin.isatty() and sys.stdout.isatty()):
        raise JigError("the manual fixture needs an operator at a terminal (standard input"
                       " and output must be a tty)")
    import pytest

    run_dir = new_run_dir(report_dir, sn)
    started, t0 = _now(), time.monotonic()
    args = pytest_args(Path(station_path).resolve(), uri, sn, run_dir, extra,
                       station.station.select, station.station.suite, capture=not manual)
    dont_write = sys.dont_write_bytecode
    sys.dont_write_bytecode = True  # no __pycache__ inside the installed suite
    try:
        rc = int(pytest.main(args))
    except BaseException:  # SIGINT / SIGTERM (KeyboardInterrupt) or a crash
        _set_aside_junit(run_dir)
        raise
    finally:
        sys.dont_write_bytecode = dont_write
    if rc in PYTEST_USAGE_CODES:
        _set_aside_junit(run_dir)
        raise JigError(f"pytest stopped ({PYTEST_USAGE_CODES[rc]}, exit {rc}); the run"
                       f" directory {run_dir} holds what was written ({INCOMPLETE_JUNIT}:"
                       " the tests that ran before the stop)")
    raw_path = run_dir / MEASUREMENTS_FILE
    if not raw_path.exists():
        raise JigError(f"{raw_path}: the jig plugin wrote no measurements")
    raw = json.loads(raw_path.read_text())
    result = build_result(raw, serial=sn, station=station.station.name,
                          sensor=station.station.sensor, run_id=run_dir.name,
                          started_utc=started, finished_utc=_now(),
                          wall_time_s=time.monotonic() - t0)
    try:
        # the verdict first, then the report: a SIGINT or SIGTERM while the plots are
        # drawn left result.json without its history line and no report
        write_result(run_dir, result)
        append_history(run_dir, {"run_id": run_dir.name, "verdict": result["verdict"],
                                 "finished_utc": result["finished_utc"],
                                 "station": result["station"],
                                 "limits_sha256": result["limits_sha256"],
                                 "software": result["software"]})
        try:
            write_report(run_dir, result, raw.get("artifacts", {}))
        except KeyboardInterrupt:
            result["report"] = None  # stopped while drawing: the verdict stands
            write_result(run_dir, result)
            raise
    except OSError as exc:  # a full disk: no result may read as complete
        _set_aside_junit(run_dir)
        raise JigError(f"{run_dir}: cannot write the run's result ({exc.strerror}: "
                       f"{exc.filename or run_dir}); the board's verdict "
                       f"{result['verdict']} is not recorded, {INCOMPLETE_JUNIT} holds the "
                       "tests' outcomes") from None
    topic = error = None
    if station.mqtt.broker:
        from imubench.jig.publish import publish_result

        try:
            topic = publish_result(station.mqtt, result)
        except JigError as exc:
            error = str(exc)
    return JigRun(int(result["exit_status"]), run_dir, result, topic, error)


__all__ = ["SUITE_DIR", "JigRun", "pytest_args", "run_jig"]

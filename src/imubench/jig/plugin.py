"""The pytest plugin of the jig (entry point ``imubench.jig.plugin`` in group ``pytest11``).

Options ``--jig-station``, ``--jig-dut``, ``--jig-serial``, ``--jig-out`` turn it on
(``imubench jig run`` passes them); without ``--jig-station`` the plugin does nothing
but declare its options and fixtures, and the fixtures skip the tests that ask for
them, so a project's own test suite is neither slowed nor changed by it.

Fixtures: ``jig`` (session: the :class:`~imubench.jig.session.JigSession`), ``dut``
(session: the :class:`~imubench.jig.dut.Dut`), ``fixture`` (session: the
:class:`~imubench.jig.fixtures.base.Fixture`) and ``measure`` (function: records a
judged measurement, ``measure(name, value, ci=(lo, hi), unit=..., low=..., high=...,
method=...)``). A test whose measurements include a FAIL is reported failed, one with an
INCONCLUSIVE (and no FAIL) skipped with the reason ``INCONCLUSIVE: ...``; the
measurements themselves go to the run's ``measurements.json`` and JUnit properties.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Generator, Iterator
from typing import TYPE_CHECKING, Any

import pluggy
import pytest

if TYPE_CHECKING:
    from imubench.jig.dut import Dut
    from imubench.jig.fixtures.base import Fixture
    from imubench.jig.measurement import Measurement
    from imubench.jig.session import JigSession

Measure = Callable[..., "Measurement"]
"""Type of the ``measure`` fixture: ``measure(name, value, ci, unit=None, low=None,
high=None, method="") -> Measurement``."""
SESSION_KEY = pytest.StashKey["JigSession"]()
ITEM_KEY = pytest.StashKey[list["Measurement"]]()
OUTCOMES_KEY = pytest.StashKey[list[dict[str, str]]]()


def pytest_addoption(parser: pytest.Parser) -> None:
    group = parser.getgroup("imubench-jig", "imubench hardware-in-the-loop jig")
    group.addoption("--jig-station", default=None, metavar="STATION.toml",
                    help="run as a jig with this station file (turns the jig plugin on)")
    group.addoption("--jig-dut", default=None, metavar="URI",
                    help="DUT source URI (default: the station's dut.uri)")
    group.addoption("--jig-serial", default=None, metavar="SN", help="board serial number")
    group.addoption("--jig-out", default=None, metavar="DIR",
                    help="directory for measurements.json (default: jig-out)")


def _active(config: pytest.Config) -> bool:
    return config.getoption("--jig-station", default=None) is not None


def pytest_configure(config: pytest.Config) -> None:
    if _active(config):
        config.addinivalue_line("markers", "jig: a test that needs the jig fixtures")


@pytest.fixture(scope="session")
def jig(request: pytest.FixtureRequest) -> Iterator[JigSession]:
    """The jig run (station, limits, DUT, fixture, captures, measurements)."""
    config = request.config
    if not _active(config):
        pytest.skip("jig fixtures need a jig run: imubench jig run, or --jig-station")
    from imubench.jig.session import JigSession

    session = JigSession(
        config.getoption("--jig-station"),
        config.getoption("--jig-dut"),
        config.getoption("--jig-serial") or "unknown",
        config.getoption("--jig-out") or "jig-out",
    )
    config.stash[SESSION_KEY] = session
    try:
        yield session
    finally:
        session.close()


@pytest.fixture(scope="session")
def dut(jig: JigSession) -> Dut:
    """The board under test (:class:`imubench.jig.dut.Dut`)."""
    return jig.dut


@pytest.fixture(scope="session", name="fixture")
def fixture_(jig: JigSession) -> Fixture:
    """What moves and conditions the board (:class:`imubench.jig.fixtures.base.Fixture`)."""
    return jig.fixture


@pytest.fixture
def measure(jig: JigSession, request: pytest.FixtureRequest) -> Measure:
    """Record a judged measurement of this test (see the module docstring)."""
    item = request.node
    found = item.stash.setdefault(ITEM_KEY, [])

    def record(name: str, value: float, ci: tuple[float, float], **kw: Any) -> Measurement:
        m = jig.measure(name, value, ci, test=item.nodeid, **kw)
        found.append(m)
        item.user_properties.append((f"measurement:{name}", json.dumps(m.as_dict())))
        return m

    return record


def _not_the_boards(exc: BaseException) -> bool:
    """Whether a test's error says nothing of the board: a capture too short (the
    station's length or the data lost), or a station or limits setting
    (:class:`~imubench.jig.errors.StationError`): INCONCLUSIVE, not FAIL."""
    from imubench.calibration.means import TooFewSamplesError  # only when a test failed
    from imubench.jig.errors import StationError

    return isinstance(exc, TooFewSamplesError | StationError)


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(
    item: pytest.Item, call: pytest.CallInfo[None]
) -> Generator[None, pluggy.Result[pytest.TestReport], None]:
    outcome = yield
    if not _active(item.config):
        return
    rep = outcome.get_result()
    found = item.stash.get(ITEM_KEY, [])
    if rep.when == "call" and rep.passed and found:
        failed = [m for m in found if m.verdict == "FAIL"]
        unsure = [m for m in found if m.verdict == "INCONCLUSIVE"]
        if failed:
            rep.outcome = "failed"
            rep.longrepr = "FAIL: " + "; ".join(m.describe() for m in failed)
        elif unsure:
            rep.outcome = "skipped"
            rep.longrepr = (str(item.path), item.location[1] or 0,
                            "INCONCLUSIVE: " + "; ".join(m.describe() for m in unsure))
    if rep.failed and call.excinfo is not None and _not_the_boards(call.excinfo.value):
        # nothing was measured, for a reason that says nothing of the board
        rep.outcome = "skipped"
        rep.longrepr = (str(item.path), item.location[1] or 0,
                        f"INCONCLUSIVE: {call.excinfo.value}")
    if rep.when == "call" or not rep.passed:
        message = ""
        if isinstance(rep.longrepr, tuple):
            message = str(rep.longrepr[2])
        elif call.excinfo is not None and rep.failed and not isinstance(rep.longrepr, str):
            # the exception's own words ("CalibrationError: rate +400 dps about x: the
            # output was clipped ..."), not the traceback's last line (file:line: Type)
            message = call.excinfo.exconly()[:2000]
        elif rep.longrepr is not None:
            message = str(rep.longrepr).strip().splitlines()[-1][:2000]
        item.config.stash.setdefault(OUTCOMES_KEY, []).append(
            {"nodeid": item.nodeid, "when": rep.when, "outcome": rep.outcome,
             "message": message})


@pytest.hookimpl(trylast=True)
def pytest_report_teststatus(report: pytest.TestReport, config: pytest.Config) -> Any:
    if not _active(config) or not report.skipped or report.when != "call":
        return None
    if isinstance(report.longrepr, tuple) and str(report.longrepr[2]).startswith("INCONCLUSIVE"):
        return "inconclusive", "I", "INCONCLUSIVE"
    return None


def pytest_sessionfinish(session: pytest.Session, exitstatus: int) -> None:
    config = session.config
    if not _active(config):
        return
    from imubench.jig.session import write_measurements

    write_measurements(config.getoption("--jig-out") or "jig-out",
                       config.stash.get(SESSION_KEY, None),
                       config.stash.get(OUTCOMES_KEY, []))

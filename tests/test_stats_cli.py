"""The ``imubench allan`` subcommand on one-column text input."""

from __future__ import annotations

import gzip
import json
from pathlib import Path

import numpy as np
import pytest

from imubench import cli
from imubench.commands import allan as cmd


def _run(argv: list[str]) -> int:
    """The real CLI entry point (errors become exit code 2 there)."""
    return cli.main(argv)


def test_allan_json_matches_nbs14(reference_dir: Path, tmp_path: Path) -> None:
    y = np.loadtxt(reference_dir / "allantools-stable32/nbs14/nbs14_1000point_frequency.txt")
    src = tmp_path / "y.txt.gz"
    with gzip.open(src, "wt") as fh:
        fh.write("# NBS14 1000 point\n")
        fh.write("\n".join(repr(float(v)) for v in y))
    out = tmp_path / "o.json"
    rc = _run(
        [
            "allan",
            str(src),
            "--stat",
            "oadev",
            "--data-type",
            "freq",
            "--taus",
            "1,10,100",
            "--alpha",
            "0",
            "--json",
            str(out),
        ]
    )
    assert rc == 0
    d = json.loads(out.read_text())
    assert d["stat"] == "oadev" and d["m"] == [1, 10, 100]
    np.testing.assert_allclose(d["dev"], [2.922319e-01, 9.159953e-02, 3.241343e-02], rtol=1e-6)
    assert d["alpha"] == [0, 0, 0]


def test_allan_table_and_errors(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    src = tmp_path / "x.txt"
    src.write_text("1\n2\n# c\n3\nnan\n" + "\n".join(str(v) for v in range(40)) + "\n")
    assert _run(["allan", str(src), "--stat", "mdev", "--alpha", "0"]) == 0
    out = capsys.readouterr().out
    assert "mdev" in out and "tau_s" in out
    bad = tmp_path / "bad.txt"
    bad.write_text("1\nabc\n")
    assert _run(["allan", str(bad), "--stat", "adev"]) == 2
    assert "bad.txt:2" in capsys.readouterr().err
    assert _run(["allan", str(src), "--stat", "adev", "--taus", "weekly"]) == 2


def test_parse_taus() -> None:
    assert cmd.parse_taus("octave") == "octave"
    assert cmd.parse_taus("5") == 5
    assert cmd.parse_taus("1,10.5") == [1.0, 10.5]


def test_time_deviation_is_in_degrees_and_gaps_are_terms(tmp_path: Path,
                                                         capsys: pytest.CaptureFixture[str]
                                                         ) -> None:
    """TDEV = tau MDEV / sqrt(3) is a phase (deg for a gyro in dps), not a rate; the
    ``gaps`` column counts the terms a missing sample removed."""
    p = tmp_path / "g.csv"
    y = np.random.default_rng(2).standard_normal(2000) * 0.01
    p.write_text("t,gx [dps]\n" + "".join(f"{i / 100:.2f},{v:.5f}\n" for i, v in enumerate(y)
                                    if i != 1000))
    out = tmp_path / "tdev.json"
    assert cli.main(["allan", str(p), "--column", "gx", "--stat", "tdev", "--taus", "1",
                 "--json", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "dev in deg" in printed
    assert "gx: 1 of 2000 samples missing (0.05 %)" in printed  # the table alone did not say
    doc = json.loads(out.read_text())
    assert doc["units"]["dev"] == "deg" and doc["units"]["drift"] == "dps/s"
    assert doc["units"]["gaps"].startswith("terms") and doc["gaps"][0] > 1


def test_a_plain_series_is_in_its_own_unit_not_dps(tmp_path: Path,
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    """A one-column file states no unit (a clock's fractional frequency, Stable32's
    format): its deviations are in the input unit, not labelled dps."""
    p = tmp_path / "y.txt"
    p.write_text("".join(f"{v:.6e}\n" for v in np.random.default_rng(3).normal(0, 1e-9, 500)))
    out = tmp_path / "y.json"
    assert cli.main(["allan", str(p), "--stat", "oadev", "--taus", "1,2",
                     "--json", str(out)]) == 0
    assert "dev in input unit" in capsys.readouterr().out
    doc = json.loads(out.read_text())
    assert doc["units"]["dev"] == "input unit" and doc["data_unit"] == "input unit"

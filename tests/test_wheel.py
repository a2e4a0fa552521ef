"""A wheel built from the tree, installed in a fresh venv, works like the editable install.

The wheel is built without build isolation (the test venv's setuptools) from a copy of
the tree and installed with ``--no-deps`` into a new venv; the dependencies come from
this test's own environment through a ``.pth`` line (nothing is downloaded), and the
test checks that the wheel's ``imubench`` is what runs, not the editable one. The
default test runs ``imubench run --check`` and the shipped data through the installed
package; the slow one simulates a recording and fits it, datasheet comparison included.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import sysconfig
import zipfile
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest

from imubench import __version__

REPO = Path(__file__).resolve().parents[1]
TREE = ("pyproject.toml", "README.md", "LICENSE", "src", "drivers", "simulator")


@dataclass
class Installed:
    wheel: Path
    venv: Path
    work: Path
    env: dict[str, str]

    @property
    def bin(self) -> Path:
        return self.venv / "bin"

    def run(self, *args: str, timeout: float = 300) -> subprocess.CompletedProcess[str]:
        return subprocess.run([str(self.bin / "imubench"), *args], capture_output=True,
                              text=True, timeout=timeout, env=self.env, cwd=self.work)


@pytest.fixture(scope="module")
def installed(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Installed]:
    root = tmp_path_factory.mktemp("wheel")
    src = root / "tree"
    src.mkdir()
    for name in TREE:
        if (REPO / name).is_dir():
            shutil.copytree(REPO / name, src / name,
                            ignore=shutil.ignore_patterns("__pycache__", "*.egg-info"))
        else:
            shutil.copy2(REPO / name, src / name)
    dist = root / "dist"
    subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation",
                    "--disable-pip-version-check", "-q", "-w", str(dist), str(src)],
                   check=True, timeout=600, capture_output=True)
    (wheel,) = dist.glob("imubench-*.whl")
    venv = root / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True,
                   timeout=120)
    vpy = venv / "bin" / "python"
    subprocess.run([sys.executable, "-m", "pip", "--python", str(vpy), "install", "--no-deps",
                    "--no-index", "--disable-pip-version-check", "-q", str(wheel)],
                   check=True, timeout=600, capture_output=True)
    purelib = subprocess.run([str(vpy), "-c", "import sysconfig; "
                              "print(sysconfig.get_paths()['purelib'])"],
                             check=True, capture_output=True, text=True).stdout.strip()
    # the dependencies from this environment, after the venv's own site-packages
    deps = {sysconfig.get_paths()["purelib"], sysconfig.get_paths()["platlib"]}
    (Path(purelib) / "imubench-test-deps.pth").write_text("\n".join(sorted(deps)) + "\n")
    work = root / "work"
    work.mkdir()
    env = {k: v for k, v in os.environ.items()
           if k != "PYTHONPATH" and not k.upper().startswith("IMUBENCH_")}
    env["NUMBA_CACHE_DIR"] = str(root / "numba-cache")
    yield Installed(wheel, venv, work, env)


def test_wheel_holds_data_licence_and_version(installed: Installed) -> None:
    names = zipfile.ZipFile(installed.wheel).namelist()
    for data in ("imubench/data/quickstart.toml", "lsm6ds_sim/datasheet/lsm6dsl.toml",
                 "lsm6ds_sim/datasheet/lsm6dsm.toml", "lsm6ds_sim/datasheet/lsm6ds3h.toml",
                 "imubench/__main__.py"):
        assert data in names, data
    meta = next(n for n in names if n.endswith(".dist-info/METADATA"))
    text = zipfile.ZipFile(installed.wheel).read(meta).decode()
    assert f"Version: {__version__}" in text
    assert "License-Expression: LicenseRef-Proprietary" in text
    assert any(n.endswith(".dist-info/licenses/LICENSE") for n in names)


def test_installed_package_is_the_wheel_not_the_tree(installed: Installed) -> None:
    proc = subprocess.run([str(installed.bin / "python"), "-c",
                           "import imubench, lsm6ds_sim; print(imubench.__file__); "
                           "print(lsm6ds_sim.__file__)"],
                          capture_output=True, text=True, env=installed.env, cwd=installed.work,
                          check=True, timeout=120)
    for line in proc.stdout.splitlines():
        assert Path(line).is_relative_to(installed.venv), line


def test_run_check_and_module_entry_point(installed: Installed) -> None:
    check = installed.run("run", "--check")
    assert check.returncode == 0, check.stderr
    assert check.stdout.strip() == "shipped quick start: configuration is valid"
    version = subprocess.run([str(installed.bin / "python"), "-m", "imubench", "--version"],
                             capture_output=True, text=True, env=installed.env,
                             cwd=installed.work, timeout=120)
    assert version.stdout.strip() == f"imubench {__version__}", version.stderr
    quick = installed.run("run", "--print-quickstart")
    cfg = installed.work / "mine.toml"
    cfg.write_text(quick.stdout)
    assert installed.run("run", "--config", str(cfg), "--check").returncode == 0


@pytest.mark.slow
def test_sim_and_fit_with_datasheet_comparison(installed: Installed) -> None:
    rec = installed.work / "rec.imbr"
    sim = installed.run("sim", "--chip", "lsm6dsl", "--odr-hz", "104", "--duration-s", "600",
                        "--model", "datasheet:lsm6dsl", "--seed", "3", "--out", str(rec),
                        timeout=900)
    assert sim.returncode == 0, sim.stderr
    fit = installed.run("fit", str(rec), "-o", "fitted.toml", "--json", "fit.json",
                        timeout=1800)
    assert fit.returncode == 0, fit.stderr
    doc = json.loads((installed.work / "fit.json").read_text())
    comparison = doc["datasheet_comparison"]
    assert set(comparison) == {"gx", "gy", "gz", "ax", "ay", "az"}
    for ch, row in comparison.items():
        # simulated from the datasheet model itself: the fitted white density is its own
        assert 0.8 < row["ratio"] < 1.25, (ch, row)

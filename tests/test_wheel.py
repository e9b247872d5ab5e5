"""The package works installed from its wheel, away from the repository (no path into the checkout)."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow  # trains, starts Ray or servers, or builds the wheel

REPO = Path(__file__).resolve().parents[1]


def test_wheel_installed_elsewhere_finds_its_paper_data(tmp_path: Path) -> None:
    wheels, site, work, src = (tmp_path / name for name in ("wheels", "site", "work", "src"))
    work.mkdir()
    # build from a copy: setuptools writes build/ into the source tree
    shutil.copytree(REPO / "vlmrl_cli", src / "vlmrl_cli", ignore=shutil.ignore_patterns("__pycache__"))
    for name in ("pyproject.toml", "README.md"):
        shutil.copy(REPO / name, src / name)
    subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q", "-w",
                    str(wheels), str(src)], check=True, capture_output=True, timeout=300)
    (wheel,) = wheels.glob("vlmrl-*.whl")
    subprocess.run([sys.executable, "-m", "pip", "install", "--no-deps", "-q", "--target", str(site), str(wheel)],
                   check=True, capture_output=True, timeout=300)
    # the installed copy first on the path; the checkout's editable install must not be the one imported
    env = os.environ | {"PYTHONPATH": str(site)}
    where = subprocess.run([sys.executable, "-c", "import vlmrl_cli; print(vlmrl_cli.__file__)"], cwd=work,
                           env=env, capture_output=True, text=True, check=True)
    assert Path(where.stdout.strip()).is_relative_to(site)

    def vlmrl(*args: str) -> subprocess.CompletedProcess[str]:
        return subprocess.run([sys.executable, "-m", "vlmrl_cli", *args], cwd=work, env=env, capture_output=True,
                              text=True, timeout=600)

    taxonomy = vlmrl("taxonomy", "--vlm", "replay", "--out", str(work / "tax"),
                     "--tracking-uri", f"sqlite:///{work / 'mlflow.db'}")
    assert taxonomy.returncode == 0, taxonomy.stdout + taxonomy.stderr
    assert (work / "tax" / "table1.md").is_file()
    report_help = vlmrl("report", "--help")
    assert report_help.returncode == 0 and "--experiment" in report_help.stdout
    prose = subprocess.run([sys.executable, "-c", "from vlmrl_cli.study.outputs import prose; "
                            "print(prose('estimate', pending=1, minutes=2, how='x'))"], cwd=work, env=env,
                           capture_output=True, text=True, timeout=300)  # the report's prose is package data
    assert prose.returncode == 0 and "Estimated up front: 1 run(s)" in prose.stdout, prose.stderr

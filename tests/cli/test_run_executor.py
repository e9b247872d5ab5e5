"""`vlmrl run --executor`: errors that must come before anything is created."""

from __future__ import annotations

from pathlib import Path

import pytest
from typer.testing import CliRunner

from vlmrl_cli.cli.app import app
from vlmrl_cli.sweep import executors

pytestmark = pytest.mark.slow  # trains, starts Ray or servers, or builds the wheel

runner = CliRunner()


def test_remote_ray_with_sqlite_exits_2_and_creates_nothing(tmp_path: Path) -> None:
    store = tmp_path / "none" / "m.db"
    result = runner.invoke(app, ["run", "--preset", "smoke", "--executor", "ray", "--ray-address", "10.0.0.5:6379",
                                 "--tracking-uri", f"sqlite:///{store}"])
    assert result.exit_code == 2, result.output
    assert "start a tracking server" in result.output + result.stderr
    assert not (tmp_path / "none").exists()


def test_ray_not_installed_exits_2_with_the_install_command(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(executors, "find_spec", lambda name: None)
    result = runner.invoke(app, ["run", "--preset", "smoke", "--executor", "ray",
                                 "--tracking-uri", f"sqlite:///{tmp_path / 'none' / 'm.db'}"])
    assert result.exit_code == 2
    assert "pip install 'vlmrl[ray]'" in result.output + result.stderr
    assert not (tmp_path / "none").exists()


def test_an_unknown_executor_is_refused(tmp_path: Path) -> None:
    result = runner.invoke(app, ["run", "--preset", "smoke", "--executor", "slurm",
                                 "--tracking-uri", f"sqlite:///{tmp_path / 'none' / 'm.db'}"])
    assert result.exit_code == 2
    assert "executor" in result.output + result.stderr
    assert not (tmp_path / "none").exists()

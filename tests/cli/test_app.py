"""CLI conventions: --version, -h, and help that does not import the heavy libraries."""

from __future__ import annotations

import subprocess
import sys

from typer.testing import CliRunner

from vlmrl_cli.cli.app import app

HEAVY = ("torch", "stable_baselines3", "mlflow", "transformers")


def test_version_prints_the_package_version() -> None:
    result = CliRunner().invoke(app, ["--version"])
    assert result.exit_code == 0
    assert result.stdout.startswith("vlmrl 0.") and "commit" in result.stdout


def test_short_help_flag_works_on_the_app_and_a_command() -> None:
    for args in (["-h"], ["run", "-h"], ["report", "-h"]):
        result = CliRunner().invoke(app, args)
        assert result.exit_code == 0, args
        assert "Usage:" in result.stdout


def test_help_imports_no_heavy_library() -> None:
    code = (
        "import sys\n"
        "from typer.testing import CliRunner\n"
        "from vlmrl_cli.cli.app import app\n"
        "for args in (['--help'], ['run', '--help'], ['report', '--help'], ['calibrate', '--help'],"
        " ['evaluate', '--help'], ['taxonomy', '--help'], ['study', '--help'], ['export', '--help'],"
        " ['import', '--help'], ['compare', '--help']):\n"
        "    assert CliRunner().invoke(app, args).exit_code == 0, args\n"
        f"print(sorted(m for m in {HEAVY!r} if m in sys.modules))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def test_calibrate_and_study_take_the_vlm_options_run_takes(tmp_path, monkeypatch, capsys) -> None:  # type: ignore[no-untyped-def]
    from vlmrl_cli.cli.app import cli

    monkeypatch.chdir(tmp_path)
    vlm = ["--vlm", "openai", "--base-url", "http://127.0.0.1:8000/v1", "--model", "M"]
    for command in ("study", "calibrate"):
        assert cli([command, *vlm, "--dry-run"]) == 0, capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []  # a dry run creates nothing


def test_a_ctrl_c_in_a_finalizer_is_not_printed_and_other_unraisables_are(monkeypatch) -> None:
    import sys
    import types

    from vlmrl_cli.cli.app import _unraisable

    seen: list[object] = []
    monkeypatch.setattr(sys, "__unraisablehook__", seen.append)
    _unraisable(types.SimpleNamespace(exc_value=KeyboardInterrupt()))
    assert seen == []
    other = types.SimpleNamespace(exc_value=ValueError("x"))
    _unraisable(other)
    assert seen == [other]


def test_the_preset_help_states_the_tasks_own_default(tmp_path) -> None:  # type: ignore[no-untyped-def]
    for command in ("run", "calibrate"):
        text = " ".join(CliRunner().invoke(app, [command, "--help"]).stdout.split())
        assert "[default: the task's default preset; mountain-car's is paper]" in text, command
        assert "[default: paper]" not in text and "e.g. zoo" not in text, command
    # and that is what a run does: Acrobot's default preset is its own zoo
    uri = f"sqlite:///{tmp_path / 'm.db'}"
    dry = CliRunner().invoke(app, ["run", "--task", "acrobot", "--dry-run", "--tracking-uri", uri])
    assert dry.exit_code == 0 and 'preset = "zoo"' in dry.stdout, dry.output
    assert not list(tmp_path.iterdir())


def test_the_app_help_shows_each_commands_whole_summary_on_one_line() -> None:
    from vlmrl_cli.cli.app import SUMMARIES, SUMMARY_WIDTH

    result = CliRunner().invoke(app, ["--help"], terminal_width=80)
    assert result.exit_code == 0
    lines = result.stdout.splitlines()
    for name, summary in SUMMARIES.items():
        assert len(summary) <= SUMMARY_WIDTH, name
        assert any(line.split() == [name, *summary.split()] for line in lines), (name, result.stdout)
    commands = lines[lines.index("Commands:") + 1:]
    assert len(commands) == len(SUMMARIES) and not any("..." in line for line in commands)

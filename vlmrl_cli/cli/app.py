"""The Typer app; each command lives in its own module."""

from __future__ import annotations

import typer

app = typer.Typer(
    name="vlmrl",
    help="Reproduce 'Macro Semantics, Micro Kinematics' (VLM milestone shaping for PPO on MountainCar-v0).",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)


def _register() -> None:
    from vlmrl_cli.cli import calibrate, evaluate, report, run, taxonomy

    app.command("taxonomy")(taxonomy.taxonomy)
    app.command("run")(run.run)
    app.command("report")(report.report)
    app.command("calibrate")(calibrate.calibrate)
    app.command("evaluate")(evaluate.evaluate)


_register()


def main() -> None:
    app()

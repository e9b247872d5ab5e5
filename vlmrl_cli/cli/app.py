"""The Typer app; each command lives in its own module."""

from __future__ import annotations

from typing import Annotated

import typer

app = typer.Typer(
    name="vlmrl",
    help="Reproduce 'Macro Semantics, Micro Kinematics' (VLM milestone shaping for PPO on MountainCar-v0).",
    no_args_is_help=True,
    rich_markup_mode=None,  # plain click help: flags shown as flags (rich help printed <bool> after them)
    add_completion=False,
    pretty_exceptions_enable=False,
    context_settings={"help_option_names": ["-h", "--help"]},
)


def _version(value: bool) -> None:
    if value:
        from importlib.metadata import PackageNotFoundError, version

        from vlmrl_cli.core.provenance import git_commit

        try:
            number = version("vlmrl")
        except PackageNotFoundError:  # running from a checkout that was never installed
            number = "unknown"
        typer.echo(f"vlmrl {number} (commit {git_commit()})")
        raise typer.Exit()


@app.callback()
def _root(
    version: Annotated[
        bool, typer.Option("--version", callback=_version, is_eager=True, help="Print the version and exit.")
    ] = False,
) -> None:
    """Reproduce 'Macro Semantics, Micro Kinematics' (VLM milestone shaping for PPO on MountainCar-v0)."""


def _register() -> None:
    from vlmrl_cli.cli import calibrate, evaluate, report, run, study, taxonomy, transfer

    app.command("taxonomy")(taxonomy.taxonomy)
    app.command("run")(run.run)
    app.command("report")(report.report)
    app.command("calibrate")(calibrate.calibrate)
    app.command("evaluate")(evaluate.evaluate)
    app.command("study")(study.study)
    app.command("export")(transfer.export)
    app.command("import")(transfer.import_)


_register()


def main() -> None:
    app()

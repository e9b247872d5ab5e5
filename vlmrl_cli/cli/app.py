"""The Typer app; each command lives in its own module."""

from __future__ import annotations

import signal
import sys
from collections.abc import Sequence
from typing import Annotated, Any

import typer

from vlmrl_cli.cli.exit_codes import EXIT_BAD_INPUT, EXIT_INTERRUPTED, ExitCodes

app = typer.Typer(
    name="vlmrl",
    cls=ExitCodes,
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


#: Each command's summary in `vlmrl --help` (click would cut a docstring's), at most ``SUMMARY_WIDTH``
#: characters: one line of an 80-column terminal.
SUMMARIES = {
    "taxonomy": "Table 1 and Figure 1: float, box and MCQ answers of a VLM.",
    "run": "Train PPO arms x seeds, tracked in MLflow; resumable.",
    "report": "Table 2, Figures 2-4 and verdicts on the paper's claims.",
    "compare": "Arms across tasks from export files (IQM, P(> baseline)).",
    "calibrate": "Rank PPO regimes by distance to the paper's baseline.",
    "evaluate": "A trained policy's success rate and a captioned GIF.",
    "study": "Regimes x arms x seeds, placebo, dose-response, lock.",
    "export": "Write an experiment's finished runs to one file.",
    "import": "Read an export file's runs into a store.",
    "verify": "Retrain recorded runs and compare them bit for bit.",
}
SUMMARY_WIDTH = 60


def _register() -> None:
    from vlmrl_cli.cli import calibrate, compare, evaluate, report, run, study, taxonomy, transfer, verify
    from vlmrl_cli.cli.options import VLM_OPTIONS, fields_command

    # the options built from config fields that a command takes beside its signature's
    field_options = {"taxonomy": VLM_OPTIONS, "run": VLM_OPTIONS, "calibrate": VLM_OPTIONS,
                     "study": study.FIELD_OPTIONS}
    for name, command in (("taxonomy", taxonomy.taxonomy), ("run", run.run), ("report", report.report),
                          ("compare", compare.compare), ("calibrate", calibrate.calibrate),
                          ("evaluate", evaluate.evaluate), ("study", study.study), ("export", transfer.export),
                          ("import", transfer.import_), ("verify", verify.verify)):
        cls = fields_command(*field_options[name]) if name in field_options else None
        app.command(name, short_help=SUMMARIES[name], cls=cls)(command)


_register()


def cli(args: Sequence[str] | None = None) -> int:
    """Run ``vlmrl ARGS`` and return its exit code; every refusal, click's usage errors included, is
    one ``error:`` line."""
    try:  # typer >= 0.22 runs its own copy of click; older versions run click itself
        from typer._click import exceptions as click
    except ImportError:  # pragma: no cover - depends on the installed typer
        from click import exceptions as click  # type: ignore[no-redef]

    command = typer.main.get_command(app)
    try:
        code = command.main(args=list(args) if args is not None else None, prog_name="vlmrl", standalone_mode=False)
    except click.NoArgsIsHelpError as exc:  # bare `vlmrl` or `vlmrl run`-style groups: show the help
        print(exc.format_message(), file=sys.stderr)
        return EXIT_BAD_INPUT
    except click.UsageError as exc:
        where = exc.ctx.command_path if exc.ctx is not None else "vlmrl"
        message = " ".join(exc.format_message().split())
        print(f"error: {message} (see '{where} --help')", file=sys.stderr)
        return EXIT_BAD_INPUT
    except click.ClickException as exc:
        print(f"error: {' '.join(exc.format_message().split())}", file=sys.stderr)
        return exc.exit_code
    except typer.Abort:
        print("interrupted.", file=sys.stderr)
        return EXIT_INTERRUPTED
    return code if isinstance(code, int) else 0


def _unraisable(info: Any) -> None:
    """Drop a Ctrl-C raised in a finalizer (Ray's ``ActorHandle.__del__`` as a sweep closes), which
    Python would print as a traceback; anything else goes to the default hook."""
    if not isinstance(info.exc_value, KeyboardInterrupt):
        sys.__unraisablehook__(info)


def main() -> None:
    sys.unraisablehook = _unraisable
    code = cli()
    # the command is over: a Ctrl-C in the atexit callbacks (Ray's shutdown sleeps) would only print a traceback
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    sys.exit(code)

"""`vlmrl export` and `vlmrl import`: finished training runs as one compact file, between stores."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from vlmrl_cli.cli.options import Experiment, TrackingUri, TrustPickle
from vlmrl_cli.core.errors import BadInput

ExportFile = Annotated[Path, typer.Option("--out", help="The export file to write (gzip JSON lines: runs.jsonl.gz).")]
Models = Annotated[bool, typer.Option(
    "--models", help="Include the policy's weights and observation statistics (for vlmrl evaluate).")]


Earlier = Annotated[list[Path] | None, typer.Option(
    "--skip-exported", help="An earlier export file, repeatable: its runs are left out (an incremental export).")]


def export(
    out: ExportFile,
    experiment: Experiment = "vlmrl",
    tracking_uri: TrackingUri = None,
    models: Models = False,
    skip_exported: Earlier = None,
) -> None:
    """Write every FINISHED training run of an experiment (tags, params, per-episode and evaluation
    histories, config; models with --models) to one file that `vlmrl import` reads into another store."""
    from vlmrl_cli.core.names import experiment_problem, tracking_uri_problem
    from vlmrl_cli.core.paths import file_problem
    from vlmrl_cli.tracking import store
    from vlmrl_cli.tracking.transfer import export_runs, read_records

    problem = experiment_problem(experiment) or tracking_uri_problem(tracking_uri)
    if problem:
        raise BadInput(problem + ".")
    if out.exists() and out.is_dir():
        raise BadInput(f"--out {out} is a folder; name the export file, e.g. {out / 'runs.jsonl.gz'}.")
    if not out.parent.is_dir():
        raise BadInput(f"--out {out}: the folder {out.parent} does not exist; create it first.")
    unwritable = file_problem(out)
    if unwritable:
        raise BadInput(f"--out {out}: cannot write the export file there ({unwritable}); pass --out to a file in "
                       "a writable folder.")
    missing = [p for p in skip_exported or [] if not p.is_file()]
    if missing:
        raise BadInput(f"--skip-exported {missing[0]}: no such export file.")
    skip = {r["source_run_id"] for p in skip_exported or [] for r in read_records(p)}
    client = store.connect_existing(tracking_uri)
    summary = export_runs(client, experiment, out, models=models, skip=skip)
    typer.echo(f"exported {summary.written} FINISHED training run(s) of '{experiment}' to {out} "
               f"({out.stat().st_size / 1e6:.1f} MB); {summary.skipped} left out as exported before")


def import_(
    paths: Annotated[list[Path], typer.Argument(help="Export files written by `vlmrl export`.", show_default=False)],
    experiment: Experiment = "vlmrl",
    tracking_uri: TrackingUri = None,
    trust_pickle: TrustPickle = False,
) -> None:
    """Create the runs of an export file in an experiment (created if missing) as FINISHED runs; runs
    already there (same arm, seed and config hash) are skipped, so a resumed sweep never retrains them.
    Every file is checked whole before the store is touched; a file imports entirely or not at all."""
    from vlmrl_cli.core.names import experiment_problem, tracking_uri_problem
    from vlmrl_cli.tracking import access, store
    from vlmrl_cli.tracking.transfer import import_runs, read_export, refuse_pickles

    problem = experiment_problem(experiment) or tracking_uri_problem(tracking_uri)
    if problem:
        raise BadInput(problem + ".")
    access.check_store(tracking_uri)  # before MLflow or any file
    for path in paths:
        if not path.is_file():
            raise BadInput(f"there is no export file {path}; write one with `vlmrl export --out FILE`.")
    exports = [read_export(path) for path in paths]  # every file whole, before the store exists
    for export in exports:
        refuse_pickles(export, trust_pickle)
    client = store.connect(tracking_uri)
    for export in exports:
        summary = import_runs(client, export, experiment, trust_pickle=trust_pickle)
        checked = "" if export.digest_checked else " (format 1: the file carries no digest to check)"
        typer.echo(f"{export.path}: imported {summary.written} run(s) into '{experiment}'; {summary.skipped} "
                   f"already present{checked}")

"""`vlmrl verify`: retrain recorded runs from their configs and compare their returns bit for bit."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Annotated

import typer

from vlmrl_cli.cli.options import Experiment, TrackingUri, UserTasks, given
from vlmrl_cli.cli.progress import RetrainProgress
from vlmrl_cli.core.errors import BadInput

#: Exit code when a retrained run differs from its record.
EXIT_DIFFERS = 1

Source = Annotated[Path | None, typer.Argument(
    help="An export file (`vlmrl export`); without it, the runs of --experiment in --tracking-uri.",
    show_default=False)]
Sample = Annotated[int | None, typer.Option("--sample", min=1, help="Verify this many runs, drawn at random.")]
SampleSeed = Annotated[int, typer.Option("--sample-seed", help="Seed of --sample's draw (the same on every machine).")]
RunIds = Annotated[list[str] | None, typer.Option("--run-id", help="A run to verify (repeatable; 8+ characters).")]
SeedFilter = Annotated[list[int] | None, typer.Option("--seed", help="Only runs of this training seed (repeatable).")]
ArmFilter = Annotated[list[str] | None, typer.Option("--arm", help="Only runs of this arm (repeatable).")]
VerifyWorkers = Annotated[int, typer.Option("--workers", min=1, help="Worker processes (one torch thread each).")]
DryRun = Annotated[bool, typer.Option("--dry-run", help="List the runs and the estimated cost; train nothing.")]


def verify(
    ctx: typer.Context,
    source: Source = None,
    sample: Sample = None,
    sample_seed: SampleSeed = 0,
    run_id: RunIds = None,
    seed: SeedFilter = None,
    arm: ArmFilter = None,
    workers: VerifyWorkers = 1,
    dry_run: DryRun = False,
    experiment: Experiment = "vlmrl",
    tracking_uri: TrackingUri = None,
    user_task: UserTasks = None,
) -> None:
    """Retrain finished runs of an export file or a store from their recorded configs and compare
    their per-episode native returns bit for bit: prints `identical` or `differs from episode k` per
    run, with both sides' CPU and pin tags, and exits 1 when any run differs."""
    from rich.console import Console

    from vlmrl_cli.sweep.cost import retrain_estimate
    from vlmrl_cli.tasks.registry import command_tasks
    from vlmrl_cli.training import verify as lib

    console = Console(highlight=False, soft_wrap=True)
    store_flags = [flag for flag, name in (("--tracking-uri", "tracking_uri"), ("--experiment", "experiment"))
                   if given(ctx, name)]
    if source is not None and store_flags:  # the file's runs would be verified, the store's ignored
        verb = "choose" if len(store_flags) > 1 else "chooses"
        raise BadInput(f"{' and '.join(store_flags)} {verb} a store's runs, and {source} is an export file: verify "
                       f"reads one or the other; drop {' and '.join(store_flags)} to verify the file, or the file "
                       "to verify the store's runs.")
    tasks = command_tasks(user_task or ())
    runs, where = lib.recorded_runs(source, experiment, tracking_uri)
    chosen = lib.choose(runs, run_ids=run_id or (), seeds=seed or (), arms=arm or (), sample=sample,
                        sample_seed=sample_seed, source=where)
    jobs = [lib.rebuild_job(run, tasks) for run in chosen]  # every config is rebuilt before anything trains
    cost = retrain_estimate([(job, run.wall_s) for job, run in zip(jobs, chosen, strict=True)], workers)
    console.print(f"verifying {len(chosen)} of {len(runs)} run(s) of {where}: {cost.minutes_range()} on "
                  f"{cost.workers} worker(s) ({cost.how})")
    here_tags = lib.here_paths()  # once: this process's path does not change while it runs
    console.print(f"here: {lib.describe_paths(here_tags)}")
    for run, job in zip(chosen, jobs, strict=True):
        console.print(f"  {run.run_id[:12]}  {run.name:<28} {len(run.native_returns)} episodes, "
                      f"{job.timesteps:,} steps")
    if dry_run:
        return
    differ = 0
    steps = {run.run_id: job.timesteps for run, job in zip(chosen, jobs, strict=True)}
    with RetrainProgress(len(chosen), sum(steps.values())) as progress:
        for outcome in lib.verify_many(chosen, tasks, workers=workers):
            progress.advance(steps[outcome.run.run_id])
            differ += not outcome.identical
            for line in outcome.lines(here_tags):  # both sides' paths, run by run
                console.print(line)
    console.print(f"{len(chosen) - differ} identical, {differ} differ")
    if differ:
        print(f"error: {differ} of {len(chosen)} run(s) did not reproduce here; the paths above say where each "
              "was trained.", file=sys.stderr)
        raise typer.Exit(EXIT_DIFFERS)

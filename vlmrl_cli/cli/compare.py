"""`vlmrl compare`: the arms across tasks (IQM, mean, probability of improvement, performance
profile of normalised scores) from export files; trains nothing, needs no store."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from vlmrl_cli.cli.options import AllowMixedPaths, UserTasks, choices
from vlmrl_cli.report.config import DEFAULT_NORMALISATION, NORMALISATIONS

NORMALISE_CHOICES = tuple(NORMALISATIONS)

Files = Annotated[list[Path], typer.Argument(help="Export files written by `vlmrl export` (any tasks).",
                                             show_default=False)]
Out = Annotated[Path | None, typer.Option(
    "--out", help="Output folder (default: a new folder results/_scratch/compare/YYYYMMDD-HHMMSS, git-ignored, so "
                  "that no committed result is overwritten unless named here).", show_default=False)]
Normalise = Annotated[str, typer.Option(
    "--normalise", metavar=choices(NORMALISE_CHOICES),
    help="Per-task min-max normalisation of the scores: random-zoo (fixed references: 0 = a random policy's "
         "measured score, 1 = rl-baselines3-zoo's published PPO score) or baseline-best (anchors estimated from "
         "the data: 0 = the baseline arm's mean, 1 = the best arm's mean; its outputs say so).")]
ConfigHashes = Annotated[list[str] | None, typer.Option(
    "--config-hash", help="The configuration of a task's arm to compare, a hash or its prefix, repeatable "
                          "(default per task and arm: the one with the most runs).")]
Boot = Annotated[int, typer.Option("--n-boot", min=100, help="Bootstrap resamples.")]
Seed = Annotated[int, typer.Option("--seed", help="Seed of the bootstrap.")]


def compare(
    files: Files,
    out: Out = None,
    normalise: Normalise = DEFAULT_NORMALISATION,
    config_hash: ConfigHashes = None,
    n_boot: Boot = 2000,
    seed: Seed = 0,
    user_task: UserTasks = None,
    allow_mixed_paths: AllowMixedPaths = False,
) -> None:
    """Aggregate the arms' detached evaluation scores across tasks: aggregate.md/.csv, per_task.csv and
    performance_profile.png.

    They go to --out, by default to a new folder under results/_scratch/ (git-ignored).
    """
    from vlmrl_cli.core.paths import fresh_scratch_folder
    from vlmrl_cli.report.config import CompareConfig, check_compare
    from vlmrl_cli.tasks.registry import command_tasks

    lookup = command_tasks(user_task or ())
    cfg = CompareConfig(files=tuple(files), out=out or fresh_scratch_folder("compare"), normalise=normalise,
                        config_hashes=tuple(config_hash or ()), n_boot=n_boot, seed=seed,
                        allow_mixed_paths=allow_mixed_paths)
    check_compare(cfg)  # before the analysis stack loads (seconds)
    from vlmrl_cli.report.compare import compare as run_compare

    result = run_compare(cfg, lookup)
    typer.echo(f"{len(result.arms)} arm(s) on {len(result.tasks)} task(s) ({', '.join(result.tasks)}); "
               f"normalisation {normalise}" + ("; SIMULATED VLM" if result.simulated else ""))
    if result.estimated:
        typer.echo("ANCHORS ESTIMATED FROM THE DATA: 0 and 1 are arms' own means; read random-zoo for verdicts")
    for task, r in result.pairs.iterrows():
        typer.echo(f"  {task:<24} 0 = {r.lo:.4g} ({r.lo_from}); 1 = {r.hi:.4g} ({r.hi_from})")
    for r in result.table.itertuples(index=False):
        poi = "" if r.arm == "baseline" else (f"; P(> baseline) {r.poi_over_baseline:.2f} "
                                               f"[{r.poi_over_baseline_low:.2f}, {r.poi_over_baseline_high:.2f}]")
        typer.echo(f"  {r.arm:<16} IQM {r.iqm:.2f} [{r.iqm_low:.2f}, {r.iqm_high:.2f}]{poi}")
    if result.counted_once:
        typer.echo(f"counted once: {result.counted_once} run(s) that a second file also holds (same task, arm, "
                   "seed and config hash)")
    for arm, tasks in result.left_out.items():
        typer.echo(f"left out: {arm} (missing on {', '.join(tasks)})")
    if result.other_configs:
        typer.echo(f"not compared: {len(result.other_configs)} other configuration(s), the arm's configuration "
                   f"with the most runs kept (name one with --config-hash): {'; '.join(result.other_configs)}")
    typer.echo(f"written to {result.out}/ (aggregate.md, aggregate.csv, per_task.csv, performance_profile.png)")

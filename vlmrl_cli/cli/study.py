"""`vlmrl study`: regimes x arms x seeds and the hybrid's VLM-quality variants, one regime map and report."""

from __future__ import annotations

import functools
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer
from rich.console import Console

from vlmrl_cli.cli import options as opt
from vlmrl_cli.cli.progress import exit_if_failed, regime_reporter
from vlmrl_cli.core.errors import BadInput
from vlmrl_cli.study.settings import DEFAULT_ARMS, DEFAULT_EXPERIMENT, DEFAULT_SEEDS, Regimes, StudySettings
from vlmrl_cli.tasks.registry import command_tasks

if TYPE_CHECKING:
    from vlmrl_cli.study.config import StudyConfig
    from vlmrl_cli.study.pipeline import StudyResult

StudyArms = Annotated[str | None, typer.Option("--arms", help=f"Arms of every regime (default: "
                                                              f"{','.join(DEFAULT_ARMS)}).")]
DryRun = Annotated[bool, typer.Option("--dry-run", help="Print the grid and the cost estimate; train nothing.")]
NoTrain = Annotated[bool, typer.Option("--no-train", help="Analyse the runs already FINISHED and write the report; "
                                                          "train nothing (a long study's progress; the report says "
                                                          "PARTIAL and what is missing).")]

#: The options of the study's runs: `vlmrl run`'s, read as config keys by ``options.typed_flags``.
RUN_OPTIONS = ("arms", "task", "seeds", "seed_list", "timesteps", "workers", "executor", "ray_address",
               "eval_episodes", "experiment", "tracking_uri")
#: The options that set no config key: where the layers come from, and what to do with the study.
CLI_ONLY = ("config", "sets", "dry_run", "no_train")


def _names(text: str, flag: str) -> list[str]:
    """``"a,b"`` -> ["a", "b"]; ``"none"`` -> []; ``""`` or ``","`` is ``BadInput``."""
    if text.strip().lower() == "none":
        return []
    names = [t.strip() for t in text.split(",") if t.strip()]
    if not names:
        raise BadInput(f"{flag} lists no value, got '{text}'; pass comma-separated values, or 'none' for no run.")
    return opt.list_entries(text, flag)


def _numbers(text: str, flag: str) -> list[float]:
    try:
        return [float(v) for v in _names(text, flag)]
    except ValueError:
        raise BadInput(f"{flag} takes numbers like 0,0.1,0.3 or 'none', got '{text}'.") from None


def _regimes(texts: list[str], flag: str) -> dict[str, dict[str, Any]]:
    from vlmrl_cli.study.config import regimes_of  # the grid's module loads scipy: only when a study runs

    return regimes_of(texts)


_SYNTAX: opt.Syntax = {
    tuple[str, ...]: (str | None, _names),
    tuple[float, ...]: (str | None, _numbers),
    Regimes: (list[str] | None, _regimes),
}
#: The options `vlmrl study` adds to its signature's (``cli/app.py`` registers it with them).
SETTING_OPTIONS = opt.field_options(StudySettings, "study", defaults=False, shown_default=False, syntax=_SYNTAX)
FIELD_OPTIONS = (*SETTING_OPTIONS, *opt.VLM_OPTIONS)


def study(
    ctx: typer.Context,
    arms: StudyArms = None,
    task: opt.TaskOpt = None,
    seeds: opt.Seeds = DEFAULT_SEEDS,
    seed_list: opt.SeedList = None,
    timesteps: opt.Timesteps = None,
    workers: opt.Workers = None,
    executor: opt.ExecutorOpt = None,
    ray_address: opt.RayAddress = None,
    eval_episodes: opt.EvalEpisodes = None,
    config: opt.ConfigFile = None,
    sets: opt.Sets = None,
    dry_run: DryRun = False,
    no_train: NoTrain = False,
    experiment: opt.Experiment = DEFAULT_EXPERIMENT,
    tracking_uri: opt.TrackingUri = None,
) -> None:
    """Run regimes x arms x seeds (and the hybrid under several simulated VLMs) through the resumable
    MLflow sweep; write the regime map, the VLM-quality figure and a report generated from the numbers."""
    from vlmrl_cli.core.paths import check_out_folder
    from vlmrl_cli.study.config import StudyConfig
    from vlmrl_cli.tracking.access import check_store

    console = Console()
    cfg = StudyConfig.from_sources(config, opt.typed_flags(ctx), sets or [],
                                   tasks=command_tasks([task]))
    check_out_folder(cfg.out)  # the pipeline checks it again; here, before its modules load (seconds)
    check_store(cfg.base.tracking_uri, write=not dry_run)  # before MLflow, the header or any file
    # the pipeline loads torch and MLflow (seconds): only once the store is known to be usable
    from vlmrl_cli.study.pipeline import estimate_cost, finished_per_seed, power_lines, run_study

    print_grid(console, cfg)
    cost = estimate_cost(cfg)
    console.print(f"cost estimate: {cost.line()}", markup=False)
    if dry_run:
        for line in power_lines(cfg, finished_per_seed(cfg)):
            console.print(line, markup=False)
        return
    result = run_study(cfg, functools.partial(regime_reporter, console),
                       command=" ".join(["vlmrl", *sys.argv[1:]]), cost=cost, train=not no_train)
    print_result(console, result, cfg.out)


def print_grid(console: Console, cfg: StudyConfig) -> None:
    """The study's grid, before anything runs: its sweeps and their budgets, the notes, the VLM."""
    base = cfg.base
    console.print(f"[bold]vlmrl study[/]: {len(cfg.regimes)} regime(s) x arms {', '.join(base.arms)} x seeds "
                  f"{list(base.seeds)}, + {len(cfg.variants)} VLM variant(s) of the hybrid and "
                  f"{len(cfg.cells)} control cell(s) (dose-response, query flicker) in "
                  f"'{cfg.vlm_regime}'; experiment '{base.experiment}'")
    for r in cfg.all_regimes():
        console.print(f"  {r.id}: {r.label}, {r.run.budget:,} steps per run", markup=False)
    if cfg.variants:
        console.print(f"  taxonomy: {cfg.states} sweep positions per VLM variant", markup=False)
    for note in cfg.notes:
        console.print(f"[yellow]note:[/] {note}")
    if base.vlm.backend == "sim":
        console.print("[yellow]VLM: the SIMULATED VLM (a pixel-reading stand-in), not a real model.[/]")


def print_result(console: Console, result: StudyResult, out: Path) -> None:
    """What the study did: the failed runs (then exit 1), else its summary, wall time and files."""
    exit_if_failed(console, result.failed, "analysed")
    for line in result.summary:
        console.print(line, markup=False)
    stages = ", ".join(f"{s['stage']} {s['wall_s']:.0f} s" for s in result.stages)
    console.print(f"wall time: {result.wall_s:,.0f} s ({stages}); {result.trained} run(s) trained now")
    console.print(f"wrote {', '.join(p.name for p in result.files)} to {out}; MLflow run {result.run_id}")

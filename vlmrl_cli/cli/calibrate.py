"""`vlmrl calibrate`: find the PPO regime whose baseline learns most like the paper's baseline
(another task: like that profile scaled to the task, slow and failing on some seeds)."""

from __future__ import annotations

import functools
import sys
from pathlib import Path
from typing import Annotated

import typer
from rich.console import Console

from vlmrl_cli.cli import options as opt
from vlmrl_cli.cli.progress import exit_if_failed, regime_reporter
from vlmrl_cli.training.config import source_layers

Grid = Annotated[
    list[str] | None,
    typer.Option(
        "--grid",
        help="Values of one key, repeatable: --grid ppo.n_envs=1,4,16 --grid "
        "ppo.ent_coef=0,0.01; the regimes are their product (replaces the default grid).",
    ),
]
Out = Annotated[Path, typer.Option("--out", help="Output folder of calibration.md/csv/png and manifest.json.")]


DryRun = Annotated[bool, typer.Option("--dry-run", help="Print the regimes and the cost estimate; train nothing.")]


def calibrate(
    ctx: typer.Context,
    seeds: opt.Seeds = 10,
    seed_list: opt.SeedList = None,
    task: opt.TaskOpt = None,
    timesteps: opt.Timesteps = None,
    preset: opt.Preset = None,
    workers: opt.Workers = None,
    executor: opt.ExecutorOpt = None,
    ray_address: opt.RayAddress = None,
    eval_episodes: opt.EvalEpisodes = None,
    config: opt.ConfigFile = None,
    sets: opt.Sets = None,
    grid: Grid = None,
    out: Out = Path("results/calibration"),
    dry_run: DryRun = False,
    experiment: opt.Experiment = "vlmrl-calibrate",
    tracking_uri: opt.TrackingUri = None,
) -> None:
    """Train the baseline arm under each PPO regime of a grid (resumable MLflow runs tagged vlmrl.regime)
    and rank the regimes by their distance to the paper's baseline learning profile."""
    from vlmrl_cli.calibration.regimes import build_regimes, calibrate_config, calibrate_section, grid_flags
    from vlmrl_cli.core.paths import check_out_folder
    from vlmrl_cli.tasks.registry import command_tasks
    from vlmrl_cli.tracking.access import check_store

    console = Console()
    file_layer, *upper = source_layers(config, opt.typed_flags(ctx), sets or [])
    file_grid = calibrate_section(file_layer.pop("calibrate", {}))
    regimes = build_regimes([file_layer, *upper], file_grid | grid_flags(grid or []), command_tasks([task]))
    opt.check_sim_flags(ctx, regimes[0].run.arms, regimes[0].run.vlm.backend,
                        remedy="drop it: calibrate trains the baseline arm alone")
    check_out_folder(out)
    check_store(regimes[0].run.tracking_uri, write=not dry_run)  # before MLflow, the header or any file
    cfg = calibrate_config(regimes, out=out)  # its target profile loads pandas and scipy (seconds)
    base = cfg.base
    # these load torch and MLflow (seconds): only once the store is known to be usable
    from vlmrl_cli.calibration.pipeline import calibrate as run_calibration
    from vlmrl_cli.sweep.cost import estimate_sweeps

    console.print(f"[bold]vlmrl calibrate[/]: {len(cfg.regimes)} regime(s) x seeds {list(base.seeds)} of the "
                  f"baseline, task {base.task}, preset {base.preset}, {base.budget:,} steps each, experiment "
                  f"'{base.experiment}'")
    console.print(f"target: {cfg.target.source}", markup=False)
    console.print(f"cost estimate: {estimate_sweeps([r.run for r in cfg.regimes]).line()}", markup=False)
    if dry_run:
        for regime in cfg.regimes:
            console.print(f"  {regime.id}: {regime.label}", markup=False)
        console.print("dry run: nothing was trained.")
        return
    result = run_calibration(cfg, functools.partial(regime_reporter, console),
                             command=" ".join(["vlmrl", *sys.argv[1:]]))
    exit_if_failed(console, result.failed, "scored")
    best = result.table.iloc[0]
    console.print(f"closest regime: {best['id']} ({best['regime']}), distance {best['distance']:.3f} "
                  f"[{best['distance_low']:.3f}, {best['distance_high']:.3f}]", markup=False)
    console.print(f"cost: {result.wall_s:,.0f} s wall time now ({result.trained} run(s) trained); the runs' own "
                  f"wall times sum to {result.train_wall_s:,.0f} s")
    console.print(f"wrote {', '.join(p.name for p in result.files)} to {out}; MLflow run {result.run_id}")

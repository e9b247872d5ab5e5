"""`vlmrl run`: multi-seed PPO runs of the chosen arms, tracked in MLflow, resumable."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any

import typer
from rich.console import Console

from vlmrl_cli.cli.errors import exit_codes
from vlmrl_cli.cli.options import Experiment, TrackingUri, vlm_overrides, with_vlm_options
from vlmrl_cli.cli.progress import RichSweepReporter
from vlmrl_cli.core.errors import BadInput
from vlmrl_cli.training.config import DEFAULT_EXPERIMENT, RunConfig, load_config_file
from vlmrl_cli.vlm.config import VLMConfig


def _given(ctx: typer.Context, name: str) -> bool:
    source = ctx.get_parameter_source(name)
    return source is not None and source.name in ("COMMANDLINE", "ENVIRONMENT", "PROMPT")


def _seeds(n: int, seed_list: str | None) -> tuple[int, ...]:
    if seed_list is not None:
        try:
            return tuple(int(s) for s in seed_list.split(",") if s.strip())
        except ValueError:
            raise BadInput(f"--seed-list must be comma-separated integers, got '{seed_list}'.") from None
    if n < 1:
        raise BadInput(f"--seeds must be at least 1, got {n}.")
    return tuple(range(n))


@with_vlm_options
def run(
    ctx: typer.Context,
    vlm_cfg: VLMConfig,
    arms: Annotated[str, typer.Option("--arms", help="Comma-separated arms (see README): baseline, hybrid, ...")] = (
        "baseline,hybrid"
    ),
    seeds: Annotated[int, typer.Option("--seeds", help="Number of seeds: 0..N-1.")] = 5,
    seed_list: Annotated[str | None, typer.Option("--seed-list", help="Explicit seeds, e.g. 3,7,11.")] = None,
    timesteps: Annotated[int | None, typer.Option("--timesteps", help="Budget per run (default: preset's).")] = None,
    preset: Annotated[str, typer.Option("--preset", help="PPO preset: paper, zoo, sb3-default, smoke.")] = "paper",
    workers: Annotated[int | None, typer.Option("--workers", help="Worker processes (default: cores).")] = None,
    eval_episodes: Annotated[
        int | None, typer.Option("--eval-episodes", help="Detached evaluation episodes (default: the preset's).")
    ] = None,
    config: Annotated[Path | None, typer.Option("--config", help="TOML file with any of these knobs.")] = None,
    experiment: Experiment = DEFAULT_EXPERIMENT,
    tracking_uri: TrackingUri = None,
) -> None:
    """Train PPO on every (arm, seed); rerunning the same command trains only what is missing."""
    from vlmrl_cli.training.sweep import run_sweep

    console = Console(stderr=False)
    with exit_codes():
        # Flags typed on the command line (or from the environment) override the config file.
        explicit = {name for name in ctx.params if _given(ctx, name)}
        kwargs: dict[str, Any] = load_config_file(config) if config is not None else {}
        flags: dict[str, Any] = {
            "arms": tuple(a.strip() for a in arms.split(",") if a.strip()),
            "seeds": _seeds(seeds, seed_list),
            "timesteps": timesteps, "preset": preset, "eval_episodes": eval_episodes,
            "experiment": experiment, "tracking_uri": tracking_uri,
        }
        if workers is not None:
            flags["workers"] = workers
        flag_source = {"seeds": {"seeds", "seed_list"}}
        for key, value in flags.items():
            if config is None or explicit & flag_source.get(key, {key}):
                kwargs[key] = value
        kwargs["vlm"] = vlm_overrides(kwargs.get("vlm", VLMConfig()), vlm_cfg, explicit if config else None)
        cfg = RunConfig(**kwargs)
        cfg.validate()
        console.print(f"[bold]vlmrl run[/]: arms {', '.join(cfg.arms)} x seeds {list(cfg.seeds)}, preset "
                      f"{cfg.preset}, {cfg.budget:,} steps each, {cfg.workers} worker(s), experiment "
                      f"'{cfg.experiment}'")
        if cfg.vlm.backend == "sim":
            console.print("[yellow]VLM: the SIMULATED VLM (a pixel-reading stand-in), not a real model.[/]")
        with RichSweepReporter(console) as reporter:
            summary = run_sweep(cfg, reporter)
        if summary.parent_run_id is None:
            console.print("Nothing to train: every (arm, seed) run of this configuration is already FINISHED.")
            return
        console.print(f"parent run {summary.parent_run_id}: {len(summary.results)} run(s) in "
                      f"{summary.wall_s:.0f} s; skipped {len(summary.skipped)}; stale runs marked failed "
                      f"{len(summary.marked_failed)}")
        if summary.failed:
            for r in summary.failed:
                console.print(f"[red]{r.job}: {r.status} {r.error or ''}[/]")
            raise typer.Exit(1)



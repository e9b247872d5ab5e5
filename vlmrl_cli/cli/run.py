"""`vlmrl run`: multi-seed PPO runs of the chosen arms, tracked in MLflow, resumable."""

from __future__ import annotations

from typing import Annotated

import typer
from rich.console import Console

from vlmrl_cli.cli.options import (
    Arms,
    ConfigFile,
    EvalEpisodes,
    ExecutorOpt,
    Experiment,
    Preset,
    RayAddress,
    SeedList,
    Seeds,
    Sets,
    TaskOpt,
    Timesteps,
    TrackingUri,
    Workers,
    check_sim_flags,
    typed_flags,
)
from vlmrl_cli.cli.progress import RichSweepReporter, exit_if_failed
from vlmrl_cli.tasks.registry import command_tasks
from vlmrl_cli.training.config import DEFAULT_EXPERIMENT, RunConfig, to_toml
from vlmrl_cli.training.events import SweepSummary

DryRun = Annotated[
    bool, typer.Option("--dry-run", help="Print the resolved config (TOML) and the job list; train nothing.")
]
VlmQps = Annotated[float, typer.Option(
    "--vlm-qps", min=0.001,
    help="Queries per second of your VLM, for the dry run's estimate of its time (default 3: a 7B VLM under HF "
         "transformers at batch 1; a vLLM/SGLang server with many requests in flight answers 10-20).")]


def run(
    ctx: typer.Context,
    arms: Arms = "baseline,hybrid",
    task: TaskOpt = None,
    seeds: Seeds = 5,
    seed_list: SeedList = None,
    timesteps: Timesteps = None,
    preset: Preset = None,
    workers: Workers = None,
    executor: ExecutorOpt = None,
    ray_address: RayAddress = None,
    eval_episodes: EvalEpisodes = None,
    config: ConfigFile = None,
    sets: Sets = None,
    dry_run: DryRun = False,
    vlm_qps: VlmQps = 3.0,
    experiment: Experiment = DEFAULT_EXPERIMENT,
    tracking_uri: TrackingUri = None,
) -> None:
    """Train PPO on every (arm, seed); rerunning the same command trains only what is missing.

    Settings resolve in layers: the --preset < --config FILE < --set KEY=VALUE < other flags.
    """
    from vlmrl_cli.tracking.access import check_store

    console = Console(stderr=False)
    cfg = RunConfig.from_sources(config, typed_flags(ctx), sets or [], tasks=command_tasks([task]))
    check_sim_flags(ctx, cfg.arms, cfg.vlm.backend)
    check_store(cfg.tracking_uri, write=not dry_run)  # before MLflow, the header or any file
    # the sweep's modules load torch and MLflow (seconds): only once the store is known to be usable
    from vlmrl_cli.sweep.preflight import preflight
    from vlmrl_cli.sweep.runner import run_sweep

    if dry_run:
        typer.echo(dry_run_text(cfg, vlm_qps), nl=False)
        return
    preflight(cfg)  # refuse before the header; run_sweep(checked=True) then does not check again
    print_header(console, cfg)
    with RichSweepReporter(console) as reporter:
        summary = run_sweep(cfg, reporter, checked=True)
    if summary.elsewhere:
        console.print(f"[yellow]{len(summary.elsewhere)} job(s) are being trained by another live sweep and "
                      f"were left to it: {', '.join(summary.elsewhere)}[/]")
    if summary.parent_run_id is None:
        if not summary.elsewhere:
            console.print("Nothing to train: every (arm, seed) run of this configuration is already FINISHED.")
        return
    console.print(sweep_summary_line(summary))
    print_children(console, cfg, summary.experiment_id)
    exit_if_failed(console, summary.failed)


def print_header(console: Console, cfg: RunConfig) -> None:
    """What the sweep trains, before it starts: the grid, the overrides, the shaping scales, the VLM."""
    console.print(f"[bold]vlmrl run[/]: task {cfg.task}, arms {', '.join(cfg.arms)} x seeds "
                  f"{list(cfg.seeds)}, preset {cfg.preset}, {cfg.budget:,} steps each, {cfg.workers} "
                  f"worker(s) ({cfg.executor}), experiment '{cfg.experiment}'")
    overrides = cfg.jobs()[0].overrides()
    if overrides:
        console.print("overrides: " + " ".join(f"{k}={v}" for k, v in overrides.items()), markup=False)
    scales = cfg.task_plugin.scales_note(cfg.task_shaping)
    if scales and any(job.arm.kinematic or job.arm.uses_vlm for job in cfg.jobs()):
        console.print(f"scales: {scales} (set them with --set shaping.alpha=A --set shaping.kin_scale=K)",
                      markup=False)
    if cfg.vlm.backend == "sim":
        console.print("[yellow]VLM: the SIMULATED VLM (a pixel-reading stand-in), not a real model.[/]")


def sweep_summary_line(summary: SweepSummary) -> str:
    """One line of what a sweep did: trained, skipped, left to others, retried, failed."""
    line = (f"parent run {summary.parent_run_id}: {len(summary.finished)} run(s) FINISHED in {summary.wall_s:.0f} s; "
            f"skipped {len(summary.skipped)} already FINISHED; stale runs marked failed {len(summary.marked_failed)}")
    if summary.lost_claims:
        line += f"; {len(summary.lost_claims)} claimed first by another sweep"
    if summary.retried:
        line += f"; {len(summary.retried)} attempt(s) lost with their worker and retried"
    return line


def print_children(console: Console, cfg: RunConfig, experiment_id: str) -> None:
    """The sweep's training runs, one plain line each: the ids `vlmrl evaluate` takes."""
    from vlmrl_cli.report.children import child_rows, format_rows, header
    from vlmrl_cli.tracking import store

    task = cfg.task_plugin
    top = task.thresholds[-1]
    client = store.connect(cfg.tracking_uri)
    rows = [header(top), *format_rows(child_rows(client, experiment_id, cfg.jobs(), top, task.window), top)]
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    console.print("training runs (vlmrl evaluate RUN_ID):", markup=False)
    for r in rows:
        console.print("  " + "  ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)).rstrip(), markup=False,
                      highlight=False, soft_wrap=True)


def dry_run_text(cfg: RunConfig, vlm_qps: float = 3.0) -> str:
    """The resolved config as TOML, then as comments the jobs (a FINISHED one's run id, steps to the
    top threshold and detached success) and the pending runs' cost: a file ``--config`` reads back."""
    from vlmrl_cli.report.children import child_rows, format_rows
    from vlmrl_cli.sweep.cost import estimate_sweeps, vlm_cost
    from vlmrl_cli.sweep.runner import dry_plan
    from vlmrl_cli.tracking import store

    plan = dry_plan(cfg)
    task = cfg.task_plugin
    top = task.thresholds[-1]
    done = {(j.arm.name, j.seed) for j in plan.done}
    found = {}
    if plan.done and plan.experiment_id is not None:
        rows = child_rows(store.connect(cfg.tracking_uri), plan.experiment_id, plan.done, top, task.window)
        found = {(r.arm, r.seed): cells for r, cells in zip(rows, format_rows(rows, top), strict=True)}
    lines = [f"# {plan.note}", "# arm        seed  config_hash   status    run id                            "
             f"{f'steps to {top:g}':>13}  detached success"]
    for job in cfg.jobs():
        status = "FINISHED" if (job.arm.name, job.seed) in done else "pending"
        line = f"# {job.arm.name:<10} {job.seed:>4}  {job.config_hash}  {status:<8}"
        cells = found.get((job.arm.name, job.seed))
        if cells is not None:
            line += f"  {cells[2]:<32}  {cells[4]:>13}  {cells[5]}"
        lines.append(line.rstrip())
    lines.append(f"# {len(plan.done)} FINISHED, {len(plan.pending)} pending; nothing was trained.")
    if plan.pending:
        lines.append(f"# cost estimate: {estimate_sweeps([cfg]).line()}")
        asked = vlm_cost(plan.pending, vlm_qps)
        if asked is not None:
            sim = cfg.vlm.backend == "sim"
            simulated = " (the simulated VLM of this config answers at no such cost)" if sim else ""
            lines.append(f"# VLM cost with a real VLM{simulated}: {asked.line()}")
    return "# vlmrl run --dry-run: the resolved configuration\n" + to_toml(cfg) + "\n" + "\n".join(lines) + "\n"

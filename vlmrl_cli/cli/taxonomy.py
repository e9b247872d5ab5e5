"""`vlmrl taxonomy`: the paper's Table 1 and Figure 1, recomputed for one VLM backend."""

from __future__ import annotations

import math
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer
from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

from vlmrl_cli.cli.options import Experiment, OutDir, TaskOpt, TrackingUri, vlm_config
from vlmrl_cli.vlm.config import VLMConfig

if TYPE_CHECKING:
    from vlmrl_cli.probe.taxonomy import TaxonomyResult
    from vlmrl_cli.tasks.base import Task

States = Annotated[
    int | None,
    typer.Option("--states", min=2, help="Sweep positions over the track (default 101; replay: its frames only)."),
]


def taxonomy(
    ctx: typer.Context,
    task: TaskOpt = None,
    states: States = None,
    out: OutDir = None,
    tracking_uri: TrackingUri = None,
    experiment: Experiment = "vlmrl-taxonomy",
) -> None:
    """Probe a VLM with float, box and MCQ prompts (paper Section 2); write Table 1 and Figure 1."""
    vlm_cfg = vlm_config(ctx)
    _check_flags(vlm_cfg, states, out, tracking_uri, experiment)
    # the probe's modules load scipy and pandas (seconds): only once the flags are known to be usable
    from vlmrl_cli.probe.states import DEFAULT_STATES
    from vlmrl_cli.probe.taxonomy import TaxonomyConfig, run_taxonomy
    from vlmrl_cli.tasks.registry import command_tasks, paper_task

    chosen = paper_task() if task is None else command_tasks([task])(task)
    numbers = chosen.numbers is not None  # else the milestone MCQ alone (``probe/milestones.py``)
    default_out = vlm_cfg.backend if numbers else f"{chosen.name}-{vlm_cfg.backend}"
    cfg = TaxonomyConfig(
        vlm=vlm_cfg,
        states=states if states is not None or (numbers and vlm_cfg.backend == "replay") else DEFAULT_STATES,
        out=out if out is not None else Path("results") / "taxonomy" / default_out,
        tracking_uri=tracking_uri,
        experiment=experiment,
    )
    # a transient bar on stderr, off in a pipe
    with Progress(TextColumn("probing frames"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
                  console=Console(stderr=True), transient=True, disable=not sys.stderr.isatty()) as bar:
        probe = bar.add_task("probe", total=None)
        result = run_taxonomy(cfg, progress=lambda done, total: bar.update(probe, completed=done, total=total),
                              task=None if task is None else chosen)
    if result.simulated:
        typer.secho("WARNING: SIMULATED VLM (not a real model): the answers come from a pixel reader with "
                    "noise.", fg=typer.colors.YELLOW, err=True)
    for line in _number_lines(result, vlm_cfg) if numbers else _milestone_lines(result, chosen):
        typer.echo(line)
    typer.echo(f"outputs:   {result.out}/ ({', '.join(p.name for p in result.files)})")
    typer.echo(f"MLflow:    run {result.run_id}")


def _number_lines(result: TaxonomyResult, vlm_cfg: VLMConfig) -> list[str]:
    """The summary of a probe with number questions: the backend, the frames, the sweep."""
    from vlmrl_cli.probe.table1 import with_ci

    lines = [f"backend:   {result.backend_label}"]
    if vlm_cfg.backend == "sim":
        sim = vlm_cfg.sim
        lines.append(f"profile:   {sim.profile} (flicker {sim.flicker:g}, float noise {sim.float_noise:g}, box noise "
                     f"{sim.box_noise_px:g} px, box failure {sim.box_failure:g}, patch {sim.patch_px} px)")
    lines.append(f"frames:    {len(result.probes)} probed, {result.queries} queries "
                 f"(cache: {result.cache_hits} hits, {result.cache_misses} misses)")
    sweep = result.sweep
    if math.isfinite(sweep.get("mcq.accuracy", math.nan)):
        lines.append(f"sweep:     MCQ accuracy {sweep['mcq.accuracy']:.2f}, float Spearman "
                     f"{with_ci(sweep, 'float.spearman', 2)}, box IoU {sweep['box.mean_iou']:.2f}, MCQ dPhi dead "
                     f"zone {sweep['mcq.dphi.dead_zone']:.2f}")
    else:
        lines.append("sweep:     n/a (only the transcript's frames were probed)")
    return lines


def _milestone_lines(result: TaxonomyResult, task: Task) -> list[str]:
    """The summary of a probe of the milestone MCQ alone."""
    m = result.metrics
    return [f"task:      {task.name} ({task.env_id}); float and box prompts are not defined for it",
            f"backend:   {result.backend_label}",
            f"frames:    {m['frames']} probed",
            f"MCQ:       accuracy {m['mcq.accuracy']:.2f} [{m['mcq.accuracy_low']:.2f}, "
            f"{m['mcq.accuracy_high']:.2f}], format failures {m['mcq.format_failure_rate']:.2f}, "
            f"mean |dPhi| {m['mcq.mean_abs_dphi']:.3f}"]


def _check_flags(vlm_cfg: VLMConfig, states: int | None, out: Path | None, tracking_uri: str | None,
                 experiment: str) -> None:
    """The probe's checks that need no task, before its modules load (seconds), in the probe's order."""
    from vlmrl_cli.core.errors import BadInput
    from vlmrl_cli.core.names import experiment_problem, tracking_uri_problem
    from vlmrl_cli.core.paths import check_out_folder
    from vlmrl_cli.probe.states import states_problem
    from vlmrl_cli.tracking.access import check_store
    from vlmrl_cli.vlm.preflight import check_vlm

    problem = (states_problem(states) if states is not None else None) or experiment_problem(experiment) or \
        tracking_uri_problem(tracking_uri)
    if problem:
        raise BadInput(problem + ".")
    check_store(tracking_uri)
    if out is not None:
        check_out_folder(out)
    check_vlm(vlm_cfg)

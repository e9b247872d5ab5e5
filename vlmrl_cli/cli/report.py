"""`vlmrl report`: Table 2, Figures 2-4 and the claims table from the runs in MLflow (never retrains)."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer
from rich.console import Console

from vlmrl_cli.analysis.defaults import DEFAULT_MARGIN
from vlmrl_cli.analysis.multiplicity import DEFAULT_ADJUST
from vlmrl_cli.cli.options import Adjust, AllowMixedPaths, Experiment, Margin, OutDir, TrackingUri, UserTasks
from vlmrl_cli.core.errors import BadInput
from vlmrl_cli.report.config import check_thresholds

if TYPE_CHECKING:  # the CLI imports no analysis code before a command runs (help stays fast)
    from vlmrl_cli.report.table2 import Table2

DEFAULT_OUT = Path("results/report")


def parse_thresholds(text: str) -> tuple[float, ...]:
    """``"-190,-160,-130"`` -> ``(-190.0, -160.0, -130.0)``; anything else is ``BadInput``."""
    try:
        values = tuple(float(v) for v in text.split(",") if v.strip())
    except ValueError:
        raise BadInput(f"--thresholds must be comma-separated numbers like -190,-160,-130, got '{text}'.") from None
    if not values:
        raise BadInput("--thresholds is empty; pass numbers like -190,-160,-130.")
    check_thresholds(values)
    return values


def console_summary(table: Table2, experiment: str) -> list[str]:
    """Table 2's headline rows as short plain lines (the full table is in table2.md)."""
    from vlmrl_cli.report.markdown import format_cell, format_speedup
    from vlmrl_cli.report.table2 import BASELINE, threshold_key

    lines = [f"Table 2, experiment {experiment} (full table: table2.md)"]
    for t in table.thresholds:
        lines.append(f"steps to {t:g} (restricted mean, a DNF at the budget):")
        for arm in table.arms:
            lines.append(f"  {arm:<16} {format_cell(table.cell(threshold_key(t), arm))}")
            if arm != BASELINE and table.has_baseline:
                lines.append(f"  {'':<16} speedup vs baseline {format_speedup(table.speedup(t, arm))}")
    lines.append("reliability (seeds reaching the top threshold):")
    lines += [f"  {arm:<16} {format_cell(table.cell('reliability', arm))}" for arm in table.arms]
    return lines


def report(
    experiment: Experiment = "vlmrl",
    tracking_uri: TrackingUri = None,
    out: OutDir = None,
    thresholds: Annotated[str | None, typer.Option(
        "--thresholds", help="Reward targets, comma-separated [default: the task's; MountainCar's -190,-160,-130].",
        show_default=False)] = None,
    window: Annotated[int | None, typer.Option(
        "--window", help="Episodes in the rolling mean return [default: the task's; MountainCar's 100].",
        show_default=False)] = None,
    margin: Margin = DEFAULT_MARGIN,
    adjust: Adjust = DEFAULT_ADJUST,
    user_task: UserTasks = None,
    allow_mixed_paths: AllowMixedPaths = False,
) -> None:
    """Write Table 2, Figures 2-4, the claims table and report.md from finished runs in MLflow."""
    from vlmrl_cli.core.paths import check_out_folder
    from vlmrl_cli.report.config import ReportConfig, check_report
    from vlmrl_cli.tasks.registry import command_tasks
    from vlmrl_cli.tracking.access import check_store

    tasks = command_tasks(user_task or ())
    cfg = ReportConfig(experiment=experiment, tracking_uri=tracking_uri, out=out or DEFAULT_OUT,
                       thresholds=parse_thresholds(thresholds) if thresholds is not None else None,
                       window=window, margin=margin, adjust=adjust,
                       allow_mixed_paths=allow_mixed_paths)
    # every flag, the folder and the store are checked before the analysis stack loads (seconds)
    check_report(cfg)
    check_out_folder(cfg.out)
    check_store(cfg.tracking_uri, write=False, existing=True)
    from vlmrl_cli.report.writer import write_report

    result = write_report(cfg, tasks)
    console = Console()
    for line in console_summary(result.table, experiment):
        console.print(line, markup=False, highlight=False, soft_wrap=True)
    for w in result.warnings:
        console.print(f"[yellow]warning:[/] {w}")
    console.print(f"Report written to {result.out}/ ({len(result.files)} files; see report.md)")
    if result.report_run_id:
        console.print(f"Logged as MLflow run {result.report_run_id} (vlmrl.kind=report).")

"""Progress: rich rows for a sweep or a retrain on a terminal, plain lines for a log or a pipe."""

from __future__ import annotations

import math
import sys
import time
from collections.abc import Sequence
from typing import TYPE_CHECKING

import typer
from rich.console import Console
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    TaskID,
    TextColumn,
    TimeElapsedColumn,
    TimeRemainingColumn,
)

from vlmrl_cli.training.config import TrainJob
from vlmrl_cli.training.events import JobResult, ProgressEvent

if TYPE_CHECKING:
    from vlmrl_cli.calibration.regimes import Regime


class RichSweepReporter:
    """Implements ``sweep.runner.SweepReporter`` on a rich ``Progress``."""

    def __init__(self, console: Console) -> None:
        self.console = console
        self._bars = Progress(
            TextColumn("{task.description:<22}"),
            BarColumn(bar_width=24),
            MofNCompleteColumn(),
            TextColumn("{task.fields[status]}"),
            TimeElapsedColumn(),
            TimeRemainingColumn(),
            console=console,
            transient=False,
            disable=not console.is_terminal,  # logs and CI get one plain line per finished run instead
        )
        self._tasks: dict[str, TaskID] = {}
        self._seen: dict[str, int] = {}
        self._overall: TaskID | None = None
        self._finished = 0

    def __enter__(self) -> RichSweepReporter:
        self._bars.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._bars.stop()

    def planned(self, pending: list[TrainJob], done: list[TrainJob]) -> None:
        if done:
            names = ", ".join(j.name for j in done)
            self.console.print(f"[dim]{len(done)} run(s) already FINISHED, skipped: {names}[/]")
        if not pending:
            return
        total = sum(j.timesteps for j in pending)
        self._overall = self._bars.add_task("all runs", total=total, status="")
        for job in pending:
            self._tasks[job.name] = self._bars.add_task(job.name, total=job.timesteps, status="[dim]queued[/]")
            self._seen[job.name] = 0

    def progress(self, event: ProgressEvent) -> None:
        task = self._tasks.get(event.job)
        if task is None:
            return
        recent = "n/a" if math.isnan(event.recent_return) else f"{event.recent_return:7.1f}"
        status = f"ep {event.episodes:5d}  R100 {recent}" + ("  [cyan]evaluating[/]" if event.phase == "eval" else "")
        self._bars.update(task, completed=event.timesteps, status=status)
        if self._overall is not None:
            self._bars.advance(self._overall, max(0, event.timesteps - self._seen[event.job]))
        self._seen[event.job] = max(self._seen[event.job], event.timesteps)

    def finished(self, result: JobResult) -> None:
        task = self._tasks.get(result.job)
        if task is None:
            return
        if result.status == "FINISHED":
            status = (f"[green]done[/] eval success {result.eval_success_rate:.0%}, "
                      f"len {result.eval_mean_length:.0f}")
        else:
            color = "yellow" if result.status in ("SKIPPED", "CANCELLED") else "red"
            status = f"[{color}]{result.status}[/] {result.error or ''}"[:80]
        self._bars.update(task, status=status)
        self._finished += 1
        if not self.console.is_terminal:
            self.console.print(f"{self._finished}/{len(self._tasks)} {result.job}: {status} ({result.wall_s:.0f} s)")


def regime_reporter(console: Console, regime: Regime) -> RichSweepReporter:
    """The progress of one regime's sweep, under a line naming it."""
    console.print(f"[bold]{regime.id}[/]: {regime.label}", highlight=False)
    return RichSweepReporter(console)


def exit_if_failed(console: Console, failed: Sequence[JobResult], skipped: str = "") -> None:
    """Each failed run in red (then that nothing was ``skipped``) and exit 1; nothing when no run failed."""
    if not failed:
        return
    for r in failed:
        console.print(f"[red]{r.job}: {r.status} {r.error or ''}[/]")
    if skipped:
        console.print(f"Some runs failed; nothing was {skipped}. Rerun the same command to retry them.")
    raise typer.Exit(1)


class RetrainProgress:
    """Retraining's progress on stderr in steps: a bar on a terminal, else a line per finished run."""

    def __init__(self, runs: int, steps: int) -> None:
        err = Console(stderr=True, highlight=False, soft_wrap=True)
        self.runs, self.steps, self.out = runs, steps, None if err.is_terminal else sys.stderr
        self.runs_done = self.steps_done = 0
        self.started = time.monotonic()
        self._bar = Progress(TextColumn("{task.description}"), BarColumn(),
                             TextColumn("{task.completed:,.0f}/{task.total:,.0f} steps"), TimeElapsedColumn(),
                             TimeRemainingColumn(), console=err, transient=True, disable=not err.is_terminal)
        self._task = self._bar.add_task(f"retraining {runs} run(s)", total=steps)
        if self.out is not None:
            print(f"progress: retraining {runs} run(s), {steps:,} steps; a line as each run finishes", file=self.out,
                  flush=True)

    def __enter__(self) -> RetrainProgress:
        self._bar.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._bar.stop()

    def advance(self, steps: int) -> None:
        self._bar.advance(self._task, steps)
        self.runs_done += 1
        self.steps_done += steps
        if self.out is not None:  # the time left at the pace so far, in steps
            elapsed = time.monotonic() - self.started
            left = elapsed * (self.steps - self.steps_done) / self.steps_done if self.steps_done else math.nan
            tail = "" if math.isnan(left) else f", about {left / 60:,.1f} min left"
            print(f"progress: {self.runs_done}/{self.runs} run(s), {self.steps_done:,}/{self.steps:,} steps, "
                  f"{elapsed / 60:,.1f} min elapsed{tail}", file=self.out, flush=True)

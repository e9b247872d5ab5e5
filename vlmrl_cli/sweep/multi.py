"""Many sweeps as one piece of work (`vlmrl calibrate`'s and `vlmrl study`'s): train them on one
pool, find their runs, and log the summary run of their outputs."""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from contextlib import AbstractContextManager
from pathlib import Path
from typing import Any, Protocol, TypeVar

import pandas as pd

from vlmrl_cli.sweep.runner import JobResult, SharedPool, SweepReporter, run_sweep
from vlmrl_cli.tracking import schema, store
from vlmrl_cli.tracking.lifecycle import tracked_run
from vlmrl_cli.training.config import RunConfig


class Sweep(Protocol):
    """One sweep of many (a calibration's or a study's regime): its ``RunConfig``."""

    @property
    def run(self) -> RunConfig: ...


S = TypeVar("S", bound=Sweep)


def train_sweeps(sweeps: Sequence[S], reporter_for: Callable[[S], AbstractContextManager[SweepReporter]]
                 ) -> tuple[int, list[JobResult]]:
    """Train what each sweep misses, on one ``SharedPool``: the number of runs trained and the failed ones."""
    trained, failed = 0, []
    with SharedPool() as pool:
        for sweep in sweeps:
            with reporter_for(sweep) as reporter:
                summary = run_sweep(sweep.run, reporter, pool=pool)
            trained += len(summary.results)
            failed += summary.failed
    return trained, failed


def runs_of(runs: pd.DataFrame, run: RunConfig) -> pd.DataFrame:
    """The rows of ``runs`` (see ``analysis/load.py``) that are jobs of ``run``: same arm, seed and config hash."""
    keys = {(j.arm.name, j.seed, j.config_hash) for j in run.jobs()}
    mine = [(a, s, h) in keys for a, s, h in zip(runs["arm"], runs["seed"], runs["config_hash"], strict=True)]
    return runs[pd.Series(mine, index=runs.index, dtype=bool)]


def wall_s(client: Any, run_id: str) -> float:
    return float(client.get_run(run_id).data.metrics.get(schema.METRIC_WALL_S, 0.0))


def log_summary_run(client: Any, experiment_id: str, kind: str, key: str, params: dict[str, str],
                    files: list[Path], vlm: tuple[str, bool]) -> str:
    """The run of ``kind`` and config hash ``key`` (a new one with ``params`` and the (label,
    simulated) ``vlm`` unless there is one), holding ``files``."""
    keys = {schema.TAG_KIND: kind, schema.TAG_CONFIG_HASH: key}
    found = client.search_runs([experiment_id], filter_string=schema.runs_filter(keys), max_results=1)
    if found:
        run_id = str(found[0].info.run_id)
    else:
        name = {schema.MLFLOW_RUN_NAME: f"{kind}-{time.strftime('%Y%m%d-%H%M%S')}"}
        run_id = str(client.create_run(experiment_id, tags={**store.provenance_tags(*vlm), **name, **keys}).info.run_id)
        store.log_params(client, run_id, params)
    with tracked_run(client, run_id):
        store.log_artifacts(client, run_id, files)
    return run_id

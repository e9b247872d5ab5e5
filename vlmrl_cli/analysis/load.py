"""Read the finished training runs of one MLflow experiment (the tags, params and metrics that
``vlmrl run`` writes, ``tracking.schema``) into tidy DataFrames.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pandas as pd

from vlmrl_cli.core.errors import BadInput
from vlmrl_cli.tasks.registry import recorded_task
from vlmrl_cli.tracking import schema

EPISODE_METRICS = {
    schema.METRIC_NATIVE_RETURN: "native_return",
    schema.METRIC_LENGTH: "length",
    schema.METRIC_SUCCESS: "success",
    schema.METRIC_SHAPED_RETURN: "shaped_return",
}
EVAL_METRICS = {
    schema.METRIC_EVAL_SUCCESS_RATE: "eval_success_rate",
    schema.METRIC_EVAL_MEAN_LENGTH: "eval_mean_length",
    schema.METRIC_EVAL_MEAN_RETURN: "eval_mean_return",
    schema.METRIC_EVAL_HOVER_FRACTION: "eval_hover_fraction",  # NaN for runs older than the hovering diagnostic
    schema.METRIC_EVAL_DWELL_RIGHT_STEPS: "eval_dwell_right_steps",
}
EVAL_EPISODE_METRIC = schema.METRIC_EVAL_EPISODE_LENGTH

CPU_COLUMNS = {"numpy_simd": "cpu_numpy_simd", "blas": "cpu_blas", "torch": "cpu_torch",
               "model": "cpu_model"}  # tag suffix -> column
#: A run computed before the numeric pin existed (core.numeric_pin) carries no vlmrl.pin tag.
UNPINNED_BEFORE = "unpinned (run predates the numeric pin)"
RUN_COLUMNS = ["run_id", "arm", "seed", "config_hash", "preset", "budget", "vlm", "simulated", "end_time",
               *CPU_COLUMNS.values(), "numeric_path", *EVAL_METRICS.values()]
EPISODE_COLUMNS = ["run_id", "arm", "seed", "timestep", *EPISODE_METRICS.values()]
EVAL_EPISODE_COLUMNS = ["run_id", "arm", "seed", "episode", "length"]


@dataclass(frozen=True)
class ExperimentData:
    """Finished training runs of one experiment: ``runs`` (``RUN_COLUMNS``), ``episodes`` (one row per
    training episode, ``EPISODE_COLUMNS``, by run and timestep), ``eval_episodes`` (one row per
    detached evaluation episode, or empty) and the runs' one ``task``."""

    experiment_id: str
    experiment_name: str
    runs: pd.DataFrame
    episodes: pd.DataFrame
    eval_episodes: pd.DataFrame
    task: str = field(kw_only=True)


def _history(client: Any, run_id: str, key: str) -> pd.DataFrame:
    """One metric's history as (step, rank, value): ``rank`` numbers points logged at the same step."""
    points = client.get_metric_history(run_id, key)
    df = pd.DataFrame({"step": [int(p.step) for p in points], "ts": [int(p.timestamp) for p in points],
                       "value": [float(p.value) for p in points]})
    df = df.sort_values(["step", "ts"], kind="stable").reset_index(drop=True)
    df["rank"] = df.groupby("step").cumcount()
    return df[["step", "rank", "value"]]


def _episodes(client: Any, run_id: str, table: str | None = None) -> pd.DataFrame:
    """The run's episodes: from its episode table artifact ``table``, else from the metric histories."""
    if table:
        from_table = _episodes_from_table(client, run_id, table)
        if from_table is not None:
            return from_table
    merged: pd.DataFrame | None = None
    for key, column in EPISODE_METRICS.items():
        h = _history(client, run_id, key).rename(columns={"value": column})
        merged = h if merged is None else merged.merge(h, on=["step", "rank"], how="outer")
    assert merged is not None
    merged = merged.sort_values(["step", "rank"]).rename(columns={"step": "timestep"})
    return merged.drop(columns="rank").reset_index(drop=True)


def _episodes_from_table(client: Any, run_id: str, name: str) -> pd.DataFrame | None:
    import tempfile
    from pathlib import Path

    from vlmrl_cli.tracking import store

    with tempfile.TemporaryDirectory(prefix="vlmrl-episodes-") as tmp:
        try:
            store.download_artifacts(client, run_id, [name], Path(tmp))
            table = pd.read_csv(Path(tmp) / name, dtype=float)
        except Exception:  # not there (an imported run) or unreadable: the histories hold the same data
            return None
    columns = {"timestep": "timestep", **EPISODE_METRICS}
    if set(table.columns) != set(columns):
        return None
    table = table.rename(columns=columns)[["timestep", *EPISODE_METRICS.values()]]
    table["timestep"] = table["timestep"].astype("int64")  # as the histories' steps
    return table


def _int_or_nan(text: str | None) -> float:
    try:
        return float(int(float(text))) if text is not None else float("nan")
    except ValueError:
        return float("nan")


def _run_row(run: Any) -> dict[str, Any]:
    tags, params, metrics = run.data.tags, run.data.params, run.data.metrics
    seed = _int_or_nan(tags.get(schema.TAG_SEED))
    return {
        "run_id": run.info.run_id,
        "arm": tags.get(schema.TAG_ARM, "unknown"),
        "seed": seed,
        "config_hash": tags.get(schema.TAG_CONFIG_HASH, ""),
        "preset": tags.get(schema.TAG_PRESET, ""),
        "budget": _int_or_nan(params.get(schema.PARAM_TIMESTEPS)),
        "vlm": tags.get(schema.TAG_VLM, "unknown"),
        "simulated": tags.get(schema.TAG_SIMULATED, "false").lower() == "true",
        "end_time": pd.Timestamp(run.info.end_time or 0, unit="ms", tz="UTC"),
        **{col: tags.get(f"{schema.TAG_CPU_PREFIX}{key}", "unrecorded") for key, col in CPU_COLUMNS.items()},
        "numeric_path": numeric_path(tags),
        **{col: float(metrics.get(key, np.nan)) for key, col in EVAL_METRICS.items()},
    }


def numeric_path(tags: Mapping[str, str]) -> str:
    """The numeric path a run computed on, from its tags: the pin, its values, and torch's CPU capability.

    Example:
        >>> numeric_path({"vlmrl.pin": "x86-64-v3/1", "vlmrl.pin.env": "MKL_CBWR=COMPATIBLE",
        ...               "vlmrl.cpu.torch": "AVX2"})
        'x86-64-v3/1 (MKL_CBWR=COMPATIBLE; torch AVX2)'
        >>> numeric_path({"vlmrl.cpu.torch": "AVX512"})
        'unpinned (run predates the numeric pin; torch AVX512)'
    """
    torch = tags.get(f"{schema.TAG_CPU_PREFIX}torch", "unrecorded")
    if schema.TAG_PIN not in tags:
        return f"{UNPINNED_BEFORE[:-1]}; torch {torch})"
    return f"{tags[schema.TAG_PIN]} ({tags.get(schema.TAG_PIN_ENV, 'unrecorded')}; torch {torch})"


def check_one_task(runs: Sequence[Any], experiment: str) -> str:
    """The one task of ``runs`` (no ``vlmrl.task`` tag: MountainCar-v0); ``BadInput`` when they mix tasks."""
    tasks = sorted({recorded_task(r.data.tags.get(schema.TAG_TASK)) for r in runs})
    if len(tasks) > 1:
        raise BadInput(f"MLflow experiment '{experiment}' mixes tasks ({', '.join(tasks)}); a report compares runs "
                       "of one task: train each task into its own --experiment.")
    return tasks[0] if tasks else recorded_task(None)


def load_experiment(client: Any, experiment: str) -> ExperimentData:
    """The finished training runs of ``experiment``, the latest per (arm, seed, config_hash); ``BadInput``
    when there are none."""
    exp = client.get_experiment_by_name(experiment)
    if exp is None or exp.lifecycle_stage == "deleted":
        raise BadInput(f"MLflow experiment '{experiment}' does not exist; pass --experiment NAME of a run sweep.")
    found = schema.search_all(client, exp.experiment_id, schema.runs_filter({schema.TAG_KIND: schema.KIND_TRAIN},
                                                                          finished=True))
    if not found:
        raise BadInput(f"MLflow experiment '{experiment}' has no finished training runs; run `vlmrl run` first.")
    task = check_one_task(found, experiment)
    tables = {r.info.run_id: r.data.tags.get(schema.TAG_EPISODES_TABLE) for r in found}
    runs = pd.DataFrame([_run_row(r) for r in found], columns=RUN_COLUMNS)
    runs = (runs.sort_values("end_time", ascending=False, kind="stable")
            .drop_duplicates(["arm", "seed", "config_hash"], keep="first"))
    runs["seed"] = runs["seed"].astype("Int64")
    runs["budget"] = runs["budget"].astype("Int64")
    runs = runs.sort_values(["arm", "seed"], kind="stable").reset_index(drop=True)

    episodes, evals = [], []
    for row in runs.itertuples(index=False):
        ep = _episodes(client, row.run_id, tables.get(row.run_id))
        ep.insert(0, "seed", row.seed)
        ep.insert(0, "arm", row.arm)
        ep.insert(0, "run_id", row.run_id)
        episodes.append(ep)
        h = _history(client, row.run_id, EVAL_EPISODE_METRIC)
        if len(h):
            h = h.sort_values(["step", "rank"])
            evals.append(pd.DataFrame({"run_id": row.run_id, "arm": row.arm, "seed": row.seed,
                                       "episode": h["step"].to_numpy(), "length": h["value"].to_numpy()}))
    episodes_df = pd.concat(episodes, ignore_index=True)[EPISODE_COLUMNS] if episodes else pd.DataFrame(
        columns=EPISODE_COLUMNS)
    evals_df = pd.concat(evals, ignore_index=True)[EVAL_EPISODE_COLUMNS] if evals else pd.DataFrame(
        columns=EVAL_EPISODE_COLUMNS)
    return ExperimentData(str(exp.experiment_id), str(exp.name), runs, episodes_df, evals_df, task=task)

"""One (arm, seed) job in a worker process: train PPO, evaluate detached, record its MLflow run."""

from __future__ import annotations

import dataclasses
import json
import os
import signal
import tempfile
import time
import traceback
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from vlmrl_cli.core.provenance import flatten
from vlmrl_cli.shaping.placebo import describe_map, placebo_map
from vlmrl_cli.sweep import leases
from vlmrl_cli.tracking import schema, store
from vlmrl_cli.tracking.lifecycle import RunStatus, tracked_run
from vlmrl_cli.training.callbacks import EpisodeTracker
from vlmrl_cli.training.config import EVAL_SEED, TrainJob
from vlmrl_cli.training.evaluation import EvalResult, evaluate_detached
from vlmrl_cli.training.events import JobContext, JobResult, ProgressEvent
from vlmrl_cli.training.trained import deterministic_policy as _policy


@dataclass
class Channels:
    """How a job reaches its sweep: ``progress.put(event)`` and ``stop.is_set()``, or None."""

    progress: Any = None
    stop: Any = None


_channels = Channels()

#: The part of a job between claiming its run and ending it: ``body(job, client, run_id, channels)``.
Body = Callable[[TrainJob, Any, str, Channels], JobResult]


def init_worker(progress: Any, stop: Any, ignore_sigint: bool = True) -> None:
    """Worker set-up (once per process; Ray's per job): one torch thread, Ctrl-C left to the sweep,
    headless rendering, the sweep's channels."""
    import torch

    torch.set_num_threads(1)
    # the cameras render through gymnasium's rgb_array mode, whose pygame.display.init() needs a driver
    os.environ.setdefault("SDL_VIDEODRIVER", "dummy")
    os.environ.setdefault("MUJOCO_GL", "egl")  # MuJoCo's frames (--task pusher), headless
    if ignore_sigint:
        signal.signal(signal.SIGINT, signal.SIG_IGN)
    _channels.progress = progress
    _channels.stop = stop


def run_tags(job: TrainJob, parent_run_id: str | None, vlm_label: str, simulated: bool) -> dict[str, str]:
    if not job.arm.uses_vlm:
        vlm_label, simulated = "none (this arm queries no VLM)", False
    tags = {
        **store.provenance_tags(vlm_label, simulated),
        schema.MLFLOW_RUN_NAME: job.name,
        schema.TAG_KIND: schema.KIND_TRAIN,
        schema.TAG_ARM: job.arm.name,
        schema.TAG_SEED: str(job.seed),
        schema.TAG_CONFIG_HASH: job.config_hash,
        schema.TAG_PRESET: job.preset,
        schema.TAG_TASK: job.task,
        schema.TAG_OVERRIDES: " ".join(f"{k}={v}" for k, v in job.overrides().items()) or "none",
    }
    if job.regime is not None:
        tags[schema.TAG_REGIME] = job.regime
    if job.arm.kinematic or job.arm.uses_vlm:  # alpha and kin_scale: the task's rule, the paper's, or the run's
        task, shaping = job.task_plugin, job.shaping
        own = task.default_shaping()
        source = ("set for this run" if (shaping.alpha, shaping.kin_scale) != (own.alpha, own.kin_scale)
                  else "the task's rule: " + task.scales.rule if task.scales is not None else "the paper's")
        tags[schema.TAG_SCALES] = f"alpha {shaping.alpha:g}, kin_scale {shaping.kin_scale:g} ({source})"
    if job.arm.uses_vlm and job.vlm.backend == "sim":
        tags[schema.TAG_SIM_PROFILE] = job.vlm.sim.profile
    if job.arm.uses_vlm and job.vlm.backend == "sim" and job.vlm.sim.query_flicker > 0:
        tags[schema.TAG_STOCHASTIC_VLM] = "true"
    if job.arm.placebo:
        tags[schema.TAG_PLACEBO_MAP] = describe_map(placebo_map(job.shaping.label_potentials, job.seed))
    if parent_run_id is not None:
        tags[schema.MLFLOW_PARENT_RUN_ID] = parent_run_id
    return tags


def train_job(job: TrainJob, ctx: JobContext) -> JobResult:
    """Claim, train, evaluate and record one job (what both executors dispatch)."""
    return run_claimed(job, ctx, train_body)


def with_task(job: TrainJob) -> TrainJob:
    """``job`` with its Task resolved from its name (a job crosses to a worker without it)."""
    if job.plugin is not None:
        return job
    from vlmrl_cli.tasks.registry import job_task

    return dataclasses.replace(job, plugin=job_task(job.task))


def run_claimed(job: TrainJob, ctx: JobContext, body: Body) -> JobResult:
    """Create and claim the job's run, then run ``body`` under a heartbeat. Never raises: a failure
    is a FAILED run; after a stop, CANCELLED without a run; a job another live run owns, SKIPPED."""
    start = time.perf_counter()
    job = with_task(job)
    channels = _channels
    if channels.stop is not None and channels.stop.is_set():
        return JobResult(job.name, "", "CANCELLED", 0.0)
    try:
        client = store.connect(ctx.tracking_uri, wait_s=ctx.connect_wait_s)
        run = client.create_run(ctx.experiment_id, tags={
            **run_tags(job, ctx.parent_run_id, ctx.vlm_label, ctx.simulated), **leases.heartbeat_tags()})
        run_id = run.info.run_id
        decision = leases.claim(client, ctx.experiment_id, run_id, job.name, job.arm.name, job.seed,
                                job.config_hash, ctx.stale_after_s)
    except BaseException as exc:  # the store failed before the job had a run: the next sweep redoes it
        return JobResult(job.name, "", "FAILED", time.perf_counter() - start, error=f"{type(exc).__name__}: {exc}")
    if not decision.won:
        return JobResult(job.name, run_id, "SKIPPED", time.perf_counter() - start, error=decision.reason)
    message = ""
    try:
        with tracked_run(client, run_id) as run:
            try:
                with leases.heartbeat(client, run_id, ctx.heartbeat_s):
                    result = body(job, client, run_id, channels)
                run.status = RunStatus(result.status)
                finished = leases.job_runs(client, ctx.experiment_id, job.name, job.arm.name, job.seed,
                                           job.config_hash, finished=True) if result.status == "FINISHED" else []
                rival = next((r.info.run_id for r in finished if r.info.run_id != run_id), None)
                if rival is not None:  # two claimants raced past each other: keep the first FINISHED run only
                    store.set_tags(client, run_id, {schema.TAG_ERROR: f"duplicate of FINISHED run {rival}"})
                    run.status = RunStatus.KILLED
                    result = dataclasses.replace(result, status="SKIPPED", error=f"duplicate of FINISHED run {rival}")
            except KeyboardInterrupt:
                raise
            except BaseException as exc:
                message = f"{type(exc).__name__}: {exc}"
                store.set_tags(client, run_id, {schema.TAG_ERROR: message[:4000],
                                                schema.TAG_TRACEBACK: traceback.format_exc()[-4000:]})
                raise
        return dataclasses.replace(result, superseded=decision.superseded, wall_s=time.perf_counter() - start)
    except KeyboardInterrupt:  # a terminal's Ctrl-C reaches Ray's workers too: a stop, not a failure
        return JobResult(job.name, run_id, "KILLED", time.perf_counter() - start, superseded=decision.superseded)
    except BaseException as exc:  # a failed job must not take the sweep down; nor a store that failed too
        return JobResult(job.name, run_id, "FAILED", time.perf_counter() - start,
                         error=message or f"{type(exc).__name__}: {exc}", superseded=decision.superseded)


def train_body(job: TrainJob, client: Any, run_id: str, channels: Channels) -> JobResult:
    """Train PPO, evaluate detached, log metrics and artifacts; the result's status closes the run."""
    from stable_baselines3.common.logger import Logger

    from vlmrl_cli.training.logger import MetricsOutputFormat
    from vlmrl_cli.training.session import session

    start = time.perf_counter()
    progress, stop = channels.progress, channels.stop

    def stopped() -> bool:  # a Ctrl-C during the imports or the set-up ends the job before it trains
        return stop is not None and bool(stop.is_set())

    def send(event: ProgressEvent) -> None:
        if progress is not None:
            progress.put(event)

    with tempfile.TemporaryDirectory(prefix="vlmrl-") as tmp:
        out = Path(tmp)
        store.log_params(client, run_id, {schema.PARAM_TIMESTEPS: str(job.timesteps), **flatten(job.params())})
        if stopped():
            return JobResult(job.name, run_id, "KILLED", time.perf_counter() - start)
        task = job.task_plugin
        with session(job, transcript=out / "transcript.jsonl") as built:
            model, env, oracle = built.model, built.env, built.oracle
            if stopped():
                return JobResult(job.name, run_id, "KILLED", time.perf_counter() - start)
            metrics = store.BatchLogger(client, run_id)
            model.set_logger(Logger(folder=None, output_formats=[MetricsOutputFormat(metrics)]))
            tracker = EpisodeTracker(
                job.name, job.timesteps, metrics=metrics, progress=send,
                should_stop=stopped if stop is not None else None,
                vlm_stats=oracle.stats if oracle is not None else None, success=task.success,
            )
            model.learn(total_timesteps=job.timesteps, callback=tracker)
            model.logger.dump(step=model.num_timesteps)  # the last update's train/ figures
            if tracker.stopped:
                metrics.flush()
                return JobResult(job.name, run_id, "KILLED", time.perf_counter() - start)
            send(ProgressEvent(job.name, job.timesteps, job.timesteps, len(tracker.episodes),
                               float(np.mean(tracker.recent)) if tracker.recent else float("nan"), "eval"))
            result = evaluate_detached(_policy(model, env), job.eval_episodes, EVAL_SEED, task)
            _log_eval(metrics, result)
            metrics.log({schema.METRIC_WALL_S: time.perf_counter() - start}, step=job.timesteps)
            metrics.flush()
            _save_artifacts(out, job, model, env)
            write_episodes_table(tracker.episodes, out / schema.EPISODES_TABLE)
            store.log_artifacts(client, run_id, [p for p in out.iterdir()])
            store.set_tags(client, run_id, {schema.TAG_EPISODES_TABLE: schema.EPISODES_TABLE})
            return JobResult(job.name, run_id, "FINISHED", time.perf_counter() - start,
                             result.success_rate, result.mean_length)


def _log_eval(metrics: store.BatchLogger, result: EvalResult) -> None:
    metrics.log({schema.METRIC_EVAL_SUCCESS_RATE: result.success_rate,
                 schema.METRIC_EVAL_MEAN_LENGTH: result.mean_length,
                 schema.METRIC_EVAL_MEAN_RETURN: result.mean_return}, step=0)
    if result.positions:  # the hovering diagnostic (issue 9): R_kin can pay more for parking than finishing
        hover = result.hovering
        metrics.log({schema.METRIC_EVAL_HOVER_FRACTION: hover.hover_fraction,
                     schema.METRIC_EVAL_DWELL_RIGHT_STEPS: hover.dwell_right_steps}, step=0)
    for i, (ret, length, ok) in enumerate(zip(result.returns, result.lengths, result.successes, strict=True)):
        metrics.log({schema.METRIC_EVAL_EPISODE_RETURN: float(ret), schema.METRIC_EVAL_EPISODE_LENGTH: float(length),
                     schema.METRIC_EVAL_EPISODE_SUCCESS: float(ok)}, step=i)


def write_episodes_table(episodes: list[dict[str, float]], path: Path) -> None:
    """The run's episodes as one CSV table: ``timestep`` then each ``episode/*`` metric, floats exact."""
    import pandas as pd

    columns = ["timestep", *schema.EPISODE_METRICS]
    table = pd.DataFrame([[e[c] for c in columns] for e in episodes], columns=columns, dtype=float)
    table.to_csv(path, index=False)


def _save_artifacts(out: Path, job: TrainJob, model: Any, env: Any) -> None:
    from stable_baselines3.common.vec_env import VecNormalize

    from vlmrl_cli.training import trained

    model.save(out / trained.MODEL)
    # the observation statistics, as arrays rather than SB3's pickle (evaluation unpickles nothing); a
    # VecNormalize of rewards alone keeps none, and its policy reads raw observations
    if isinstance(env, VecNormalize) and env.norm_obs:
        trained.save_normalizer(env, out / trained.NORMALIZER)
    config = {"config_hash": job.config_hash, **job.params()}
    (out / trained.CONFIG).write_text(json.dumps(config, indent=2, sort_keys=True))

"""One (arm, seed) job: train PPO, evaluate detached, record everything in its MLflow child run.

Runs inside a worker process (one torch thread each: 2 cores, 2 workers). The process-wide
progress queue and stop event arrive once through ``init_worker`` (they can only be shared by
inheritance), never as module state that the library reads elsewhere.
"""

from __future__ import annotations

import json
import signal
import tempfile
import time
import traceback
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from vlmrl_cli.core.provenance import flatten
from vlmrl_cli.tracking import schema, store
from vlmrl_cli.training.callbacks import EpisodeTracker
from vlmrl_cli.training.config import EVAL_SEED, TrainJob
from vlmrl_cli.training.evaluation import EvalResult, evaluate_detached
from vlmrl_cli.training.events import JobResult, ProgressEvent
from vlmrl_cli.training.trained import deterministic_policy as _policy


@dataclass
class _Channels:
    progress: Any = None  # multiprocessing queue of ProgressEvent
    stop: Any = None  # multiprocessing event


_channels = _Channels()


def init_worker(progress: Any, stop: Any) -> None:
    """Pool initializer: single-threaded torch, Ctrl-C left to the parent, channels kept."""
    import torch

    torch.set_num_threads(1)
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
        schema.TAG_OVERRIDES: " ".join(f"{k}={v}" for k, v in job.overrides().items()) or "none",
    }
    if job.regime is not None:
        tags[schema.TAG_REGIME] = job.regime
    if job.arm.uses_vlm and job.vlm.backend == "sim":
        tags[schema.TAG_SIM_PROFILE] = job.vlm.sim.profile
    if parent_run_id is not None:
        tags[schema.MLFLOW_PARENT_RUN_ID] = parent_run_id
    return tags


def train_job(
    job: TrainJob,
    tracking_uri: str,
    experiment_id: str,
    parent_run_id: str | None,
    vlm_label: str,
    simulated: bool,
) -> JobResult:
    """Train, evaluate and record one job. Never raises: failures end as a FAILED run."""
    from stable_baselines3.common.logger import Logger

    from vlmrl_cli.training.envs import make_train_env
    from vlmrl_cli.training.logger import MetricsOutputFormat
    from vlmrl_cli.training.model import make_model
    from vlmrl_cli.vlm.registry import build_client

    start = time.perf_counter()
    client = store.connect(tracking_uri)
    run = client.create_run(experiment_id, tags=run_tags(job, parent_run_id, vlm_label, simulated))
    run_id = run.info.run_id
    progress = _channels.progress
    stop = _channels.stop

    def send(event: ProgressEvent) -> None:
        if progress is not None:
            progress.put(event)

    with tempfile.TemporaryDirectory(prefix="vlmrl-") as tmp:
        out = Path(tmp)
        vlm_client = None
        try:
            store.log_params(client, run_id, {schema.PARAM_TIMESTEPS: str(job.timesteps), **flatten(job.params())})
            if job.arm.uses_vlm:
                vlm_client = build_client(job.vlm, transcript=out / "transcript.jsonl")
            env, oracle = make_train_env(job.arm, job.ppo, job.shaping, vlm_client, job.seed)
            model = make_model(job.ppo, env, job.seed)
            metrics = store.BatchLogger(client, run_id)
            model.set_logger(Logger(folder=None, output_formats=[MetricsOutputFormat(metrics)]))
            tracker = EpisodeTracker(
                job.name, job.timesteps, metrics=metrics, progress=send,
                should_stop=(lambda: bool(stop.is_set())) if stop is not None else None,
                vlm_stats=oracle.stats if oracle is not None else None,
            )
            model.learn(total_timesteps=job.timesteps, callback=tracker)
            model.logger.dump(step=model.num_timesteps)  # the last update's train/ figures
            if tracker.stopped:
                client.set_terminated(run_id, "KILLED")
                return JobResult(job.name, run_id, "KILLED", time.perf_counter() - start)
            send(ProgressEvent(job.name, job.timesteps, job.timesteps, len(tracker.episodes),
                               float(np.mean(tracker.recent)) if tracker.recent else float("nan"), "eval"))
            result = evaluate_detached(_policy(model, env), job.eval_episodes, EVAL_SEED)
            _log_eval(metrics, result)
            metrics.log({schema.METRIC_WALL_S: time.perf_counter() - start}, step=job.timesteps)
            metrics.flush()
            _save_artifacts(out, job, model, env)
            store.log_artifacts(client, run_id, [p for p in out.iterdir()])
            client.set_terminated(run_id, "FINISHED")
            return JobResult(job.name, run_id, "FINISHED", time.perf_counter() - start,
                             result.success_rate, result.mean_length)
        except BaseException as exc:  # a failed job must not take the sweep down
            message = f"{type(exc).__name__}: {exc}"
            try:
                store.set_tags(client, run_id, {schema.TAG_ERROR: message[:4000],
                                                schema.TAG_TRACEBACK: traceback.format_exc()[-4000:]})
                client.set_terminated(run_id, "FAILED")
            except Exception:  # the store itself failed; the parent reports the error
                pass
            return JobResult(job.name, run_id, "FAILED", time.perf_counter() - start, error=message)
        finally:
            if vlm_client is not None:
                vlm_client.close()


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


def _save_artifacts(out: Path, job: TrainJob, model: Any, env: Any) -> None:
    from stable_baselines3.common.vec_env import VecNormalize

    model.save(out / "model.zip")
    if isinstance(env, VecNormalize):
        env.save(str(out / "vecnormalize.pkl"))
    config = {"config_hash": job.config_hash, **job.params()}
    (out / "config.json").write_text(json.dumps(config, indent=2, sort_keys=True))

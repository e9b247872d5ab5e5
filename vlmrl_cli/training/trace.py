"""A training run reduced to its learning curve, in this process and with no tracking.

``native_returns(job)`` trains exactly as a ``vlmrl run`` worker does (same env stack, same PPO
arguments, same seed, one torch thread: the thread count is part of the numeric path) and
returns the native return of every completed episode, in order.
It is the probe for determinism checks: two code paths that give the same list trained the
same agent. Nothing is written to MLflow and no evaluation is run.
"""

from __future__ import annotations

from vlmrl_cli.tracking import schema
from vlmrl_cli.training.callbacks import EpisodeTracker
from vlmrl_cli.training.config import TrainJob


def native_returns(job: TrainJob) -> list[float]:
    """Native (unshaped) returns of the episodes completed while training ``job``."""
    import torch

    from vlmrl_cli.training.envs import make_train_env
    from vlmrl_cli.training.model import make_model
    from vlmrl_cli.vlm.registry import build_client

    torch.set_num_threads(1)  # as every worker (sweep.worker.init_worker)
    task = job.task_plugin
    client = build_client(job.vlm, stream=job.seed, reader=task.reader) if job.arm.uses_vlm else None
    try:
        env, _ = make_train_env(job.arm, job.ppo, job.shaping, client, job.seed, task)
        model = make_model(job.ppo, env, job.seed)
        tracker = EpisodeTracker(job.name, job.timesteps, success=task.success)
        model.learn(total_timesteps=job.timesteps, callback=tracker)
        return [e[schema.METRIC_NATIVE_RETURN] for e in tracker.episodes]
    finally:
        if client is not None:
            client.close()

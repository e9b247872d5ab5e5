"""A training run reduced to its learning curve and weights' digest, in this process, no tracking:
the probe of determinism checks (two code paths that give the same trace trained the same agent)."""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from typing import Any

from vlmrl_cli.tracking import schema
from vlmrl_cli.training.callbacks import EpisodeTracker
from vlmrl_cli.training.config import TrainJob


@dataclass(frozen=True)
class TrainTrace:
    """What a training run leaves to compare: its learning curve and its weights' digest."""

    native_returns: list[float]
    weights_sha256: str


def weights_digest(state_dict: Any) -> str:
    """sha256 (hex) over a torch state dict's names, dtypes, shapes and raw bytes, in order.

    Example:
        >>> import torch
        >>> a = {"w": torch.tensor([1.0, 2.0])}
        >>> weights_digest(a) == weights_digest({"w": torch.tensor([1.0, 2.0])})
        True
        >>> weights_digest(a) == weights_digest({"w": torch.tensor([1.0, 2.0000002])})
        False
    """
    h = hashlib.sha256()
    for name, tensor in state_dict.items():
        t = tensor.detach().cpu().contiguous()
        h.update(f"{name}:{t.dtype}:{tuple(t.shape)};".encode())
        h.update(t.numpy().tobytes())
    return h.hexdigest()


def train_trace(job: TrainJob) -> TrainTrace:
    """Train ``job`` as a worker does (one torch thread: part of the numeric path)."""
    import torch

    from vlmrl_cli.training.session import session

    torch.set_num_threads(1)  # as every worker (sweep.worker.init_worker)
    with session(job) as built:
        tracker = EpisodeTracker(job.name, job.timesteps, success=job.task_plugin.success)
        built.model.learn(total_timesteps=job.timesteps, callback=tracker)
        return TrainTrace([e[schema.METRIC_NATIVE_RETURN] for e in tracker.episodes],
                          weights_digest(built.model.policy.state_dict()))


def native_returns(job: TrainJob) -> list[float]:
    """Native (unshaped) returns of the episodes completed while training ``job``."""
    return train_trace(job).native_returns

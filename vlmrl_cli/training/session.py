"""What training one job needs, built the one way every run builds it: VLM client, envs, learner."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from vlmrl_cli.shaping.semantic import SemanticOracle
from vlmrl_cli.training.config import TrainJob


@dataclass(frozen=True)
class Session:
    """One job's learner, its (vector) env and the oracle of its VLM (None without one)."""

    model: Any
    env: Any
    oracle: SemanticOracle | None


@contextmanager
def session(job: TrainJob, transcript: Path | None = None) -> Iterator[Session]:
    """``job``'s learner, env stack and oracle, closed when the block ends (a MuJoCo renderer that
    outlives its EGL display prints errors at the interpreter's exit)."""
    from vlmrl_cli.training.envs import make_train_env
    from vlmrl_cli.training.model import make_model
    from vlmrl_cli.vlm.registry import build_client

    task = job.task_plugin
    client = (build_client(job.vlm, transcript=transcript, stream=job.seed, reader=task.reader)
              if job.arm.uses_vlm else None)
    env = None
    try:
        env, oracle = make_train_env(job.arm, job.ppo, job.shaping, client, job.seed, task, job.vlm.max_queries)
        yield Session(make_model(job.ppo, env, job.seed), env, oracle)
    finally:
        if env is not None:
            env.close()
        if client is not None:
            client.close()

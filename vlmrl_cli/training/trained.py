"""A trained run read back from MLflow: its policy (model.zip + vecnormalize.pkl) and configs."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from vlmrl_cli.core.errors import BadInput
from vlmrl_cli.shaping.arms import ARMS, ArmSpec
from vlmrl_cli.shaping.config import ShapingConfig
from vlmrl_cli.tasks.base import Task, TaskLookup
from vlmrl_cli.tasks.registry import recorded_task
from vlmrl_cli.tracking import schema, store
from vlmrl_cli.training.evaluation import Policy
from vlmrl_cli.training.validation import validate_as
from vlmrl_cli.vlm.config import VLMConfig

MODEL = "model.zip"
NORMALIZER = "vecnormalize.pkl"
CONFIG = "config.json"


def deterministic_policy(model: Any, env: Any) -> Policy:
    """The trained policy on raw observations, applying the training obs normalisation
    (when ``env`` is a ``VecNormalize``)."""
    from gymnasium.spaces import Discrete
    from stable_baselines3.common.vec_env import VecNormalize

    discrete = isinstance(model.action_space, Discrete)

    def act(obs: np.ndarray) -> Any:
        x = np.asarray(obs, dtype=np.float32)[None, :]
        if isinstance(env, VecNormalize):
            x = np.asarray(env.normalize_obs(x), dtype=np.float32)
        action, _ = model.predict(x, deterministic=True)
        if discrete:
            return int(np.asarray(action).reshape(-1)[0])
        return np.asarray(action)[0]  # a continuous action: the env's action shape

    return act


@dataclass(frozen=True)
class TrainedRun:
    """What evaluating a finished training run needs; ``simulated`` is the run's own tag."""

    run_id: str
    name: str
    status: str
    arm: ArmSpec
    shaping: ShapingConfig
    vlm: VLMConfig
    vlm_label: str
    simulated: bool
    policy: Policy
    seed: int = 0  # the training seed (a placebo arm's label map depends on it)
    task: Task = field(kw_only=True)  # the run's task, resolved once from its config.json
    task_ref: str = field(default="", kw_only=True)  # how its config.json names it (a user task: module:NAME)


def load_trained_run(client: Any, run_id: str, workdir: Path, tasks: TaskLookup) -> TrainedRun:
    """Download run ``run_id``'s model, normaliser and config into ``workdir`` and load them; the
    task its config names is resolved once, by the command's ``tasks``.

    ``BadInput`` when the store has no such run or the run saved no model (it failed, was
    stopped, or is not a training run).
    """
    from mlflow.exceptions import MlflowException

    try:
        run = client.get_run(run_id)
    except MlflowException:
        raise BadInput(f"there is no run '{run_id}' in this tracking store; copy a run id from "
                       "`vlmrl run`'s output or the MLflow UI.") from None
    artifacts = {a.path for a in client.list_artifacts(run_id)}
    if MODEL not in artifacts or CONFIG not in artifacts:
        raise BadInput(f"run '{run_id}' ({run.info.status}) has no {MODEL} artifact; evaluate a FINISHED "
                       "training run.")
    store.download_artifacts(client, run_id, [n for n in (MODEL, CONFIG, NORMALIZER) if n in artifacts], workdir)
    config = json.loads((workdir / CONFIG).read_text(encoding="utf-8"))
    tags = run.data.tags
    task_ref = recorded_task(config.get("task"))
    task = tasks(task_ref)
    return TrainedRun(
        run_id=run_id,
        name=tags.get(schema.MLFLOW_RUN_NAME, run_id),
        status=run.info.status,
        arm=ARMS[config["arm"]["name"]],
        shaping=_shaping_config(config.get("shaping")),
        vlm=validate_as(VLMConfig, dict(config["vlm"])) if "vlm" in config else VLMConfig(),
        vlm_label=tags.get(schema.TAG_VLM, "unknown"),
        simulated=tags.get(schema.TAG_SIMULATED) == "true",
        policy=_load_policy(workdir, task),
        seed=int(config.get("seed", 0)),
        task=task,
        task_ref=task_ref,
    )


def _shaping_config(data: dict[str, Any] | None) -> ShapingConfig:
    """The run's shaping knobs (config.json keeps the label potentials as [label, value] pairs,
    as the schema reads them)."""
    if data is None:
        return ShapingConfig()
    result: ShapingConfig = validate_as(ShapingConfig, data)
    return result


def _load_policy(workdir: Path, task: Task) -> Policy:
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

    model = PPO.load(workdir / MODEL, device="cpu")
    normalizer: Any = None
    if (workdir / NORMALIZER).exists():
        normalizer = VecNormalize.load(str(workdir / NORMALIZER), DummyVecEnv([task.make_env]))
        normalizer.training = False
        normalizer.norm_reward = False
    return deterministic_policy(model, normalizer)

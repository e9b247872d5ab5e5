"""A trained run read back from MLflow: its policy and configs, without unpickling anything
(docs/commands/export-import.md); an old run's ``vecnormalize.pkl`` only with ``trust_pickle``."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from vlmrl_cli.core.errors import BadInput
from vlmrl_cli.shaping.arms import ArmSpec
from vlmrl_cli.shaping.config import ShapingConfig
from vlmrl_cli.tasks.base import Task, TaskLookup
from vlmrl_cli.tracking import schema, store
from vlmrl_cli.training.evaluation import Policy
from vlmrl_cli.training.presets import PPOConfig
from vlmrl_cli.training.verify import job_of
from vlmrl_cli.vlm.config import VLMConfig

MODEL = schema.ARTIFACT_MODEL
#: The policy's ``state_dict`` (``torch.save``): an entry of ``model.zip``, and an imported run's artifact.
POLICY_WEIGHTS = schema.ARTIFACT_POLICY
NORMALIZER = schema.ARTIFACT_NORMALIZER
#: What runs saved before ``NORMALIZER`` kept instead: a pickle, loaded only with ``trust_pickle``.
PICKLED_NORMALIZER = schema.ARTIFACT_PICKLED_NORMALIZER
CONFIG = schema.ARTIFACT_CONFIG
PICKLE_WARNING = ("a pickle, and loading a pickle runs whatever code it holds; pass --trust-pickle only if you "
                  "trust where the run came from")


def deterministic_policy(model: Any, env: Any) -> Policy:
    """The trained policy on raw observations (normalised when ``env`` is a ``VecNormalize``)."""
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


def load_trained_run(client: Any, run_id: str, workdir: Path, tasks: TaskLookup,
                     trust_pickle: bool = False) -> TrainedRun:
    """Download run ``run_id``'s model, normaliser and config into ``workdir`` and load them without
    unpickling; ``BadInput`` for no such run, no model, or files that do not fit its config."""
    from mlflow.exceptions import MlflowException

    try:
        run = client.get_run(run_id)
    except MlflowException:
        raise BadInput(f"there is no run '{run_id}' in this tracking store; copy a run id from "
                       "`vlmrl run`'s output or the MLflow UI.") from None
    artifacts = {a.path for a in client.list_artifacts(run_id)}
    if not {MODEL, POLICY_WEIGHTS} & artifacts or CONFIG not in artifacts:
        raise BadInput(f"run '{run_id}' ({run.info.status}) has no {MODEL} artifact; evaluate a FINISHED "
                       "training run (an imported one: export it with --models).")
    if NORMALIZER not in artifacts and PICKLED_NORMALIZER in artifacts and not trust_pickle:
        raise BadInput(f"run '{run_id}' keeps its observation statistics as {PICKLED_NORMALIZER}, {PICKLE_WARNING}.")
    wanted = [n for n in (MODEL, POLICY_WEIGHTS, CONFIG, NORMALIZER, PICKLED_NORMALIZER) if n in artifacts]
    store.download_artifacts(client, run_id, wanted, workdir)
    try:
        config = json.loads((workdir / CONFIG).read_text(encoding="utf-8"))
    except (ValueError, OSError) as exc:
        raise BadInput(f"run '{run_id}': its {CONFIG} cannot be read here ({exc}).") from None
    tags = run.data.tags
    job = job_of(config if isinstance(config, dict) else {}, tags, tasks, f"run '{run_id}'")
    return TrainedRun(
        run_id=run_id,
        name=tags.get(schema.MLFLOW_RUN_NAME, run_id),
        status=run.info.status,
        arm=job.arm,
        shaping=job.shaping,
        vlm=job.vlm,
        vlm_label=tags.get(schema.TAG_VLM, "unknown"),
        simulated=tags.get(schema.TAG_SIMULATED) == "true",
        policy=_load_policy(workdir, job.task_plugin, job.ppo, run_id),
        seed=job.seed,
        task=job.task_plugin,
        task_ref=job.task,
    )


def _load_policy(workdir: Path, task: Task, ppo: PPOConfig, run_id: str) -> Policy:
    """The run's deterministic policy: an ``ActorCriticPolicy`` built from its PPO config holding the
    weights of ``policy.pth`` (the artifact, else ``model.zip``'s), read with ``weights_only``."""
    import io
    import pickle
    import zipfile

    import torch
    from stable_baselines3.common.policies import ActorCriticPolicy

    env = task.make_env()
    try:
        if (workdir / POLICY_WEIGHTS).exists():
            blob = (workdir / POLICY_WEIGHTS).read_bytes()
        else:
            with zipfile.ZipFile(workdir / MODEL) as archive:
                blob = archive.read(POLICY_WEIGHTS)
        state = torch.load(io.BytesIO(blob), map_location="cpu", weights_only=True)
        kwargs: dict[str, Any] = dict(ppo.policy_kwargs)
        policy = ActorCriticPolicy(env.observation_space, env.action_space, lambda _: 0.0, use_sde=ppo.use_sde,
                                   **kwargs)
        policy.load_state_dict(state)
        normalizer = load_normalizer(workdir, task)
    except (zipfile.BadZipFile, KeyError, RuntimeError, pickle.UnpicklingError, ValueError, TypeError, OSError,
            EOFError) as exc:
        raise BadInput(f"run '{run_id}': its model files do not hold a policy for task {task.name} and its PPO "
                       f"config ({type(exc).__name__}: {str(exc).splitlines()[0][:160] if str(exc) else ''}).") \
            from None
    finally:
        env.close()
    policy.set_training_mode(False)
    return deterministic_policy(policy, normalizer)


def save_normalizer(env: Any, path: Path) -> None:
    """Write the observation statistics of the ``VecNormalize`` ``env`` to ``path`` as plain arrays."""
    rms = env.obs_rms
    np.savez(path, obs_mean=np.asarray(rms.mean, dtype=np.float64), obs_var=np.asarray(rms.var, dtype=np.float64),
             obs_count=np.float64(rms.count), clip_obs=np.float64(env.clip_obs), epsilon=np.float64(env.epsilon),
             norm_obs=np.bool_(env.norm_obs))


def load_normalizer(workdir: Path, task: Task) -> Any:
    """The run's frozen ``VecNormalize`` (None without one), from ``vecnormalize.npz``, else from an
    older run's pickle (downloaded only when trusted)."""
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

    arrays, pickled = workdir / NORMALIZER, workdir / PICKLED_NORMALIZER
    if not arrays.exists():
        if not pickled.exists():
            return None
        try:  # the user trusted this pickle (load_trained_run's trust_pickle): whatever it is, it ran
            normalizer = VecNormalize.load(str(pickled), DummyVecEnv([task.make_env]))
        except Exception as exc:
            raise ValueError(f"{PICKLED_NORMALIZER} holds no VecNormalize ({type(exc).__name__})") from None
    else:
        with np.load(arrays, allow_pickle=False) as saved:
            stats = {key: saved[key] for key in saved.files}
        normalizer = VecNormalize(DummyVecEnv([task.make_env]), training=False, norm_obs=bool(stats["norm_obs"]),
                                  norm_reward=False, clip_obs=float(stats["clip_obs"]), epsilon=float(stats["epsilon"]))
        rms: Any = normalizer.obs_rms
        if stats["obs_mean"].shape != rms.mean.shape or stats["obs_var"].shape != rms.mean.shape:
            raise ValueError(f"{NORMALIZER} holds statistics of shape {stats['obs_mean'].shape}, the task's "
                             f"observations are {rms.mean.shape}")
        rms.mean, rms.var, rms.count = stats["obs_mean"], stats["obs_var"], float(stats["obs_count"])
    normalizer.training = False
    normalizer.norm_reward = False
    return normalizer

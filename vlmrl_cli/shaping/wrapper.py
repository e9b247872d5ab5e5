"""An arm as an ordered stack of reward wrappers (paper Eq. 2), each checking its own arguments,
stepped whole or in labelling rounds (``LabelRoundVecEnv``). See docs/method.md."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from copy import deepcopy
from typing import Any, SupportsFloat

import gymnasium as gym
import numpy as np
from stable_baselines3.common.vec_env import DummyVecEnv
from stable_baselines3.common.vec_env.base_vec_env import VecEnvObs, VecEnvStepReturn

from vlmrl_cli.shaping.arms import ArmSpec
from vlmrl_cli.shaping.camera import FrameView
from vlmrl_cli.shaping.config import ShapingConfig
from vlmrl_cli.shaping.pbrs import pbrs_term
from vlmrl_cli.shaping.scene import DenseTerm, Scene, SceneCamera, SuccessRule, ended_by_env
from vlmrl_cli.shaping.semantic import EpisodePotential, SemanticOracle

StepResult = tuple[Any, SupportsFloat, bool, bool, dict[str, Any]]
ResetResult = tuple[Any, dict[str, Any]]


def _gamma(gamma: float) -> float:
    if not (math.isfinite(gamma) and 0.0 < gamma <= 1.0):
        raise ValueError(f"gamma must be in (0, 1], got {gamma}; pass the learner's discount.")
    return float(gamma)


class RewardStage(gym.Wrapper[Any, Any, Any, Any], gym.utils.RecordConstructorArgs):
    """A wrapper that changes what a step and a reset return, whether run whole or in the two halves
    of a labelling round (``begin_step``, ``finish_step``): the same rewards, bit for bit."""

    def __init__(self, env: gym.Env, **recorded: Any) -> None:
        gym.utils.RecordConstructorArgs.__init__(self, **recorded)
        gym.Wrapper.__init__(self, env)
        # a begun step and a begun reset (an episode that ended in the step) wait side by side
        self._begun_step: StepResult | None = None
        self._begun_reset: ResetResult | None = None

    def _after_step(self, obs: Any, reward: SupportsFloat, terminated: bool, truncated: bool,
                    info: dict[str, Any]) -> StepResult:
        return obs, reward, terminated, truncated, info

    def _stepped(self, obs: Any, reward: SupportsFloat, terminated: bool, truncated: bool,
                 info: dict[str, Any]) -> StepResult:
        """``_after_step``, the reward below the first reward wrapper kept as ``native_reward``."""
        native = info.get("native_reward", float(reward))
        return self._after_step(obs, reward, terminated, truncated, info | {"native_reward": native})

    def _after_reset(self, obs: Any, info: dict[str, Any]) -> ResetResult:
        return obs, info

    def step(self, action: Any) -> StepResult:
        return self._stepped(*self.env.step(action))

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> ResetResult:
        return self._after_reset(*self.env.reset(seed=seed, options=options))

    def begin_step(self, action: Any) -> tuple[bool, bool]:
        """The first half of ``step``: the env below moves; (terminated, truncated)."""
        if isinstance(self.env, RewardStage):
            return self.env.begin_step(action)
        result = self.env.step(action)
        self._begun_step = result
        return bool(result[2]), bool(result[3])

    def finish_step(self) -> StepResult:
        """The second half of ``step``: what ``step`` would have returned."""
        if isinstance(self.env, RewardStage):
            return self._stepped(*self.env.finish_step())
        result, self._begun_step = self._begun_step, None
        assert result is not None, "finish_step without begin_step"
        return self._stepped(*result)

    def begin_reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> None:
        """The first half of ``reset``."""
        if isinstance(self.env, RewardStage):
            self.env.begin_reset(seed=seed, options=options)
        else:
            self._begun_reset = self.env.reset(seed=seed, options=options)

    def finish_reset(self) -> ResetResult:
        """The second half of ``reset``: what ``reset`` would have returned."""
        if isinstance(self.env, RewardStage):
            return self._after_reset(*self.env.finish_reset())
        result, self._begun_reset = self._begun_reset, None
        assert result is not None, "finish_reset without begin_reset"
        return self._after_reset(*result)


class KinematicReward(RewardStage):
    """Adds Eq. 1's dense term ``R_kin = dense(obs, scale, offset)`` of the new observation.

    Example:
        >>> from gymnasium.envs.classic_control.cartpole import CartPoleEnv
        >>> upright = lambda obs, scale, offset: scale * (offset - abs(float(obs[2])))
        >>> env = KinematicReward(gym.make("CartPole-v1"), upright, scale=2.0, offset=0.4)
        >>> obs, _ = env.reset(seed=0)
        >>> obs, reward, terminated, truncated, info = env.step(1)
        >>> info["native_reward"], reward == 1.0 + 2.0 * (0.4 - abs(float(obs[2])))
        (1.0, True)
    """

    def __init__(self, env: gym.Env, dense: DenseTerm, scale: float, offset: float) -> None:
        super().__init__(env, dense=dense, scale=scale, offset=offset)
        if not (math.isfinite(scale) and math.isfinite(offset)):
            raise ValueError(f"the dense term's scale and offset must be finite, got {scale} and {offset}.")
        self._dense, self._scale, self._offset = dense, float(scale), float(offset)

    def _after_step(self, obs: Any, reward: SupportsFloat, terminated: bool, truncated: bool,
                    info: dict[str, Any]) -> StepResult:
        return obs, float(reward) + self._dense(obs, self._scale, self._offset), terminated, truncated, info


class KinematicPotential(RewardStage):
    """Pays the dense term as a potential: ``gamma Phi_kin(s') - Phi_kin(s)`` with
    ``Phi_kin = horizon x R_kin`` (what Eq. 1 would pay for staying in ``s`` a whole episode, so
    both forms have the same largest episode total; 0 at a terminal state, as ``pbrs_term`` does).

    Example:
        >>> from gymnasium.envs.classic_control.cartpole import CartPoleEnv
        >>> upright = lambda obs, scale, offset: scale * (offset - abs(float(obs[2])))
        >>> env = KinematicPotential(gym.make("CartPole-v1"), upright, 2.0, 0.4, horizon=500, gamma=1.0)
        >>> obs0, _ = env.reset(seed=0)
        >>> obs1, reward, *_ = env.step(1)
        >>> round(reward - 1.0, 9) == round(500 * (upright(obs1, 2.0, 0.4) - upright(obs0, 2.0, 0.4)), 9)
        True
    """

    def __init__(self, env: gym.Env, dense: DenseTerm, scale: float, offset: float, horizon: int | None,
                 gamma: float) -> None:
        super().__init__(env, dense=dense, scale=scale, offset=offset, horizon=horizon, gamma=gamma)
        if not isinstance(horizon, int) or horizon < 1:
            raise ValueError(f"the dense term paid as a potential needs the task's time limit as horizon (got "
                             f"{horizon}).")
        self._dense, self._scale, self._offset = dense, float(scale), float(offset)
        self._horizon, self._gamma = float(horizon), _gamma(gamma)
        self._phi = 0.0

    def _potential(self, obs: Any) -> float:
        return self._horizon * self._dense(obs, self._scale, self._offset)

    def _after_reset(self, obs: Any, info: dict[str, Any]) -> ResetResult:
        self._phi = self._potential(obs)
        return obs, info

    def _after_step(self, obs: Any, reward: SupportsFloat, terminated: bool, truncated: bool,
                    info: dict[str, Any]) -> StepResult:
        phi = self._potential(obs)
        reward = float(reward) + pbrs_term(self._phi, phi, self._gamma, 1.0, terminated)
        self._phi = phi
        return obs, reward, terminated, truncated, info


class SemanticPotential(RewardStage):
    """Adds ``alpha (gamma Phi(s') - Phi(s))``, ``Phi`` the arm's ``EpisodePotential`` of what the
    ``camera`` shows (never the observation), from the run's shared ``oracle``.

    Example:
        >>> from vlmrl_cli.shaping.arms import ARMS
        >>> from vlmrl_cli.shaping.semantic import SemanticOracle
        >>> from vlmrl_cli.tasks.registry import get_task
        >>> from vlmrl_cli.vlm.config import VLMConfig
        >>> from vlmrl_cli.vlm.registry import build_client
        >>> task, arm = get_task("mountain-car"), ARMS["semantic"]
        >>> cfg = task.shaping_for(ShapingConfig())
        >>> client = build_client(VLMConfig(backend="sim", use_cache=False), reader=task.reader)
        >>> oracle = SemanticOracle(client, cfg, arm.potential, task.milestones, task.camera.feature_dim)
        >>> env = SemanticPotential(gym.make("MountainCar-v0"), arm, 2.0, 0.99, task.camera.make(cfg), oracle,
        ...                         task.scene.sim_type)
        >>> _ = env.reset(seed=0)
        >>> phi0 = env.potential
        >>> _, reward, *_ = env.step(2)
        >>> reward == -1.0 + 2.0 * (0.99 * env.potential - phi0)
        True
    """

    def __init__(self, env: gym.Env, arm: ArmSpec, alpha: float, gamma: float, camera: SceneCamera,
                 oracle: SemanticOracle, sim_type: type) -> None:
        super().__init__(env, arm=arm, alpha=alpha, gamma=gamma, camera=camera, oracle=oracle, sim_type=sim_type)
        if not arm.uses_vlm:
            raise ValueError(f"arm '{arm.name}' shapes with no VLM; it needs no SemanticPotential.")
        if not (math.isfinite(alpha) and alpha >= 0):
            raise ValueError(f"ShapingConfig.alpha must be a finite value >= 0, got {alpha}.")
        if oracle.source is not arm.potential or oracle.rbf != arm.rbf:
            raise ValueError(f"the oracle ({oracle.source}, rbf={oracle.rbf}) does not match arm '{arm.name}' "
                             f"({arm.potential}, rbf={arm.rbf}); build it with the arm's potential and rbf.")
        if not isinstance(env.unwrapped, sim_type):
            raise ValueError(f"the camera images {sim_type.__name__}; wrap an env of that simulator.")
        self.camera, self._alpha, self._gamma = camera, float(alpha), _gamma(gamma)
        self.episode = EpisodePotential(oracle, arm.lock)
        self._sim = env.unwrapped  # looked up once: this runs every step
        self._phi = 0.0
        # the frames a labelling round took in the halves' first part (None: take it now)
        self._step_view: FrameView | None = None
        self._reset_view: FrameView | None = None

    @property
    def potential(self) -> float:
        """Phi of the current state."""
        return self._phi

    def _after_reset(self, obs: Any, info: dict[str, Any]) -> ResetResult:
        view, self._reset_view = self._reset_view, None
        self._phi = self.episode.reset(view if view is not None else self.camera.look(self._sim))
        return obs, info

    def _after_step(self, obs: Any, reward: SupportsFloat, terminated: bool, truncated: bool,
                    info: dict[str, Any]) -> StepResult:
        view, self._step_view = self._step_view, None
        phi_next = self.episode.step(view if view is not None else self.camera.look(self._sim))
        reward = float(reward) + pbrs_term(self._phi, phi_next, self._gamma, self._alpha, terminated)
        self._phi = phi_next
        return obs, reward, terminated, truncated, info

    def begin_step(self, action: Any) -> tuple[bool, bool]:
        done = super().begin_step(action)
        self._step_view = self.camera.look(self._sim)
        self.episode.request_step(self._step_view)
        return done

    def begin_reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> None:
        super().begin_reset(seed=seed, options=options)
        self._reset_view = self.camera.look(self._sim)
        self.episode.oracle.request(self._reset_view)  # a reset always labels

    def close(self) -> None:
        self.camera.close()  # idempotent; a camera shared by other envs reopens on demand
        super().close()


class EpisodeStatistics(RewardStage):
    """Adds no reward: puts ``shaped_return`` and ``is_success`` (the task's ``success`` rule) in an
    episode's last ``info``, and ``native_reward`` in every step's. The outermost wrapper of every arm.

    Example:
        >>> env = EpisodeStatistics(gym.make("CartPole-v1"), success=lambda terminated, length: length >= 500)
        >>> _ = env.reset(seed=0)
        >>> steps, done = 0, False
        >>> while not done:
        ...     _, _, terminated, truncated, info = env.step(0)
        ...     steps, done = steps + 1, terminated or truncated
        >>> info["shaped_return"] == steps, info["native_reward"], info["is_success"]
        (True, 1.0, False)
    """

    def __init__(self, env: gym.Env, success: SuccessRule | None = None) -> None:
        super().__init__(env, success=success)
        self.success = success if success is not None else ended_by_env
        self._return = 0.0
        self._length = 0

    def _after_reset(self, obs: Any, info: dict[str, Any]) -> ResetResult:
        self._return, self._length = 0.0, 0
        return obs, info

    def _after_step(self, obs: Any, reward: SupportsFloat, terminated: bool, truncated: bool,
                    info: dict[str, Any]) -> StepResult:
        self._return += float(reward)
        self._length += 1
        if terminated or truncated:
            info["shaped_return"] = self._return
            info["is_success"] = bool(self.success(bool(terminated), self._length))
        return obs, reward, terminated, truncated, info


def wrap_arm(env: gym.Env, arm: ArmSpec, shaping: ShapingConfig, gamma: float, scene: Scene,
             camera: SceneCamera | None = None, oracle: SemanticOracle | None = None, horizon: int | None = None,
             success: SuccessRule | None = None) -> EpisodeStatistics:
    """``env`` (observations of ``scene.obs_shape``) under ``arm``'s wrappers, innermost first: its
    dense term (a reward, or a potential that needs the task's time limit ``horizon``), its semantic
    potential, then ``EpisodeStatistics``, which is returned.

    Example:
        >>> from vlmrl_cli.shaping.arms import ARMS
        >>> from vlmrl_cli.tasks.registry import get_task
        >>> env = wrap_arm(gym.make("MountainCar-v0"), ARMS["kinematic"], ShapingConfig(), 0.99,
        ...                get_task("mountain-car").scene, horizon=200)
        >>> type(env).__name__, type(env.env).__name__
        ('EpisodeStatistics', 'KinematicReward')
    """
    shape = getattr(env.observation_space, "shape", None)
    if shape != scene.obs_shape:
        raise ValueError(f"the arm's wrappers read {scene.name}, observation shape {scene.obs_shape}; "
                         f"got shape {shape}.")
    gamma = _gamma(gamma)
    if arm.dense_potential:
        env = KinematicPotential(env, scene.dense, shaping.kin_scale, shaping.kin_offset, horizon, gamma)
    elif arm.kinematic:
        env = KinematicReward(env, scene.dense, shaping.kin_scale, shaping.kin_offset)
    if arm.uses_vlm:
        if camera is None or oracle is None:
            raise ValueError(f"arm '{arm.name}' shapes with the VLM; pass the run's camera and oracle.")
        env = SemanticPotential(env, arm, shaping.alpha, gamma, camera, oracle, scene.sim_type)
    return EpisodeStatistics(env, success)


class LabelRoundVecEnv(DummyVecEnv):
    """SB3's ``DummyVecEnv`` with one labelling round per vector step: every env's step is begun, the
    VLM asked about all their frames in one call, then each step finished, exactly as it would be."""

    def __init__(self, env_fns: Sequence[Callable[[], gym.Env]], oracle: SemanticOracle) -> None:
        super().__init__(list(env_fns))
        if not all(isinstance(env, RewardStage) for env in self.envs):
            raise ValueError("a labelling round steps RewardStage stacks (wrap_arm); got another env")
        self.oracle = oracle

    def reset(self) -> VecEnvObs:
        for i in range(self.num_envs):
            maybe_options = {"options": self._options[i]} if self._options[i] else {}
            self._stage(i).begin_reset(seed=self._seeds[i], **maybe_options)
        self.oracle.fetch()
        for i in range(self.num_envs):
            obs, self.reset_infos[i] = self._stage(i).finish_reset()
            self._save_obs(i, obs)
        self._reset_seeds()
        self._reset_options()
        return self._obs_from_buf()

    def step_wait(self) -> VecEnvStepReturn:
        done = [False] * self.num_envs
        for i in range(self.num_envs):
            terminated, truncated = self._stage(i).begin_step(self.actions[i])
            done[i] = terminated or truncated
            if done[i]:
                self._stage(i).begin_reset()
        self.oracle.fetch()
        for i in range(self.num_envs):
            stage = self._stage(i)
            obs, self.buf_rews[i], terminated, truncated, self.buf_infos[i] = stage.finish_step()  # type: ignore[assignment]
            self.buf_dones[i] = terminated or truncated
            self.buf_infos[i]["TimeLimit.truncated"] = truncated and not terminated
            if self.buf_dones[i]:
                self.buf_infos[i]["terminal_observation"] = obs
                obs, self.reset_infos[i] = stage.finish_reset()
            self._save_obs(i, obs)
        return self._obs_from_buf(), np.copy(self.buf_rews), np.copy(self.buf_dones), deepcopy(self.buf_infos)

    def _stage(self, i: int) -> RewardStage:
        env = self.envs[i]
        assert isinstance(env, RewardStage)
        return env

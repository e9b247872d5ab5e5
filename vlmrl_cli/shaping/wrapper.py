"""The hybrid reward of paper Eq. 2 as a gymnasium wrapper."""

from __future__ import annotations

import math
from typing import Any, SupportsFloat

import gymnasium as gym
import numpy as np

from vlmrl_cli.shaping.arms import ArmSpec
from vlmrl_cli.shaping.camera import FrameView
from vlmrl_cli.shaping.config import ShapingConfig
from vlmrl_cli.shaping.pbrs import pbrs_term
from vlmrl_cli.shaping.scene import Scene, SceneCamera, SuccessRule, ended_by_env
from vlmrl_cli.shaping.semantic import EpisodePotential, SemanticOracle


class HybridReward(gym.Wrapper[np.ndarray, Any, np.ndarray, Any], gym.utils.RecordConstructorArgs):
    """``R_total = R_env [+ R_kin(x)] [+ alpha (gamma Phi(s') - Phi(s))]``, terms chosen by ``arm``.

    Observations pass through unchanged: the policy sees the task's native observation.
    ``R_kin`` is the ``scene``'s dense term on the observation
    (proprioception); the potential reads the simulator only through ``camera``
    (exteroception), whose ``FrameView`` is all the
    ``oracle`` ever gets. Every step puts the env's own reward in ``info["native_reward"]``;
    the last step of an episode adds ``info["shaped_return"]`` (the sum of ``R_total``) and
    ``info["is_success"]`` (``success(terminated, length)``, the episode's length counted here).
    An arm without shaping (``baseline``) passes rewards through and still adds these keys.

    Args:
        env: an env of ``scene``'s task.
        arm: which terms to add.
        shaping: alpha, the kinematic coefficients and the label schedule.
        gamma: PBRS discount in (0, 1], normally the learner's.
        scene: what the task's observation, dense term and simulator are (``Task.scene``).
        camera, oracle: required when ``arm.uses_vlm``; shared by the envs of one run.
        horizon: the task's time limit, required when ``arm.dense_potential``: the dense term is
            then paid as ``gamma Phi_kin(s') - Phi_kin(s)`` with ``Phi_kin = horizon x R_kin``
            (what Eq. 1 would pay for staying in ``s`` a whole episode, so both forms have the
            same largest episode total; 0 at a terminal state, as ``pbrs_term`` does).
        success: the task's success rule (``Task.success``); None: the env itself ended the
            episode (``scene.ended_by_env``), at any length.

    Example:
        >>> import gymnasium as gym
        >>> from gymnasium.envs.classic_control.cartpole import CartPoleEnv
        >>> from vlmrl_cli.shaping.arms import ARMS
        >>> upright = Scene("cartpole", (4,), lambda obs, scale, offset: scale * (offset - abs(float(obs[2]))),
        ...                 CartPoleEnv)
        >>> env = HybridReward(gym.make("CartPole-v1"), ARMS["kinematic"], ShapingConfig(), 0.99, upright)
        >>> obs, _ = env.reset(seed=0)
        >>> obs, reward, terminated, truncated, info = env.step(1)
        >>> info["native_reward"], reward == 1.0 + 2.0 * (0.4 - abs(float(obs[2])))
        (1.0, True)
        >>> env.close()
    """

    def __init__(
        self,
        env: gym.Env[np.ndarray, Any],
        arm: ArmSpec,
        shaping: ShapingConfig,
        gamma: float,
        scene: Scene,
        camera: SceneCamera | None = None,
        oracle: SemanticOracle | None = None,
        horizon: int | None = None,
        success: SuccessRule | None = None,
    ) -> None:
        gym.utils.RecordConstructorArgs.__init__(
            self, arm=arm, shaping=shaping, gamma=gamma, camera=camera, oracle=oracle, scene=scene, horizon=horizon,
            success=success,
        )
        gym.Wrapper.__init__(self, env)
        shape = getattr(env.observation_space, "shape", None)
        if shape != scene.obs_shape:
            raise ValueError(f"HybridReward wraps {scene.name}, observation shape {scene.obs_shape}; "
                             f"got shape {shape}.")
        if not (math.isfinite(gamma) and 0.0 < gamma <= 1.0):
            raise ValueError(f"gamma must be in (0, 1], got {gamma}; pass the learner's discount.")
        if not (math.isfinite(shaping.alpha) and shaping.alpha >= 0):
            raise ValueError(f"ShapingConfig.alpha must be a finite value >= 0, got {shaping.alpha}.")
        if arm.dense_potential and not (isinstance(horizon, int) and horizon >= 1):
            raise ValueError(f"arm '{arm.name}' pays the dense term as a potential; pass the task's time limit "
                             f"as horizon (got {horizon}).")
        if arm.uses_vlm:
            if camera is None or oracle is None:
                raise ValueError(f"arm '{arm.name}' shapes with the VLM; pass the run's camera and oracle.")
            if oracle.source is not arm.potential or oracle.rbf != arm.rbf:
                raise ValueError(
                    f"the oracle ({oracle.source}, rbf={oracle.rbf}) does not match arm '{arm.name}' "
                    f"({arm.potential}, rbf={arm.rbf}); build it with the arm's potential and rbf."
                )
            if not isinstance(env.unwrapped, scene.sim_type):
                raise ValueError(f"the camera images {scene.name}'s simulator ({scene.sim_type.__name__}); "
                                 f"wrap an env of that task.")
        self.arm = arm
        self.shaping = shaping
        self.gamma = float(gamma)
        self.camera = camera
        self.scene = scene
        self._dense = scene.dense
        self._sim = env.unwrapped  # looked up once: this runs every step
        self._episode = EpisodePotential(oracle, arm.lock) if arm.uses_vlm and oracle is not None else None
        self._phi = 0.0
        self._horizon = float(horizon or 0)
        self._phi_kin = 0.0
        self._return = 0.0
        self.success = success if success is not None else ended_by_env
        self._length = 0

    @property
    def potential(self) -> float:
        """Phi of the current state (0.0 for arms without a potential)."""
        return self._phi

    @property
    def lock_level(self) -> float:
        """The hysteresis lock's level in this episode (0.0 without a lock)."""
        return self._episode.lock_state.level if self._episode is not None else 0.0

    def _view(self) -> FrameView:
        assert self.camera is not None
        # The camera images the simulator (as env.render() would), not the agent's observation.
        return self.camera.look(self._sim)

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        obs, info = self.env.reset(seed=seed, options=options)
        self._return = 0.0
        self._length = 0
        if self.arm.dense_potential:
            self._phi_kin = self._horizon * self._dense(obs, self.shaping.kin_scale, self.shaping.kin_offset)
        self._phi = self._episode.reset(self._view()) if self._episode is not None else 0.0
        return obs, info

    def step(self, action: Any) -> tuple[np.ndarray, SupportsFloat, bool, bool, dict[str, Any]]:
        obs, native, terminated, truncated, info = self.env.step(action)
        reward = float(native)
        if self.arm.dense_potential:
            phi_kin = self._horizon * self._dense(obs, self.shaping.kin_scale, self.shaping.kin_offset)
            reward += pbrs_term(self._phi_kin, phi_kin, self.gamma, 1.0, terminated)
            self._phi_kin = phi_kin
        elif self.arm.kinematic:
            reward += self._dense(obs, self.shaping.kin_scale, self.shaping.kin_offset)
        if self._episode is not None:
            assert self.camera is not None  # with the episode: checked in __init__
            # the camera images the simulator (as env.render() would), not the observation
            phi_next = self._episode.step(self.camera.look(self._sim))
            reward += pbrs_term(self._phi, phi_next, self.gamma, self.shaping.alpha, terminated)
            self._phi = phi_next
        self._return += reward
        self._length += 1
        info = dict(info)
        info["native_reward"] = float(native)
        if terminated or truncated:
            info["shaped_return"] = self._return
            info["is_success"] = bool(self.success(bool(terminated), self._length))
        return obs, reward, terminated, truncated, info

    def close(self) -> None:
        if self.camera is not None:
            self.camera.close()  # idempotent; a camera shared by other envs reopens on demand
        super().close()

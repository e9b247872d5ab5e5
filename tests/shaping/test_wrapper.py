from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from stable_baselines3.common.monitor import Monitor

from tests.shaping import ScriptedBackend, mc_oracle, sim_client
from tests.tasks.mountain_car.test_kinematic import kinematic_reward
from vlmrl_cli.shaping.arms import ARMS, ArmSpec
from vlmrl_cli.shaping.camera import FrameView
from vlmrl_cli.shaping.config import ShapingConfig
from vlmrl_cli.shaping.semantic import EpisodePotential
from vlmrl_cli.shaping.wrapper import HybridReward
from vlmrl_cli.tasks.mountain_car.camera import Camera
from vlmrl_cli.tasks.mountain_car.render import FrameRenderer
from vlmrl_cli.tasks.mountain_car.task import MOUNTAIN_CAR_SCENE as MC_SCENE
from vlmrl_cli.vlm.client import VLMClient

GAMMA = 0.99


def wrap(arm: ArmSpec, cfg: ShapingConfig | None = None, client: VLMClient | None = None,
         camera: Camera | None = None) -> HybridReward:
    cfg = cfg or ShapingConfig()
    oracle = None
    if arm.uses_vlm:
        camera = camera or Camera(cfg.render_quantum)
        oracle = mc_oracle(client or sim_client(), cfg, arm.potential, rbf=arm.rbf)
    return HybridReward(Monitor(gym.make("MountainCar-v0")), arm, cfg, GAMMA, MC_SCENE, camera=camera, oracle=oracle,
                        horizon=200)


def momentum_policy(obs: np.ndarray) -> int:
    """Push in the direction of motion: reaches the goal in about 100-120 steps."""
    return 2 if obs[1] >= 0 else 0


def rollout(env: gym.Env, seed: int, actions: list[int]) -> list[tuple]:
    obs, _ = env.reset(seed=seed)
    out = []
    for a in actions:
        obs, r, term, trunc, info = env.step(a)
        out.append((obs.copy(), r, term, trunc, info))
        if term or trunc:
            break
    return out


@pytest.mark.parametrize("name", list(ARMS))
def test_check_env_passes_for_every_arm(name: str) -> None:
    arm, cfg = ARMS[name], ShapingConfig()
    camera = Camera(cfg.render_quantum) if arm.uses_vlm else None
    oracle = mc_oracle(sim_client(), cfg, arm.potential, rbf=arm.rbf) if arm.uses_vlm else None
    env = HybridReward(gym.make("MountainCar-v0"), arm, cfg, GAMMA, MC_SCENE, camera=camera, oracle=oracle,
                       horizon=200)
    check_env(env)
    env.close()


@pytest.mark.parametrize("name", list(ARMS))
def test_check_env_passes_on_the_training_stack(name: str) -> None:
    """With Monitor underneath; SB3's Monitor cannot be re-made from the spec (render and close checks need that)."""
    env = wrap(ARMS[name])
    check_env(env, skip_render_check=True, skip_close_check=True)
    env.close()


@pytest.mark.parametrize("name", list(ARMS))
def test_observations_are_native_and_native_reward_is_in_info(name: str) -> None:
    actions = list(np.random.default_rng(0).integers(0, 3, size=60))
    bare = rollout(gym.make("MountainCar-v0"), 3, actions)
    shaped = rollout(wrap(ARMS[name]), 3, actions)
    for (o0, r0, *_), (o1, _, _, _, info) in zip(bare, shaped, strict=True):
        np.testing.assert_array_equal(o0, o1)
        assert info["native_reward"] == r0


@pytest.mark.parametrize("name", list(ARMS))
def test_episode_end_infos_monitor_is_native_and_success_means_terminated(name: str) -> None:
    env = wrap(ARMS[name])
    for policy, success in ((momentum_policy, True), (lambda obs: 1, False)):  # goal vs time limit
        obs, _ = env.reset(seed=1)
        native, shaped, done = 0.0, 0.0, False
        while not done:
            obs, r, term, trunc, info = env.step(policy(obs))
            native += info["native_reward"]
            shaped += float(r)
            done = term or trunc
        assert info["is_success"] is success and term is success
        assert info["shaped_return"] == pytest.approx(shaped)
        assert info["episode"]["r"] == pytest.approx(native)  # SB3's Monitor sees the NATIVE return
        assert info["episode"]["l"] == -native
        if name == "baseline":
            assert shaped == native
    env.close()


@pytest.mark.parametrize("name", ["baseline", "hybrid"])
def test_is_success_is_the_given_rule_on_the_episode_length_the_wrapper_counts(name: str) -> None:
    calls: list[tuple[bool, int]] = []

    def rule(terminated: bool, length: int) -> bool:
        calls.append((terminated, length))
        return length % 2 == 0  # any rule at all: the wrapper asks it, and nothing else

    arm, cfg = ARMS[name], ShapingConfig()
    camera = Camera(cfg.render_quantum) if arm.uses_vlm else None
    oracle = mc_oracle(sim_client(), cfg, arm.potential, rbf=arm.rbf) if arm.uses_vlm else None
    env = HybridReward(Monitor(gym.make("MountainCar-v0")), arm, cfg, GAMMA, MC_SCENE, camera=camera, oracle=oracle,
                       horizon=200, success=rule)
    for policy in (momentum_policy, lambda obs: 1, momentum_policy):  # goal, time limit, goal after a reset
        obs, _ = env.reset(seed=1)
        done = False
        while not done:
            obs, _, term, trunc, info = env.step(policy(obs))
            done = term or trunc
        assert calls[-1] == (term, info["episode"]["l"])  # Monitor's length: the episode's, counted from reset
        assert info["is_success"] is (info["episode"]["l"] % 2 == 0)
    assert [t for t, _ in calls] == [True, False, True] and calls[1][1] == 200
    env.close()


def test_the_hybrid_reward_is_eq2() -> None:
    cfg = ShapingConfig()
    env = wrap(ARMS["hybrid"], cfg)
    obs, _ = env.reset(seed=5)
    for _ in range(80):
        phi = env.potential
        obs, r, term, _, _ = env.step(momentum_policy(obs))
        expected = -1.0 + kinematic_reward(float(obs[0])) + cfg.alpha * (GAMMA * (0.0 if term else env.potential) - phi)
        assert r == pytest.approx(expected)


class SpyCamera(Camera):
    """Records every position the camera was asked to image and every view it gave out."""

    def __init__(self, quantum: float) -> None:
        super().__init__(quantum)
        self.calls: list[tuple[float, str]] = []

    def look(self, sim: Any) -> FrameView:
        v = super().look(sim)
        self.calls.append((float(sim.state[0]), v.key))
        return v


def test_the_visual_pipeline_sees_only_frame_views() -> None:
    """Replaying the camera's frames through a fresh oracle, with FrameViews built from gymnasium's
    frames and no state at all, reproduces the wrapper's potentials exactly."""
    cfg = ShapingConfig()
    camera = SpyCamera(cfg.render_quantum)
    env = wrap(ARMS["hybrid"], cfg, client=sim_client(), camera=camera)
    obs, _ = env.reset(seed=7)
    potentials = [env.potential]
    for _ in range(150):
        obs, _, term, trunc, _ = env.step(momentum_policy(obs))
        potentials.append(env.potential)
        if term or trunc:
            break
    # the camera imaged exactly the simulator positions the policy observed
    xs = [x for x, _ in camera.calls]
    assert len(xs) == len(potentials)

    replay = EpisodePotential(mc_oracle(sim_client(), cfg, ARMS["hybrid"].potential, rbf=True), lock=True)
    with FrameRenderer() as renderer:
        views = [FrameView.of_frame(renderer.render(camera.rendered_position(x))) for x in xs]
    assert [v.key for v in views] == [k for _, k in camera.calls]
    replayed = [replay.reset(views[0])] + [replay.step(v) for v in views[1:]]
    assert replayed == potentials
    assert max(potentials) > 0.0  # the run was not trivially flat


def test_same_seed_and_actions_give_identical_shaped_rewards() -> None:
    actions = list(np.random.default_rng(1).integers(0, 3, size=400))
    a = rollout(wrap(ARMS["hybrid"]), 11, actions)
    b = rollout(wrap(ARMS["hybrid"]), 11, actions)
    assert [r for _, r, *_ in a] == [r for _, r, *_ in b]


def test_lock_resets_at_episode_start() -> None:
    client = VLMClient(ScriptedBackend(["GOAL"]))  # type: ignore[arg-type]
    cfg = ShapingConfig(query_every=1, confirm=2, reuse_radius=0.0)
    env = wrap(ARMS["hybrid-no-rbf"], cfg, client=client)
    env.reset(seed=0)
    env.step(1)
    assert env.lock_level == 1.0  # GOAL confirmed twice
    env.reset(seed=0)
    assert env.lock_level == 0.0 and env.potential == 1.0  # unlocked; the held label is the new one
    env.close()


def test_constructor_validates_its_arguments() -> None:
    cfg = ShapingConfig()
    base = gym.make("MountainCar-v0")
    with pytest.raises(ValueError, match="camera and oracle"):
        HybridReward(base, ARMS["hybrid"], cfg, GAMMA, MC_SCENE)
    with pytest.raises(ValueError, match="gamma"):
        HybridReward(base, ARMS["kinematic"], cfg, 0.0, MC_SCENE)
    with pytest.raises(ValueError, match="shape"):
        HybridReward(gym.make("CartPole-v1"), ARMS["kinematic"], cfg, GAMMA, MC_SCENE)
    oracle = mc_oracle(sim_client(), cfg, ARMS["hybrid"].potential, rbf=True)
    with pytest.raises(ValueError, match="does not match"):
        HybridReward(base, ARMS["hybrid-no-rbf"], cfg, GAMMA, MC_SCENE, camera=Camera(), oracle=oracle)


def test_another_scene_brings_its_dense_term_observation_and_simulator() -> None:
    from gymnasium.envs.classic_control.acrobot import AcrobotEnv

    from vlmrl_cli.shaping.scene import Scene

    def bonus(obs: np.ndarray, scale: float, offset: float) -> float:  # a dense term of the whole observation
        return scale * float(np.abs(obs).sum()) + offset

    scene = Scene("acrobot-test", (6,), bonus, AcrobotEnv)
    env = HybridReward(gym.make("Acrobot-v1"), ARMS["kinematic"], ShapingConfig(kin_scale=0.5, kin_offset=0.1),
                       gamma=0.99, scene=scene)
    env.reset(seed=0)
    obs, reward, *_, info = env.step(1)
    assert reward == pytest.approx(info["native_reward"] + bonus(obs, 0.5, 0.1))
    with pytest.raises(ValueError, match=r"wraps acrobot-test.*shape \(6,\); got shape \(2,\)"):
        HybridReward(gym.make("MountainCar-v0"), ARMS["kinematic"], ShapingConfig(), 0.99, scene)
    moving = Scene("mc-wrong-sim", (2,), bonus, AcrobotEnv)
    client = sim_client()
    oracle = mc_oracle(client, ShapingConfig(), ARMS["hybrid"].potential)
    with pytest.raises(ValueError, match="images mc-wrong-sim's simulator"):
        HybridReward(gym.make("MountainCar-v0"), ARMS["hybrid"], ShapingConfig(), 0.99, moving, camera=Camera(),
                     oracle=oracle)
    client.close()


def test_the_potential_form_dense_term_telescopes_and_pays_nothing_for_lingering() -> None:
    """hybrid-dense-pbrs pays gamma Phi_kin(s') - Phi_kin(s), Phi_kin = horizon x R_kin: an episode's
    dense part sums to gamma^T Phi_T - Phi_0 whatever the path, so staying still earns nothing."""
    arm, cfg, horizon = ARMS["hybrid-dense-pbrs"], ShapingConfig(alpha=0.0), 200
    env = HybridReward(gym.make("MountainCar-v0"), arm, cfg, 1.0, MC_SCENE, camera=Camera(cfg.render_quantum),
                       oracle=mc_oracle(sim_client(), cfg, arm.potential, rbf=arm.rbf), horizon=horizon)
    obs0, _ = env.reset(seed=5)
    shaped = native = 0.0
    obs = obs0
    for a in [2] * 40 + [1] * 30:
        obs, r, _, _, info = env.step(a)
        shaped, native = shaped + float(r), native + info["native_reward"]
    phi = [horizon * kinematic_reward(float(o[0]), cfg.kin_scale, cfg.kin_offset) for o in (obs0, obs)]
    assert shaped - native == pytest.approx(phi[1] - phi[0], abs=1e-9)
    eq1 = wrap(ARMS["kinematic"], cfg)
    eq1.reset(seed=5)
    paid = sum(float(eq1.step(a)[1]) + 1.0 for a in [2] * 40 + [1] * 30)
    assert paid > 0 and paid != pytest.approx(shaped - native)


def test_the_potential_form_dense_term_needs_the_horizon() -> None:
    arm, cfg = ARMS["hybrid-dense-pbrs"], ShapingConfig()
    with pytest.raises(ValueError, match="horizon"):
        HybridReward(gym.make("MountainCar-v0"), arm, cfg, GAMMA, MC_SCENE, camera=Camera(cfg.render_quantum),
                     oracle=mc_oracle(sim_client(), cfg, arm.potential, rbf=arm.rbf))

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
from vlmrl_cli.shaping.wrapper import EpisodeStatistics, wrap_arm
from vlmrl_cli.tasks.mountain_car.camera import Camera
from vlmrl_cli.tasks.mountain_car.render import FrameRenderer
from vlmrl_cli.tasks.mountain_car.task import MOUNTAIN_CAR_SCENE as MC_SCENE
from vlmrl_cli.vlm.client import VLMClient

GAMMA = 0.99


def wrap(arm: ArmSpec, cfg: ShapingConfig | None = None, client: VLMClient | None = None,
         camera: Camera | None = None) -> EpisodeStatistics:
    cfg = cfg or ShapingConfig()
    oracle = None
    if arm.uses_vlm:
        camera = camera or Camera(cfg.render_quantum)
        oracle = mc_oracle(client or sim_client(), cfg, arm.potential, rbf=arm.rbf)
    return wrap_arm(Monitor(gym.make("MountainCar-v0")), arm, cfg, GAMMA, MC_SCENE, camera=camera, oracle=oracle,
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
    env = wrap_arm(gym.make("MountainCar-v0"), arm, cfg, GAMMA, MC_SCENE, camera=camera, oracle=oracle,
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
    env = wrap_arm(Monitor(gym.make("MountainCar-v0")), arm, cfg, GAMMA, MC_SCENE, camera=camera, oracle=oracle,
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
        phi = env.get_wrapper_attr("potential")
        obs, r, term, _, _ = env.step(momentum_policy(obs))
        phi_next = 0.0 if term else env.get_wrapper_attr("potential")
        expected = -1.0 + kinematic_reward(float(obs[0])) + cfg.alpha * (GAMMA * phi_next - phi)
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
    potentials = [env.get_wrapper_attr("potential")]
    for _ in range(150):
        obs, _, term, trunc, _ = env.step(momentum_policy(obs))
        potentials.append(env.get_wrapper_attr("potential"))
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
    assert env.get_wrapper_attr("episode").lock_state.level == 1.0  # GOAL confirmed twice
    env.reset(seed=0)
    # unlocked; the held label is the new one
    assert env.get_wrapper_attr("episode").lock_state.level == 0.0 and env.get_wrapper_attr("potential") == 1.0
    env.close()


def test_constructor_validates_its_arguments() -> None:
    cfg = ShapingConfig()
    base = gym.make("MountainCar-v0")
    with pytest.raises(ValueError, match="camera and oracle"):
        wrap_arm(base, ARMS["hybrid"], cfg, GAMMA, MC_SCENE)
    with pytest.raises(ValueError, match="gamma"):
        wrap_arm(base, ARMS["kinematic"], cfg, 0.0, MC_SCENE)
    with pytest.raises(ValueError, match="shape"):
        wrap_arm(gym.make("CartPole-v1"), ARMS["kinematic"], cfg, GAMMA, MC_SCENE)
    oracle = mc_oracle(sim_client(), cfg, ARMS["hybrid"].potential, rbf=True)
    with pytest.raises(ValueError, match="does not match"):
        wrap_arm(base, ARMS["hybrid-no-rbf"], cfg, GAMMA, MC_SCENE, camera=Camera(), oracle=oracle)


def test_another_scene_brings_its_dense_term_observation_and_simulator() -> None:
    from gymnasium.envs.classic_control.acrobot import AcrobotEnv

    from vlmrl_cli.shaping.scene import Scene

    def bonus(obs: np.ndarray, scale: float, offset: float) -> float:  # a dense term of the whole observation
        return scale * float(np.abs(obs).sum()) + offset

    scene = Scene("acrobot-test", (6,), bonus, AcrobotEnv)
    env = wrap_arm(gym.make("Acrobot-v1"), ARMS["kinematic"], ShapingConfig(kin_scale=0.5, kin_offset=0.1),
                       gamma=0.99, scene=scene)
    env.reset(seed=0)
    obs, reward, *_, info = env.step(1)
    assert reward == pytest.approx(info["native_reward"] + bonus(obs, 0.5, 0.1))
    with pytest.raises(ValueError, match=r"read acrobot-test.*shape \(6,\); got shape \(2,\)"):
        wrap_arm(gym.make("MountainCar-v0"), ARMS["kinematic"], ShapingConfig(), 0.99, scene)
    moving = Scene("mc-wrong-sim", (2,), bonus, AcrobotEnv)
    client = sim_client()
    oracle = mc_oracle(client, ShapingConfig(), ARMS["hybrid"].potential)
    with pytest.raises(ValueError, match="images AcrobotEnv"):
        wrap_arm(gym.make("MountainCar-v0"), ARMS["hybrid"], ShapingConfig(), 0.99, moving, camera=Camera(),
                     oracle=oracle)
    client.close()


def test_the_potential_form_dense_term_telescopes_and_pays_nothing_for_lingering() -> None:
    """hybrid-dense-pbrs pays gamma Phi_kin(s') - Phi_kin(s), Phi_kin = horizon x R_kin: an episode's
    dense part sums to gamma^T Phi_T - Phi_0 whatever the path, so staying still earns nothing."""
    arm, cfg, horizon = ARMS["hybrid-dense-pbrs"], ShapingConfig(alpha=0.0), 200
    env = wrap_arm(gym.make("MountainCar-v0"), arm, cfg, 1.0, MC_SCENE, camera=Camera(cfg.render_quantum),
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
        wrap_arm(gym.make("MountainCar-v0"), arm, cfg, GAMMA, MC_SCENE, camera=Camera(cfg.render_quantum),
                     oracle=mc_oracle(sim_client(), cfg, arm.potential, rbf=arm.rbf))


# --- one labelling round per vector step (LabelRoundVecEnv) ---------------------------------------


class CountingSim:
    """The simulated VLM, counting the frames of each backend call (a batch, or one ``answer``)."""

    def __init__(self, client: VLMClient) -> None:
        self.inner = client.backend
        self.name, self.model, self.simulated = self.inner.name, self.inner.model, self.inner.simulated
        self.stochastic = bool(getattr(self.inner, "stochastic", False))
        self.calls: list[int] = []

    def answer(self, prompt: Any, frame: Any) -> str:
        self.calls.append(1)
        return self.inner.answer(prompt, frame)

    def answer_many(self, prompt: Any, frames: Any) -> list[str]:
        self.calls.append(len(frames))
        return [self.inner.answer(prompt, frame) for frame in frames]

    def close(self) -> None:
        self.inner.close()


def _venv(name: str, rounds: bool, cfg: ShapingConfig, query_flicker: float = 0.0, n_envs: int = 4,
          max_queries: int | None = None) -> tuple[Any, Any, CountingSim]:
    from stable_baselines3.common.vec_env import DummyVecEnv

    from vlmrl_cli.shaping.wrapper import LabelRoundVecEnv
    from vlmrl_cli.tasks.mountain_car import MOUNTAIN_CAR
    from vlmrl_cli.vlm.config import SimKnobs, VLMConfig
    from vlmrl_cli.vlm.registry import build_client

    arm = ARMS[name]
    client = build_client(VLMConfig(use_cache=False, sim=SimKnobs(query_flicker=query_flicker)), stream=3,
                          reader=MOUNTAIN_CAR.reader)
    backend = CountingSim(client)
    client = VLMClient(backend)
    oracle = mc_oracle(client, cfg, arm.potential, rbf=arm.rbf)
    oracle.max_queries = max_queries
    camera = Camera(cfg.render_quantum)

    def make() -> gym.Env:
        return wrap_arm(Monitor(gym.make("MountainCar-v0")), arm, cfg, GAMMA, MC_SCENE, camera=camera, oracle=oracle,
                        horizon=200)

    venv = LabelRoundVecEnv([make] * n_envs, oracle) if rounds else DummyVecEnv([make] * n_envs)
    venv.seed(11)
    return venv, oracle, backend


def _play(venv: Any, steps: int) -> list[Any]:
    rng = np.random.default_rng(2)
    out = [venv.reset().copy()]
    for _ in range(steps):
        obs, rewards, dones, infos = venv.step(rng.integers(0, 3, size=venv.num_envs))
        # Monitor's wall-clock time ("t") aside, every info key is compared
        out.append((obs.copy(), rewards.copy(), dones.copy(),
                    [{k: ({**v, "t": None} if k == "episode" else v) for k, v in i.items()
                      if k != "terminal_observation"} for i in infos]))
    return out


@pytest.mark.parametrize(("name", "cfg", "query_flicker"), [
    ("hybrid", ShapingConfig(), 0.0),
    ("hybrid", ShapingConfig(reuse_radius=0.05, query_every=1), 0.0),  # reuse: a later env's label may be reused
    ("hybrid-no-rbf", ShapingConfig(query_every=3), 0.3),  # a stochastic VLM: a draw per labelling view, in order
    ("hybrid-dense-pbrs", ShapingConfig(), 0.0),
])
def test_a_labelling_round_steps_every_env_as_one_env_at_a_time_would(name: str, cfg: ShapingConfig,
                                                                      query_flicker: float) -> None:
    serial, serial_oracle, one = _venv(name, False, cfg, query_flicker)
    rounds, round_oracle, batched = _venv(name, True, cfg, query_flicker)
    a, b = _play(serial, 260), _play(rounds, 260)  # past the 200-step limit: every env resets inside a round
    np.testing.assert_array_equal(a[0], b[0])
    for (obs_a, rew_a, done_a, info_a), (obs_b, rew_b, done_b, info_b) in zip(a[1:], b[1:], strict=True):
        np.testing.assert_array_equal(obs_a, obs_b)
        np.testing.assert_array_equal(rew_a, rew_b)  # bit for bit
        np.testing.assert_array_equal(done_a, done_b)
        assert info_a == info_b
    labels = ("vlm/queries", "vlm/prototypes", "vlm/label_reuses", "vlm/parse_failures")
    assert [serial_oracle.stats()[k] for k in labels] == [round_oracle.stats()[k] for k in labels]
    assert set(one.calls) == {1} and max(batched.calls) > 1  # the rounds asked several frames per call
    assert len(batched.calls) < len(one.calls)
    assert round_oracle.stats()["vlm/backend_calls"] == len(batched.calls)
    assert round_oracle.stats()["vlm/largest_batch"] == max(batched.calls)
    serial.close()
    rounds.close()


def test_the_query_budget_is_respected_and_the_nearest_prototype_labels_past_it() -> None:
    cfg = ShapingConfig(query_every=1)
    venv, oracle, backend = _venv("hybrid", True, cfg, max_queries=12)
    _play(venv, 150)
    stats = oracle.stats()
    assert stats["vlm/queries"] == 12 and sum(backend.calls) == 12 and stats["vlm/prototypes"] <= 12
    assert stats["vlm/budget_labels"] > 0  # labels past the budget came from the nearest prototype
    venv.close()
    free, unbounded, _ = _venv("hybrid", True, cfg)
    _play(free, 150)
    assert unbounded.stats()["vlm/queries"] > 12 and unbounded.stats()["vlm/budget_labels"] == 0
    free.close()

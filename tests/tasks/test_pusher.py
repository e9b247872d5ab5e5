"""Pusher-v5 as a task: the sparse reward and success rule, the dense term from the observation,
PBRS telescoping, the reader against the simulator's truth, the camera's cells, the GL refusal.

gymnasium's and SB3's env checkers run on every (pusher, arm) training env in
tests/training/test_env_checkers.py (it takes every built-in task)."""

from __future__ import annotations

import collections
import functools
import math
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from vlmrl_cli.core.errors import BadInput
from vlmrl_cli.shaping.arms import ARMS, DENSE_POTENTIAL
from vlmrl_cli.shaping.semantic import SemanticOracle
from vlmrl_cli.shaping.wrapper import wrap_arm
from vlmrl_cli.tasks import pusher, pusher_scene
from vlmrl_cli.tasks.registry import get_task
from vlmrl_cli.vlm.config import SimKnobs, VLMConfig
from vlmrl_cli.vlm.registry import build_client
from vlmrl_cli.vlm.sim import SimulatedVLM

# importing tasks.pusher chose a headless GL (MUJOCO_GL) before anything imported mujoco
pytest.importorskip("mujoco")
TASK = get_task("pusher")
coords = st.floats(-1.0, 1.0, allow_nan=False)


def test_the_sparse_reward_is_minus_one_until_the_puck_is_on_the_goal() -> None:
    env = TASK.make_env()
    obs, _ = env.reset(seed=3)
    sim: Any = env.unwrapped
    _, reward, terminated, _, info = env.step(np.zeros(7, dtype=np.float32))
    assert reward == -1.0 and not terminated and info["dense_reward"] < 0
    qpos, qvel = sim.data.qpos.copy(), sim.data.qvel.copy()
    qpos[-4:-2] = (0.01, 0.0)  # the puck's slides: 1 cm from the goal
    sim.set_state(qpos, qvel)
    obs, reward, terminated, truncated, _ = env.step(np.zeros(7, dtype=np.float32))
    assert terminated and not truncated and pusher.puck_goal_distance(obs) < pusher_scene.SUCCESS_M
    assert TASK.truth(sim) == "ON_TARGET" and TASK.success(True, 2) and not TASK.success(False, 100)
    env.close()


@given(coords, coords, coords, coords, coords)
def test_the_dense_term_is_eq1_on_the_envs_weighted_distance(tx: float, ty: float, px: float, py: float,
                                                            gz: float) -> None:
    obs = np.zeros(pusher.OBS_DIM)
    obs[14:17], obs[17:20], obs[20:23] = (tx, ty, 0.0), (px, py, -0.275), (0.45, -0.05, gz)
    d_tp = math.dist((tx, ty, 0.0), (px, py, -0.275))
    d_pg = math.dist((px, py), (0.45, -0.05))
    assert pusher.pusher_dense(obs, 2.0, 0.4) == pytest.approx(max(0.0, 2.0 * (0.4 - d_pg - 0.5 * d_tp)), abs=1e-9)
    assert pusher.pusher_dense(obs, 2.0, 0.4) <= 0.8  # below the step cost: hovering never pays


@functools.cache
def shared_camera() -> Any:
    """One camera (one GL context) for every example below."""
    return TASK.camera.make(TASK.default_shaping())


@settings(max_examples=8, deadline=None)
@given(st.integers(0, 2**16))
def test_pbrs_telescopes_over_a_pusher_episode(seed: int) -> None:
    """With gamma 1 the potential-form arm's shaping of a whole episode is the end's potentials
    (0 at a terminal state) minus the start's: alpha (Phi_T - Phi_0) + (Phi_kin_T - Phi_kin_0)."""
    arm = ARMS[DENSE_POTENTIAL]
    shaping = TASK.default_shaping()
    client = build_client(VLMConfig(backend="sim", use_cache=False), reader=TASK.reader)
    oracle = SemanticOracle(client, shaping, arm.potential, TASK.milestones, TASK.camera.feature_dim, rbf=arm.rbf)
    env = wrap_arm(TASK.make_env(), arm, shaping, 1.0, TASK.scene, camera=shared_camera(), oracle=oracle,
                       horizon=pusher.MAX_STEPS, success=TASK.success)
    obs, _ = env.reset(seed=seed)
    kin = functools.partial(pusher.pusher_dense, scale=shaping.kin_scale, offset=shaping.kin_offset)
    start = shaping.alpha * env.get_wrapper_attr("potential") + pusher.MAX_STEPS * kin(obs)
    rng = np.random.default_rng(seed)
    shaped_minus_native, terminated = 0.0, False
    for _ in range(15):
        obs, reward, terminated, _, info = env.step(rng.uniform(-2, 2, 7).astype(np.float32))
        shaped_minus_native += float(reward) - info["native_reward"]
        if terminated:
            break
    end = 0.0 if terminated else shaping.alpha * env.get_wrapper_attr("potential") + pusher.MAX_STEPS * kin(obs)
    assert shaped_minus_native == pytest.approx(end - start, abs=1e-6)


def test_the_reader_agrees_with_the_truth_on_random_states() -> None:
    """>= 0.9 of 200 random states (50 of each true milestone, seed 0; the reader's own edge was set
    on seed 1) read right from the pixels by the ideal simulated VLM (no flicker)."""
    states = pusher.random_states(200, seed=0)
    renderer = pusher_scene.PusherRenderer(states[0].model)
    vlm = SimulatedVLM(TASK.reader, SimKnobs(flicker=0.0))
    confusion: collections.Counter[tuple[str, str | None]] = collections.Counter()
    try:
        for state in states:
            frame = renderer.render(state.data.qpos)
            answer = vlm.answer(TASK.milestones.prompt, frame)
            read = next((label for label in sorted(TASK.milestones.labels, key=len, reverse=True) if label in answer),
                        None)
            confusion[(TASK.truth(state), read)] += 1
    finally:
        renderer.close()
    accuracy = sum(n for (truth, read), n in confusion.items() if truth == read) / len(states)
    print(f"pusher reader: label accuracy {accuracy:.3f} on {len(states)} random states; "
          f"confusion {dict(confusion)}")
    assert accuracy >= 0.9


def test_the_reader_measures_the_puck_goal_distance_from_the_pixels() -> None:
    qpos = np.zeros(11)
    qpos[:7] = (1.0, 0.5, 0.0, -1.0, 0.0, -0.5, 0.0)  # the arm away to one side
    qpos[7:9] = (-0.2, 0.1)  # the puck 0.224 m from the goal
    state = pusher.PusherState.at(qpos)
    renderer = pusher_scene.PusherRenderer(state.model)
    try:
        d_tp, d_pg = pusher_scene.read_distances(renderer.render(state.data.qpos).pixels)
    finally:
        renderer.close()
    assert d_pg == pytest.approx(math.hypot(0.2, 0.1), abs=0.02)
    assert d_tp is None or d_tp > pusher_scene.READ_AT_PUCK_M


def test_the_camera_draws_a_cell_once_and_keeps_its_frame() -> None:
    env = TASK.make_env()
    env.reset(seed=0)
    camera = TASK.camera.make(TASK.default_shaping())
    try:
        first = camera.look(env.unwrapped)
        again = camera.look(env.unwrapped)
        assert again is first and camera.renders == 1 and first.features.shape == (TASK.camera.feature_dim,)
        frame = first.frame()
        assert frame.pixels.shape == pusher_scene.FRAME_SHAPE and frame.sha256 == first.key
        camera.close()
        assert camera.look(env.unwrapped).frame().sha256 == first.key  # drawn again: the same pixels
    finally:
        camera.close()
        env.close()


def test_a_machine_without_opengl_is_told_so_in_one_line(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(pusher, "gl_problem", lambda: "task 'pusher' cannot render: no working OpenGL")
    pusher.pusher_task.cache_clear()
    try:
        with pytest.raises(BadInput, match="cannot render") as caught:
            get_task("pusher")
        assert "\n" not in str(caught.value)
    finally:
        pusher.pusher_task.cache_clear()


def test_headless_gl_keeps_the_users_choice(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("MUJOCO_GL", "osmesa")
    assert pusher_scene.use_headless_gl() == "osmesa"
    monkeypatch.delenv("MUJOCO_GL")
    assert pusher_scene.use_headless_gl() == "egl"


def test_the_bare_env_is_the_sparse_one() -> None:
    env = TASK.make_env()
    assert isinstance(env, pusher.SparsePush) and isinstance(env.unwrapped, TASK.scene.sim_type)
    assert env.observation_space.shape == TASK.scene.obs_shape and isinstance(env, gym.Env)
    env.close()


@pytest.mark.slow
def test_a_smoke_run_of_the_hybrid_trains_headless() -> None:
    """The CI's Pusher smoke run: the hybrid (camera, reader, oracle) trains 1,024 steps off screen."""
    from vlmrl_cli.training.config import RunConfig
    from vlmrl_cli.training.trace import native_returns

    sources = {"task": "pusher", "arms": ["hybrid"], "seeds": [0], "preset": "smoke"}
    job = RunConfig.from_sources(None, sources).jobs()[0]
    returns = native_returns(job)
    assert job.timesteps == 1_024 and len(returns) >= 8
    assert all(-pusher.MAX_STEPS <= r <= -1 for r in returns)


def test_presets_of_other_tasks_stay_known_where_pusher_cannot_load(monkeypatch: pytest.MonkeyPatch) -> None:
    from vlmrl_cli.tasks import registry
    from vlmrl_cli.training import config

    def refused() -> Any:
        raise BadInput("task 'pusher' cannot render: no working OpenGL")

    monkeypatch.setitem(registry.BUILTIN, "pusher", refused)
    known = config._builtin_presets()
    assert "paper" in known and "zoo" in known and "pusher" not in known


def test_the_dense_term_pays_everywhere_on_the_table_at_the_tasks_scales() -> None:
    """The task's offset (1 m) is part of its scales: a run that sets none takes it, and the dense term
    pays at a typical start (c about 0.5 m), where Eq. 1's default offset 0.4 paid nothing."""
    task = get_task("pusher")
    shaping = task.default_shaping()
    assert (shaping.alpha, shaping.kin_scale, shaping.kin_offset) == (12.5, 0.125, 1.0)
    obs = np.zeros(pusher.OBS_DIM)
    obs[14:17], obs[17:20], obs[20:23] = (0.0, 0.0, 0.0), (0.4, 0.0, 0.0), (0.4, 0.3, 0.0)  # c = 0.3 + 0.2
    assert pusher.pusher_dense(obs, shaping.kin_scale, 0.4) == 0.0
    assert pusher.pusher_dense(obs, shaping.kin_scale, shaping.kin_offset) == pytest.approx(0.125 * 0.5)
    assert "kin_offset 1 replace" in (task.scales_note(shaping) or "")

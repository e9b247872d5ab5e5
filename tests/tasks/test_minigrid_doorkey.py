"""MiniGrid DoorKey, built through the public Task interface: the reader reads the pixels as the
simulator's truth says, the dense term keeps its bound, the camera memoises, and a smoke run works."""

from __future__ import annotations

import random
from pathlib import Path

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from vlmrl_cli.sweep.runner import SilentReporter, run_sweep
from vlmrl_cli.tasks.minigrid_doorkey import (
    LABELS,
    MAX_STEPS,
    DoorKeyCamera,
    doorkey_dense,
    label_of_sim,
    make_doorkey_env,
    probe_states,
    read_stage,
    render_state,
)
from vlmrl_cli.tasks.registry import get_task
from vlmrl_cli.training.config import RunConfig


def test_the_reader_agrees_with_the_simulator_on_every_frame_of_random_episodes() -> None:
    env = make_doorkey_env()
    rng = random.Random(0)
    seen: dict[str, int] = {}
    agree = total = 0
    for episode in range(12):
        env.reset(seed=episode)
        sim = env.unwrapped
        for _ in range(MAX_STEPS):
            truth = label_of_sim(sim)
            seen[truth] = seen.get(truth, 0) + 1
            agree += read_stage(render_state(sim).pixels) == truth
            total += 1
            _, _, terminated, truncated, _ = env.step(rng.choice([0, 1, 2, 2, 2, 3, 5]))
            if terminated or truncated:
                break
    env.close()
    assert agree == total and {"NO_KEY", "HAS_KEY", "DOOR_OPEN"} <= set(seen)


def test_no_agent_in_the_picture_is_no_answer() -> None:
    assert read_stage(np.zeros((160, 160, 3), dtype=np.uint8)) is None


@given(st.integers(0, 1), st.integers(0, 1), st.floats(0.0, 10.0), st.floats(-1.0, 1.0))
def test_the_dense_term_is_bounded_and_pays_nothing_before_the_key(carries: int, door: int, scale: float,
                                                                    offset: float) -> None:
    view = np.zeros((7, 7, 3))
    if carries:
        view[3, 6] = (5, 4, 0)
    if door:
        view[3, 2] = (4, 4, 0)
    r = doorkey_dense(view.reshape(-1), scale, offset)
    assert 0.0 <= r <= scale * (1.0 + abs(offset)) / MAX_STEPS + 1e-12
    if not carries and not door and offset <= 1.0:
        assert r == 0.0


def test_the_camera_draws_each_pose_once() -> None:
    env = make_doorkey_env()
    env.reset(seed=3)
    camera = DoorKeyCamera()
    a, b = camera.look(env.unwrapped), camera.look(env.unwrapped)
    assert a.key == b.key and camera.renders == 1 and a.frame().pixels.shape == (160, 160, 3)
    camera.close()
    env.close()


def test_the_taxonomy_s_probe_states_cover_every_stage_evenly_and_read_as_their_truth() -> None:
    sims = probe_states(40)
    camera = DoorKeyCamera()
    truths = [label_of_sim(s) for s in sims]
    assert len(sims) == 40 and {t: truths.count(t) for t in LABELS} == dict.fromkeys(LABELS, 10)
    assert [read_stage(camera.look(s).frame().pixels) for s in sims] == truths
    assert all(s.grid.get(*s.agent_pos) is None or s.grid.get(*s.agent_pos).type == "goal" for s in sims)


def test_the_task_is_a_builtin_with_its_labels_and_presets() -> None:
    task = get_task("minigrid-doorkey")
    assert task.milestones.labels == LABELS and {"zoo", "smoke"} <= set(task.presets)
    assert task.make_env().observation_space.shape == (147,) and not task.probes_floats


def test_baseline_hybrid_and_placebo_run_at_smoke_size(tmp_path: Path) -> None:
    uri = f"sqlite:///{tmp_path / 'd.db'}"
    cfg = RunConfig.from_sources(None, {"task": "minigrid-doorkey", "arms": ["baseline", "hybrid", "hybrid-shuffled"],
                                        "seeds": [0], "preset": "smoke", "workers": 1, "tracking_uri": uri})
    summary = run_sweep(cfg, SilentReporter())
    assert len(summary.finished) == 3 and not summary.failed

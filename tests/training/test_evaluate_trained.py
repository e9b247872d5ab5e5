"""Playing and labelling one episode for `vlmrl evaluate` (no MLflow here)."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from tests.tasks.mountain_car.test_kinematic import kinematic_reward
from vlmrl_cli.core.errors import BadInput
from vlmrl_cli.shaping.arms import ARMS
from vlmrl_cli.shaping.camera import FrameView
from vlmrl_cli.shaping.config import ShapingConfig
from vlmrl_cli.tasks.mountain_car import MOUNTAIN_CAR
from vlmrl_cli.tasks.mountain_car.camera import Camera
from vlmrl_cli.tasks.mountain_car.geometry import Zone
from vlmrl_cli.training.config import EVAL_SEED
from vlmrl_cli.training.evaluate_trained import EvaluateConfig, _summary, label_frames, play_episode
from vlmrl_cli.training.evaluation import evaluate_detached
from vlmrl_cli.training.trained import TrainedRun
from vlmrl_cli.vlm.config import VLMConfig


def _views(positions: list[float]) -> list[FrameView]:
    camera = Camera(ShapingConfig().render_quantum)  # the training camera (closed views stay loadable)
    return [camera.view(x) for x in positions]


def _energy(obs: np.ndarray) -> int:
    return 2 if obs[1] >= 0 else 0


def test_played_steps_add_up_and_keep_every_kth_frame_and_the_last() -> None:
    steps = play_episode(_energy, seed=3, shaping=ShapingConfig(), task=MOUNTAIN_CAR, frame_every=4)
    assert [s.t for s in steps] == list(range(len(steps)))
    assert steps[0].action is None and steps[0].native_return == 0.0
    assert all(s.native_return == -s.t for s in steps)  # native reward is -1 per step
    assert all(s.r_kin == kinematic_reward(s.obs[0]) for s in steps[1:])
    assert steps[-1].terminated and steps[-1].obs[0] >= 0.5
    kept = [s.t for s in steps if s.pixels is not None]
    assert kept[:3] == [0, 4, 8] and kept[-1] == steps[-1].t
    pixels = steps[0].pixels
    assert pixels is not None and pixels.shape == (400, 600, 3) and pixels.dtype == np.uint8


def _run(arm: str) -> TrainedRun:
    return TrainedRun(run_id="r", name=f"{arm}-s0", status="FINISHED", arm=ARMS[arm], shaping=ShapingConfig(),
                      vlm=VLMConfig(), vlm_label="sim", simulated=True, policy=_energy,
                      task=MOUNTAIN_CAR)


def test_mcq_labels_carry_the_label_potential() -> None:
    cfg = EvaluateConfig("r", use_cache=False)
    labels = label_frames(_run("hybrid"), _views([-1.15, -0.52, 0.55]), cfg)
    potentials = dict(MOUNTAIN_CAR.label_potentials)
    assert len(labels) == 3
    for label in labels:
        assert label.answer in Zone.__members__ and label.potential == potentials[Zone(label.answer)]
        assert label.caption.startswith(f"VLM {label.answer}  Phi_raw ")


def test_float_arm_labels_show_the_parsed_position() -> None:
    labels = label_frames(_run("vision-float"), _views([-0.5, 0.3]), EvaluateConfig("r", use_cache=False))
    for label in labels:
        assert label.answer.startswith("x=") or label.potential is None
        assert label.potential is None or 0.0 <= label.potential <= 1.0


@pytest.mark.parametrize(("kwargs", "words"), [
    ({"episodes": 0}, "--episodes"),
    ({"episodes": 3, "episode_index": 3}, "--episode-index"),
    ({"run_id": " "}, "run id"),
])
def test_bad_settings_are_bad_input(kwargs: dict[str, object], words: str) -> None:
    cfg = EvaluateConfig(**{"run_id": "r", **kwargs})  # type: ignore[arg-type]
    with pytest.raises(BadInput, match=words):
        cfg.validate()


@pytest.mark.parametrize("own_rule", [False, True])
def test_the_gifs_success_is_the_tasks_rule_as_the_detached_evaluations(own_rule: bool, tmp_path: Path) -> None:
    """An idle car never reaches the flag: a failure by MountainCar's rule, a success by a task's
    own rule that counts lasting the time limit."""
    task = (dataclasses.replace(MOUNTAIN_CAR, name="survive-car",
                                success_rule=lambda terminated, length: not terminated and length >= 200)
            if own_rule else MOUNTAIN_CAR)
    run = dataclasses.replace(_run("baseline"), policy=lambda obs: 1, task=task)
    cfg = EvaluateConfig("r", episodes=1, frame_every=50, use_cache=False)
    result = evaluate_detached(run.policy, 1, EVAL_SEED, task)
    steps = play_episode(run.policy, EVAL_SEED, run.shaping, task, cfg.frame_every)
    shown = [s for s in steps if s.pixels is not None]
    figures = _summary(run, result, cfg, steps, shown, None, tmp_path / "episode-0.gif")
    assert steps[-1].t == 200 and not steps[-1].terminated
    assert figures["gif"]["success"] is own_rule and figures["successes"] == [own_rule]

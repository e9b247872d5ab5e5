from __future__ import annotations

import numpy as np

from vlmrl_cli.tasks.mountain_car import MOUNTAIN_CAR
from vlmrl_cli.training.evaluation import evaluate_detached


def _energy_pumping(obs: np.ndarray) -> int:
    """Push in the direction of motion: solves MountainCar in well under 200 steps."""
    return 2 if obs[1] >= 0 else 0


def test_a_solving_policy_succeeds_and_a_idle_one_times_out() -> None:
    good = evaluate_detached(_energy_pumping, episodes=5, seed=0, task=MOUNTAIN_CAR)
    idle = evaluate_detached(lambda obs: 1, episodes=5, seed=0, task=MOUNTAIN_CAR)
    assert good.success_rate == 1.0 and good.mean_length < 200
    assert np.allclose(good.returns, -good.lengths)  # -1 per step is the whole native reward
    assert idle.success_rate == 0.0 and np.all(idle.lengths == 200) and idle.mean_return == -200.0


def test_fixed_evaluation_seeds_repeat_exactly() -> None:
    a = evaluate_detached(_energy_pumping, episodes=4, seed=123, task=MOUNTAIN_CAR)
    b = evaluate_detached(_energy_pumping, episodes=4, seed=123, task=MOUNTAIN_CAR)
    assert np.array_equal(a.lengths, b.lengths)
    assert a.lengths.shape == (4,)


class _Recorder:
    def __init__(self) -> None:
        self.logged: dict[str, list[tuple[int, float]]] = {}

    def log(self, values: dict[str, float], step: int) -> None:
        for k, v in values.items():
            self.logged.setdefault(k, []).append((step, v))


def test_detached_evaluation_logs_the_hovering_diagnostic() -> None:
    from vlmrl_cli.sweep.worker import _log_eval

    rec = _Recorder()
    _log_eval(rec, evaluate_detached(_energy_pumping, episodes=2, seed=0, task=MOUNTAIN_CAR))  # type: ignore[arg-type]
    assert rec.logged["eval/hover_fraction"] == [(0, 0.0)]
    assert 0 < rec.logged["eval/dwell_right_steps"][0][1] <= 10
    assert len(rec.logged["eval/episode_length"]) == 2

from __future__ import annotations

import math

from vlmrl_cli.training.callbacks import EpisodeTracker
from vlmrl_cli.training.events import ProgressEvent


def _step(tracker: EpisodeTracker, t: int, infos: list[dict[str, object]]) -> bool:
    tracker.num_timesteps = t
    tracker.locals = {"infos": infos}
    return tracker._on_step()


def test_completed_episodes_become_native_and_shaped_records() -> None:
    events: list[ProgressEvent] = []
    tracker = EpisodeTracker("hybrid-s0", total=1000, progress=events.append, interval_s=0.0)
    _step(tracker, 16, [{}, {}])
    _step(tracker, 32, [{"episode": {"r": -200.0, "l": 200}, "TimeLimit.truncated": True, "shaped_return": 35.5},
                        {}])
    _step(tracker, 48, [{}, {"episode": {"r": -150.0, "l": 150}, "TimeLimit.truncated": False,
                             "shaped_return": 80.0}])
    assert [e["timestep"] for e in tracker.episodes] == [32.0, 48.0]
    assert [e["episode/native_return"] for e in tracker.episodes] == [-200.0, -150.0]
    assert [e["episode/success"] for e in tracker.episodes] == [0.0, 1.0]
    assert [e["episode/shaped_return"] for e in tracker.episodes] == [35.5, 80.0]
    assert math.isnan(events[0].recent_return) and events[-1].recent_return == -175.0
    assert events[-1].episodes == 2 and events[-1].timesteps == 48


def test_success_falls_back_to_episode_length_and_stop_is_honoured() -> None:
    stop = {"now": False}
    tracker = EpisodeTracker("baseline-s0", total=100, should_stop=lambda: stop["now"])
    assert _step(tracker, 1, [{"episode": {"r": -120.0, "l": 120}}])
    assert tracker.episodes[0]["episode/success"] == 1.0
    assert tracker.episodes[0]["episode/shaped_return"] == -120.0
    stop["now"] = True
    assert _step(tracker, 2, [{}]) is False and tracker.stopped


class _Sink:
    def __init__(self) -> None:
        self.calls: list[tuple[dict[str, float], int]] = []

    def log(self, metrics: dict[str, float], step: int) -> None:
        self.calls.append((dict(metrics), step))

    def flush(self) -> None:
        pass


def test_rollout_end_logs_the_mean_native_return_of_the_last_100_episodes() -> None:
    sink = _Sink()
    tracker = EpisodeTracker("baseline-s0", total=10_000, metrics=sink)  # type: ignore[arg-type]
    tracker.num_timesteps = 64
    tracker._on_rollout_end()
    assert "rollout/return_100" not in sink.calls[-1][0]  # no episode yet: nothing to average
    for i in range(150):
        _step(tracker, 100 + i, [{"episode": {"r": float(-200 + i), "l": 200}}])
    tracker._on_rollout_end()
    figures, step = sink.calls[-1]
    assert step == 249
    assert figures["rollout/return_100"] == sum(range(-150, -50)) / 100  # episodes 50..149 only


def test_the_tasks_own_rule_decides() -> None:
    from vlmrl_cli.tasks.registry import get_task

    acrobot, car = get_task("acrobot"), get_task("mountain-car")
    long_finish: list[dict[str, object]] = [{"episode": {"r": -300.0, "l": 300}}]  # ended by the env after 300 steps
    cut: list[dict[str, object]] = [{"episode": {"r": -500.0, "l": 500}, "TimeLimit.truncated": True}]
    on_acrobot = EpisodeTracker("baseline-s0", total=1_000, success=acrobot.success)
    _step(on_acrobot, 300, long_finish)
    _step(on_acrobot, 800, cut)
    assert [e["episode/success"] for e in on_acrobot.episodes] == [1.0, 0.0]
    on_car = EpisodeTracker("baseline-s0", total=1_000, success=car.success)
    _step(on_car, 300, long_finish)  # past MountainCar-v0's 200-step limit: not a success there
    assert on_car.episodes[0]["episode/success"] == 0.0


def test_an_is_success_in_the_infos_does_not_overrule_the_tasks_rule() -> None:
    """One rule: the tracker applies the task's, whatever another wrapper wrote as is_success."""
    from vlmrl_cli.tasks.registry import get_task

    car = get_task("mountain-car")
    tracker = EpisodeTracker("baseline-s0", total=1_000, success=car.success)
    _step(tracker, 200, [{"episode": {"r": -200.0, "l": 200}, "TimeLimit.truncated": True, "is_success": True}])
    _step(tracker, 320, [{"episode": {"r": -120.0, "l": 120}, "is_success": False}])
    assert [e["episode/success"] for e in tracker.episodes] == [0.0, 1.0]

"""Cost estimates: measured per-step time, scaled for the worker count and the sweeps' utilisation."""

from __future__ import annotations

import dataclasses

import pytest

from vlmrl_cli.sweep.cost import FALLBACK_S_PER_STEP, Timings, contention, estimate, estimate_sweeps
from vlmrl_cli.tasks.registry import get_task
from vlmrl_cli.training.config import RunConfig
from vlmrl_cli.training.presets import preset_of


def _jobs(arms: tuple[str, ...], seeds: int, steps: int = 100_000) -> list:  # type: ignore[type-arg]
    ppo = dataclasses.replace(preset_of(get_task("mountain-car"), "smoke"), timesteps=steps)
    return RunConfig(arms=arms, seeds=tuple(range(seeds)), preset="smoke", ppo=ppo).jobs()


def test_measured_arms_are_used_per_arm_and_divided_over_the_workers() -> None:
    timings = Timings({"baseline": (1e-4, 2), "hybrid": (2e-4, 2)}, utilisation=1.0, runs=10)
    cost = estimate(_jobs(("baseline", "hybrid"), 2), done=3, workers=2, timings=timings, cores=2)
    assert cost.pending == 4 and cost.done == 3
    assert cost.per_run_s == pytest.approx((2 * 10 + 2 * 20) / 4)
    assert cost.total_s == pytest.approx(60 / 2)
    assert "4 run(s) to train (3 already FINISHED)" in cost.line() and "10 finished run(s)" in cost.line()


def test_more_workers_than_cores_slow_each_run_and_idle_time_adds_up() -> None:
    timings = Timings({"baseline": (1e-4, 2)}, utilisation=0.5, runs=4)
    two = estimate(_jobs(("baseline",), 4), 0, workers=2, timings=timings, cores=2)
    four = estimate(_jobs(("baseline",), 4), 0, workers=4, timings=timings, cores=2)
    assert four.per_run_s == pytest.approx(2 * two.per_run_s)  # each run gets half a core
    assert four.total_s == pytest.approx(two.total_s)  # no faster on 2 cores
    assert two.total_s == pytest.approx(4 * 10 / 2 / 0.5)
    assert contention(3, 2) == 1.5


def test_an_arm_never_measured_takes_the_median_and_an_empty_store_the_fallback(tmp_path) -> None:  # type: ignore[no-untyped-def]
    timings = Timings({"baseline": (1e-4, 1)}, runs=1)
    guess = estimate(_jobs(("semantic",), 1), 0, 1, timings, cores=2)
    assert guess.per_run_s == pytest.approx(10) and "a lower bound" in guess.how
    # an arm that asks the VLM takes the median of the timed arms that ask it, not of the others
    timed = Timings({"baseline": (1e-4, 1), "kinematic": (1e-4, 1), "hybrid": (6e-4, 1)}, runs=3)
    both = estimate(_jobs(("semantic", "hybrid-shuffled", "baseline"), 1), 0, 1, timed, cores=2)
    assert both.per_run_s == pytest.approx((60 + 60 + 10) / 3) and "lower bound" not in both.how
    cfg = RunConfig(arms=("baseline",), seeds=(0,), tracking_uri=f"sqlite:///{tmp_path}/none.db")
    cost = estimate_sweeps([cfg])
    assert cost.per_run_s == pytest.approx(cfg.budget * FALLBACK_S_PER_STEP) and "no finished run" in cost.how
    assert not (tmp_path / "none.db").exists()


def test_an_empty_store_estimates_each_task_from_its_own_measured_step_time(tmp_path) -> None:  # type: ignore[no-untyped-def]
    # DoorKey's steps cost about five times MountainCar's: its figure, not MountainCar's, is used
    cfg = RunConfig(task="minigrid-doorkey", plugin=get_task("minigrid-doorkey"), preset="zoo", arms=("baseline",),
                    seeds=(0,), tracking_uri=f"sqlite:///{tmp_path}/none.db")
    step_s = cfg.task_plugin.step_seconds
    assert step_s is not None and step_s > 3 * FALLBACK_S_PER_STEP
    cost = estimate_sweeps([cfg])
    assert cost.per_run_s == pytest.approx(cfg.budget * step_s)
    assert f"minigrid-doorkey {step_s * 1e3:.2f} ms per step" in cost.how


def test_an_empty_store_estimates_a_vlm_arm_from_its_tasks_vlm_figure(tmp_path) -> None:  # type: ignore[no-untyped-def]
    # Pusher's VLM arms render and smooth: their declared figure, not the plain arms', prices them
    cfg = RunConfig(task="pusher", plugin=get_task("pusher"), preset="pusher", arms=("baseline", "hybrid"),
                    seeds=(0,), tracking_uri=f"sqlite:///{tmp_path}/none.db")
    plain, vlm = cfg.task_plugin.step_seconds, cfg.task_plugin.vlm_step_seconds
    assert plain is not None and vlm is not None and vlm > 5 * plain
    cost = estimate_sweeps([cfg])
    assert cost.per_run_s == pytest.approx(cfg.budget * (plain + vlm) / 2)
    assert f"pusher {plain * 1e3:.2f} ms (VLM arms {vlm * 1e3:.2f} ms) per step" in cost.how


# --- a real VLM's queries ------------------------------------------------------------------------

def test_the_hit_rate_table_is_what_the_committed_exports_measure() -> None:
    from vlmrl_cli.sweep.cost import VLM_HIT_RATES, committed_exports, measure_hit_rates

    assert measure_hit_rates(committed_exports()) == VLM_HIT_RATES


def test_vlm_cost_counts_only_the_arms_that_ask_and_scales_with_qps() -> None:
    from vlmrl_cli.sweep.cost import VLM_HIT_RATES, VlmHitRate, vlm_cost
    from vlmrl_cli.training.config import RunConfig

    jobs = RunConfig.from_sources(None, {"preset": "paper", "seeds": [0, 1], "arms": ["baseline", "hybrid"]}).jobs()
    cost = vlm_cost(jobs, qps=3.0)
    assert cost is not None and cost.runs == 2
    assert cost.queries == pytest.approx(2 * 300_000 / 10 * VLM_HIT_RATES["mountain-car"].asked)
    assert vlm_cost(jobs, qps=6.0).seconds == pytest.approx(cost.seconds / 2)  # type: ignore[union-attr]
    assert vlm_cost([j for j in jobs if j.arm.name == "baseline"]) is None
    unmeasured = vlm_cost(jobs, rates={"other": VlmHitRate(1.0, 0.5, 1)})
    assert unmeasured is not None and unmeasured.queries == 2 * 30_000 and "h = 0 assumed" in unmeasured.how

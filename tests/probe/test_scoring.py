"""Table 1's scoring asks the task for everything about its picture (``Task.numbers``,
``Task.milestones``, ``Task.label_potentials``): it imports no task's internals."""

from __future__ import annotations

import dataclasses
from contextlib import closing
from pathlib import Path

import pytest

from tests.mountain_car_helpers import sim_vlm
from tests.test_layers import PACKAGE, _imports, _module_name
from vlmrl_cli.core.errors import BadInput
from vlmrl_cli.probe.scoring import _Planned, plan_frames, probe_frame, sweep_positions, table1_prompts
from vlmrl_cli.probe.taxonomy import TaxonomyConfig, run_taxonomy
from vlmrl_cli.tasks.mountain_car import MOUNTAIN_CAR
from vlmrl_cli.tasks.mountain_car.geometry import GroundTruth
from vlmrl_cli.tasks.mountain_car.probe import NUMBER_PROBE
from vlmrl_cli.tasks.registry import get_task
from vlmrl_cli.vlm.client import VLMClient
from vlmrl_cli.vlm.config import SimKnobs, VLMConfig
from vlmrl_cli.vlm.prompts import PromptKind


@pytest.mark.parametrize("package", ["probe", "vlm"])
def test_no_module_below_the_task_imports_mountain_car(package: str) -> None:
    offending = sorted(f"{_module_name(path)} -> {target}" for path in (PACKAGE / package).rglob("*.py")
                       for target in _imports(path) if target.startswith("vlmrl_cli.tasks.mountain_car"))
    assert not offending, "ask the Task (Task.numbers, Task.sim_profiles) instead:\n" + "\n".join(offending)


def test_the_mountain_car_probe_is_its_geometry() -> None:
    numbers = MOUNTAIN_CAR.numbers
    assert numbers is NUMBER_PROBE
    assert (numbers.low, numbers.high, numbers.width, numbers.height) == (-1.2, 0.6, 600, 400)
    assert [(p, x) for p, x, _ in numbers.panels] == [("a", -0.50), ("b", -0.69)]
    assert numbers.truth(-0.69) == GroundTruth.of(-0.69) and numbers.truth(-0.69).label == "LEFT_SLOPE"
    assert table1_prompts(MOUNTAIN_CAR)[PromptKind.MCQ] is MOUNTAIN_CAR.milestones.prompt


def test_frames_truths_and_potentials_come_from_the_task() -> None:
    asked: list[float] = []

    def truth(x: float) -> GroundTruth:
        asked.append(x)
        return GroundTruth.of(x)

    # the same car, probed over the right half of the track, with its own panels and label map
    numbers = dataclasses.replace(NUMBER_PROBE, low=-0.3, truth=truth,
                                  panels=(("l", -0.2, "left"), ("r", 0.1, "right")))
    flat = tuple((label, 0.5) for label, _ in MOUNTAIN_CAR.label_potentials)
    task = dataclasses.replace(MOUNTAIN_CAR, name="half-car", numbers=numbers, label_potentials=flat)
    planned, is_sweep = plan_frames(4, sim_vlm(), numbers)
    assert is_sweep and [p.x for p in planned] == sorted([*sweep_positions(4, numbers), -0.2, 0.1])
    assert min(p.x for p in planned) == -0.3 and [p.panel for p in planned if p.panel] == ["l", "r"]
    client = VLMClient(sim_vlm(SimKnobs(flicker=0.0, float_noise=0.0, box_failure=0.0, patch_px=1)))
    with closing(numbers.renderer()) as renderer:
        probe = probe_frame(client, task, renderer, _Planned(0.1, "x=0.10", "r", "right"))
    assert asked == [0.1] and probe.truth.label == "NEAR_GOAL"
    assert probe.phi[PromptKind.MCQ] == (0.5, 0.5)  # the task's label map, not MountainCar's
    vlm_phi, true_phi = probe.phi[PromptKind.FLOAT]
    assert true_phi == pytest.approx((0.1 + 0.3) / 0.9) and vlm_phi == pytest.approx(true_phi, abs=0.01)


def test_a_task_with_neither_numbers_nor_probe_states_is_refused_naming_it(tmp_path: Path) -> None:
    cfg = TaxonomyConfig(vlm=VLMConfig(cache_path=tmp_path / "c.sqlite"), states=2, out=tmp_path / "out",
                         tracking_uri=f"sqlite:///{tmp_path}/m.db")
    with pytest.raises(BadInput, match="task 'acrobot' names no probe states"):
        run_taxonomy(cfg, task=dataclasses.replace(get_task("acrobot"), probe_states=None))
    assert not (tmp_path / "out").exists() and not (tmp_path / "m.db").exists()


def test_a_profile_the_task_does_not_offer_is_refused_before_anything(tmp_path: Path) -> None:
    llava = SimKnobs.of_profile("llava-table1", MOUNTAIN_CAR)
    cfg = TaxonomyConfig(vlm=VLMConfig(sim=llava, cache_path=tmp_path / "c.sqlite"), states=2,
                         out=tmp_path / "out", tracking_uri=f"sqlite:///{tmp_path}/m.db")
    plain = dataclasses.replace(MOUNTAIN_CAR, name="plain-car", sim_profiles=())
    with pytest.raises(BadInput, match="unknown simulated-VLM profile 'llava-table1' for task plain-car"):
        run_taxonomy(cfg, task=plain)
    assert not (tmp_path / "out").exists() and not (tmp_path / "m.db").exists()

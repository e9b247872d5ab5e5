"""Config hashes of committed runs, pinned: a refactor that changes any of them would make resume
retrain (and reports miss) every run in results/. Values printed at 35307a3, before this phase."""

from __future__ import annotations

import pytest

from vlmrl_cli.shaping.arms import ARMS
from vlmrl_cli.training.config import RunConfig

PINNED: dict[str, dict[str, str]] = {
    "paper": {"baseline": "fc4e291b3615", "hybrid": "bd68fb4a7e27", "kinematic": "be2dce7a13d6",
              "semantic": "7b6fd37737ff", "hybrid-no-rbf": "f8dcce057c6c", "hybrid-no-lock": "ed6951dbe91a",
              "vision-float": "ea3eac5ddb85"},
    "paper-calibrated": {"baseline": "ccf04fccc253", "hybrid": "cc103936c6f8", "kinematic": "ec359e0a241f",
                         "semantic": "f8cbf055350a", "hybrid-no-rbf": "128b9c1ed665",
                         "hybrid-no-lock": "581366937afc", "vision-float": "3b688a21d30b"},
    "smoke": {"baseline": "2c7507107f7e", "hybrid": "92ef497b0c1b", "kinematic": "64411528ca57",
              "semantic": "afccc2f82c72", "hybrid-no-rbf": "0ed70b419b6d", "hybrid-no-lock": "4f609379462b",
              "vision-float": "9f92e8a0933d"},
}


@pytest.mark.parametrize("preset", sorted(PINNED))
def test_arm_hashes_are_pinned(preset: str) -> None:
    arms = list(PINNED[preset])
    cfg = RunConfig.from_sources(None, {"arms": arms, "seeds": [0], "preset": preset})
    assert {j.arm.name: j.config_hash for j in cfg.jobs()} == PINNED[preset]


def test_overridden_hashes_are_pinned() -> None:
    llava = RunConfig.from_sources(None, {"arms": ["hybrid"], "seeds": [0], "preset": "paper-calibrated"},
                                   ['vlm.sim.profile="llava-table1"'])
    assert llava.jobs()[0].config_hash == "1b80434b426c"
    slower = RunConfig.from_sources(None, {"arms": ["baseline"], "seeds": [0], "preset": "paper"},
                                    ["ppo.normalize_reward=false", "ppo.learning_rate=0.0002"])
    assert slower.jobs()[0].config_hash == "79aba46a767e"


def test_every_arm_of_the_original_seven_is_pinned() -> None:
    assert set(PINNED["paper"]) <= set(ARMS)


#: The other built-in tasks' hashes (their committed runs under results/tasks/), printed at c3927e8
#: before the Task refactor of issue 28: moving MountainCar into its task must not move these either.
TASK_PINNED: dict[tuple[str, str], dict[str, str]] = {
    ("acrobot", "zoo-100k-lr1e-4"): {"baseline": "c7a057560711", "hybrid": "dc0dcccf4d32",
                                     "kinematic": "2a2185d82909", "hybrid-shuffled": "0cc8547736e0",
                                     "semantic": "925193c701c2"},
    ("acrobot", "smoke"): {"baseline": "0634da9fafcc", "hybrid": "71280e51d8c2", "kinematic": "c90698aa83d2",
                           "hybrid-shuffled": "f4a96e13db41", "semantic": "75cf6a079d77"},
    ("mountain-car-continuous", "sb3-default-100k"): {"baseline": "2fbb126d2845", "hybrid": "c65b7cbf4d74",
                                                      "kinematic": "5c1f93a8d245", "hybrid-shuffled": "ee924239aea8",
                                                      "semantic": "af1523fe87a7"},
    ("mountain-car-continuous", "smoke"): {"baseline": "2474d03a33a7", "hybrid": "49e90177566b",
                                           "kinematic": "bd2c3110b39c", "hybrid-shuffled": "c8d76d0e1aef",
                                           "semantic": "7ddfb9236310"},
}

#: DoorKey at its own scales (alpha 0.241, kin_scale 0.172) on the float observation: the study and
#: dose-response of issue 41, printed at their launch; refactors must not move them.
DOORKEY_PINNED = {"baseline": "f6edfe817bcc", "hybrid": "2602860e603b", "kinematic": "5fbf053716e9",
                  "hybrid-shuffled": "f802929538af", "semantic": "072d42d13814", "hybrid-dense-pbrs": "a31ad98117c0"}


def test_doorkey_hashes_at_its_own_scales_are_pinned() -> None:
    cfg = RunConfig.from_sources(None, {"arms": list(DOORKEY_PINNED), "seeds": [0], "preset": "zoo",
                                        "task": "minigrid-doorkey"})
    assert {j.arm.name: j.config_hash for j in cfg.jobs()} == DOORKEY_PINNED


@pytest.mark.parametrize(("task", "preset"), sorted(TASK_PINNED))
def test_other_tasks_hashes_are_pinned(task: str, preset: str) -> None:
    """Their committed runs used the paper's scales (alpha 5, kin_scale 2): given explicitly, they keep
    their hashes. Since issue 41 a task's own scales are its default: the baseline's hash is unmoved
    (no shaping knob enters it), every shaped arm's is new."""
    arms = list(TASK_PINNED[task, preset])
    flags = {"arms": arms, "seeds": [0], "preset": preset, "task": task}
    paper = RunConfig.from_sources(None, flags, ["shaping.alpha=5", "shaping.kin_scale=2"])
    assert {j.arm.name: j.config_hash for j in paper.jobs()} == TASK_PINNED[task, preset]
    own = {j.arm.name: j.config_hash for j in RunConfig.from_sources(None, flags).jobs()}
    assert own["baseline"] == TASK_PINNED[task, preset]["baseline"]
    assert all(own[a] != h for a, h in TASK_PINNED[task, preset].items() if a != "baseline")


def test_label_map_overrides_keep_their_hashes() -> None:
    """A TOML table of some of MountainCar's labels (the rest keep their default), and another
    task's whole map: both hashed as before the label map moved into the tasks."""
    partial = RunConfig.from_sources(None, {"arms": ["hybrid"], "seeds": [0], "preset": "paper"},
                                     ["shaping.label_potentials={GOAL=2.0}"])
    assert partial.jobs()[0].config_hash == "9f70161ccb2b"
    whole = RunConfig.from_sources(None, {"arms": ["hybrid"], "seeds": [0], "preset": "smoke", "task": "acrobot"},
                                   ["shaping.label_potentials={HANGING=0.0, LOW_SWING=0.2, HIGH_SWING=0.5, "
                                    "ABOVE_BAR=1.0}", "shaping.alpha=5", "shaping.kin_scale=2"])
    assert whole.jobs()[0].config_hash == "f781e52f2c48"

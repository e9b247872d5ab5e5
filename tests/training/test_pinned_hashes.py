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

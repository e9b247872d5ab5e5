"""Tests of vlmrl_cli.shaping; helpers shared by these tests live here."""

from __future__ import annotations

from vlmrl_cli.shaping.arms import PotentialSource
from vlmrl_cli.shaping.config import ShapingConfig
from vlmrl_cli.shaping.semantic import SemanticOracle
from vlmrl_cli.tasks.mountain_car import MOUNTAIN_CAR
from vlmrl_cli.vlm.client import VLMClient
from vlmrl_cli.vlm.config import SimKnobs, VLMConfig
from vlmrl_cli.vlm.registry import build_client


def sim_client(flicker: float = 0.1, seed: int = 0) -> VLMClient:
    """The simulated VLM on MountainCar's frames, without the on-disk response cache (tests leave
    no files behind)."""
    return build_client(VLMConfig(backend="sim", use_cache=False, sim=SimKnobs(flicker=flicker, seed=seed)),
                        reader=MOUNTAIN_CAR.reader)


def mc_oracle(client: VLMClient, cfg: ShapingConfig, source: PotentialSource, rbf: bool = True) -> SemanticOracle:
    """A ``SemanticOracle`` of MountainCar-v0 (its labels, features and float question)."""
    return SemanticOracle(client, MOUNTAIN_CAR.shaping_for(cfg), source, MOUNTAIN_CAR.milestones,
                          MOUNTAIN_CAR.camera.feature_dim, rbf=rbf, numbers=MOUNTAIN_CAR.numbers)


class ScriptedBackend:
    """A backend that answers from a fixed list, in order (cycling); for parse-failure paths."""

    name = "scripted"
    model = "script"
    simulated = True

    def __init__(self, answers: list[str]) -> None:
        self.answers = answers
        self.calls = 0

    def answer(self, prompt: object, frame: object) -> str:
        text = self.answers[self.calls % len(self.answers)]
        self.calls += 1
        return text

    def close(self) -> None:
        pass

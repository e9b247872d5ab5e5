from __future__ import annotations

import dataclasses

import pytest

from tests.shaping import ScriptedBackend, mc_oracle, sim_client
from vlmrl_cli.shaping.arms import PotentialSource
from vlmrl_cli.shaping.config import ShapingConfig
from vlmrl_cli.shaping.semantic import EpisodePotential
from vlmrl_cli.tasks.mountain_car import MOUNTAIN_CAR
from vlmrl_cli.tasks.mountain_car.camera import Camera
from vlmrl_cli.tasks.mountain_car.geometry import Zone
from vlmrl_cli.tasks.mountain_car.prompts import NUMBERS
from vlmrl_cli.vlm.client import VLMClient

MCQ, FLOAT = PotentialSource.MCQ, PotentialSource.FLOAT
float_potential = NUMBERS.potential


@pytest.fixture(scope="module")
def camera():
    cam = Camera(0.001)
    yield cam
    cam.close()


def scripted(*answers: str) -> tuple[VLMClient, ScriptedBackend]:
    backend = ScriptedBackend(list(answers))
    return VLMClient(backend), backend  # type: ignore[arg-type]


def test_stats_have_exactly_the_documented_keys() -> None:
    oracle = mc_oracle(sim_client(), ShapingConfig(), MCQ)
    assert tuple(oracle.stats()) == (
        "vlm/queries", "vlm/cache_hits", "vlm/prototypes", "vlm/label_reuses", "vlm/parse_failures",
        "vlm/backend_calls", "vlm/backend_frames", "vlm/largest_batch", "vlm/backend_s", "vlm/budget_labels",
        "vlm/scored", "vlm/generated")
    assert all(v == 0.0 for v in oracle.stats().values())


def test_near_frames_reuse_a_prototype_and_far_frames_ask(camera: Camera) -> None:
    cfg = ShapingConfig()
    oracle = mc_oracle(sim_client(flicker=0.0), cfg, MCQ)
    assert oracle.label(camera.view(-0.52)) == MOUNTAIN_CAR.shaping_for(cfg).potential_of(Zone.BOTTOM)
    assert oracle.label(camera.view(-0.5203)) == 0.0  # a third of a pixel away: reused
    assert oracle.label(camera.view(-1.0)) == MOUNTAIN_CAR.shaping_for(cfg).potential_of(Zone.LEFT_PEAK)  # far: asked
    stats = oracle.stats()
    assert stats | {"vlm/backend_s": 0.0} == {
        "vlm/queries": 2.0, "vlm/cache_hits": 0.0, "vlm/prototypes": 2.0, "vlm/label_reuses": 1.0,
        "vlm/parse_failures": 0.0, "vlm/backend_calls": 2.0, "vlm/backend_frames": 2.0, "vlm/largest_batch": 1.0,
        "vlm/backend_s": 0.0, "vlm/budget_labels": 0.0, "vlm/scored": 0.0,
        "vlm/generated": 2.0}  # asked one by one: two calls of one frame, each generated
    assert stats["vlm/backend_s"] > 0


def test_an_identical_frame_is_asked_once_and_its_own_label_reused(camera: Camera) -> None:
    client, backend = scripted("BOTTOM", "GOAL")
    oracle = mc_oracle(client, ShapingConfig(reuse_radius=0.0), MCQ)
    assert [oracle.label(camera.view(-0.5)) for _ in range(3)] == [0.0, 0.0, 0.0]
    assert backend.calls == 1 and oracle.prototypes == 1 and oracle.stats()["vlm/label_reuses"] == 2.0
    assert oracle.label(camera.view(-0.49)) == 1.0  # another picture, even one pixel away, is asked
    assert backend.calls == 2


def test_unparsed_answers_are_counted_and_add_no_prototype(camera: Camera) -> None:
    client, _ = scripted("I cannot tell.")
    oracle = mc_oracle(client, ShapingConfig(), MCQ)
    assert oracle.label(camera.view(-0.5)) is None
    assert oracle.stats()["vlm/parse_failures"] == 1.0 and oracle.prototypes == 0


def test_float_answers_map_x_onto_zero_one(camera: Camera) -> None:
    client, _ = scripted("x = -0.3", "far away", "7.5")
    oracle = mc_oracle(client, ShapingConfig(reuse_radius=0.0), FLOAT, rbf=False)
    assert oracle.label(camera.view(-0.5)) == pytest.approx(0.5)
    assert oracle.label(camera.view(-0.49)) is None
    assert oracle.label(camera.view(-0.48)) is None  # out of range is not a parsed answer
    assert oracle.stats()["vlm/parse_failures"] == 2.0
    assert float_potential(-0.3) == pytest.approx(0.5)


def test_phi_rbf_follows_new_prototypes(camera: Camera) -> None:
    oracle = mc_oracle(sim_client(flicker=0.0), ShapingConfig(), MCQ)
    view = camera.view(-1.0)
    assert oracle.phi_rbf(view) == 0.0  # no prototype yet
    oracle.label(camera.view(-1.0))
    assert oracle.phi_rbf(view) == pytest.approx(0.3)  # the new prototype updates the memoised value


def test_labels_every_query_every_steps_including_step_zero(camera: Camera) -> None:
    client, backend = scripted("BOTTOM")
    oracle = mc_oracle(client, ShapingConfig(reuse_radius=0.0, query_every=10), MCQ)
    episode = EpisodePotential(oracle, lock=True)
    views = [camera.view(-0.5 + 0.004 * t) for t in range(26)]  # a new picture every step
    episode.reset(views[0])
    calls = [backend.calls]
    for view in views[1:]:
        episode.step(view)
        calls.append(backend.calls)
    assert [t for t in range(1, 26) if calls[t] > calls[t - 1]] == [10, 20]
    assert calls[0] == 1


def test_lock_holds_within_an_episode_and_resets_at_the_start(camera: Camera) -> None:
    client, _ = scripted("GOAL", "GOAL", "BOTTOM", "LEFT_SLOPE", "BOTTOM")
    cfg = ShapingConfig(reuse_radius=0.0, query_every=1, confirm=2)
    episode = EpisodePotential(mc_oracle(client, cfg, MCQ, rbf=False), lock=True)
    views = [camera.view(-0.5 + 0.004 * t) for t in range(5)]  # distinct pictures: each one is asked
    phis = [episode.reset(views[0])] + [episode.step(v) for v in views[1:4]]
    assert phis == [1.0, 1.0, 1.0, 1.0]  # held GOAL, then locked at GOAL despite BOTTOM / LEFT_SLOPE
    assert episode.lock_state.level == 1.0
    assert episode.reset(views[4]) == 0.0 and episode.lock_state.level == 0.0  # new episode: BOTTOM, unlocked


def test_hybrid_is_the_max_of_lock_and_rbf_and_no_lock_is_rbf(camera: Camera) -> None:
    client, _ = scripted("NEAR_GOAL", "BOTTOM")
    cfg = ShapingConfig(reuse_radius=0.0, query_every=1, confirm=2)
    oracle = mc_oracle(client, cfg, MCQ, rbf=True)
    locked, free = EpisodePotential(oracle, lock=True), EpisodePotential(oracle, lock=False)
    near_goal, bottom = camera.view(0.3), camera.view(-0.5)
    locked.reset(near_goal)
    locked.step(near_goal)  # the same picture's label reused: NEAR_GOAL confirmed, level 0.6
    free.reset(bottom)  # asks once more: BOTTOM at the valley
    rbf = oracle.phi_rbf(bottom)
    assert rbf < 0.05  # the BOTTOM prototype dominates; NEAR_GOAL is far in feature space
    assert locked.step(bottom) == max(0.6, rbf) == 0.6  # BOTTOM's label reused: the lock keeps 0.6
    assert free.step(bottom) == rbf


def test_parse_failure_keeps_the_previous_potential(camera: Camera) -> None:
    client, _ = scripted("x = -0.3", "nothing", "nothing")
    cfg = ShapingConfig(reuse_radius=0.0, query_every=1)
    episode = EpisodePotential(mc_oracle(client, cfg, FLOAT, rbf=False), lock=False)
    a, b, c = camera.view(-0.5), camera.view(-0.49), camera.view(-0.48)
    assert [episode.reset(a), episode.step(b), episode.step(c)] == pytest.approx([0.5, 0.5, 0.5])


@pytest.mark.parametrize("change", [{"bandwidth": 0.0}, {"reuse_radius": -1.0}, {"query_every": 0}, {"confirm": 0}])
def test_invalid_config_is_rejected(change: dict) -> None:
    with pytest.raises(ValueError):
        mc_oracle(sim_client(), dataclasses.replace(ShapingConfig(), **change), MCQ)


def test_an_arm_without_potential_needs_no_oracle() -> None:
    with pytest.raises(ValueError, match="potential source"):
        mc_oracle(sim_client(), ShapingConfig(), PotentialSource.NONE)


def test_deep_copies_of_an_env_share_the_oracle_and_its_cached_client(tmp_path) -> None:  # type: ignore[no-untyped-def]
    """RecordConstructorArgs deep-copies wrapper arguments; the run's oracle (with an open sqlite
    response cache) must be shared, not cloned."""
    import copy

    from vlmrl_cli.shaping.arms import PotentialSource
    from vlmrl_cli.shaping.config import ShapingConfig
    from vlmrl_cli.vlm.config import VLMConfig
    from vlmrl_cli.vlm.registry import build_client

    client = build_client(VLMConfig(backend="sim", cache_path=tmp_path / "c.sqlite"), reader=MOUNTAIN_CAR.reader)
    oracle = mc_oracle(client, ShapingConfig(), PotentialSource.MCQ)
    assert copy.deepcopy({"oracle": oracle})["oracle"] is oracle
    client.close()


class _Stochastic(ScriptedBackend):
    stochastic = True


def test_a_stochastic_vlm_is_asked_every_time_and_its_newest_answer_wins(camera: Camera) -> None:
    cfg = ShapingConfig()
    backend = _Stochastic(["BOTTOM", "LEFT_PEAK", "BOTTOM"])
    oracle = mc_oracle(VLMClient(backend), cfg, MCQ)  # type: ignore[arg-type]
    view = camera.view(-0.5)
    assert oracle.label(view) == MOUNTAIN_CAR.shaping_for(cfg).potential_of(Zone.BOTTOM)
    assert oracle.phi_rbf(view) == MOUNTAIN_CAR.shaping_for(cfg).potential_of(Zone.BOTTOM)
    assert oracle.label(view) == MOUNTAIN_CAR.shaping_for(cfg).potential_of(Zone.LEFT_PEAK)  # asked again, not reused
    # one prototype, updated
    assert oracle.phi_rbf(view) == pytest.approx(MOUNTAIN_CAR.shaping_for(cfg).potential_of(Zone.LEFT_PEAK))
    assert oracle.prototypes == 1 and backend.calls == 2
    assert oracle.stats()["vlm/label_reuses"] == 0.0
    assert oracle.label(view) == MOUNTAIN_CAR.shaping_for(cfg).potential_of(Zone.BOTTOM)
    assert oracle.phi_rbf(view) == pytest.approx(MOUNTAIN_CAR.shaping_for(cfg).potential_of(Zone.BOTTOM))

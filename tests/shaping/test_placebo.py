"""The placebo arm's shuffled label map: a balanced, seed-determined permutation."""

from __future__ import annotations

import dataclasses

from hypothesis import given
from hypothesis import strategies as st

from tests.shaping import sim_client
from vlmrl_cli.shaping.arms import ARMS
from vlmrl_cli.shaping.config import ShapingConfig
from vlmrl_cli.shaping.placebo import describe_map, latin_permutation, oracle_shaping, permutation, placebo_map
from vlmrl_cli.tasks.mountain_car import MOUNTAIN_CAR
from vlmrl_cli.tasks.mountain_car.task import ZONE_POTENTIALS as DEFAULT_LABEL_POTENTIALS
from vlmrl_cli.training.config import RunConfig
from vlmrl_cli.training.envs import make_train_env
from vlmrl_cli.training.presets import preset_of

seeds = st.integers(0, 10_000)


@given(st.integers(0, 12), seeds)
def test_permutations_are_permutations(n: int, seed: int) -> None:
    assert sorted(permutation(n, seed)) == list(range(n))
    assert sorted(latin_permutation(n, seed)) == list(range(n))


@given(seeds)
def test_the_map_keeps_labels_in_order_and_the_multiset_of_potentials(seed: int) -> None:
    shuffled = placebo_map(DEFAULT_LABEL_POTENTIALS, seed)
    assert [z for z, _ in shuffled] == [z for z, _ in DEFAULT_LABEL_POTENTIALS]
    assert sorted(p for _, p in shuffled) == sorted(p for _, p in DEFAULT_LABEL_POTENTIALS)
    assert placebo_map(DEFAULT_LABEL_POTENTIALS, seed) == shuffled  # a pure function of the seed


@given(st.integers(0, 50))
def test_every_block_of_seeds_gives_each_label_each_potential_once(block: int) -> None:
    n = len(DEFAULT_LABEL_POTENTIALS)
    maps = [dict(placebo_map(DEFAULT_LABEL_POTENTIALS, seed)) for seed in range(block * n, (block + 1) * n)]
    values = sorted(p for _, p in DEFAULT_LABEL_POTENTIALS)
    mean = sum(values) / n
    for zone, _ in DEFAULT_LABEL_POTENTIALS:
        assert sorted(m[zone] for m in maps) == values
        assert abs(sum(m[zone] for m in maps) / n - mean) < 1e-12  # no information, on average


def test_seeds_get_different_maps() -> None:
    maps = {placebo_map(DEFAULT_LABEL_POTENTIALS, seed) for seed in range(20)}
    assert len(maps) >= 15


def test_only_the_placebo_arm_changes_the_oracle_map() -> None:
    cfg = ShapingConfig()
    for name, arm in ARMS.items():
        mapped = oracle_shaping(arm, cfg, seed=3)
        if name == "hybrid-shuffled":
            assert mapped.label_potentials == placebo_map(cfg.label_potentials, 3)
            assert dataclasses.replace(mapped, label_potentials=cfg.label_potentials) == cfg
        else:
            assert mapped is cfg


def test_the_placebo_run_builds_its_oracle_with_the_shuffled_map() -> None:
    arm = ARMS["hybrid-shuffled"]
    env, oracle = make_train_env(arm, preset_of(MOUNTAIN_CAR, "smoke"), ShapingConfig(), sim_client(), seed=4,
                                 task=MOUNTAIN_CAR)
    try:
        assert oracle is not None
        assert tuple(oracle.cfg.label_potentials) == placebo_map(DEFAULT_LABEL_POTENTIALS, 4)
    finally:
        env.close()


def test_the_placebo_is_a_new_cell_and_the_hybrid_keeps_its_hash() -> None:
    cfg = RunConfig.from_sources(None, {"arms": ["hybrid", "hybrid-shuffled"], "seeds": [0], "preset": "paper"})
    hybrid, placebo = cfg.jobs()
    assert hybrid.config_hash == "bd68fb4a7e27"
    assert placebo.config_hash != hybrid.config_hash
    assert placebo.params()["arm"]["placebo"] is True and "placebo" not in hybrid.params()["arm"]


def test_describe_map_names_every_label() -> None:
    line = describe_map(placebo_map(DEFAULT_LABEL_POTENTIALS, 0))
    assert [part.split("=")[0] for part in line.split()] == [str(z) for z, _ in DEFAULT_LABEL_POTENTIALS]

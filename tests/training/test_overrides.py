"""Override parsing and the precedence preset < config file < --set < flags."""

from __future__ import annotations

import dataclasses
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from vlmrl_cli.core.errors import BadInput
from vlmrl_cli.tasks.registry import get_task
from vlmrl_cli.training.config import resolve
from vlmrl_cli.training.overrides import dotted, merge, nest, parse_assignment, parse_value, parse_values
from vlmrl_cli.training.presets import PPOConfig, preset_of

KEYS = st.from_regex(r"[a-z][a-z_]{0,8}", fullmatch=True)
SCALARS = st.one_of(
    st.integers(-(10**9), 10**9),
    st.booleans(),
    st.floats(allow_nan=False, allow_infinity=False),
    st.from_regex(r"[a-z][a-z_]{0,8}", fullmatch=True).filter(lambda s: s not in ("true", "false", "inf", "nan")),
)
TREES = st.recursive(SCALARS, lambda inner: st.dictionaries(KEYS, inner, max_size=3), max_leaves=8)


def _toml_literal(value: Any) -> str:
    """How a user types ``value`` after ``--set KEY=``: TOML spelling, bare words unquoted."""
    if isinstance(value, bool):
        return "true" if value else "false"
    return value if isinstance(value, str) else repr(value)


@given(SCALARS)
def test_a_set_value_reads_back_as_the_toml_value_it_spells(value: Any) -> None:
    assert parse_value(_toml_literal(value)) == value


@given(st.lists(st.integers(0, 10**6), min_size=1, max_size=5))
def test_grid_values_and_comma_lists_parse_to_the_same_integers(values: list[int]) -> None:
    text = ",".join(map(str, values))
    assert parse_values(text) == values
    if len(values) > 1:
        assert parse_value(text) == values


@given(st.lists(st.tuples(st.lists(KEYS, min_size=1, max_size=3).map(".".join), SCALARS), max_size=6))
def test_nest_keeps_the_last_assignment_of_every_dotted_key(assignments: list[tuple[str, Any]]) -> None:
    try:
        tree = nest(assignments)
    except BadInput:
        return  # a key used both as a value and as a table: refused, as it must be
    last = dict(assignments)
    for key, value in last.items():
        node: Any = tree
        for part in key.split("."):
            node = node[part]
        assert node == value


@given(st.lists(st.tuples(st.lists(KEYS, min_size=1, max_size=3).map(".".join), SCALARS), max_size=6))
def test_dotted_is_nest_s_inverse(assignments: list[tuple[str, Any]]) -> None:
    try:
        tree = nest(assignments)
    except BadInput:
        return
    assert dotted(tree) == dict(assignments)
    assert nest(dotted(tree).items()) == tree


@given(st.dictionaries(KEYS, TREES, max_size=4), st.dictionaries(KEYS, TREES, max_size=4))
def test_merge_lets_the_top_layer_win_and_keeps_what_it_does_not_set(base: dict[str, Any], top: dict[str, Any]) -> None:
    merged = merge(base, top)
    assert set(merged) == set(base) | set(top)
    for key, value in top.items():
        if isinstance(value, dict) and isinstance(base.get(key), dict):
            assert merged[key] == merge(base[key], value)
        else:
            assert merged[key] == value
    for key in set(base) - set(top):
        assert merged[key] == base[key]
    assert merge(merged, top) == merged  # laying the same layer twice changes nothing


PPO_INTS = st.sampled_from(["n_epochs", "timesteps", "eval_episodes"])


@settings(deadline=None)  # the first example builds the schema's pydantic models (0.2-0.4 s on a busy machine)
@given(
    key=PPO_INTS,
    file_v=st.integers(1, 100),  # within each key's upper bound (n_epochs: 100)
    set_v=st.integers(1, 100),
    flag_v=st.integers(1, 100),
    present=st.tuples(st.booleans(), st.booleans(), st.booleans()),
)
def test_precedence_is_preset_then_file_then_set_then_flags(
    key: str, file_v: int, set_v: int, flag_v: int, present: tuple[bool, bool, bool]
) -> None:
    values = (file_v, set_v, flag_v)
    layers = [
        {"preset": "smoke", "ppo": {key: v}} if on else {"preset": "smoke"}
        for v, on in zip(values, present, strict=True)
    ]
    cfg = resolve(layers)
    expected = next(
        (v for v, on in zip(reversed(values), reversed(present), strict=True) if on),
        getattr(preset_of(get_task("mountain-car"), "smoke"), key)
    )
    assert getattr(cfg.ppo_config, key) == expected
    smoke = preset_of(get_task("mountain-car"), "smoke")
    assert cfg.ppo_config.n_envs == smoke.n_envs  # untouched knobs keep the preset's value


def test_the_highest_layer_that_names_a_preset_chooses_the_base() -> None:
    cfg = resolve([{"preset": "sb3-default"}, {}, {"preset": "smoke", "ppo": {"n_envs": 1, "n_steps": 128}}])
    assert cfg.preset == "smoke"
    assert cfg.ppo_config == dataclasses.replace(preset_of(get_task("mountain-car"), "smoke"), n_envs=1, n_steps=128)


@pytest.mark.parametrize("text", ["ppo.n_envs", "=3", "ppo..n_envs=3", ""])
def test_a_malformed_assignment_is_bad_input(text: str) -> None:
    with pytest.raises(BadInput, match="KEY=VALUE"):
        parse_assignment(text)


def test_a_key_below_a_value_is_bad_input() -> None:
    with pytest.raises(BadInput, match="'ppo' is a value"):
        nest([("ppo", 3), ("ppo.n_envs", 1)])


def test_every_ppo_knob_is_settable_and_typed() -> None:
    layer = {
        "ppo": {
            "n_envs": 1,
            "n_steps": 128,
            "batch_size": 32,
            "n_epochs": 3,
            "learning_rate": 1e-3,
            "lr_schedule": "linear",
            "gamma": 0.95,
            "gae_lambda": 0.9,
            "clip_range": 0.1,
            "ent_coef": 0.01,
            "vf_coef": 0.25,
            "max_grad_norm": 1,
            "normalize_obs": True,
            "normalize_reward": False,
            "net_arch_pi": [32],
            "net_arch_vf": [128, 128],
            "timesteps": 5000,
            "eval_episodes": 7,
            "use_sde": False,
            "log_std_init": -1.0,
            "ortho_init": False,
        }
    }
    assert set(layer["ppo"]) == {f.name for f in dataclasses.fields(PPOConfig)}
    ppo = resolve([layer]).ppo_config
    assert ppo.net_arch_vf == (128, 128) and ppo.max_grad_norm == 1.0 and isinstance(ppo.max_grad_norm, float)
    assert ppo.lr_schedule == "linear" and ppo.normalize_reward is False and ppo.timesteps == 5000

from __future__ import annotations

import dataclasses
import itertools
import math
import tomllib
from pathlib import Path
from typing import Any

import pytest
from hypothesis import given
from hypothesis import strategies as st

from vlmrl_cli.core.errors import BadInput
from vlmrl_cli.core.provenance import to_jsonable
from vlmrl_cli.tasks.mountain_car.geometry import Zone
from vlmrl_cli.tasks.registry import get_task
from vlmrl_cli.training.config import RunConfig, load_config_file, resolve, to_toml
from vlmrl_cli.training.presets import preset_of
from vlmrl_cli.vlm.config import SimKnobs, VLMConfig


def _write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "run.toml"
    path.write_text(text)
    return path


def test_every_knob_loads_from_one_toml_file(tmp_path: Path) -> None:
    path = _write(tmp_path, """
arms = ["baseline", "semantic"]
seeds = [3, 7]
preset = "smoke"
timesteps = 512
workers = 1
experiment = "exp"

[vlm]
backend = "sim"
cache_path = "c.sqlite"

[vlm.sim]
flicker = 0.3

[shaping]
alpha = 2.5
query_every = 4

[shaping.label_potentials]
LEFT_PEAK = 0.4
""")
    cfg = resolve([load_config_file(path)])
    cfg.validate()
    assert cfg.arms == ("baseline", "semantic") and cfg.seeds == (3, 7)
    assert cfg.budget == 512 and cfg.workers == 1 and cfg.experiment == "exp"
    assert cfg.vlm.sim.flicker == 0.3 and cfg.vlm.cache_path == Path("c.sqlite")
    assert cfg.shaping.alpha == 2.5 and cfg.shaping.query_every == 4
    assert cfg.shaping.potential_of(Zone.LEFT_PEAK) == 0.4
    assert cfg.shaping.potential_of(Zone.BOTTOM) == 0.0  # untouched labels keep the default


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("colour = 'red'", "unknown key 'colour'"),
        ("[shaping]\nbandwith = 1.0", r"unknown key 'shaping.bandwith' \(did you mean 'shaping.bandwidth'\?\)"),
        ("[shaping.label_potentials]\nSKY = 1.0", "unknown label 'SKY'"),
        ("[vlm.sim]\nflick = 0.1", "unknown key 'vlm.sim.flick'"),
        ("[shaping]\nalpha = 'big'", "invalid shaping.alpha"),
        ("timesteps = 5\n[ppo]\ntimesteps = 6", "set ppo.timesteps once"),
    ],
)
def test_malformed_config_files_are_bad_input(tmp_path: Path, text: str, match: str) -> None:
    with pytest.raises(BadInput, match=match):
        resolve([load_config_file(_write(tmp_path, text))])


def test_invalid_toml_is_bad_input(tmp_path: Path) -> None:
    with pytest.raises(BadInput, match="not valid TOML"):
        load_config_file(_write(tmp_path, "arms = ["))


def test_top_level_timesteps_of_older_files_land_in_ppo(tmp_path: Path) -> None:
    cfg = resolve([load_config_file(_write(tmp_path, 'preset = "smoke"\ntimesteps = 512\neval_episodes = 3'))])
    assert cfg.budget == 512 and cfg.ppo_config.eval_episodes == 3 and cfg.ppo_config.n_envs == 2


def test_missing_config_file_is_bad_input(tmp_path: Path) -> None:
    with pytest.raises(BadInput, match="cannot read"):
        load_config_file(tmp_path / "nope.toml")


@pytest.mark.parametrize(
    ("changes", "match"),
    [
        ({"arms": ("baseline", "teleport")}, "unknown arm 'teleport'"),
        ({"preset": "huge"}, "unknown preset 'huge'"),
        ({"seeds": ()}, "no seed"),
        ({"seeds": (1, 1)}, "twice"),
        ({"ppo": dataclasses.replace(preset_of(get_task("mountain-car"), "smoke"), timesteps=0)}, "ppo.timesteps"),
        ({"workers": 0}, "invalid workers"),
        ({"vlm": VLMConfig(backend="gpt9")}, "unknown VLM backend"),
    ],
)
def test_validate_rejects_bad_values_before_training(changes: dict[str, object], match: str) -> None:
    with pytest.raises(BadInput, match=match):
        dataclasses.replace(RunConfig(), **changes).validate()  # type: ignore[arg-type]


def test_jobs_cover_every_arm_and_seed_with_the_preset_budget() -> None:
    cfg = RunConfig(arms=("baseline", "hybrid"), seeds=(0, 1, 2), preset="smoke")
    jobs = cfg.jobs()
    assert [j.name for j in jobs] == ["baseline-s0", "baseline-s1", "baseline-s2", "hybrid-s0", "hybrid-s1",
                                      "hybrid-s2"]
    assert {j.timesteps for j in jobs} == {1_024}


def test_config_hash_ignores_the_seed_and_knobs_an_arm_does_not_use() -> None:
    base = RunConfig(arms=("baseline", "hybrid"), seeds=(0, 1), preset="smoke")
    other_vlm = dataclasses.replace(base, vlm=VLMConfig(sim=SimKnobs(flicker=0.5)))
    b0, b1, h0, _ = base.jobs()
    assert b0.config_hash == b1.config_hash  # seed excluded
    ob0, _, oh0, _ = other_vlm.jobs()
    assert ob0.config_hash == b0.config_hash  # the baseline uses no VLM: not redone
    assert oh0.config_hash != h0.config_hash  # the hybrid does
    no_cache = dataclasses.replace(base, vlm=VLMConfig(use_cache=False))
    assert no_cache.jobs()[2].config_hash == h0.config_hash  # the cache changes speed, not answers
    smoke = preset_of(get_task("mountain-car"), "smoke")
    longer = dataclasses.replace(base, ppo=dataclasses.replace(smoke, timesteps=2_048))
    assert longer.jobs()[0].config_hash != b0.config_hash


def test_the_preset_name_is_a_label_the_resolved_values_are_the_identity() -> None:
    paper = RunConfig(arms=("baseline",), seeds=(0,), preset="paper")
    zoo_cut = dataclasses.replace(paper, preset="zoo", ppo=preset_of(get_task("mountain-car"), "paper"))
    assert paper.jobs()[0].config_hash == zoo_cut.jobs()[0].config_hash
    assert zoo_cut.jobs()[0].overrides() == {"ppo.timesteps": "300000"}
    assert paper.jobs()[0].overrides() == {}
    one_env = dataclasses.replace(paper, ppo=dataclasses.replace(preset_of(get_task("mountain-car"), "paper"), n_envs=1,
                                                                 n_steps=256))
    assert one_env.jobs()[0].config_hash != paper.jobs()[0].config_hash
    assert one_env.jobs()[0].overrides() == {"ppo.n_envs": "1", "ppo.n_steps": "256"}


def test_the_sim_profile_enters_the_hash_but_the_default_keeps_the_old_one() -> None:
    hybrid = {"arms": ["hybrid", "baseline"], "seeds": [0]}
    default = resolve([hybrid])
    named = resolve([hybrid, {"vlm": {"sim": {"profile": "default"}}}])
    llava = resolve([hybrid, {"vlm": {"sim": {"profile": "llava-table1"}}}])
    assert default.jobs()[0].config_hash == named.jobs()[0].config_hash == "bd68fb4a7e27"  # as before profiles
    assert llava.jobs()[0].config_hash != default.jobs()[0].config_hash
    assert llava.jobs()[1].config_hash == default.jobs()[1].config_hash  # the baseline queries no VLM
    assert "vlm.sim.profile" in llava.jobs()[0].overrides()
    # an explicit knob, in any layer, beats the profile's value
    mixed = resolve([{"vlm": {"sim": {"flicker": 0.3}}}, {"vlm": {"sim": {"profile": "ideal"}}}])
    assert mixed.vlm.sim.flicker == 0.3 and mixed.vlm.sim.patch_px == 1


@given(
    n_envs=st.integers(1, 32),
    n_steps=st.integers(4, 512),
    lr=st.floats(1e-6, 1.0),
    schedule=st.sampled_from(["constant", "linear"]),
    norm=st.tuples(st.booleans(), st.booleans()),
    arch=st.lists(st.integers(1, 256), max_size=3).map(tuple),
)
def test_to_toml_reads_back_to_the_same_config(
    n_envs: int, n_steps: int, lr: float, schedule: str, norm: tuple[bool, bool], arch: tuple[int, ...]
) -> None:
    ppo = {
        "n_envs": n_envs,
        "n_steps": n_steps,
        # a minibatch size SB3 takes whole: one that divides the rollout (at least 2)
        "batch_size": math.gcd(64, n_envs * n_steps) if math.gcd(64, n_envs * n_steps) > 1 else n_envs * n_steps,
        "learning_rate": lr,
        "lr_schedule": schedule,
        "normalize_obs": norm[0],
        "normalize_reward": norm[1],
        "net_arch_pi": list(arch),
    }
    cfg = resolve(
        [
            {
                "preset": "smoke",
                "ppo": ppo,
                "shaping": {"alpha": 3, "label_potentials": {"GOAL": 0.9}},
                "vlm": {"sim": {"flicker": 0.3}},
            }
        ]
    )
    again = resolve([tomllib.loads(to_toml(cfg))])
    assert again == dataclasses.replace(cfg, ppo=cfg.ppo_config)
    assert [j.config_hash for j in again.jobs()] == [j.config_hash for j in cfg.jobs()]


@pytest.mark.parametrize(("in_file", "in_set", "in_flag"), list(itertools.product([False, True], repeat=3)))
def test_from_sources_lets_flags_beat_set_beat_the_file_beat_the_preset(
    tmp_path: Path, in_file: bool, in_set: bool, in_flag: bool
) -> None:
    path = _write(tmp_path, 'preset = "smoke"\n' + ("[ppo]\nn_epochs = 2\n" if in_file else ""))
    sets = ["ppo.n_epochs=3"] if in_set else []
    flags = {"ppo.n_epochs": 4} if in_flag else {}
    cfg = RunConfig.from_sources(path, flags, sets)
    smoke = preset_of(get_task("mountain-car"), "smoke")
    expected = 4 if in_flag else 3 if in_set else 2 if in_file else smoke.n_epochs
    assert cfg.preset == "smoke" and cfg.ppo_config == dataclasses.replace(smoke, n_epochs=expected)


def test_from_sources_takes_the_preset_of_the_highest_source_that_names_one(tmp_path: Path) -> None:
    path = _write(tmp_path, 'preset = "smoke"\nseeds = [7]\n')
    by_set = RunConfig.from_sources(path, {}, ["preset=sb3-default"])
    assert by_set.preset == "sb3-default" and by_set.ppo_config == preset_of(get_task("mountain-car"), "sb3-default")
    by_flag = RunConfig.from_sources(path, {"preset": "zoo", "arms": ["hybrid"]}, ["preset=sb3-default"])
    assert by_flag.ppo_config == preset_of(get_task("mountain-car"), "zoo")
    assert by_flag.arms == ("hybrid",) and by_flag.seeds == (7,)
    assert RunConfig.from_sources(None).ppo_config == preset_of(get_task("mountain-car"), RunConfig.preset)


@pytest.mark.parametrize(
    ("sets", "match"),
    [
        (["ppo.n_envs"], "KEY=VALUE"),
        (["=3"], "KEY=VALUE"),
        (["ppo..n_envs=3"], "KEY=VALUE"),
        (["ppo.n_envs=abc"], "ppo.n_envs"),
        (["ppo.nenvs=1"], "did you mean 'ppo.n_envs'"),
        (["ppo=3", "ppo.n_envs=1"], "'ppo' is a value"),
        (["preset=huge"], "unknown preset 'huge'"),
    ],
)
def test_from_sources_turns_a_bad_set_into_bad_input(sets: list[str], match: str) -> None:
    with pytest.raises(BadInput, match=match):
        RunConfig.from_sources(None, {}, sets)


def test_from_sources_with_a_missing_file_is_bad_input(tmp_path: Path) -> None:
    with pytest.raises(BadInput, match="cannot read"):
        RunConfig.from_sources(tmp_path / "nope.toml", {}, [])


def test_the_default_preset_is_the_default_tasks_own() -> None:
    from vlmrl_cli.tasks.registry import get_task
    from vlmrl_cli.training.config import DEFAULT_PRESET, DEFAULT_TASK

    assert get_task(DEFAULT_TASK).default_preset == DEFAULT_PRESET == RunConfig().preset
    assert RunConfig().task == DEFAULT_TASK


@given(n_envs=st.integers(1, 8), n_steps=st.integers(1, 64), batch_size=st.integers(1, 600))
def test_a_ppo_config_is_accepted_exactly_when_sb3_takes_whole_minibatches(n_envs: int, n_steps: int,
                                                                           batch_size: int) -> None:
    # SB3's PPO asserts batch_size > 1 and a rollout > 1 (it normalises advantages) and only warns on
    # a batch_size that does not divide the rollout, training then on a truncated last minibatch
    rollout = n_envs * n_steps
    whole = 2 <= batch_size <= rollout and rollout % batch_size == 0
    sets = [f"ppo.n_envs={n_envs}", f"ppo.n_steps={n_steps}", f"ppo.batch_size={batch_size}"]
    try:
        RunConfig.from_sources(None, {}, sets)
    except BadInput as exc:
        assert not whole, exc
        assert "inconsistent [ppo]" in str(exc)
        if batch_size <= rollout and rollout >= 2:  # the fix is named: sizes that divide the rollout
            assert f"use a batch_size that divides {rollout}, e.g. " in str(exc)
    else:
        assert whole


def test_every_builtin_tasks_presets_and_calibration_grid_pass_the_ppo_rules() -> None:
    from vlmrl_cli.tasks.registry import BUILTIN, get_task

    for name in BUILTIN:
        task = get_task(name)
        for preset in task.presets:
            preset_of(get_task(name), preset)  # checked like a config file, the consistency rules included
        for regime in task.calibration:
            sets = [f"{key}={str(value).lower() if isinstance(value, bool) else value}"
                    for key, value in regime.items()]
            RunConfig.from_sources(None, {"task": name}, sets)


def test_the_task_is_resolved_once_and_carried_whole() -> None:
    """A config's task name becomes its Task where the config is built (by the command's lookup), and
    the config and its jobs carry that same object; a pickled job crosses as the name alone."""
    import pickle

    calls: list[str] = []

    def lookup(name: str) -> Any:
        calls.append(name)
        return get_task(name)

    cfg = RunConfig.from_sources(None, {"task": "acrobot", "arms": ["baseline", "hybrid"], "seeds": [0, 1],
                                        "preset": "smoke"}, tasks=lookup)
    assert calls == ["acrobot"]
    jobs = cfg.jobs()
    assert all(job.task_plugin is cfg.task_plugin for job in jobs) and cfg.task_plugin.name == "acrobot"
    assert "plugin" not in to_jsonable(cfg) and calls == ["acrobot"]  # serialised as its name; no lookup again
    crossed = pickle.loads(pickle.dumps(jobs[1]))
    assert crossed.plugin is None
    with pytest.raises(RuntimeError, match="resolves a job's task at its entry"):
        crossed.task_plugin  # noqa: B018
    from vlmrl_cli.sweep.worker import with_task

    assert with_task(crossed).task_plugin.name == "acrobot" and with_task(crossed).config_hash == jobs[1].config_hash


def test_a_config_built_without_the_registry_names_what_to_pass() -> None:
    with pytest.raises(BadInput, match=r"not built in; .*pass tasks=get_task"):
        RunConfig.from_sources(None, {"task": "mytasks.valley:TASK"})


def test_a_config_cannot_carry_another_task_than_it_names() -> None:
    with pytest.raises(ValueError, match="names task 'acrobot' but carries task 'mountain-car'"):
        RunConfig(task="acrobot")

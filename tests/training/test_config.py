from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest

from vlmrl_cli.core.errors import BadInput
from vlmrl_cli.frames.geometry import Zone
from vlmrl_cli.training.config import RunConfig, load_config_file
from vlmrl_cli.training.overrides import resolve
from vlmrl_cli.training.presets import get_preset
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
        ({"ppo": dataclasses.replace(get_preset("smoke"), timesteps=0)}, "ppo.timesteps"),
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
    longer = dataclasses.replace(base, ppo=dataclasses.replace(get_preset("smoke"), timesteps=2_048))
    assert longer.jobs()[0].config_hash != b0.config_hash


def test_the_preset_name_is_a_label_the_resolved_values_are_the_identity() -> None:
    paper = RunConfig(arms=("baseline",), seeds=(0,), preset="paper")
    zoo_cut = dataclasses.replace(paper, preset="zoo", ppo=get_preset("paper"))
    assert paper.jobs()[0].config_hash == zoo_cut.jobs()[0].config_hash
    assert zoo_cut.jobs()[0].overrides() == {"ppo.timesteps": "300000"}
    assert paper.jobs()[0].overrides() == {}
    one_env = dataclasses.replace(paper, ppo=dataclasses.replace(get_preset("paper"), n_envs=1, n_steps=256))
    assert one_env.jobs()[0].config_hash != paper.jobs()[0].config_hash
    assert one_env.jobs()[0].overrides() == {"ppo.n_envs": "1", "ppo.n_steps": "256"}


def test_the_sim_profile_enters_the_hash_but_the_default_keeps_the_old_one() -> None:
    from vlmrl_cli.training.overrides import resolve

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

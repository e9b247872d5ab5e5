"""The options built from config fields (``cli/options.py``): each states its field's help and
range, declared once on the field."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

import typer
from annotated_types import Ge, Gt

from vlmrl_cli.cli import options as opt
from vlmrl_cli.cli.app import app
from vlmrl_cli.core.fields import AtMost, help_of, rules_of
from vlmrl_cli.study.settings import StudySettings
from vlmrl_cli.training.config import RunConfig
from vlmrl_cli.training.presets import PPOConfig
from vlmrl_cli.vlm.config import SimKnobs, VLMConfig

#: The config section of each prefix of a field option's key.
SECTIONS: dict[str, Any] = {"vlm": VLMConfig, "vlm.sim": SimKnobs, "study": StudySettings, "ppo": PPOConfig,
                            "run": RunConfig}
#: The options that share a field's declaration under their own name, and the commands that have them.
ALIASES = {"use_cache": ("vlm.use_cache", {"evaluate"}), "cache_path": ("vlm.cache_path", {"evaluate"}),
           "timesteps": ("ppo.timesteps", {"run", "calibrate", "study"}),
           "eval_episodes": ("ppo.eval_episodes", {"run", "calibrate", "study"}),
           "workers": ("run.workers", {"run", "calibrate", "study"}),
           "margin": ("study.margin", {"report"}), "adjust": ("study.adjust", {"report"})}


def _field(key: str) -> dataclasses.Field[Any]:
    section, name = key.rsplit(".", 1)
    return next(f for f in dataclasses.fields(SECTIONS[section]) if f.name == name)


def _bounds(f: dataclasses.Field[Any]) -> tuple[Any, Any]:
    """The closed range the field's rules declare, read from the rules themselves."""
    low = high = None
    for rule in rules_of(f):
        if isinstance(rule, Gt | AtMost):
            continue  # an open bound, or one refused with its reason, is the config's validation's
        low = getattr(rule, "ge", None) if getattr(rule, "ge", None) is not None else low
        high = getattr(rule, "le", None) if getattr(rule, "le", None) is not None else high
    return low, high


def test_every_field_option_states_its_fields_help_and_range() -> None:
    keys = {o.name: o.key for o in (*opt.VLM_OPTIONS, *opt.field_options(StudySettings, "study"))}
    checked = set()
    for name, command in typer.main.get_command(app).commands.items():  # type: ignore[attr-defined]
        for param in command.params:
            key, commands = ALIASES.get(param.name, (keys.get(param.name), {name}))
            if key is None or name not in commands:
                continue
            f = _field(key)
            assert param.help == help_of(f) and param.help, (name, param.name)
            bounds = (param.min, param.max)  # type: ignore[attr-defined]
            assert bounds == _bounds(f), (name, param.name, bounds)
            checked.add(key)
    # every VLMConfig and SimKnobs field has its option, and so does every study setting
    for section in ("vlm", "vlm.sim", "study"):
        assert {f"{section}.{f.name}" for f in dataclasses.fields(SECTIONS[section]) if f.name != "sim"} <= checked
    assert {key for key, _ in ALIASES.values()} <= checked


def test_a_new_field_gets_its_option_from_its_declaration() -> None:
    @dataclass(frozen=True)
    class Toy:
        depth: int = field(default=3, metadata={"rules": (Ge(1), AtMost(9, "too deep")), "help": "how deep"})
        label_name: str = field(default="x", metadata={"flag": "--label", "help": "a label"})

    depth, label = (o.click_param() for o in opt.field_options(Toy, "toy"))
    assert (depth.opts, depth.help, depth.min, depth.max, depth.default) == (["--depth"], "how deep", 1, None, 3)
    assert (label.name, label.opts, label.help) == ("toy_label_name", ["--label"], "a label")


def test_only_the_options_typed_set_config_keys() -> None:
    from typer.testing import CliRunner

    seen: dict[str, Any] = {}

    def probe(ctx: typer.Context) -> None:
        seen.update(opt.typed_fields(ctx))
        seen["config"] = opt.vlm_config(ctx)

    toy = typer.Typer()
    toy.command(cls=opt.fields_command(*opt.VLM_OPTIONS))(probe)
    result = CliRunner().invoke(toy, ["--sim-flicker", "0.3", "--no-cache", "--sim-profile", "ideal"])
    assert result.exit_code == 0, result.output
    config = seen.pop("config")
    assert seen == {"vlm.sim.flicker": 0.3, "vlm.use_cache": False, "vlm.sim.profile": "ideal"}
    assert (config.use_cache, config.sim.flicker, config.sim.float_noise) == (False, 0.3, 0.0)  # the profile's
    assert CliRunner().invoke(toy, ["--max-new-tokens", "0"]).exit_code == 2  # the field's Ge(1)
    refused = CliRunner().invoke(toy, ["--timeout", "0"])  # Gt(0), open: the config's validation, by its key
    assert "invalid vlm.timeout_s = 0.0: input should be greater than 0" in str(refused.exception)

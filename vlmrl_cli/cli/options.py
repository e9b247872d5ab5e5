"""Options shared by several commands, declared once as ``Annotated`` aliases."""

from __future__ import annotations

import copy
import dataclasses
import typing
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any

import typer
from annotated_types import Ge, Interval
from typer.core import TyperCommand

from vlmrl_cli.core.errors import BadInput
from vlmrl_cli.core.fields import help_of, rules_of
from vlmrl_cli.shaping.arms import ARMS
from vlmrl_cli.study.settings import StudySettings
from vlmrl_cli.tasks.registry import get_task
from vlmrl_cli.training.config import DEFAULT_PRESET, DEFAULT_TASK, RunConfig, seed_count_problem
from vlmrl_cli.training.events import EXECUTORS
from vlmrl_cli.training.overrides import nest
from vlmrl_cli.training.presets import PPOConfig
from vlmrl_cli.vlm.config import SimKnobs, VLMConfig, resolve_sim_profile

TrackingUri = Annotated[
    str | None,
    typer.Option("--tracking-uri", help="MLflow tracking URI (default: $MLFLOW_TRACKING_URI or sqlite:///mlflow.db)."),
]
OutDir = Annotated[Path | None, typer.Option("--out", help="Output folder (default under results/).")]
Experiment = Annotated[str, typer.Option("--experiment", help="MLflow experiment name.")]


def choices(names: Sequence[str]) -> str:
    """The metavar ``[a|b|c]`` of an option's choices (checked where the config is validated)."""
    return "[" + "|".join(names) + "]"


#: Where a ``fields_command`` leaves the field options typed, for the command to read.
_TYPED = "vlmrl.typed_fields"


def field_option(f: dataclasses.Field[Any], hint: Any, flag: str, shown_default: bool | str = True) -> Any:
    """The ``Annotated`` typer option ``flag`` of config field ``f`` (of type ``hint``): the field's
    help, and its ``Ge``/``Interval`` rules as the range (the others are left to validation)."""
    bounds: dict[str, Any] = {}
    for rule in rules_of(f):
        if isinstance(rule, Ge | Interval) and rule.ge is not None:
            bounds["min"] = rule.ge
        if isinstance(rule, Interval) and rule.le is not None:
            bounds["max"] = rule.le
    return Annotated[hint, typer.Option(flag, help=help_of(f), show_default=shown_default, **bounds)]


#: How the text of a flag becomes its field's value, by the field's type: (the option's type, the parser).
Syntax = Mapping[Any, tuple[Any, Callable[[Any, str], Any]]]


@dataclass(frozen=True)
class FieldOption:
    """The option of one config field: parameter name, dotted config key, flag, ``Annotated`` option,
    default, and the parser of the flag's value."""

    name: str
    key: str
    flag: str
    annotation: Any
    default: Any
    parse: Callable[[Any, str], Any]

    def click_param(self) -> Any:
        """The click option typer would make of a parameter ``name: annotation = default``."""
        from typer import main
        from typer.models import ParamMeta

        kind, info = typing.get_args(self.annotation)[0], copy.copy(self.annotation.__metadata__[0])
        info.param_decls, info.default = (info.default, *(info.param_decls or ())), self.default
        meta = ParamMeta(name=self.name, default=info, annotation=kind)
        if hasattr(main, "_get_param"):  # a recent typer, which runs its own copy of click
            return main._get_param(meta)
        return main.get_click_param(meta)[0]  # type: ignore[attr-defined]  # pragma: no cover - older typer


def field_options(cls: type, key: str, flag_prefix: str = "", defaults: bool = True, shown_default: bool | str = True,
                  syntax: Syntax | None = None) -> tuple[FieldOption, ...]:
    """One option per non-dataclass field of ``cls``: the flag ``--{flag_prefix}{name}`` (or the
    field's ``flag``) sets ``{key}.{name}``; its default is the field's (None unless ``defaults``);
    ``syntax`` maps a field type to the option's type and parser where they differ."""
    hints = typing.get_type_hints(cls)
    out = []
    for f in dataclasses.fields(cls):
        if dataclasses.is_dataclass(hints[f.name]):
            continue
        kind, parse = (syntax or {}).get(hints[f.name], (hints[f.name] | None, lambda value, _flag: value))
        default = f.default if f.default is not dataclasses.MISSING else f.default_factory()  # type: ignore[misc,operator]
        flag = str(f.metadata.get("flag", f"--{flag_prefix}{f.name.replace('_', '-')}"))
        out.append(FieldOption(f"{key}.{f.name}".replace(".", "_"), f"{key}.{f.name}", flag.split("/")[0],
                               field_option(f, kind, flag, shown_default), default if defaults else None, parse))
    return tuple(out)


def fields_command(*options: FieldOption) -> type[TyperCommand]:
    """The typer command class that adds the field ``options`` to a command's own (read with ``typed_fields``)."""

    class FieldsCommand(TyperCommand):
        def __init__(self, *args: Any, params: list[Any], **kwargs: Any) -> None:
            super().__init__(*args, params=[*params, *(o.click_param() for o in options)], **kwargs)

        def invoke(self, ctx: Any) -> Any:
            values = {o.name: ctx.params.pop(o.name) for o in options}
            ctx.meta[_TYPED] = [(o, values[o.name]) for o in options if given(ctx, o.name)]
            return super().invoke(ctx)

    return FieldsCommand


def typed_fields(ctx: typer.Context) -> dict[str, Any]:
    """The field options typed on the command line, parsed, by dotted config key (``{"vlm.sim.flicker": 0.3}``)."""
    return {o.key: o.parse(value, o.flag) for o, value in ctx.meta.get(_TYPED, [])}


#: The VLM options: one per ``VLMConfig`` and ``SimKnobs`` field (``--sim-*``, over the profile's knobs).
VLM_OPTIONS = (*field_options(VLMConfig, "vlm"),
               *field_options(SimKnobs, "vlm.sim", "sim-", defaults=False, shown_default="the profile's"))
_PROFILE_TASK = get_task(DEFAULT_TASK)
_BY_KEY = {o.key: o.annotation for o in VLM_OPTIONS}
#: The cache options alone, for a command that takes no other VLM option (``evaluate``).
UseCache = _BY_KEY["vlm.use_cache"]
CachePath = _BY_KEY["vlm.cache_path"]


def vlm_config(ctx: typer.Context) -> VLMConfig:
    """The validated ``VLMConfig`` of the VLM options typed, over the default task's profile knobs."""
    from vlmrl_cli.training.validation import validate_as

    raw = nest(typed_fields(ctx).items()).get("vlm", {})
    raw["sim"] = resolve_sim_profile(raw.get("sim", {}), _PROFILE_TASK)
    return typing.cast(VLMConfig, validate_as(VLMConfig, raw, at="vlm"))


def given(ctx: typer.Context, name: str) -> bool:
    """Whether parameter ``name`` was typed on the command line (or came from the environment)."""
    source = ctx.get_parameter_source(name)
    return source is not None and source.name in ("COMMANDLINE", "ENVIRONMENT", "PROMPT")


def check_sim_flags(ctx: typer.Context, arms: Sequence[str], backend: str,
                    remedy: str = "drop it, or add an arm that uses the VLM (e.g. --arms baseline,hybrid)") -> None:
    """``BadInput`` for a ``--sim-*`` flag typed for runs that never ask the simulated VLM (no arm of
    ``arms`` asks a VLM: then ``remedy``; or another ``backend``); a config file's knobs are left alone."""
    typed = [o.flag for o, _ in ctx.meta.get(_TYPED, []) if o.key.startswith("vlm.sim.")]
    if not typed:
        return
    if not any(ARMS[arm].uses_vlm for arm in arms):
        raise BadInput(f"{typed[0]} sets the simulated VLM, which no arm of these runs asks (arms: {', '.join(arms)}); "
                       f"{remedy}.")
    if backend != "sim":
        raise BadInput(f"{typed[0]} sets the simulated VLM, and these runs ask the '{backend}' backend; drop it, or "
                       "pass --vlm sim.")


def _field(cls: type, name: str) -> dataclasses.Field[Any]:
    return next(f for f in dataclasses.fields(cls) if f.name == name)


#: The verdicts' knobs of `report`, declared with the study's (``StudySettings``).
Margin = field_option(_field(StudySettings, "margin"), float, "--margin", shown_default=False)
Adjust = field_option(_field(StudySettings, "adjust"), str, "--adjust", shown_default=False)
Arms = Annotated[str, typer.Option("--arms", help=f"Comma-separated arms, any of: {', '.join(ARMS)}.")]
Seeds = Annotated[int, typer.Option("--seeds", help="Number of seeds: 0..N-1.")]
SeedList = Annotated[str | None, typer.Option("--seed-list", help="Explicit seeds, e.g. 3,7,11.")]
Timesteps = field_option(_field(PPOConfig, "timesteps"), int | None, "--timesteps", shown_default=False)
# No default of its own: a run that names no preset takes its task's (``Task.default_preset``), so
# the help states that rather than one task's name (``[default: paper]`` is false for Acrobot).
Preset = Annotated[str | None, typer.Option(
    "--preset", metavar=choices(list(get_task(DEFAULT_TASK).presets)), show_default=False,
    help=f"PPO preset, the bottom layer of [ppo]: one of the task's own presets (listed: {DEFAULT_TASK}'s) "
         f"[default: the task's default preset; {DEFAULT_TASK}'s is {DEFAULT_PRESET}].")]
TaskOpt = Annotated[str | None, typer.Option(
    "--task", metavar="mountain-car|mountain-car-continuous|acrobot|minigrid-doorkey|pusher|MODULE:NAME",
    help="The environment (default mountain-car): a built-in task, or a Task in your code as "
         "package.module:NAME (see the docs' 'Add a task').")]
TrustPickle = Annotated[bool, typer.Option(
    "--trust-pickle",
    help="Accept a pickled artifact (the vecnormalize.pkl of a run saved before vlmrl kept it as arrays): loading "
         "a pickle runs whatever code it holds, so pass this only for files whose source you trust.")]
AllowMixedPaths = Annotated[bool, typer.Option(
    "--allow-mixed-paths",
    help="Compare runs computed on different numeric paths (vlmrl.pin tags) instead of refusing.")]
UserTasks = Annotated[list[str] | None, typer.Option(
    "--user-task", metavar="MODULE:NAME",
    help="A task of your own code that the runs recorded, imported for them (repeatable): vlmrl imports a module "
         "only when the command line names it, never from a file, an export or a store.")]
Workers = field_option(_field(RunConfig, "workers"), int | None, "--workers", shown_default=False)
ExecutorOpt = Annotated[str | None, typer.Option(
    "--executor", metavar=choices(EXECUTORS),
    help="Where jobs run: local (a process pool, the default) or ray (tasks on a Ray cluster; pip install "
         "'vlmrl[ray]').")]
RayAddress = Annotated[str | None, typer.Option(
    "--ray-address", help="Ray cluster to join with --executor ray (default: a cluster running on this machine, "
                          "else a new local Ray instance with --workers CPUs).")]
EvalEpisodes = field_option(_field(PPOConfig, "eval_episodes"), int | None, "--eval-episodes", shown_default=False)
ConfigFile = Annotated[Path | None, typer.Option("--config", help="TOML file with any of these knobs.")]
Sets = Annotated[
    list[str] | None,
    typer.Option("--set", help="Override one config key, repeatable: --set ppo.n_envs=1 --set shaping.alpha=3 "
                               "(dotted TOML key = TOML value; beats --config, loses to explicit flags)."),
]

# CLI parameter -> dotted config key (seeds come from --seeds or --seed-list)
_RUN_KEYS = {"arms": "arms", "task": "task", "preset": "preset", "timesteps": "ppo.timesteps",
             "eval_episodes": "ppo.eval_episodes", "workers": "workers", "experiment": "experiment",
             "tracking_uri": "tracking_uri", "executor": "executor", "ray_address": "ray_address"}


def list_entries(text: str, flag: str) -> list[str]:
    """``"a, b"`` -> ["a", "b"]; an empty entry (``"a,,b"``, ``""``) is ``BadInput``."""
    entries = [t.strip() for t in text.split(",")]
    if not text.strip() or any(not t for t in entries):
        raise BadInput(f"{flag} '{text}' has an empty entry; list the values separated by single commas.")
    return entries


def seeds_of(n: int, seed_list: str | None) -> tuple[int, ...]:
    """``--seed-list 3,7`` -> (3, 7); else ``--seeds N`` -> (0, ..., N-1)."""
    if seed_list is not None:
        try:
            seeds = tuple(int(s) for s in list_entries(seed_list, "--seed-list"))
        except ValueError:
            raise BadInput(f"--seed-list must be comma-separated integers, got '{seed_list}'.") from None
        if len(set(seeds)) != len(seeds):
            raise BadInput(f"--seed-list '{seed_list}' lists a seed twice; list each seed once.")
        return seeds
    if n < 1:
        raise BadInput(f"--seeds must be at least 1, got {n}.")
    problem = seed_count_problem(n)  # before a tuple of n seeds is built
    if problem:
        raise BadInput(f"--seeds {n}: {problem}.")
    return tuple(range(n))


def typed_flags(ctx: typer.Context) -> dict[str, Any]:
    """The options of a training command typed on the command line, by dotted config key: the top
    layer of its configuration (``{"arms": ["baseline"], "ppo.timesteps": 512}``)."""
    p = ctx.params
    flags: dict[str, Any] = {key: p[param] for param, key in _RUN_KEYS.items() if given(ctx, param)}
    if "arms" in flags:
        flags["arms"] = list_entries(str(flags["arms"]), "--arms")
    if given(ctx, "seeds") and given(ctx, "seed_list"):
        raise BadInput("--seeds and --seed-list both given; pass --seeds N for 0..N-1 or --seed-list A,B,... alone.")
    if given(ctx, "seeds") or given(ctx, "seed_list"):
        flags["seeds"] = list(seeds_of(p["seeds"], p.get("seed_list")))
    return flags | typed_fields(ctx)

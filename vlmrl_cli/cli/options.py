"""Options shared by several commands, declared once as ``Annotated`` aliases."""

from __future__ import annotations

import enum
import functools
import inspect
import typing
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated, Any

import typer

from vlmrl_cli.analysis.multiplicity import METHODS
from vlmrl_cli.core.errors import BadInput
from vlmrl_cli.shaping.arms import ARMS
from vlmrl_cli.tasks.registry import get_task
from vlmrl_cli.training.config import DEFAULT_PRESET, DEFAULT_TASK, seed_count_problem, source_layers
from vlmrl_cli.training.events import EXECUTORS
from vlmrl_cli.training.presets import preset_names
from vlmrl_cli.vlm.config import BACKENDS, DEFAULT_SIM_PROFILE, SimKnobs, VLMConfig, sim_profiles

TrackingUri = Annotated[
    str | None,
    typer.Option("--tracking-uri", help="MLflow tracking URI (default: $MLFLOW_TRACKING_URI or sqlite:///mlflow.db)."),
]
OutDir = Annotated[Path | None, typer.Option("--out", help="Output folder (default under results/).")]
Experiment = Annotated[str, typer.Option("--experiment", help="MLflow experiment name.")]
Margin = Annotated[float, typer.Option(
    "--margin", help="Equivalence margin of a speedup: 'equivalent' when the 90% interval lies inside [1/M, M].")]

def choices(names: Sequence[str]) -> str:
    """The metavar listing an option's choices in the help (``[a|b|c]``); the values are checked,
    with one-sentence errors, where the config is validated, before anything runs."""
    return "[" + "|".join(names) + "]"


Adjust = Annotated[str, typer.Option(
    "--adjust", metavar=choices(METHODS),
    help="Multiplicity adjustment of the speedups' p-values within the command's family of comparisons: holm "
         "(Holm's step-down, the family-wise error rate), bh (Benjamini-Hochberg, the false discovery rate) or none. "
         "Verdicts use the adjusted p.")]


_DEFAULT = VLMConfig()
_SIM = SimKnobs()
#: The profiles as a choice typer validates and lists in the help: the generic ones and the default
#: task's own (a run of another task is checked against its own where its layers are resolved).
_PROFILE_TASK = get_task(DEFAULT_TASK)
SimProfileName = enum.StrEnum(  # type: ignore[misc]
    "SimProfileName", [(name, name) for name in sim_profiles(_PROFILE_TASK)])


@dataclass(frozen=True)
class VlmOption:
    """One shared VLM option, declared once: its parameter, the ``VLMConfig`` field it sets (dotted
    under ``sim.`` for a ``SimKnobs`` field), its type, flag, help and typer's extra checks. The
    typer options, the config mapping and the help's defaults all derive from this table."""

    param: str
    target: str
    kind: Any
    flag: str
    help: str
    extra: dict[str, Any] = field(default_factory=dict)
    # the option's default when it is not the field's own (None: "the profile's"; the inverted no-cache)
    default: Any = "field"

    @property
    def annotation(self) -> Any:
        return Annotated[self.kind, typer.Option(self.flag, help=self.help, **self.extra)]

    @property
    def default_value(self) -> Any:
        if self.default != "field":
            return self.default
        holder: Any = _SIM if self.target.startswith("sim.") else _DEFAULT
        return getattr(holder, self.target.removeprefix("sim."))


VLM_OPTIONS: tuple[VlmOption, ...] = (
    VlmOption("vlm", "backend", str, "--vlm", "VLM backend: sim (simulated, default), hf, openai, replay.",
              {"metavar": choices(BACKENDS)}),
    VlmOption("model", "model", str | None, "--model",
              "hf: hub id or local path; openai: served model name; sim/replay: ignored."),
    VlmOption("base_url", "base_url", str | None, "--base-url", "openai: server URL, e.g. http://localhost:11434/v1."),
    VlmOption("api_key_env", "api_key_env", str, "--api-key-env", "openai: environment variable holding the API key."),
    VlmOption("device", "device", str | None, "--device", "hf: torch device (default: cuda if present)."),
    VlmOption("dtype", "dtype", str, "--dtype", "hf: torch dtype (auto, float32, float16, bfloat16)."),
    VlmOption("max_new_tokens", "max_new_tokens", int, "--max-new-tokens", "hf/openai: answer length cap.",
              {"min": 1}),
    VlmOption("timeout", "timeout_s", float, "--timeout", "openai: seconds per request.", {"min": 0.1}),
    VlmOption("retries", "retries", int, "--retries", "openai: retries with exponential backoff.", {"min": 0}),
    VlmOption("transcript", "transcript_in", Path | None, "--transcript",
              "replay: JSONL transcript (default: the paper's Table 1 outputs)."),
    VlmOption("no_cache", "use_cache", bool, "--no-cache", "Bypass the on-disk VLM response cache.", default=False),
    VlmOption("cache_path", "cache_path", Path, "--cache-path", "sqlite file of the VLM response cache."),
    VlmOption("sim_profile", "sim.profile", SimProfileName, "--sim-profile",
              "sim: named set of knobs: ideal (no noise), default (the results so far), llava-table1 (the paper's "
              "Table 1 failures). Explicit --sim-* knobs beat the profile's values.",
              default=SimProfileName(DEFAULT_SIM_PROFILE)),
    VlmOption("sim_flicker", "sim.flicker", float | None, "--sim-flicker",
              "sim: P(neighbouring MCQ label) [default: the profile's].", {"min": 0.0, "max": 1.0}, default=None),
    VlmOption("sim_float_noise", "sim.float_noise", float | None, "--sim-float-noise",
              "sim: std of float answers, x units [default: the profile's].", {"min": 0.0}, default=None),
    VlmOption("sim_seed", "sim.seed", int, "--sim-seed", "sim: seed of the simulated answers."),
    VlmOption("sim_latency", "sim.latency_s", float, "--sim-latency", "sim: fixed seconds per query.", {"min": 0.0}),
)
_BY_PARAM = {o.param: o for o in VLM_OPTIONS}
#: The cache options alone, for a command that takes no other VLM option (``evaluate``).
NoCache = _BY_PARAM["no_cache"].annotation
CachePath = _BY_PARAM["cache_path"].annotation
_INVERTED = {"no_cache"}  # a flag that sets its field to the opposite
# sim knobs that default to the profile's value: laid over the profile only when given
_OVER_PROFILE = {"sim_flicker", "sim_float_noise"}


def vlm_config(**values: Any) -> VLMConfig:
    """The ``VLMConfig`` of the shared VLM options (``VLM_OPTIONS``, by parameter name): the
    profile's knobs, then the knobs given.

    Example:
        >>> defaults = {o.param: o.default_value for o in VLM_OPTIONS}
        >>> vlm_config(**defaults) == VLMConfig()
        True
        >>> vlm_config(**(defaults | {"sim_flicker": 0.3, "no_cache": True})).sim.flicker
        0.3
    """
    top: dict[str, Any] = {}
    sim: dict[str, Any] = {}
    for option in VLM_OPTIONS:
        value = values[option.param]
        if option.param in _INVERTED:
            value = not value
        if isinstance(value, enum.Enum):
            value = value.value
        if option.param in _OVER_PROFILE and value is None:
            continue
        if option.target.startswith("sim."):
            sim[option.target.removeprefix("sim.")] = value
        else:
            top[option.target] = value
    profile = str(sim.pop("profile"))
    return VLMConfig(**top, sim=SimKnobs.of_profile(profile, _PROFILE_TASK, **sim))


def with_vlm_options(command: Callable[..., None]) -> Callable[..., None]:
    """Give ``command`` the shared VLM options (``VLM_OPTIONS``); it receives them as one
    ``vlm_cfg: VLMConfig``.

    Declared once here so ``taxonomy``, ``run``, ``calibrate`` and ``study`` cannot drift apart.
    """
    hints = typing.get_type_hints(command, include_extras=True)
    own = [
        p.replace(annotation=hints.get(p.name, p.annotation))
        for p in inspect.signature(command).parameters.values()
        if p.name != "vlm_cfg"
    ]
    shared = [
        inspect.Parameter(o.param, inspect.Parameter.KEYWORD_ONLY, annotation=o.annotation, default=o.default_value)
        for o in VLM_OPTIONS
    ]

    @functools.wraps(command)
    def wrapper(**kwargs: Any) -> None:
        vlm_kwargs = {o.param: kwargs.pop(o.param) for o in VLM_OPTIONS}
        command(vlm_cfg=vlm_config(**vlm_kwargs), **kwargs)

    params = [p.replace(kind=inspect.Parameter.KEYWORD_ONLY) for p in own] + shared
    wrapper.__signature__ = inspect.Signature(params)  # type: ignore[attr-defined]
    wrapper.__annotations__ = {p.name: p.annotation for p in params}
    del wrapper.__wrapped__  # typer must see the merged signature, not the original
    return wrapper


def given(ctx: typer.Context, name: str) -> bool:
    """Whether parameter ``name`` was typed on the command line (or came from the environment)."""
    source = ctx.get_parameter_source(name)
    return source is not None and source.name in ("COMMANDLINE", "ENVIRONMENT", "PROMPT")


def vlm_flags(ctx: typer.Context, flags: VLMConfig) -> dict[str, Any]:
    """The VLM options typed on the command line, as dotted config keys (``{"vlm.sim.flicker": 0.3}``)."""
    out: dict[str, Any] = {}
    for param, target in ((o.param, o.target) for o in VLM_OPTIONS):
        if given(ctx, param):
            obj: Any = flags.sim if target.startswith("sim.") else flags
            out[f"vlm.{target}"] = getattr(obj, target.removeprefix("sim."))
    return out


def check_sim_flags(ctx: typer.Context, arms: Sequence[str], backend: str,
                    remedy: str = "drop it, or add an arm that uses the VLM (e.g. --arms baseline,hybrid)") -> None:
    """``BadInput`` for a simulated-VLM knob (``--sim-*``) typed for runs that never ask it: no arm
    of ``arms`` queries a VLM (the message then ends with ``remedy``), or the VLM is not the
    simulated one (``backend``). A knob from a config file is left alone: one file may serve
    several commands."""
    typed = [o.flag for o in VLM_OPTIONS if o.target.startswith("sim.") and given(ctx, o.param)]
    if not typed:
        return
    if not any(ARMS[arm].uses_vlm for arm in arms):
        raise BadInput(f"{typed[0]} sets the simulated VLM, which no arm of these runs asks (arms: {', '.join(arms)}); "
                       f"{remedy}.")
    if backend != "sim":
        raise BadInput(f"{typed[0]} sets the simulated VLM, and these runs ask the '{backend}' backend; drop it, or "
                       "pass --vlm sim.")


# --- the options of commands that train (`run`, `calibrate`) and how they layer -----------

Arms = Annotated[str, typer.Option("--arms", help=f"Comma-separated arms, any of: {', '.join(ARMS)}.")]
Seeds = Annotated[int, typer.Option("--seeds", help="Number of seeds: 0..N-1.")]
SeedList = Annotated[str | None, typer.Option("--seed-list", help="Explicit seeds, e.g. 3,7,11.")]
Timesteps = Annotated[int | None, typer.Option("--timesteps", help="Budget per run (= --set ppo.timesteps=N).")]
# No default of its own: a run that names no preset takes its task's (``Task.default_preset``), so
# the help states that rather than one task's name (``[default: paper]`` is false for Acrobot).
Preset = Annotated[str | None, typer.Option(
    "--preset", metavar=choices(preset_names(get_task(DEFAULT_TASK))), show_default=False,
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
UserTasks = Annotated[list[str] | None, typer.Option(
    "--user-task", metavar="MODULE:NAME",
    help="A task of your own code that the runs recorded, imported for them (repeatable): vlmrl imports a module "
         "only when the command line names it, never from a file, an export or a store.")]
Workers = Annotated[int | None, typer.Option("--workers", help="Worker processes (default: cores).")]
ExecutorOpt = Annotated[str | None, typer.Option(
    "--executor", metavar=choices(EXECUTORS),
    help="Where jobs run: local (a process pool, the default) or ray (tasks on a Ray cluster; pip install "
         "'vlmrl[ray]').")]
RayAddress = Annotated[str | None, typer.Option(
    "--ray-address", help="Ray cluster to join with --executor ray (default: a cluster running on this machine, "
                          "else a new local Ray instance with --workers CPUs).")]
EvalEpisodes = Annotated[
    int | None, typer.Option("--eval-episodes", help="Detached evaluation episodes (= --set ppo.eval_episodes=N).")
]
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
    """``"a, b"`` -> ["a", "b"]; an empty entry (``"a,,b"``, a trailing comma, an empty string) is
    ``BadInput``: a typo or an empty shell variable, not a choice.

    Example:
        >>> list_entries("baseline, hybrid", "--arms")
        ['baseline', 'hybrid']
    """
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


def typed_flags(ctx: typer.Context, vlm_cfg: VLMConfig) -> dict[str, Any]:
    """The options of a training command typed on the command line, as dotted config keys: the top
    layer of its configuration (``{"arms": ["baseline"], "ppo.timesteps": 512}``)."""
    p = ctx.params
    flags: dict[str, Any] = {key: p[param] for param, key in _RUN_KEYS.items() if given(ctx, param)}
    if "arms" in flags:
        flags["arms"] = list_entries(str(flags["arms"]), "--arms")
    if given(ctx, "seeds") and given(ctx, "seed_list"):
        raise BadInput("--seeds and --seed-list both given; pass --seeds N for 0..N-1 or --seed-list A,B,... alone.")
    if given(ctx, "seeds") or given(ctx, "seed_list"):
        flags["seeds"] = list(seeds_of(p["seeds"], p.get("seed_list")))
    return flags | vlm_flags(ctx, vlm_cfg)


def config_layers(ctx: typer.Context, config: Path | None, sets: list[str] | None, vlm_cfg: VLMConfig
                  ) -> list[dict[str, Any]]:
    """The raw layers of a training command's configuration above the preset, lowest first: the
    config file, ``--set`` assignments, then the flags typed on the command line."""
    return source_layers(config, typed_flags(ctx, vlm_cfg), sets or [])

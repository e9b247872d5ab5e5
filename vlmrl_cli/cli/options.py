"""Options shared by several commands, declared once as ``Annotated`` aliases."""

from __future__ import annotations

import enum
import functools
import inspect
import typing
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Annotated, Any

import typer

from vlmrl_cli.analysis.multiplicity import METHODS
from vlmrl_cli.core.errors import BadInput
from vlmrl_cli.shaping.arms import ARMS
from vlmrl_cli.training.config import source_layers
from vlmrl_cli.training.events import EXECUTORS
from vlmrl_cli.training.presets import PRESETS
from vlmrl_cli.vlm.config import BACKENDS, DEFAULT_SIM_PROFILE, SIM_PROFILES, SimKnobs, VLMConfig

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


Vlm = Annotated[str, typer.Option("--vlm", metavar=choices(BACKENDS),
                                  help="VLM backend: sim (simulated, default), hf, openai, replay.")]
VlmModel = Annotated[
    str | None,
    typer.Option("--model", help="hf: hub id or local path; openai: served model name; sim/replay: ignored."),
]
VlmBaseUrl = Annotated[str | None, typer.Option("--base-url", help="openai: server URL, e.g. http://localhost:11434/v1.")]
VlmApiKeyEnv = Annotated[str, typer.Option("--api-key-env", help="openai: environment variable holding the API key.")]
VlmDevice = Annotated[str | None, typer.Option("--device", help="hf: torch device (default: cuda if present).")]
VlmDtype = Annotated[str, typer.Option("--dtype", help="hf: torch dtype (auto, float32, float16, bfloat16).")]
VlmMaxNewTokens = Annotated[int, typer.Option("--max-new-tokens", min=1, help="hf/openai: answer length cap.")]
VlmTimeout = Annotated[float, typer.Option("--timeout", min=0.1, help="openai: seconds per request.")]
VlmRetries = Annotated[int, typer.Option("--retries", min=0, help="openai: retries with exponential backoff.")]
VlmTranscript = Annotated[
    Path | None, typer.Option("--transcript", help="replay: JSONL transcript (default: the paper's Table 1 outputs).")
]
NoCache = Annotated[bool, typer.Option("--no-cache", help="Bypass the on-disk VLM response cache.")]
CachePath = Annotated[Path, typer.Option("--cache-path", help="sqlite file of the VLM response cache.")]
#: The profiles as a choice typer validates and lists in the help.
SimProfileName = enum.StrEnum("SimProfileName", [(name, name) for name in SIM_PROFILES])  # type: ignore[misc]
SimProfile = Annotated[
    SimProfileName,
    typer.Option("--sim-profile",
                 help="sim: named set of knobs: ideal (no noise), default (the results so far), llava-table1 "
                      "(the paper's Table 1 failures). Explicit --sim-* knobs beat the profile's values."),
]
SimFlicker = Annotated[
    float | None,
    typer.Option("--sim-flicker", min=0.0, max=1.0, help="sim: P(neighbouring MCQ label) [default: the profile's]."),
]
SimFloatNoise = Annotated[
    float | None,
    typer.Option("--sim-float-noise", min=0.0, help="sim: std of float answers, x units [default: the profile's]."),
]
SimSeed = Annotated[int, typer.Option("--sim-seed", help="sim: seed of the simulated answers.")]
SimLatency = Annotated[float, typer.Option("--sim-latency", min=0.0, help="sim: fixed seconds per query.")]

_DEFAULT = VLMConfig()
_SIM = SimKnobs()


def vlm_config(
    vlm: str,
    model: str | None,
    base_url: str | None,
    api_key_env: str,
    device: str | None,
    dtype: str,
    max_new_tokens: int,
    timeout: float,
    retries: int,
    transcript: Path | None,
    no_cache: bool,
    cache_path: Path,
    sim_profile: str | enum.Enum,
    sim_flicker: float | None,
    sim_float_noise: float | None,
    sim_seed: int,
    sim_latency: float,
) -> VLMConfig:
    """The ``VLMConfig`` of the shared VLM options: the profile's knobs, then the knobs given."""
    given_knobs = {"flicker": sim_flicker, "float_noise": sim_float_noise}
    profile = str(sim_profile.value if isinstance(sim_profile, enum.Enum) else sim_profile)
    sim = SimKnobs.of_profile(profile, latency_s=sim_latency, seed=sim_seed,
                              **{k: v for k, v in given_knobs.items() if v is not None})
    return VLMConfig(
        backend=vlm, model=model, base_url=base_url, api_key_env=api_key_env, device=device,
        dtype=dtype, max_new_tokens=max_new_tokens, timeout_s=timeout, retries=retries,
        transcript_in=transcript, cache_path=cache_path, use_cache=not no_cache, sim=sim,
    )


_VLM_PARAMS: dict[str, tuple[object, object]] = {
    "vlm": (Vlm, _DEFAULT.backend),
    "model": (VlmModel, None),
    "base_url": (VlmBaseUrl, None),
    "api_key_env": (VlmApiKeyEnv, _DEFAULT.api_key_env),
    "device": (VlmDevice, None),
    "dtype": (VlmDtype, _DEFAULT.dtype),
    "max_new_tokens": (VlmMaxNewTokens, _DEFAULT.max_new_tokens),
    "timeout": (VlmTimeout, _DEFAULT.timeout_s),
    "retries": (VlmRetries, _DEFAULT.retries),
    "transcript": (VlmTranscript, None),
    "no_cache": (NoCache, False),
    "cache_path": (CachePath, _DEFAULT.cache_path),
    "sim_profile": (SimProfile, SimProfileName(DEFAULT_SIM_PROFILE)),
    "sim_flicker": (SimFlicker, None),
    "sim_float_noise": (SimFloatNoise, None),
    "sim_seed": (SimSeed, _SIM.seed),
    "sim_latency": (SimLatency, _SIM.latency_s),
}


def with_vlm_options(command: Callable[..., None]) -> Callable[..., None]:
    """Give ``command`` the shared VLM options; it receives them as one ``vlm_cfg: VLMConfig``.

    Declared once here so ``taxonomy`` and ``run`` cannot drift apart.
    """
    hints = typing.get_type_hints(command, include_extras=True)
    own = [
        p.replace(annotation=hints.get(p.name, p.annotation))
        for p in inspect.signature(command).parameters.values()
        if p.name != "vlm_cfg"
    ]
    shared = [
        inspect.Parameter(name, inspect.Parameter.KEYWORD_ONLY, annotation=ann, default=default)
        for name, (ann, default) in _VLM_PARAMS.items()
    ]

    @functools.wraps(command)
    def wrapper(**kwargs: Any) -> None:
        vlm_kwargs = {name: kwargs.pop(name) for name in _VLM_PARAMS}
        command(vlm_cfg=vlm_config(**vlm_kwargs), **kwargs)

    params = [p.replace(kind=inspect.Parameter.KEYWORD_ONLY) for p in own] + shared
    wrapper.__signature__ = inspect.Signature(params)  # type: ignore[attr-defined]
    wrapper.__annotations__ = {p.name: p.annotation for p in params}
    del wrapper.__wrapped__  # typer must see the merged signature, not the original
    return wrapper


# CLI parameter -> VLMConfig field (SimKnobs fields under "sim.").
_VLM_FIELDS = {
    "vlm": "backend", "model": "model", "base_url": "base_url", "api_key_env": "api_key_env", "device": "device",
    "dtype": "dtype", "max_new_tokens": "max_new_tokens", "timeout": "timeout_s", "retries": "retries",
    "transcript": "transcript_in", "no_cache": "use_cache", "cache_path": "cache_path",
    "sim_profile": "sim.profile", "sim_flicker": "sim.flicker", "sim_float_noise": "sim.float_noise",
    "sim_seed": "sim.seed",
    "sim_latency": "sim.latency_s",
}


def given(ctx: typer.Context, name: str) -> bool:
    """Whether parameter ``name`` was typed on the command line (or came from the environment)."""
    source = ctx.get_parameter_source(name)
    return source is not None and source.name in ("COMMANDLINE", "ENVIRONMENT", "PROMPT")


def vlm_flags(ctx: typer.Context, flags: VLMConfig) -> dict[str, Any]:
    """The VLM options typed on the command line, as dotted config keys (``{"vlm.sim.flicker": 0.3}``)."""
    out: dict[str, Any] = {}
    for param, target in _VLM_FIELDS.items():
        if given(ctx, param):
            obj: Any = flags.sim if target.startswith("sim.") else flags
            out[f"vlm.{target}"] = getattr(obj, target.removeprefix("sim."))
    return out


# --- the options of commands that train (`run`, `calibrate`) and how they layer -----------

Arms = Annotated[str, typer.Option("--arms", help=f"Comma-separated arms, any of: {', '.join(ARMS)}.")]
Seeds = Annotated[int, typer.Option("--seeds", help="Number of seeds: 0..N-1.")]
SeedList = Annotated[str | None, typer.Option("--seed-list", help="Explicit seeds, e.g. 3,7,11.")]
Timesteps = Annotated[int | None, typer.Option("--timesteps", help="Budget per run (= --set ppo.timesteps=N).")]
Preset = Annotated[str, typer.Option("--preset", metavar=choices(list(PRESETS)),
                                     help="PPO preset (the bottom layer of [ppo]); another task's presets "
                                          "are its own (default: the task's, e.g. zoo).")]
TaskOpt = Annotated[str | None, typer.Option(
    "--task", metavar="mountain-car|mountain-car-continuous|acrobot|MODULE:NAME",
    help="The environment (default mountain-car): a built-in task, or a Task in your code as "
         "package.module:NAME (see the docs' 'Add a task').")]
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

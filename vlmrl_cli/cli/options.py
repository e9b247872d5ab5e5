"""Options shared by several commands, declared once as ``Annotated`` aliases."""

from __future__ import annotations

import dataclasses
import functools
import inspect
import typing
from collections.abc import Callable
from pathlib import Path
from typing import Annotated, Any

import typer

from vlmrl_cli.vlm.config import SimKnobs, VLMConfig

TrackingUri = Annotated[
    str | None,
    typer.Option("--tracking-uri", help="MLflow tracking URI (default: $MLFLOW_TRACKING_URI or sqlite:///mlflow.db)."),
]
OutDir = Annotated[Path | None, typer.Option("--out", help="Output folder (default under results/).")]
Experiment = Annotated[str, typer.Option("--experiment", help="MLflow experiment name.")]

Vlm = Annotated[str, typer.Option("--vlm", help="VLM backend: sim (simulated, default), hf, openai, replay.")]
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
SimFlicker = Annotated[float, typer.Option("--sim-flicker", min=0.0, max=1.0, help="sim: P(neighbouring MCQ label).")]
SimFloatNoise = Annotated[float, typer.Option("--sim-float-noise", min=0.0, help="sim: std of float answers, x units.")]
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
    sim_flicker: float,
    sim_float_noise: float,
    sim_seed: int,
    sim_latency: float,
) -> VLMConfig:
    """The ``VLMConfig`` of the shared VLM options."""
    sim = SimKnobs(
        flicker=sim_flicker, float_noise=sim_float_noise, box_noise_px=_SIM.box_noise_px,
        box_failure=_SIM.box_failure, patch_px=_SIM.patch_px, latency_s=sim_latency, seed=sim_seed,
    )
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
    "sim_flicker": (SimFlicker, _SIM.flicker),
    "sim_float_noise": (SimFloatNoise, _SIM.float_noise),
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
    "sim_flicker": "sim.flicker", "sim_float_noise": "sim.float_noise", "sim_seed": "sim.seed",
    "sim_latency": "sim.latency_s",
}


def vlm_overrides(base: VLMConfig, flags: VLMConfig, explicit: set[str] | None) -> VLMConfig:
    """``flags`` when no config file is in play (``explicit`` is None); else ``base`` (from the
    file) with only the explicitly given VLM flags laid over it."""
    if explicit is None:
        return flags
    top: dict[str, Any] = {}
    sim: dict[str, Any] = {}
    for param, target in _VLM_FIELDS.items():
        if param not in explicit:
            continue
        if target.startswith("sim."):
            sim[target[4:]] = getattr(flags.sim, target[4:])
        else:
            top[target] = getattr(flags, target)
    if sim:
        top["sim"] = dataclasses.replace(base.sim, **sim)
    return dataclasses.replace(base, **top)

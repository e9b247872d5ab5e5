"""Build a backend (and its client) from a ``VLMConfig``; the one place that dispatches."""

from __future__ import annotations

import importlib
from pathlib import Path
from typing import TYPE_CHECKING, cast

from vlmrl_cli.core.errors import BadInput
from vlmrl_cli.vlm.base import Backend
from vlmrl_cli.vlm.cache import ResponseCache
from vlmrl_cli.vlm.client import VLMClient
from vlmrl_cli.vlm.config import BACKENDS, VLMConfig

if TYPE_CHECKING:
    from vlmrl_cli.vlm.sim import MilestoneReader


_REAL = {"hf": ("vlmrl_cli.vlm.hf", "HFBackend"), "openai": ("vlmrl_cli.vlm.openai_compat", "OpenAIBackend"),
         "replay": ("vlmrl_cli.vlm.replay", "ReplayBackend")}


def build_backend(cfg: VLMConfig, stream: int = 0, reader: MilestoneReader | None = None) -> Backend:
    """The backend ``cfg.backend``; ``stream`` (a run's seed) and ``reader`` are the simulated VLM's."""
    if cfg.backend == "sim":
        from vlmrl_cli.vlm.sim import SimulatedVLM

        if reader is None:
            raise BadInput("the simulated VLM reads a task's frames through the task's reader; pass Task.reader.")
        return SimulatedVLM(reader, cfg.sim, stream=stream)
    if cfg.backend not in _REAL:
        raise BadInput(f"unknown VLM backend '{cfg.backend}'; choose one of {', '.join(BACKENDS)}.")
    module, cls = _REAL[cfg.backend]  # imported only when chosen: transformers and httpx load slowly
    return cast(Backend, getattr(importlib.import_module(module), cls).from_config(cfg))


def build_client(cfg: VLMConfig, transcript: Path | None = None, stream: int = 0,
                 reader: MilestoneReader | None = None) -> VLMClient:
    """The backend of ``cfg`` behind the shared response cache (unless disabled)."""
    backend = build_backend(cfg, stream, reader)
    cache = ResponseCache(cfg.cache_path) if cfg.use_cache and cfg.cache_path is not None else None
    try:
        return VLMClient(backend, cache=cache, transcript=transcript, mcq_mode=cfg.mcq_mode)
    except BaseException:
        backend.close()
        if cache is not None:
            cache.close()
        raise

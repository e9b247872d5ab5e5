"""The checks every command runs on its ``VLMConfig`` before any store, folder or cache exists."""

from __future__ import annotations

from collections.abc import Iterable

from vlmrl_cli.core.errors import BackendUnavailable, BadInput
from vlmrl_cli.core.paths import file_problem
from vlmrl_cli.frames.render import Frame
from vlmrl_cli.vlm.config import VLMConfig
from vlmrl_cli.vlm.prompts import Prompt


def check_vlm(cfg: VLMConfig) -> None:
    """Refuse a VLM configuration that would fail once started (cache path, model, server, transcript)."""
    if cfg.use_cache and cfg.cache_path is not None:
        problem = file_problem(cfg.cache_path)
        if problem:
            raise BadInput(f"cannot open the response cache {cfg.cache_path} ({problem}); pass --no-cache or a "
                           "writable --cache-path.")
    if cfg.backend == "hf":
        from vlmrl_cli.vlm.hf import hub_problem, locate_model

        _, local = locate_model(cfg)
        if not local:
            problem = hub_problem(cfg.model or "")
            if problem:
                raise BackendUnavailable(f"cannot load the hf model: {problem}; pass --model PATH to a downloaded "
                                         "model folder, or download it first.")
    elif cfg.backend != "sim":  # the simulated VLM always starts
        from vlmrl_cli.vlm.registry import build_backend

        # openai: the server answers; replay: the transcript reads; an unknown name is refused
        build_backend(cfg).close()


def check_coverage(cfg: VLMConfig, prompts: Iterable[Prompt], frames: Iterable[Frame]) -> None:
    """Refuse a replay transcript that lacks an answer to a (prompt, frame) a training run can see."""
    if cfg.backend != "replay":
        return
    from vlmrl_cli.core.errors import MissingAnswer
    from vlmrl_cli.vlm.replay import ReplayBackend

    backend = ReplayBackend.from_config(cfg)
    wanted = list(dict.fromkeys(prompts))
    missing = total = 0
    first: str | None = None
    for frame in frames:
        for prompt in wanted:
            total += 1
            try:
                backend.answer(prompt, frame)
            except MissingAnswer as exc:
                missing += 1
                first = first or str(exc)
    backend.close()
    if missing:
        raise BadInput(f"the replay transcript {backend.source} cannot answer {missing} of the {total} "
                       f"(prompt, frame) pairs a training run can see ({first}); record one that covers the camera's "
                       "grid, or use another --vlm.")

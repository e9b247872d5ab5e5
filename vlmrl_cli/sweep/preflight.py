"""The one check of a sweep's configuration before anything is created (store, parent run,
VLM cache): the executor can start, and the VLM the shaped arms need can answer them."""

from __future__ import annotations

from vlmrl_cli.shaping.arms import PotentialSource
from vlmrl_cli.sweep.executors import check_executor
from vlmrl_cli.tasks.registry import DEFAULT_TASK
from vlmrl_cli.training.config import RunConfig
from vlmrl_cli.vlm.preflight import check_coverage, check_vlm
from vlmrl_cli.vlm.prompts import PromptKind

_PROMPT_OF = {PotentialSource.MCQ: PromptKind.MCQ, PotentialSource.FLOAT: PromptKind.FLOAT}


def preflight(cfg: RunConfig) -> None:
    """``BadInput`` for anything that would fail a job once the sweep has started."""
    cfg.validate()
    check_executor(cfg)
    shaped = [job for job in cfg.jobs() if job.arm.uses_vlm]
    if not shaped:
        return
    check_vlm(cfg.vlm)
    if cfg.vlm.backend == "replay" and cfg.task == DEFAULT_TASK:  # another task's frames: replay refuses at once
        from vlmrl_cli.frames.render import FrameRenderer
        from vlmrl_cli.shaping.camera import Camera

        kinds = [_PROMPT_OF[job.arm.potential] for job in shaped]
        quanta = sorted({job.shaping.render_quantum for job in shaped})
        with FrameRenderer() as renderer:
            frames = [renderer.render(x) for q in quanta for x in Camera(q).grid_positions()]
        check_coverage(cfg.vlm, kinds, frames)

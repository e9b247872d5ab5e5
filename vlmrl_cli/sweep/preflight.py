"""The one check of a sweep's configuration before anything is created: the executor can start,
and the VLM the shaped arms need can answer them."""

from __future__ import annotations

from vlmrl_cli.shaping.arms import PotentialSource
from vlmrl_cli.sweep.executors import check_executor
from vlmrl_cli.training.config import RunConfig
from vlmrl_cli.vlm.preflight import check_coverage, check_vlm


def preflight(cfg: RunConfig) -> None:
    """``BadInput`` for anything that would fail a job once the sweep has started (``cfg`` is valid)."""
    check_executor(cfg)
    shaped = [job for job in cfg.jobs() if job.arm.uses_vlm]
    if not shaped:
        return
    check_vlm(cfg.vlm)
    task = cfg.task_plugin
    if cfg.vlm.backend == "replay" and task.camera.frames is not None:  # else replay refuses the frames at once
        prompts = [task.milestones.prompt if job.arm.potential is PotentialSource.MCQ or task.numbers is None
                   else task.numbers.float_prompt for job in shaped]
        shapings = {job.shaping.render_quantum: job.shaping for job in shaped}
        frames = [frame for _, shaping in sorted(shapings.items()) for frame in task.camera.frames(shaping)]
        check_coverage(cfg.vlm, prompts, frames)

"""The SB3 callback that turns completed episodes into tracked metrics and progress events."""

from __future__ import annotations

import time
from collections import deque
from collections.abc import Callable
from typing import Any

import numpy as np
from stable_baselines3.common.callbacks import BaseCallback

from vlmrl_cli.shaping.scene import SuccessRule, ended_by_env
from vlmrl_cli.tracking import schema
from vlmrl_cli.tracking.store import BatchLogger
from vlmrl_cli.training.events import ProgressEvent


class EpisodeTracker(BaseCallback):
    """Logs every completed episode (success by the task's rule) and, at each rollout end,
    ``rollout/return_100``, VLM and throughput figures; sends progress; stops when ``should_stop``."""

    def __init__(
        self,
        job: str,
        total: int,
        metrics: BatchLogger | None = None,
        progress: Callable[[ProgressEvent], None] | None = None,
        should_stop: Callable[[], bool] | None = None,
        vlm_stats: Callable[[], dict[str, float]] | None = None,
        interval_s: float = 0.5,
        success: SuccessRule | None = None,
    ) -> None:
        super().__init__(verbose=0)
        self.job = job
        self.total = total
        self.metrics = metrics
        self.progress = progress
        self.should_stop = should_stop
        self.vlm_stats = vlm_stats
        self.interval_s = interval_s
        self.success = success if success is not None else ended_by_env
        self.episodes: list[dict[str, float]] = []
        self.recent: deque[float] = deque(maxlen=100)
        self.stopped = False
        self._last_report = 0.0
        self._start = time.perf_counter()

    def _on_training_start(self) -> None:
        self._start = time.perf_counter()

    def _on_step(self) -> bool:
        infos: list[dict[str, Any]] = self.locals["infos"]
        for info in infos:
            ep = info.get("episode")
            if ep is None:
                continue
            length = int(ep["l"])
            record = {
                schema.METRIC_NATIVE_RETURN: float(ep["r"]),
                schema.METRIC_LENGTH: float(length),
                # SB3's VecEnvs mark a time-limit cut (truncated, not terminated) as TimeLimit.truncated
                schema.METRIC_SUCCESS: float(self.success(not info.get("TimeLimit.truncated", False), length)),
                schema.METRIC_SHAPED_RETURN: float(info.get("shaped_return", ep["r"])),
            }
            self.episodes.append({"timestep": float(self.num_timesteps), **record})
            self.recent.append(record[schema.METRIC_NATIVE_RETURN])
            if self.metrics is not None:
                self.metrics.log(record, step=self.num_timesteps)
        now = time.perf_counter()
        if self.progress is not None and now - self._last_report >= self.interval_s:
            self._last_report = now
            self._send_progress()
        if self.should_stop is not None and self.should_stop():
            self.stopped = True
            return False
        return True

    def _send_progress(self, phase: str = "train") -> None:
        if self.progress is not None:
            recent = float(np.mean(self.recent)) if self.recent else float("nan")
            self.progress(ProgressEvent(self.job, self.num_timesteps, self.total, len(self.episodes), recent, phase))

    def _on_rollout_end(self) -> None:
        if self.metrics is None:
            return
        elapsed = max(time.perf_counter() - self._start, 1e-9)
        figures = {schema.METRIC_STEPS_PER_S: self.num_timesteps / elapsed}
        if self.recent:  # the rolling mean the reward thresholds are read from
            figures[schema.METRIC_RETURN_100] = float(np.mean(self.recent))
        if self.vlm_stats is not None:
            vlm = self.vlm_stats()
            figures.update(vlm)
            if schema.METRIC_VLM_BACKEND_S in vlm:  # the share of the run's wall time spent waiting for the VLM
                figures[schema.METRIC_VLM_WAIT_SHARE] = vlm[schema.METRIC_VLM_BACKEND_S] / elapsed
        self.metrics.log(figures, step=self.num_timesteps)

    def _on_training_end(self) -> None:
        self._on_rollout_end()
        self._send_progress()
        if self.metrics is not None:
            self.metrics.flush()

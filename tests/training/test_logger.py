"""The SB3 output format that forwards train/ diagnostics to a metrics sink."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
from stable_baselines3.common.logger import Logger

from vlmrl_cli.training.logger import MetricsOutputFormat


class FakeMetrics:
    """Stands in for ``tracking.store.BatchLogger``: records every ``log`` call."""

    def __init__(self) -> None:
        self.calls: list[tuple[dict[str, float], int]] = []

    def log(self, metrics: Mapping[str, float], step: int) -> None:
        self.calls.append((dict(metrics), step))


def test_train_keys_are_forwarded_unchanged_at_the_dump_step() -> None:
    sink = FakeMetrics()
    logger = Logger(folder=None, output_formats=[MetricsOutputFormat(sink)])
    logger.record("train/approx_kl", np.float32(0.015))
    logger.record("train/clip_fraction", 0.1)
    logger.record("train/explained_variance", np.float64(-0.5))
    logger.record("train/n_updates", 3, exclude="tensorboard")
    logger.record("time/fps", 812)
    logger.record("rollout/ep_rew_mean", -200.0)
    logger.dump(step=256)
    assert len(sink.calls) == 1
    figures, step = sink.calls[0]
    assert step == 256
    assert set(figures) == {"train/approx_kl", "train/clip_fraction", "train/explained_variance", "train/n_updates"}
    assert figures["train/approx_kl"] == float(np.float32(0.015))
    assert all(type(v) is float for v in figures.values())


def test_non_numeric_excluded_and_empty_dumps_log_nothing() -> None:
    sink = FakeMetrics()
    writer = MetricsOutputFormat(sink)
    writer.write({"time/fps": 100.0}, {}, step=1)
    writer.write({"train/note": "text", "train/kl": 0.2}, {"train/kl": ("mlflow",)}, step=2)
    assert sink.calls == []
    writer.close()


def test_other_prefixes_can_be_chosen() -> None:
    sink = FakeMetrics()
    MetricsOutputFormat(sink, prefixes=("train/", "time/")).write({"time/fps": 100, "x/y": 1.0}, {}, step=5)
    assert sink.calls == [({"time/fps": 100.0}, 5)]

"""SB3's own training diagnostics (``train/approx_kl``, ...) into MLflow, as an SB3 output format."""

from __future__ import annotations

import numbers
from collections.abc import Mapping
from typing import Any, Protocol

from stable_baselines3.common.logger import KVWriter

from vlmrl_cli.tracking import schema


class MetricSink(Protocol):
    """Where the metrics go: ``tracking.store.BatchLogger`` or a test double."""

    def log(self, metrics: Mapping[str, float], step: int) -> None: ...


class MetricsOutputFormat(KVWriter):
    """An SB3 ``KVWriter`` forwarding the numeric values under ``prefixes`` (by default the PPO update's
    diagnostics) to ``metrics``."""

    def __init__(self, metrics: MetricSink, prefixes: tuple[str, ...] = (schema.TRAIN_METRIC_PREFIX,)) -> None:
        self.metrics = metrics
        self.prefixes = prefixes

    def write(self, key_values: dict[str, Any], key_excluded: dict[str, tuple[str, ...]], step: int = 0) -> None:
        figures = {
            key: float(value)
            for key, value in key_values.items()
            if key.startswith(self.prefixes)
            and isinstance(value, numbers.Real)
            and "mlflow" not in (key_excluded.get(key) or ())
        }
        if figures:
            self.metrics.log(figures, step=int(step))

    def close(self) -> None:
        """The sink belongs to the caller, who flushes it."""

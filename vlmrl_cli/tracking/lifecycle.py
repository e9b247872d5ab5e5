"""The one place an MLflow run is closed: ``terminate``, and ``tracked_run`` around a block.

Every run vlmrl creates (training jobs, sweeps, taxonomy probes, reports, calibration and study
summaries, imports) ends through here with a ``RunStatus``: FINISHED when its block completes,
KILLED on Ctrl-C, FAILED on any other error, so that no run is left RUNNING by an exception.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from enum import StrEnum
from typing import Any


class RunStatus(StrEnum):
    """MLflow's run statuses (a ``StrEnum``: equal to MLflow's own strings)."""

    RUNNING = "RUNNING"
    FINISHED = "FINISHED"
    FAILED = "FAILED"
    KILLED = "KILLED"


def terminate(client: Any, run_id: str, status: RunStatus, end_time: int | None = None) -> None:
    """Close ``run_id`` with ``status`` (``end_time`` in ms since the epoch: now by default)."""
    client.set_terminated(run_id, str(RunStatus(status)), end_time=end_time)


@dataclass
class RunHandle:
    """The run a ``tracked_run`` block works in; set ``status`` to close it otherwise than
    FINISHED when the block ends normally, ``end_time`` to keep an original end time."""

    run_id: str
    status: RunStatus = RunStatus.FINISHED
    end_time: int | None = None


@contextmanager
def tracked_run(client: Any, run_id: str) -> Iterator[RunHandle]:
    """Close ``run_id`` when the block ends: ``handle.status`` (FINISHED unless changed) when it
    completes; on an exception (which propagates) KILLED for a KeyboardInterrupt or a block that
    set ``handle.status`` KILLED (it was stopping), FAILED otherwise. A store that fails to close
    the run then does not hide the exception.

    Example:
        >>> class Client:
        ...     def set_terminated(self, run_id, status, end_time=None): print(run_id, status)
        >>> with tracked_run(Client(), "r1"):
        ...     pass
        r1 FINISHED
        >>> try:
        ...     with tracked_run(Client(), "r2"):
        ...         raise ValueError("boom")
        ... except ValueError:
        ...     pass
        r2 FAILED
    """
    handle = RunHandle(run_id)
    try:
        yield handle
    except BaseException as exc:
        killed = isinstance(exc, KeyboardInterrupt) or handle.status == RunStatus.KILLED
        with contextlib.suppress(Exception):
            terminate(client, run_id, RunStatus.KILLED if killed else RunStatus.FAILED)
        raise
    terminate(client, run_id, handle.status, handle.end_time)

"""The one place an MLflow run is closed (``terminate``, ``tracked_run``): no run vlmrl creates
is left RUNNING by an exception."""

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
    """The run of a ``tracked_run`` block: the ``status`` and ``end_time`` it closes with if the block completes."""

    run_id: str
    status: RunStatus = RunStatus.FINISHED
    end_time: int | None = None


@contextmanager
def tracked_run(client: Any, run_id: str) -> Iterator[RunHandle]:
    """Close ``run_id`` when the block ends: ``handle.status`` if it completes; on an exception (which
    propagates, whatever the store does) KILLED for a Ctrl-C or a handle set KILLED, else FAILED."""
    handle = RunHandle(run_id)
    try:
        yield handle
    except BaseException as exc:
        killed = isinstance(exc, KeyboardInterrupt) or handle.status == RunStatus.KILLED
        with contextlib.suppress(Exception):
            terminate(client, run_id, RunStatus.KILLED if killed else RunStatus.FAILED)
        raise
    terminate(client, run_id, handle.status, handle.end_time)

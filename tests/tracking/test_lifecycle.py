"""Every run closes through tracked_run/terminate: FINISHED, KILLED on Ctrl-C, FAILED on errors."""

from __future__ import annotations

import pytest

from vlmrl_cli.tracking.lifecycle import RunStatus, terminate, tracked_run


class _Client:
    def __init__(self) -> None:
        self.closed: list[tuple[str, str, int | None]] = []

    def set_terminated(self, run_id: str, status: str, end_time: int | None = None) -> None:
        self.closed.append((run_id, status, end_time))


def test_a_block_that_completes_closes_with_its_status_and_end_time() -> None:
    client = _Client()
    with tracked_run(client, "a") as handle:
        handle.end_time = 123
    with tracked_run(client, "b") as handle:
        handle.status = RunStatus.FAILED
    assert client.closed == [("a", "FINISHED", 123), ("b", "FAILED", None)]


@pytest.mark.parametrize(("error", "status"), [(KeyboardInterrupt, "KILLED"), (RuntimeError, "FAILED")])
def test_an_exception_closes_the_run_and_propagates(error: type[BaseException], status: str) -> None:
    client = _Client()
    with pytest.raises(error), tracked_run(client, "r"):
        raise error()
    assert client.closed == [("r", status, None)]


def test_terminate_refuses_a_status_mlflow_does_not_know() -> None:
    with pytest.raises(ValueError):
        terminate(_Client(), "r", "DONE")  # type: ignore[arg-type]


def test_a_block_that_was_stopping_closes_killed_and_a_failing_store_hides_no_error() -> None:
    client = _Client()
    with pytest.raises(RuntimeError), tracked_run(client, "s") as handle:
        handle.status = RunStatus.KILLED
        raise RuntimeError("the executor failed while it stopped")
    assert client.closed == [("s", "KILLED", None)]

    class _Down:
        def set_terminated(self, run_id: str, status: str, end_time: int | None = None) -> None:
            raise ConnectionError("store down")

    with pytest.raises(ValueError, match="the job's own error"), tracked_run(_Down(), "d"):
        raise ValueError("the job's own error")

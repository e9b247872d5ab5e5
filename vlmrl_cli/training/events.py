"""What a sweep and its workers exchange: plain values, importable without SB3 or torch."""

from __future__ import annotations

from dataclasses import dataclass, field

#: Where a sweep's jobs can run (``RunConfig.executor``): a local process pool, or Ray tasks.
EXECUTORS = ("local", "ray")


@dataclass(frozen=True)
class ProgressEvent:
    """What a worker reports about one run, at most every ``interval_s``."""

    job: str
    timesteps: int
    total: int
    episodes: int
    recent_return: float  # mean native return of the last 100 episodes (nan before the first)
    phase: str = "train"


@dataclass(frozen=True)
class JobResult:
    job: str
    run_id: str
    status: str  # FINISHED, KILLED, FAILED; SKIPPED (another live run owns the job), CANCELLED (never started)
    wall_s: float
    eval_success_rate: float = float("nan")
    eval_mean_length: float = float("nan")
    error: str | None = None
    superseded: tuple[str, ...] = ()  # stale runs of the job this run marked FAILED (crashed attempts)


#: Statuses of a job that did not fail: it trained, or it was not this sweep's to train.
NOT_FAILED = ("FINISHED", "SKIPPED", "CANCELLED")


@dataclass(frozen=True)
class JobContext:
    """What every job of one sweep shares, sent to the worker with each job."""

    tracking_uri: str
    experiment_id: str
    parent_run_id: str | None
    vlm_label: str
    simulated: bool
    heartbeat_s: float = 30.0
    stale_after_s: float = 300.0
    connect_wait_s: float = 120.0  # how long a worker waits for a tracking server that does not answer


@dataclass
class SweepSummary:
    parent_run_id: str | None
    experiment_id: str
    skipped: list[str] = field(default_factory=list)
    marked_failed: list[str] = field(default_factory=list)
    elsewhere: list[str] = field(default_factory=list)  # jobs a live run of another sweep owns
    results: list[JobResult] = field(default_factory=list)
    wall_s: float = 0.0
    executor: str = "local"

    @property
    def failed(self) -> list[JobResult]:
        return [r for r in self.results if r.status not in NOT_FAILED]

    @property
    def finished(self) -> list[JobResult]:
        return [r for r in self.results if r.status == "FINISHED"]

    @property
    def lost_claims(self) -> list[JobResult]:
        """Jobs another sweep claimed between our plan and their start."""
        return [r for r in self.results if r.status == "SKIPPED"]

    @property
    def retried(self) -> list[str]:
        """Run ids of crashed attempts (a killed worker) that a later attempt superseded."""
        return [run_id for r in self.results for run_id in r.superseded]


class StopFlag:
    """A flag the sweep sets once and jobs read: the body of the Ray executor's stop actor."""

    def __init__(self) -> None:
        self.value = False

    def set(self) -> None:
        self.value = True

    def is_set(self) -> bool:
        return self.value

"""What workers report to the parent process: plain values, importable without SB3 or torch
(the CLI's progress display and help must not pay for those imports)."""

from __future__ import annotations

from dataclasses import dataclass

SUCCESS_LENGTH = 200  # MountainCar-v0's time limit: an episode shorter than this reached the flag


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
    status: str  # FINISHED, KILLED or FAILED
    wall_s: float
    eval_success_rate: float = float("nan")
    eval_mean_length: float = float("nan")
    error: str | None = None

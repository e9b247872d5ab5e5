"""What pending jobs will cost: wall time, from the runs this store has timed, and a real VLM's
queries. See docs/commands/run.md (the cost estimate) and docs/real-vlm.md."""

from __future__ import annotations

import os
import statistics
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from vlmrl_cli.shaping.arms import ARMS
from vlmrl_cli.tracking import schema
from vlmrl_cli.training.config import RunConfig, TrainJob

#: Seconds per step and worker with nothing measured: `nox -s repro` on 2 cores, 20 runs x 300,000 steps in 665 s.
FALLBACK_S_PER_STEP = 665.0 * 2 / (20 * 300_000)

#: How much slower a retraining machine may be (`vlmrl verify`'s range): `nox -s repro` took 906 s on
#: a busy 2-core machine, 430 s on a Zen 5 EPYC.
SLOWER_MACHINE = 3.0


@dataclass(frozen=True)
class Timings:
    """Per-arm seconds per step and the worker count measured at, and the sweeps' median utilisation."""

    per_arm: dict[str, tuple[float, int]]
    utilisation: float = 1.0
    runs: int = 0


@dataclass(frozen=True)
class CostEstimate:
    """``pending`` runs (``done`` FINISHED) of ``per_run_s`` each, ``total_s`` on ``workers``; ``how``: its basis."""

    pending: int
    done: int
    per_run_s: float
    total_s: float
    workers: int
    how: str

    def minutes_range(self, slower: float = SLOWER_MACHINE) -> str:
        """The total in minutes, from the recorded speed to ``slower`` times slower."""
        low, high = self.total_s / 60, self.total_s * slower / 60
        return f"about {low:,.1f}-{high:,.1f} min ({low:,.1f} at the recorded speed, {high:,.1f} on a machine " \
               f"{slower:g}x slower)"

    def line(self) -> str:
        """One line for a terminal: the figure and its basis."""
        return (f"{self.pending} run(s) to train ({self.done} already FINISHED) x ~{self.per_run_s:,.0f} s per run "
                f"/ {self.workers} worker(s) = ~{self.total_s / 60:,.1f} min; {self.how}")


def contention(workers: int, cores: int) -> float:
    """How much slower one run is with ``workers`` busy workers on ``cores`` cores than alone."""
    return max(1.0, workers / max(1, cores))


def measure(client: Any, experiment_id: str) -> Timings:
    """Timings of the experiment's FINISHED training runs and sweeps (read only)."""
    runs = schema.search_all(client, experiment_id, schema.runs_filter({schema.TAG_KIND: schema.KIND_TRAIN},
                                                                       finished=True))
    sweeps = {r.info.run_id: r for r in schema.search_all(  # interrupted sweeps too: their runs count
        client, experiment_id, schema.runs_filter({schema.TAG_KIND: schema.KIND_SWEEP}))}
    per_arm: dict[str, list[tuple[float, int]]] = {}
    child_wall: dict[str, float] = {}
    for run in runs:
        steps = run.data.params.get(schema.PARAM_TIMESTEPS)
        if not steps or float(steps) <= 0 or run.info.end_time is None:
            continue
        wall = (run.info.end_time - run.info.start_time) / 1000.0
        parent = run.data.tags.get(schema.MLFLOW_PARENT_RUN_ID, "")
        workers = int(sweeps[parent].data.params.get("workers", 1)) if parent in sweeps else 1
        per_arm.setdefault(run.data.tags.get(schema.TAG_ARM, ""), []).append((wall / float(steps), workers))
        child_wall[parent] = child_wall.get(parent, 0.0) + wall
    shares = []
    for run_id, sweep in sweeps.items():
        wall = sweep.data.metrics.get(schema.METRIC_SWEEP_WALL_S)
        workers = int(sweep.data.params.get("workers", 1))
        if wall and run_id in child_wall:
            shares.append(min(1.0, child_wall[run_id] / (wall * workers)))
    medians = {arm: (statistics.median(s for s, _ in v), round(statistics.median(w for _, w in v)))
               for arm, v in per_arm.items()}
    return Timings(medians, statistics.median(shares) if shares else 1.0, sum(len(v) for v in per_arm.values()))


def unmeasured(job: TrainJob) -> float:
    """Seconds per step of ``job`` with nothing timed: its task's ``step_seconds`` (``vlm_step_seconds``
    for an arm that asks the VLM, where declared), else the fallback."""
    task = job.task_plugin
    return (task.vlm_step_seconds if job.arm.uses_vlm else None) or task.step_seconds or FALLBACK_S_PER_STEP


def _declared(jobs: Iterable[TrainJob]) -> str:
    """Each task's seconds per step with nothing timed, for a line: ``pusher 0.52 ms (VLM arms 4.60 ms)``."""
    figures: dict[str, dict[bool, float]] = {}
    for job in jobs:
        figures.setdefault(job.task_plugin.name, {})[job.arm.uses_vlm] = unmeasured(job)
    parts = []
    for task, by_kind in sorted(figures.items()):
        plain, vlm = by_kind.get(False), by_kind.get(True)
        if plain is not None and vlm is not None and vlm != plain:
            parts.append(f"{task} {plain * 1e3:.2f} ms (VLM arms {vlm * 1e3:.2f} ms)")
        else:
            parts.append(f"{task} {(plain if plain is not None else vlm or 0.0) * 1e3:.2f} ms")
    return ", ".join(parts)


def estimate(pending: Sequence[TrainJob], done: int, workers: int, timings: Timings,
             cores: int | None = None) -> CostEstimate:
    """The wall time of training ``pending`` with ``workers`` workers on ``cores`` (this machine's)."""
    cores = cores or os.cpu_count() or 1
    workers = max(1, workers)
    seconds, guessed = 0.0, False
    for job in pending:
        measured = timings.per_arm.get(job.arm.name)
        if measured is None and timings.per_arm:  # an arm not timed yet: the median of its own kind
            kind = [v for arm, v in timings.per_arm.items() if arm in ARMS and ARMS[arm].uses_vlm == job.arm.uses_vlm]
            guessed |= job.arm.uses_vlm and not kind
            measured = (statistics.median(s for s, _ in kind or timings.per_arm.values()), 1)
        s_per_step, measured_at = measured or (unmeasured(job), cores)
        seconds += job.timesteps * s_per_step * contention(workers, cores) / contention(measured_at, cores)
    total = seconds / min(workers, max(1, len(pending))) / timings.utilisation
    if timings.per_arm:
        how = (f"per-step wall time of {timings.runs} finished run(s) of {len(timings.per_arm)} arm(s) in this "
               f"experiment, {cores} core(s), sweep utilisation {timings.utilisation:.0%}"
               + ("; no arm that asks the VLM is timed yet, so those runs count at the other arms' rate: a lower "
                  "bound" if guessed else ""))
    else:
        figures = _declared(pending) or f"{FALLBACK_S_PER_STEP * 1e3:.2f} ms"
        how = (f"no finished run to measure yet: {figures} per step and worker on 2 cores (each task's "
               "committed runs; MountainCar-v0's from `nox -s repro`, 20 runs x 300,000 steps in 665 s)")
    return CostEstimate(len(pending), done, seconds / len(pending) if pending else 0.0, total, workers, how)


def retrain_estimate(runs: Sequence[tuple[TrainJob, float | None]], workers: int,
                     cores: int | None = None) -> CostEstimate:
    """The wall time of retraining ``runs`` (each job with its recorded wall time, or None) with
    ``workers`` on ``cores``: a recorded wall time (set-up included: an upper bound), else ``unmeasured``."""
    cores = cores or os.cpu_count() or 1
    workers = max(1, min(workers, len(runs)))
    measured = [(job, wall) for job, wall in runs if wall is not None and wall > 0]
    declared = [job for job, wall in runs if wall is None or wall <= 0]
    seconds = sum(wall for _, wall in measured) + sum(job.timesteps * unmeasured(job) for job in declared)
    total = seconds * contention(workers, cores) / workers
    parts = []
    if measured:
        parts.append(f"{len(measured)} run(s) at the wall time per step they recorded (with their set-up and "
                     "evaluation, which a retrain skips)")
    if declared:
        parts.append(f"{len(declared)} run(s), which recorded no wall time, at their task's {_declared(declared)} "
                     "per step")
    how = (f"{sum(job.timesteps for job, _ in runs):,} steps in all: " + "; ".join(parts) +
           f"; {cores} core(s)")
    return CostEstimate(len(runs), 0, seconds / len(runs) if runs else 0.0, total, workers, how)


def estimate_sweeps(cfgs: Sequence[RunConfig]) -> CostEstimate:
    """The cost of what the sweeps ``cfgs`` (into one experiment) still miss; a shared job counts once."""
    from vlmrl_cli.sweep.runner import dry_plan
    from vlmrl_cli.tracking import store

    pending: dict[tuple[str, int, str], TrainJob] = {}
    done: set[tuple[str, int, str]] = set()
    timings: Timings | None = None
    for cfg in cfgs:
        plan = dry_plan(cfg)
        done |= {(j.arm.name, j.seed, j.config_hash) for j in plan.done}
        pending |= {(j.arm.name, j.seed, j.config_hash): j for j in plan.pending}
        if timings is None and plan.experiment_id is not None:
            timings = measure(store.connect(cfg.tracking_uri), plan.experiment_id)
    workers = cfgs[0].workers if cfgs else 1
    return estimate(list(pending.values()), len(done - set(pending)), workers, timings or Timings({}))


# --- what a run will ask of a real VLM ---------------------------------------------------------

#: ``--vlm-qps``'s default: a 7B VLM under HF transformers at batch 1 (olmo-eval PR #347: 2.0 it/s
#: against vLLM's 11.9 on Qwen3-VL-4B; LLaVA issue #1009).
DEFAULT_VLM_QPS = 3.0


@dataclass(frozen=True)
class VlmHitRate:
    """A task's hybrid runs' labelling steps per ``T / k`` (``events``) and the share that reach the
    VLM (``miss``), medians over ``runs`` committed runs; see docs/real-vlm.md."""

    events: float
    miss: float
    runs: int

    @property
    def asked(self) -> float:
        """``1 - h``: the queries per ``T / k``."""
        return self.events * self.miss


#: ``measure_hit_rates(committed_exports())``, which tests/sweep/test_cost.py checks.
VLM_HIT_RATES: dict[str, VlmHitRate] = {
    "mountain-car": VlmHitRate(events=1.0431, miss=0.018631, runs=153),
    "mountain-car-continuous": VlmHitRate(events=1.01045, miss=0.053466, runs=60),
    "acrobot": VlmHitRate(events=1.0599, miss=0.143449, runs=60),
    "minigrid-doorkey": VlmHitRate(events=1.43905, miss=0.015269, runs=40),
    "pusher": VlmHitRate(events=1.104, miss=0.722391, runs=7),
}


def committed_exports(root: Path = Path("results")) -> list[Path]:
    """The run exports committed under ``root`` (``results/**/*.jsonl.gz``)."""
    return sorted(root.rglob("*.jsonl.gz"))


def _rate_of_run(record: Mapping[str, Any]) -> tuple[str, float, float] | None:
    """(task, events per T/k, miss) of one exported hybrid run, or None for any other run."""
    tags, params, latest = record["tags"], record["params"], record["latest"]
    needed = (schema.METRIC_VLM_QUERIES, schema.METRIC_VLM_LABEL_REUSES)
    if tags.get(schema.TAG_ARM) != "hybrid" or not all(k in latest for k in needed):
        return None
    queries, reuses = (float(latest[k][2]) for k in needed)  # [step, timestamp, value]
    steps, every = float(params["timesteps"]), float(params["shaping.query_every"])
    events = queries + reuses
    if events <= 0 or steps <= 0:
        return None
    return str(tags.get(schema.TAG_TASK) or params.get("task") or "mountain-car"), events * every / steps, \
        queries / events


def measure_hit_rates(paths: Iterable[Path]) -> dict[str, VlmHitRate]:
    """``VlmHitRate`` per task from the hybrid runs in the export files ``paths`` (a run counts once)."""
    from vlmrl_cli.tracking.transfer import read_records

    seen: dict[str, tuple[str, float, float]] = {}
    for path in paths:
        for record in read_records(path):
            rate = _rate_of_run(record)
            if rate is not None:
                seen[str(record["source_run_id"])] = rate
    by_task: dict[str, list[tuple[float, float]]] = {}
    for task, events, miss in seen.values():
        by_task.setdefault(task, []).append((events, miss))
    return {task: VlmHitRate(round(statistics.median(e for e, _ in v), 6), round(statistics.median(m for _, m in v), 6),
                             len(v)) for task, v in sorted(by_task.items())}


@dataclass(frozen=True)
class VlmCost:
    """What ``runs`` runs that ask the VLM will ask of it: ``queries`` in all, ``seconds`` at ``qps``."""

    runs: int
    queries: float
    qps: float
    how: str

    @property
    def seconds(self) -> float:
        return self.queries / self.qps

    def line(self) -> str:
        """One line for a terminal."""
        hours = self.seconds / 3600
        return (f"{self.runs} run(s) ask the VLM ~{self.queries:,.0f} queries in all; at {self.qps:g} queries/s "
                f"(--vlm-qps) ~{hours:,.1f} h of VLM time ({hours / 24:.0%} of a GPU-day); {self.how}")


def vlm_cost(jobs: Sequence[TrainJob], qps: float = DEFAULT_VLM_QPS,
             rates: Mapping[str, VlmHitRate] = VLM_HIT_RATES) -> VlmCost | None:
    """The VLM queries of ``jobs`` whose arm asks it (None: none does), each ``T / k x (1 - h)`` with
    its task's rate (``h = 0`` without one), and their time at ``qps``."""
    asking = [job for job in jobs if job.arm.uses_vlm]
    if not asking:
        return None
    queries, basis = 0.0, {}
    for job in asking:
        task = job.task_plugin.name
        rate = rates.get(task)
        queries += job.timesteps / job.shaping.query_every * (rate.asked if rate else 1.0)
        basis[task] = (f"{task}: 1 - h = {rate.asked:.4f} of T/k, the median of {rate.runs} committed hybrid runs "
                       "(vlm/queries, vlm/label_reuses), each with an empty response cache, an upper bound for "
                       "runs sharing one" if rate else f"{task}: no committed runs measured, h = 0 assumed")
    return VlmCost(len(asking), queries, qps, "; ".join(basis.values()) + "; Q = T/k x (1 - h)")

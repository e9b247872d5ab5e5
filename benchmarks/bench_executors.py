"""Executor figures for planning cluster sweeps (issue: sweeps on a Ray cluster). Prints measurements.

  1. local pool vs Ray on this machine: ``run_sweep`` of 8 short jobs (smoke preset,
     ``--timesteps`` each) with 2 workers, MLflow in a temporary sqlite store. Ray's cluster
     start is timed apart; the overhead compares the sweeps themselves (target <= 5%).
  2. dispatch scaling: ``--jobs`` trivial jobs (a fake trainer that returns at once, through the
     same claim, heartbeat and bookkeeping path as a real job) through each executor, at
     ``--jobs`` and at a quarter of it: the orchestration cost per job, and whether it stays flat
     as the store fills (a per-job lookup that scans the store would grow with it).

Usage: python benchmarks/bench_executors.py [--timesteps 5000] [--jobs 1000] [--skip-ray]
"""

from __future__ import annotations

from vlmrl_cli.core.numeric_pin import apply as pin_numeric_path

pin_numeric_path()  # before torch and numpy load: the kernels every run of vlmrl computes with

import argparse
import dataclasses
import functools
import tempfile
import time
from pathlib import Path
from typing import Any

from vlmrl_cli.sweep.ray_executor import start_local
from vlmrl_cli.sweep.runner import SilentReporter, run_sweep
from vlmrl_cli.sweep.worker import Channels, run_claimed, train_job
from vlmrl_cli.tasks.registry import get_task
from vlmrl_cli.training.config import RunConfig, TrainJob
from vlmrl_cli.training.events import JobResult
from vlmrl_cli.training.presets import preset_of


def fake_body(job: TrainJob, client: Any, run_id: str, channels: Channels) -> JobResult:
    """A trainer that trains nothing: what is left is the orchestration."""
    return JobResult(job.name, run_id, "FINISHED", 0.0)


def _sweep(cfg: RunConfig, job_fn: Any = None) -> tuple[float, int]:
    start = time.perf_counter()
    summary = run_sweep(cfg, SilentReporter(), job_fn or train_job)
    if summary.failed:
        raise SystemExit(f"failed jobs: {[(r.job, r.error) for r in summary.failed][:3]}")
    return time.perf_counter() - start, len(summary.finished)


def _short_jobs(root: Path, timesteps: int, executor: str) -> RunConfig:
    ppo = dataclasses.replace(preset_of(get_task("mountain-car"), "smoke"), timesteps=timesteps)
    return RunConfig(arms=("baseline", "hybrid"), seeds=(0, 1, 2, 3), preset="smoke", ppo=ppo, workers=2,
                     tracking_uri=f"sqlite:///{root / 'short.db'}", experiment=f"short-{executor}", executor=executor)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--timesteps", type=int, default=5000, help="steps of each of the 8 short jobs")
    parser.add_argument("--jobs", type=int, default=1000, help="trivial jobs of the dispatch-scaling figure")
    parser.add_argument("--skip-ray", action="store_true", help="local pool only")
    args = parser.parse_args()
    executors = ["local"] if args.skip_ray else ["local", "ray"]
    fake = functools.partial(run_claimed, body=fake_body)

    with tempfile.TemporaryDirectory(prefix="vlmrl-bench-") as tmp:
        root = Path(tmp)
        if not args.skip_ray:
            start = time.perf_counter()
            start_local(2)
            print(f"Ray local instance start (2 CPUs): {time.perf_counter() - start:.1f} s (not counted below)")
            # warm the Ray workers' imports once: they outlive a sweep, whereas the local pool starts
            # its processes (and pays their imports) in every sweep, inside its figure below
            _sweep(dataclasses.replace(_short_jobs(root, 1024, "ray"), experiment="warm-ray", seeds=(0,)))
        _sweep(dataclasses.replace(_short_jobs(root, 1024, "local"), experiment="warm-local", seeds=(0,)))

        print(f"\n1. 8 short jobs (baseline + hybrid x 4 seeds, smoke preset, {args.timesteps:,} steps), 2 workers")
        walls = {}
        for name in executors:
            walls[name], n = _sweep(_short_jobs(root, args.timesteps, name))
            print(f"   {name:<5}: {walls[name]:7.1f} s for {n} jobs")
        if "ray" in walls:
            overhead = 100 * (walls["ray"] / walls["local"] - 1)
            print(f"   Ray overhead vs the local pool: {overhead:+.1f}% (target <= 5%)")

        print("\n2. dispatch scaling: trivial jobs (fake trainer), 2 workers, claims and bookkeeping in sqlite")
        for name in executors:
            for n_jobs in (args.jobs // 4, args.jobs):
                cfg = RunConfig(arms=("baseline",), seeds=tuple(range(n_jobs)), preset="smoke", workers=2,
                                tracking_uri=f"sqlite:///{root / f'dispatch-{name}-{n_jobs}.db'}",
                                experiment="dispatch", executor=name)
                wall, n = _sweep(cfg, fake)
                print(f"   {name:<5} {n_jobs:>5} jobs: {wall:7.1f} s, {1000 * wall / n:6.1f} ms per job "
                      f"({1000 * wall * 2 / n:6.1f} ms of a worker per job)")
            cfg = dataclasses.replace(cfg, tracking_uri=f"sqlite:///{root / f'dispatch-{name}-{args.jobs}.db'}")
            start = time.perf_counter()
            _sweep(cfg, fake)  # every job FINISHED: the plan alone
            print(f"   {name:<5} resume check of {args.jobs} FINISHED jobs (nothing to train): "
                  f"{time.perf_counter() - start:.2f} s")


if __name__ == "__main__":
    main()

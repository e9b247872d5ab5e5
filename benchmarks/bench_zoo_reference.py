"""Every built-in task's baseline against its published reference (issue 41). Prints measurements.

For each built-in task, plain PPO (the ``baseline`` arm) under the task's ``zoo`` preset, at the
zoo's budget, on ``--seeds`` seeds, through the resumable sweep (an MLflow store at ``--store``; a
run already FINISHED there is not trained again, so an interrupted benchmark resumes). Each run's
score is its detached evaluation's mean return (``eval/mean_return``, the preset's
``eval_episodes`` episodes, deterministic policy); the row gives their mean over seeds with a 95%
t interval, each seed's score, and rl-baselines3-zoo's ``benchmark.md`` figure (mean +/- std of
one trained agent's episode returns, ``tasks.zoo``).

Verdict per row: ``met`` when the zoo's interval (mean +/- std) overlaps ours; ``cannot tell``
when it overlaps but our interval is more than ``WIDE`` times as wide as the zoo's (seeds that
disagree: an overlap then says nothing), with how many seeds score inside the zoo's interval;
else ``not met`` with the gap. The zoo's std is over one trained agent's episodes, ours over
seeds. A row that is not met is not explained away here: the docs' results page says why.

Runs trained elsewhere count when their export is imported first (``vlmrl import FILE --experiment
zoo-reference-TASK --tracking-uri sqlite:///STORE/zoo-reference.db``): only runs of the zoo preset's
config hash are read.

Usage: python benchmarks/bench_zoo_reference.py [--seeds 3] [--seeds-for TASK=N ...] [--workers 1] [--store DIR]
       [--tasks a,b] [--markdown FILE]   (also writes the table as markdown, with the date and the CPU)
"""

from __future__ import annotations

from vlmrl_cli.core.numeric_pin import apply as pin_numeric_path

pin_numeric_path()  # before torch and numpy load: the kernels every run of vlmrl computes with

import argparse
import datetime as dt
import math
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy import stats as sps

from vlmrl_cli.analysis.stats import wilson_ci
from vlmrl_cli.core.numeric_pin import cpu_model
from vlmrl_cli.core.provenance import cpu_paths
from vlmrl_cli.sweep.runner import SilentReporter, run_sweep
from vlmrl_cli.sweep.worker import train_job
from vlmrl_cli.tasks.registry import get_task, task_names
from vlmrl_cli.tasks.zoo import SOURCE, ZOO_PPO
from vlmrl_cli.tracking import schema
from vlmrl_cli.training.config import RunConfig

#: How much wider than the zoo's mean +/- std our interval may be for an overlap to count as met.
WIDE = 4.0


@dataclass(frozen=True)
class Row:
    task: str
    env_id: str
    budget: int
    scores: tuple[float, ...]
    zoo_mean: float
    zoo_std: float
    zoo_budget: str

    @property
    def mean(self) -> float:
        return float(np.mean(self.scores))

    @property
    def interval(self) -> tuple[float, float]:
        """95% t interval of the mean over seeds (a point when every seed scores the same)."""
        x = np.asarray(self.scores)
        if x.size < 2 or float(np.std(x)) == 0.0:
            return self.mean, self.mean
        half = float(sps.t.ppf(0.975, x.size - 1) * np.std(x, ddof=1) / math.sqrt(x.size))
        return self.mean - half, self.mean + half

    @property
    def verdict(self) -> str:
        lo, hi = self.interval
        z_lo, z_hi = self.zoo_mean - self.zoo_std, self.zoo_mean + self.zoo_std
        if lo <= z_hi and z_lo <= hi:
            if hi - lo <= WIDE * (z_hi - z_lo):
                return "met"
            inside = sum(z_lo <= x <= z_hi for x in self.scores)
            share = wilson_ci(inside, len(self.scores))
            return (f"cannot tell (our interval is {(hi - lo) / (z_hi - z_lo):.0f}x as wide as the zoo's; "
                    f"{inside}/{len(self.scores)} seeds inside the zoo's interval, "
                    f"{share.value:.0%} [{share.low:.0%}, {share.high:.0%}] Wilson)")
        gap = z_lo - hi if hi < z_lo else lo - z_hi
        return f"not met ({'below' if hi < z_lo else 'above'} the zoo's interval by {gap:.3g})"


def scores_of(uri: str, experiment: str, config_hash: str) -> dict[int, float]:
    """Seed -> detached mean return of the FINISHED runs of ``experiment`` with ``config_hash`` (an
    imported export may hold other configurations too)."""
    import mlflow

    client = mlflow.MlflowClient(tracking_uri=uri)
    exp = client.get_experiment_by_name(experiment)
    if exp is None:
        return {}
    out: dict[int, float] = {}
    for run in client.search_runs([exp.experiment_id], f"tags.`{schema.TAG_KIND}` = '{schema.KIND_TRAIN}'"):
        if (run.info.status == "FINISHED" and schema.METRIC_EVAL_MEAN_RETURN in run.data.metrics
                and run.data.tags.get(schema.TAG_CONFIG_HASH) == config_hash):
            out[int(run.data.tags[schema.TAG_SEED])] = float(run.data.metrics[schema.METRIC_EVAL_MEAN_RETURN])
    return out


def bench(task_name: str, seeds: int, workers: int, store: Path) -> Row:
    task = get_task(task_name)
    uri, experiment = f"sqlite:///{store / 'zoo-reference.db'}", f"zoo-reference-{task_name}"
    cfg = RunConfig.from_sources(None, {"task": task_name, "preset": "zoo", "arms": ["baseline"],
                                        "seeds": list(range(seeds)), "workers": workers, "tracking_uri": uri,
                                        "experiment": experiment})
    summary = run_sweep(cfg, SilentReporter(), train_job)
    if summary.failed:
        raise SystemExit(f"{task_name}: failed jobs: {[(r.job, r.error) for r in summary.failed][:3]}")
    found = scores_of(uri, experiment, cfg.jobs()[0].config_hash)
    zoo = ZOO_PPO[task.env_id]
    return Row(task_name, task.env_id, cfg.budget, tuple(found[s] for s in range(seeds)), zoo.mean, zoo.std,
               zoo.budget)


def cpu_line() -> str:
    """The CPU and the code paths a result may depend on (``core.provenance.cpu_paths``)."""
    paths = cpu_paths()
    return (f"{cpu_model()}; numpy SIMD {paths['numpy_simd']}; BLAS {paths['blas']}; "
            f"torch CPU capability {paths['torch']}")


def table(rows: list[Row]) -> list[str]:
    head = ["task", "env", "budget", "seeds", "ours: mean [95% t]", "each seed", "zoo: mean +/- std (budget)",
            "verdict"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in rows:
        lo, hi = r.interval
        lines.append(f"| {r.task} | {r.env_id} | {r.budget:,} | {len(r.scores)} | {r.mean:.3f} [{lo:.3f}, {hi:.3f}] | "
                     f"{', '.join(f'{s:.3f}' for s in r.scores)} | {r.zoo_mean:g} +/- {r.zoo_std:g} ({r.zoo_budget}) | "
                     f"{r.verdict} |")
    return lines


def seed_counts(pairs: list[str], tasks: list[str]) -> dict[str, int]:
    """``["task=N", ...]`` -> {task: N}, refusing a task not benchmarked or a count below 1."""
    out: dict[str, int] = {}
    for pair in pairs:
        name, sep, count = pair.partition("=")
        if not sep or not count.isdigit() or int(count) < 1:
            raise SystemExit(f"--seeds-for {pair!r}: expected TASK=N with N >= 1")
        if name not in tasks:
            raise SystemExit(f"--seeds-for {pair!r}: {name!r} is not among --tasks ({', '.join(tasks)})")
        out[name] = int(count)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seeds", type=int, default=3, help="seeds per task (0..N-1)")
    parser.add_argument("--seeds-for", action="append", default=[], metavar="TASK=N",
                        help="seeds for one task instead of --seeds (repeatable)")
    parser.add_argument("--workers", type=int, default=1, help="worker processes")
    parser.add_argument("--store", type=Path, default=None, help="folder of the resumable MLflow store "
                        "(default: a temporary one)")
    parser.add_argument("--tasks", default=",".join(task_names()), help="comma-separated built-in tasks")
    parser.add_argument("--markdown", type=Path, default=None, help="also write the table to this markdown file")
    args = parser.parse_args()
    store = args.store or Path(tempfile.mkdtemp(prefix="vlmrl-zoo-"))
    store.mkdir(parents=True, exist_ok=True)
    seeds_for = seed_counts(args.seeds_for, args.tasks.split(","))
    rows = []
    for name in args.tasks.split(","):
        rows.append(bench(name, seeds_for.get(name, args.seeds), args.workers, store))
        print(f"{name}: {rows[-1].verdict}", flush=True)
    lines = [f"Zoo references, measured {dt.date.today().isoformat()} on {cpu_line()}.", "",
             f"Reference: {SOURCE}. Ours: the baseline arm under each task's `zoo` preset at its budget, detached "
             "evaluation mean return per seed. Verdict: met when the zoo's mean +/- std overlaps our 95% t "
             f"interval over seeds and ours is at most {WIDE:g}x as wide; cannot tell when it overlaps a wider "
             "one; else not met. The zoo's std is over one agent's episodes, ours over seeds.", "", *table(rows)]
    print("\n".join(lines))
    if args.markdown is not None:
        args.markdown.write_text("\n".join(lines) + "\n", encoding="utf-8")


if __name__ == "__main__":
    main()

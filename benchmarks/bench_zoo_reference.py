"""Every built-in task's baseline against its published reference (issue 41). Prints measurements.

For each built-in task, plain PPO (the ``baseline`` arm) under the task's ``zoo`` preset, at the
zoo's budget, on ``--seeds`` seeds, through the resumable sweep (an MLflow store at ``--store``; a
run already FINISHED there is not trained again, so an interrupted benchmark resumes). Each run's
score is its detached evaluation's mean return (``eval/mean_return``, the preset's
``eval_episodes`` episodes, deterministic policy); the row gives their mean over seeds with a 95%
t interval, each seed's score, and rl-baselines3-zoo's ``benchmark.md`` figure (mean +/- std of
one trained agent's episode returns, ``tasks.zoo``).

Verdict per row, the equivalence rule of ``analysis.reference`` (issue 51): ``met`` when the seed
mean is equivalent to the zoo's score within 10% of the task's span from its random policy's score
(``Task.random_score``) to the zoo's, by two one-sided t tests on at least 10 seeds; ``not met``
when the 90% t interval lies wholly outside that band; else ``cannot tell``. A row that is not met
is not explained away here: the docs' results page says why.

Runs trained elsewhere count when their export is imported first (``vlmrl import FILE --experiment
zoo-reference-TASK --tracking-uri sqlite:///STORE/zoo-reference.db``): only runs of the zoo preset's
config hash are read.

Usage: python benchmarks/bench_zoo_reference.py [--seeds 3] [--seeds-for TASK=N ...] [--workers 1] [--store DIR]
       [--tasks a,b] [--markdown FILE]   (also writes the table as markdown, with the date and the CPU)
       [--no-train]   (judge the FINISHED runs already in the store, e.g. imported exports; train nothing)
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

from vlmrl_cli.analysis.reference import RULE, ReferenceVerdict, reference_equivalence
from vlmrl_cli.core.numeric_pin import cpu_model
from vlmrl_cli.core.provenance import cpu_paths
from vlmrl_cli.sweep.runner import SilentReporter, run_sweep
from vlmrl_cli.sweep.worker import train_job
from vlmrl_cli.tasks.registry import get_task, task_names
from vlmrl_cli.tasks.zoo import SOURCE, ZOO_PPO
from vlmrl_cli.tracking import schema
from vlmrl_cli.training.config import RunConfig


@dataclass(frozen=True)
class Row:
    task: str
    env_id: str
    budget: int
    scores: tuple[float, ...]
    zoo_mean: float
    zoo_std: float
    zoo_budget: str
    random_score: float

    @property
    def judged(self) -> ReferenceVerdict:
        return reference_equivalence(self.scores, self.zoo_mean, self.random_score)

    @property
    def verdict(self) -> str:
        v = self.judged
        return v.verdict + (f" ({v.note})" if v.note else "")


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


def bench(task_name: str, seeds: int, workers: int, store: Path, train: bool = True) -> Row:
    task = get_task(task_name)
    uri, experiment = f"sqlite:///{store / 'zoo-reference.db'}", f"zoo-reference-{task_name}"
    cfg = RunConfig.from_sources(None, {"task": task_name, "preset": "zoo", "arms": ["baseline"],
                                        "seeds": list(range(seeds)), "workers": workers, "tracking_uri": uri,
                                        "experiment": experiment})
    if train:
        summary = run_sweep(cfg, SilentReporter(), train_job)
        if summary.failed:
            raise SystemExit(f"{task_name}: failed jobs: {[(r.job, r.error) for r in summary.failed][:3]}")
    found = scores_of(uri, experiment, cfg.jobs()[0].config_hash)
    missing = [s for s in range(seeds) if s not in found]
    if missing:
        raise SystemExit(f"{task_name}: no FINISHED run of seeds {missing} in the store (--no-train trains nothing)")
    zoo = ZOO_PPO[task.env_id]
    if task.random_score is None:
        raise SystemExit(f"{task_name}: no measured random-policy score (Task.random_score)")
    return Row(task_name, task.env_id, cfg.budget, tuple(found[s] for s in range(seeds)), zoo.mean, zoo.std,
               zoo.budget, task.random_score.mean)


def cpu_line() -> str:
    """The CPU and the code paths a result may depend on (``core.provenance.cpu_paths``)."""
    paths = cpu_paths()
    return (f"{cpu_model()}; numpy SIMD {paths['numpy_simd']}; BLAS {paths['blas']}; "
            f"torch CPU capability {paths['torch']}")


def table(rows: list[Row]) -> list[str]:
    head = ["task", "env", "budget", "seeds", "ours: mean [90% t]", "each seed", "zoo: mean +/- std (budget)",
            "random policy", "band (zoo +- 10% of the span)", "TOST p", "verdict"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in rows:
        v = r.judged
        p = f"{v.p_tost:.2g}" if math.isfinite(v.p_tost) else "—"
        lines.append(f"| {r.task} | {r.env_id} | {r.budget:,} | {v.n} | {v.mean:.3f} [{v.low:.3f}, {v.high:.3f}] | "
                     f"{', '.join(f'{s:.3f}' for s in r.scores)} | {r.zoo_mean:g} +/- {r.zoo_std:g} ({r.zoo_budget}) | "
                     f"{r.random_score:g} | [{r.zoo_mean - v.delta:.3f}, {r.zoo_mean + v.delta:.3f}] | {p} | "
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
    parser.add_argument("--no-train", action="store_true", help="judge the FINISHED runs in the store; train nothing")
    args = parser.parse_args()
    store = args.store or Path(tempfile.mkdtemp(prefix="vlmrl-zoo-"))
    store.mkdir(parents=True, exist_ok=True)
    seeds_for = seed_counts(args.seeds_for, args.tasks.split(","))
    rows = []
    for name in args.tasks.split(","):
        rows.append(bench(name, seeds_for.get(name, args.seeds), args.workers, store, not args.no_train))
        print(f"{name}: {rows[-1].verdict}", flush=True)
    when = (f"judged {dt.date.today().isoformat()} from the FINISHED runs in the store (--no-train: imported "
            "exports, trained earlier; no run trained now)" if args.no_train else
            f"measured {dt.date.today().isoformat()} on {cpu_line()}")
    lines = [f"Zoo references, {when}.", "",
             f"Reference: {SOURCE}. Ours: the baseline arm under each task's `zoo` preset at its budget, detached "
             f"evaluation mean return per seed, every seed of that configuration. Verdict: {RULE}. The zoo's std is "
             "over one agent's episodes, ours over seeds.", "", *table(rows)]
    print("\n".join(lines))
    if args.markdown is not None:
        args.markdown.write_text("\n".join(lines) + "\n", encoding="utf-8")


if __name__ == "__main__":
    main()

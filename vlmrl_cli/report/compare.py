"""`vlmrl compare`: one view across tasks of the arms' detached evaluation scores, read from export files,
min-max normalised per task (``NORMALISATIONS``) and aggregated with stratified bootstrap intervals.
See docs/commands/compare.md."""

from __future__ import annotations

from collections import Counter
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from matplotlib.figure import Figure

from vlmrl_cli.analysis import aggregate as agg
from vlmrl_cli.analysis.load import numeric_path
from vlmrl_cli.analysis.stats import Estimate, Streams
from vlmrl_cli.core.errors import BadInput
from vlmrl_cli.core.tables import markdown_rows
from vlmrl_cli.report.config import ESTIMATED, ESTIMATED_BANNER, NORMALISATIONS, CompareConfig, check_compare
from vlmrl_cli.report.figures import plot_normalised_profile
from vlmrl_cli.report.table2 import BASELINE, order_arms
from vlmrl_cli.report.writer import check_paths
from vlmrl_cli.tasks.base import Task, TaskLookup
from vlmrl_cli.tasks.registry import recorded_task
from vlmrl_cli.tasks.zoo import ZOO_PPO
from vlmrl_cli.tracking import schema
from vlmrl_cli.tracking.transfer import read_records

SIMULATED_NOTE = "SIMULATED VLM, not a real model."
REAL_NOTE = "no run used the simulated VLM"
RUN_COLUMNS = ["task", "arm", "seed", "config_hash", "run_id", "score", "simulated", "numeric_path", "file", "regime"]
RUN_RULE = ("a run counts once per (task, arm, seed, config hash): when several export files hold it, the one in "
            "the first file named is kept")
WEIGHT_RULE = ("every task weighs the same in every aggregate, whatever its number of runs (IQM: the middle half "
               "of the mixture of the tasks' run distributions, each task's runs sharing 1/n_tasks)")


@dataclass(frozen=True)
class CompareResult:
    """What `vlmrl compare` wrote and found."""

    out: Path
    files: list[Path]
    table: pd.DataFrame
    arms: list[str]
    tasks: list[str]
    left_out: dict[str, list[str]] = field(default_factory=dict)
    simulated: bool = False
    counted_once: int = 0  # runs held by more than one file, counted once (``RUN_RULE``)
    # the configurations of a task's arm not compared (``select_configs`` keeps one), as "arm on task: hash (n runs)"
    other_configs: tuple[str, ...] = ()
    pairs: pd.DataFrame = field(default_factory=pd.DataFrame)  # per task (index): lo, lo_from, hi, hi_from
    estimated: bool = False  # the anchors are estimated from the runs (``ESTIMATED``)


def read_runs(files: Sequence[Path]) -> pd.DataFrame:
    """One row per training run of the export ``files`` (``RUN_COLUMNS``), each source run once.

    ``BadInput`` for a file that is not an export, or a run without a detached evaluation score.
    """
    rows: list[dict[str, object]] = []
    seen: set[str] = set()
    for path in files:
        for record in read_records(path):
            tags = record.get("tags", {})
            if tags.get(schema.TAG_KIND, schema.KIND_TRAIN) != schema.KIND_TRAIN or record["source_run_id"] in seen:
                continue
            seen.add(record["source_run_id"])
            latest = record.get("latest", {}).get(schema.METRIC_EVAL_MEAN_RETURN)
            if latest is None or not np.isfinite(float(latest[2])):
                raise BadInput(f"{path}: run {record['source_run_id']} has no {schema.METRIC_EVAL_MEAN_RETURN} (its "
                               "detached evaluation); export runs that finished their evaluation.")
            rows.append({"task": recorded_task(tags.get(schema.TAG_TASK)), "arm": tags.get(schema.TAG_ARM, ""),
                         "seed": int(tags.get(schema.TAG_SEED, -1)),
                         "config_hash": tags.get(schema.TAG_CONFIG_HASH, ""),
                         "run_id": record["source_run_id"], "score": float(latest[2]),
                         "simulated": tags.get(schema.TAG_SIMULATED) == "true",
                         "numeric_path": numeric_path(tags), "file": str(path),
                         "regime": tags.get(schema.TAG_REGIME, "")})
    if not rows:
        raise BadInput(f"the export files hold no training run: {', '.join(str(p) for p in files)}.")
    return pd.DataFrame(rows, columns=RUN_COLUMNS)


def count_once(runs: pd.DataFrame) -> tuple[pd.DataFrame, pd.DataFrame]:
    """``runs`` with each (task, arm, seed, config hash) once (``RUN_RULE``: the first row kept), and
    the rows dropped.

    Example:
        >>> runs = pd.DataFrame({"task": ["t"] * 3, "arm": ["b"] * 3, "seed": [0, 0, 1],
        ...                      "config_hash": ["h"] * 3, "file": ["study", "calibration", "study"]})
        >>> kept, dropped = count_once(runs)
        >>> kept["seed"].tolist(), dropped["file"].tolist()
        ([0, 1], ['calibration'])
    """
    twice = runs.duplicated(["task", "arm", "seed", "config_hash"], keep="first")
    return runs[~twice].reset_index(drop=True), runs[twice].reset_index(drop=True)


def select_configs(runs: pd.DataFrame, config_hashes: Sequence[str] = ()) -> pd.DataFrame:
    """The runs of one config hash per task and arm: the one ``config_hashes`` names (a hash or a
    prefix), else the one with the most runs; ``BadInput`` for a tie or an ambiguous name.

    Example:
        >>> runs = pd.DataFrame({"task": ["t"] * 3, "arm": ["a"] * 3, "config_hash": ["x1", "x1", "y2"]})
        >>> select_configs(runs)["config_hash"].tolist(), select_configs(runs, ["y"])["config_hash"].tolist()
        (['x1', 'x1'], ['y2'])
    """
    hashes = sorted(set(runs["config_hash"]))
    chosen: dict[tuple[str, str], str] = {}
    for given in config_hashes:
        matches = [h for h in hashes if h.startswith(given)]
        if len(matches) != 1:
            raise BadInput(f"--config-hash {given} matches {'no run' if not matches else 'several hashes'} in the "
                           f"export files{'' if not matches else ' (' + ', '.join(matches) + ')'}; give more of it.")
        named = runs.loc[runs["config_hash"] == matches[0], ["task", "arm"]].drop_duplicates()
        for task, arm in named.itertuples(index=False):
            cell = (str(task), str(arm))
            if cell in chosen and chosen[cell] != matches[0]:
                raise BadInput(f"--config-hash names two configurations of {cell[1]} on {cell[0]} ({chosen[cell]}, "
                               f"{matches[0]}); name one.")
            chosen[cell] = matches[0]
    keep = []
    for (task, arm), cell in runs.groupby(["task", "arm"], sort=True):
        key = (str(task), str(arm))
        if key not in chosen:
            counts = Counter(cell["config_hash"]).most_common()
            tied = [h for h, n in counts if n == counts[0][1]]
            if len(tied) > 1:
                raise BadInput(f"{arm} on {task} has {len(tied)} configurations with {counts[0][1]} runs each "
                               f"({_with_regimes(cell, sorted(tied))}); name the one to compare with --config-hash.")
            chosen[key] = counts[0][0]
        keep.append(cell[cell["config_hash"] == chosen[key]])
    return pd.concat(keep, ignore_index=True)


def configs_left_out(every: pd.DataFrame, kept: pd.DataFrame) -> tuple[str, ...]:
    """The configurations of ``every`` run not in ``kept``, each as ``arm on task: hash (n runs)``.

    Example:
        >>> runs = pd.DataFrame({"task": ["t"] * 3, "arm": ["a"] * 3, "config_hash": ["x1", "x1", "y2"]})
        >>> configs_left_out(runs, select_configs(runs))
        ('a on t: y2 (1 run)',)
    """
    keys = ["task", "arm", "config_hash"]
    counts = every.groupby(keys, sort=True).size()
    compared = set(kept[keys].itertuples(index=False, name=None))
    return tuple(f"{arm} on {task}: {h} ({n} run{'s' if n != 1 else ''})"
                 for (task, arm, h), n in counts.items() if (task, arm, h) not in compared)


def _with_regimes(cell: pd.DataFrame, hashes: Sequence[str]) -> str:
    """Each hash with the regimes (``vlmrl.regime`` tags) its runs were trained in, e.g. ``ab12 (zoo)``."""
    def regimes(h: str) -> str:
        if "regime" not in cell:
            return ""
        named = sorted({str(r) for r in cell.loc[cell["config_hash"] == h, "regime"] if r})
        return f" ({', '.join(named)})" if named else " (no regime tag)"

    return ", ".join(f"{h}{regimes(h)}" for h in hashes)


def compared_arms(runs: pd.DataFrame) -> tuple[list[str], dict[str, list[str]]]:
    """The arms on every task (``order_arms`` order), and each left-out arm with the tasks that lack it.

    ``BadInput`` when a task has no baseline arm, or no other arm is on every task.
    """
    tasks = sorted(set(runs["task"]))
    arms_of = {t: set(runs.loc[runs["task"] == t, "arm"]) for t in tasks}
    lacking = [t for t in tasks if BASELINE not in arms_of[t]]
    if lacking:
        raise BadInput(f"task {lacking[0]} has no {BASELINE} arm in the export files; every task needs one (the "
                       "normalisation and the probability of improvement start from it).")
    every = set.intersection(*arms_of.values())
    left_out = {a: [t for t in tasks if a not in arms_of[t]] for a in order_arms(sorted(set.union(*arms_of.values())))
                if a not in every}
    if every == {BASELINE}:
        raise BadInput(f"no arm besides {BASELINE} is on every task ({', '.join(tasks)}); left out: "
                       + "; ".join(f"{a} (missing on {', '.join(ts)})" for a, ts in left_out.items()) + ".")
    return order_arms(sorted(every)), left_out


def normalisation_pairs(runs: pd.DataFrame, arms: Sequence[str], method: str, tasks: TaskLookup) -> pd.DataFrame:
    """Per task, the pair ``lo``/``hi`` of ``method`` and where each comes from (``tasks``: the
    command's registry); ``BadInput`` when a task lacks a reference, or ``hi <= lo``."""
    rows = []
    for task, cell in runs[runs["arm"].isin(arms)].groupby("task", sort=True):
        if method == "random-zoo":
            lo, lo_from, hi, hi_from = fixed_pair(tasks(str(task)))
        else:
            means = cell.groupby("arm")["score"].mean()
            best = str(means.idxmax())
            lo, lo_from, hi, hi_from = float(means[BASELINE]), f"{BASELINE} mean", float(means[best]), f"{best} mean"
        if not hi > lo:
            raise BadInput(f"on task {task} the {method} range is empty: {lo:g} ({lo_from}) to {hi:g} ({hi_from})"
                           + ("; the baseline is the best arm there." if method != "random-zoo" else "."))
        rows.append({"task": task, "lo": lo, "lo_from": lo_from, "hi": hi, "hi_from": hi_from})
    return pd.DataFrame(rows)


def fixed_pair(task: Task) -> tuple[float, str, float, str]:
    """The fixed references of ``task`` (random policy: 0, the zoo's PPO: 1), each with where it comes from.

    Example:
        >>> from vlmrl_cli.tasks.registry import get_task
        >>> lo, _, hi, _ = fixed_pair(get_task("acrobot"))
        >>> lo, hi
        (-497.37, -73.506)
    """
    if task.random_score is None:
        raise BadInput(f"task {task.name} has no measured random-policy score (Task.random_score); measure it "
                       "with `python scripts/random_scores.py` or use --normalise baseline-best.")
    if task.env_id not in ZOO_PPO:
        raise BadInput(f"task {task.name} ({task.env_id}) has no published rl-baselines3-zoo PPO score in the "
                       "package; use --normalise baseline-best.")
    r, zoo = task.random_score, ZOO_PPO[task.env_id]
    return (r.mean, f"random policy ({r.episodes} episodes from seed {r.seed}, `{r.command}`)", zoo.mean,
            f"zoo PPO {task.env_id} ({zoo.budget} steps)")


def _cell(r: Mapping[str, Any], key: str) -> str:
    """``value [low, high]`` of the aggregate ``key`` in the row ``r`` of ``compare``'s table."""
    return f"{r[key]:.3f} [{r[f'{key}_low']:.3f}, {r[f'{key}_high']:.3f}]"


def compare(cfg: CompareConfig, lookup: TaskLookup) -> CompareResult:
    """Read the export files, aggregate across tasks (``lookup``: the command's task registry) and write
    ``aggregate.md``, ``aggregate.csv``, ``per_task.csv`` and ``performance_profile.png`` to ``cfg.out``."""
    check_compare(cfg)
    every_config, dropped = count_once(read_runs(cfg.files))
    runs = select_configs(every_config, cfg.config_hashes)
    other_configs = configs_left_out(every_config, runs)
    check_paths(runs, cfg.allow_mixed_paths)  # one numeric path, as `vlmrl report` requires
    arms, left_out = compared_arms(runs)
    runs = runs[runs["arm"].isin(arms)].reset_index(drop=True)
    tasks = sorted(set(runs["task"]))
    short = runs.groupby(["task", "arm"]).size()
    if short.min() < 2:
        task, arm = short.idxmin()
        raise BadInput(f"{arm} on {task} has {short.min()} run; the stratified bootstrap needs at least 2 per task.")
    pairs = normalisation_pairs(runs, arms, cfg.normalise, lookup).set_index("task")
    runs["lo"], runs["hi"] = runs["task"].map(pairs["lo"]), runs["task"].map(pairs["hi"])
    runs["normalised"] = (runs["score"] - runs["lo"]) / (runs["hi"] - runs["lo"])
    simulated = bool(runs["simulated"].any())
    note = SIMULATED_NOTE if simulated else REAL_NOTE

    scores = {a: [runs.loc[(runs["arm"] == a) & (runs["task"] == t), "normalised"].to_numpy() for t in tasks]
              for a in arms}
    streams = Streams(cfg.seed)
    rows = []
    for arm in arms:
        est = {"iqm": agg.iqm_interval(scores[arm], streams(f"compare/iqm/{arm}"), cfg.n_boot, cfg.ci),
               "mean": agg.mean_interval(scores[arm], streams(f"compare/mean/{arm}"), cfg.n_boot, cfg.ci)}
        if arm != BASELINE:
            est["poi_over_baseline"] = agg.probability_of_improvement_interval(
                scores[arm], scores[BASELINE], streams(f"compare/poi/{arm}"), cfg.n_boot, cfg.ci)
        row: dict[str, object] = {"arm": arm, "tasks": len(tasks), "runs": sum(s.size for s in scores[arm])}
        for key in ("iqm", "mean", "poi_over_baseline"):
            e = est.get(key, Estimate(float("nan")))
            row |= {key: e.value, f"{key}_low": e.low, f"{key}_high": e.high}
        rows.append(row)
    table = pd.DataFrame(rows)
    table["normalisation"], table["vlm"] = cfg.normalise, note

    cfg.out.mkdir(parents=True, exist_ok=True)
    files = [cfg.out / "aggregate.csv", cfg.out / "per_task.csv", cfg.out / "aggregate.md",
             cfg.out / "performance_profile.png"]
    table.to_csv(files[0], index=False)
    per_task = runs[["task", "arm", "seed", "config_hash", "run_id", "score", "lo", "hi", "normalised"]].copy()
    per_task["normalisation"], per_task["vlm"] = cfg.normalise, note
    per_task.sort_values(["task", "arm", "seed"]).to_csv(files[1], index=False)
    files[2].write_text(_markdown(cfg, table, runs, pairs, left_out, simulated, len(dropped)) + "\n",
                        encoding="utf-8")
    _profile_figure(scores, cfg, streams, note).savefig(files[3], dpi=200)
    return CompareResult(cfg.out, files, table, arms, tasks, left_out, simulated, len(dropped), other_configs, pairs,
                         cfg.normalise in ESTIMATED)


def profile_taus(scores: Mapping[str, Sequence[np.ndarray]], n: int) -> np.ndarray:
    """``n`` thresholds from a little below the lowest normalised score to a little above the highest."""
    every = np.concatenate([t for tasks in scores.values() for t in tasks])
    pad = 0.05 * max(float(every.max() - every.min()), 1e-9)
    return np.linspace(float(every.min()) - pad, float(every.max()) + pad, n)


def _profile_figure(scores: Mapping[str, Sequence[np.ndarray]], cfg: CompareConfig, streams: Streams, note: str
                    ) -> Figure:
    taus = profile_taus(scores, cfg.n_taus)
    fig = Figure(figsize=(7.0, 3.4), layout="constrained")
    ax = fig.subplots()
    for arm, tasks in scores.items():
        curve, low, high = agg.performance_profile_band(tasks, taus, streams(f"compare/profile/{arm}"), cfg.n_boot,
                                                        cfg.ci)
        plot_normalised_profile(taus, curve, low, high, arm, list(scores), ax=ax)
    estimated = "; anchors estimated from the data" if cfg.normalise in ESTIMATED else ""
    ax.set_xlabel(f"normalised score tau ({cfg.normalise}{estimated})", fontsize=9)
    fig.suptitle(f"Performance profile across {len(next(iter(scores.values())))} task(s) "
                 f"({100 * cfg.ci:g}% stratified bootstrap band)\n{note}", fontsize=9)
    return fig


def _markdown(cfg: CompareConfig, table: pd.DataFrame, runs: pd.DataFrame, pairs: pd.DataFrame,
              left_out: Mapping[str, Sequence[str]], simulated: bool, counted_once: int = 0) -> str:
    pct = f"{100 * cfg.ci:g}%"
    lines = [f"# Across tasks{' (SIMULATED VLM)' if simulated else ''}", ""]
    if cfg.normalise in ESTIMATED:
        lines += [ESTIMATED_BANNER, ""]
    if simulated:
        lines += ["> **SIMULATED VLM.** Some runs used the simulated VLM (a pixel-reading stand-in), not a real "
                  "model: nothing here is evidence about a real VLM.", ""]
    lines += [f"Score of a run: its detached evaluation's mean return (`{schema.METRIC_EVAL_MEAN_RETURN}`). "
              f"Normalisation `{cfg.normalise}`: {NORMALISATIONS[cfg.normalise]}.", "",
              *markdown_rows(["task", "lo", "from", "hi", "from"],
                             [[t, f"{r.lo:.3f}", r.lo_from, f"{r.hi:.3f}", r.hi_from]
                              for t, r in pairs.iterrows()]), "",
              f"## Aggregates of the normalised scores ({pct} stratified bootstrap intervals)", ""]
    body = []
    for r in table.to_dict("records"):
        poi = "—" if r["arm"] == BASELINE else _cell(r, "poi_over_baseline")
        body.append([r["arm"], r["tasks"], r["runs"], _cell(r, "iqm"), _cell(r, "mean"), poi])
    lines += markdown_rows(["arm", "tasks", "runs", f"IQM [{pct}]", f"mean [{pct}]",
                            f"P(arm > {BASELINE}) [{pct}]"], body)
    lines += ["", "## Runs compared", ""]
    cells = runs.groupby(["task", "arm", "config_hash"], sort=True).agg(runs=("run_id", "size"),
                                                                       score=("score", "mean"))
    lines += markdown_rows(["task", "arm", "config hash", "runs", "mean score"],
                           [[t, a, h, int(c.runs), f"{c.score:.2f}"] for (t, a, h), c in cells.iterrows()])
    lines += [""]
    if left_out:
        lines += ["Left out (not on every task): "
                  + "; ".join(f"{a} (missing on {', '.join(ts)})" for a, ts in left_out.items()) + ".", ""]
    lines += ["## Method", "",
              f"- Weights: {WEIGHT_RULE}. IQM: the 25% trimmed mean of that mixture (rliable's `aggregate_iqm` when "
              "every task has the same number of runs and their total is a multiple of 4); mean: the mean over "
              "tasks of each task's mean (`aggregate_mean`).",
              f"- Runs: {RUN_RULE}; {counted_once} run(s) held by a second file were not counted again.",
              f"- P(arm > {BASELINE}): per task, P(X > Y) + P(X = Y)/2 for a random run of each arm (the "
              "Mann-Whitney U over n_x n_y), then the mean over tasks (rliable's `probability_of_improvement`).",
              "- Performance profile (`performance_profile.png`): the fraction of runs whose normalised score is "
              "above tau, each task weighing the same (rliable's run-score distribution).",
              f"- Intervals: percentile intervals of a stratified bootstrap ({cfg.n_boot} resamples, seed "
              f"{cfg.seed}): the runs of each task resampled with replacement, each arm on its own; the tasks "
              "are fixed, so the interval is about the runs (seeds), not about a population of tasks.",
              "- One configuration per task and arm: the one named by --config-hash, else the one with the most runs.",
              f"- Files read: {', '.join(f'`{p}`' for p in cfg.files)}."]
    return "\n".join(lines)

"""`vlmrl study` end to end: train every regime, variant and control cell through the resumable
sweep, probe each variant's VLM with the taxonomy, read the runs back from MLflow, then analyse and
write (``outputs.py``), logged as one MLflow run tagged ``vlmrl.kind=study``.
"""

from __future__ import annotations

import math
import re
import time
from collections.abc import Callable, Mapping, Sequence
from contextlib import AbstractContextManager
from pathlib import Path
from typing import Any

import pandas as pd

from vlmrl_cli.analysis import censored, power, stats
from vlmrl_cli.analysis.load import load_experiment
from vlmrl_cli.calibration.regimes import Regime
from vlmrl_cli.core.errors import BadInput
from vlmrl_cli.core.paths import check_out_folder
from vlmrl_cli.core.provenance import config_hash
from vlmrl_cli.probe.taxonomy import TaxonomyConfig, run_taxonomy
from vlmrl_cli.report import hacking
from vlmrl_cli.report.table2 import per_seed_table
from vlmrl_cli.report.writer import check_paths
from vlmrl_cli.study import markdown, verdicts
from vlmrl_cli.study.config import StudyConfig
from vlmrl_cli.study.outputs import StudyResult, finished_keys, write
from vlmrl_cli.sweep import cost as cost_model
from vlmrl_cli.sweep.cost import CostEstimate
from vlmrl_cli.sweep.multi import log_summary_run, runs_of, train_sweeps, wall_s
from vlmrl_cli.sweep.runner import SweepReporter, vlm_identity
from vlmrl_cli.tracking import schema, store


def estimate_cost(cfg: StudyConfig) -> CostEstimate:
    """The study's cost, read without writing (``training.cost.estimate_sweeps`` of its regimes)."""
    return cost_model.estimate_sweeps([regime.run for regime in cfg.all_regimes()])


def slug(name: str) -> str:
    """A folder name for a variant.

    Example:
        >>> slug("profile llava-table1"), slug("flicker 0.3")
        ('profile-llava-table1', 'flicker-0.3')
    """
    return re.sub(r"[^A-Za-z0-9.]+", "-", name).strip("-")


def run_study(
    cfg: StudyConfig,
    reporter_for: Callable[[Regime], AbstractContextManager[SweepReporter]],
    command: str = "",
    cost: CostEstimate | None = None,
    train: bool = True,
) -> StudyResult:
    """Train what is missing (failed runs stop here; a rerun resumes), probe each variant's VLM, then
    analyse and write. ``train=False`` analyses the runs already FINISHED, naming what is missing."""
    result = StudyResult()

    def stage(name: str, start: float, **extra: Any) -> None:
        result.stages.append({"stage": name, "wall_s": round(time.perf_counter() - start, 1), **extra})

    check_out_folder(cfg.out)
    start = time.perf_counter()
    if train:
        result.trained, result.failed = train_sweeps(cfg.all_regimes(), reporter_for)
    stage("train", start, runs_trained_now=result.trained)
    if result.failed:
        return result
    start = time.perf_counter()
    accuracy = _probe_variants(cfg)
    stage("taxonomy", start, variants=len(cfg.variants))

    start = time.perf_counter()
    client = store.connect(cfg.base.tracking_uri)
    data = load_experiment(client, cfg.base.experiment)
    check_paths(data.runs, allow_mixed=False)  # one numeric path, as a report needs (core.numeric_pin)
    hack_frame = _analyse(cfg, result, client, data, accuracy)
    simulated = any(r.run.vlm.backend == "sim" for r in cfg.all_regimes())
    stage("analysis", start)
    result.files = write(cfg, result, hack_frame, simulated, command, cost)
    label, sim = vlm_identity(cfg.base)
    result.run_id = log_summary_run(client, data.experiment_id, schema.KIND_STUDY, config_hash(identity(cfg)),
                                    {"regimes": " | ".join(f"{r.id}: {r.label}" for r in cfg.regimes),
                                     "variants": " | ".join(v.id for v in cfg.variants),
                                     "vlm_regime": cfg.vlm_regime, "thresholds": str(list(cfg.thresholds))},
                                    result.files, (label, sim))
    return result


def _analyse(cfg: StudyConfig, result: StudyResult, client: Any, data: Any, accuracy: Mapping[str, float]
             ) -> pd.DataFrame:
    """Fill ``result`` from the study's runs in ``data``; return the reward-hacking table."""
    streams = stats.Streams(cfg.seed)
    rows, hack, seeds, hacking_answers = [], [], [], {}
    for regime in cfg.regimes:
        sub = verdicts.subset(data, regime.run)
        row, per_seed = verdicts.regime_row(regime.id, sub, cfg.thresholds, streams, cfg.n_boot, cfg.ci, cfg.alpha,
                                            cfg.margin, cfg.window, cfg.base.task_plugin.auc_margin)
        row["overrides"] = regime.label
        row["train_wall_s"] = sum(wall_s(client, r) for r in per_seed["run_id"])
        rows.append(row)
        hack.append(hacking.hacking_frame(per_seed, sub.eval_episodes, cfg.ci, regime.run.task_plugin.max_steps)
                    .assign(regime=regime.id))
        seeds.append(per_seed.assign(regime=regime.id, variant=""))
        answer = verdicts.hacking_answer(per_seed, streams(f"study/hacking/{regime.id}"), cfg.alpha, cfg.n_boot, cfg.ci)
        if answer:
            hacking_answers[regime.id] = answer
    result.per_seed = study_per_seed(seeds + _sweep_frames(cfg, data), cfg.thresholds)
    result.missing = missing_runs(cfg, result.per_seed)
    # the cost of everything reported, not only of the regimes' runs (cells and variants too; a run that
    # two cells share counts once)
    every_run = result.per_seed["run_id"].drop_duplicates() if len(result.per_seed) else []
    result.runs, result.runs_wall_s = len(every_run), float(sum(wall_s(client, r) for r in every_run))
    ready = [c for c in verdicts.controls(cfg.cells, cfg.regimes)
             if all(len(runs_of(data.runs, side.regime.run)) >= 2 for side in (c.a, c.b))]
    control_rows = [verdicts.control_row(c, data, cfg.thresholds, streams, cfg.n_boot, cfg.ci, cfg.alpha, cfg.margin,
                                         cfg.window, cfg.base.task_plugin.auc_margin) for c in ready]
    rows, control_rows = verdicts.adjust_family(rows, control_rows, cfg.adjust, cfg.alpha, cfg.margin)
    result.controls = pd.DataFrame(control_rows)
    # a finished study sizes its power for the family it adjusted (the comparisons made); a partial one for the plan
    made = None if any(result.missing.values()) else verdicts.family_size(rows, control_rows)
    result.power = power_lines(cfg, result.per_seed, made)
    reference = next(r for r in cfg.regimes if r.id == cfg.vlm_regime)
    points = [verdicts.vlm_point(v.id, verdicts.paired(data, reference.run, v.run), cfg.top, accuracy[v.id], cfg.ci)
              for v in cfg.variants]
    result.regime_map = pd.DataFrame(rows)
    result.vlm_points = pd.DataFrame(points, columns=["variant", "mcq_accuracy", "speedup", "low", "high", "p",
                                                      "hybrid_seeds", "baseline_seeds"])
    result.summary = markdown.summary(rows, result.vlm_points, cfg.top, cfg.alpha, cfg.vlm_regime, control_rows,
                                      cfg.margin, cfg.adjust, cfg.ci, hacking=hacking_answers,
                                      planned=planned_family(cfg)) + verdicts.twin_lines(cfg.cells, cfg.regimes)
    return pd.concat(hack, ignore_index=True) if hack else pd.DataFrame()


def _sweep_frames(cfg: StudyConfig, data: Any, own: bool = False) -> list[pd.DataFrame]:
    """The per-seed tables of the regimes' arms (``own``), then of the variants and cells (by sweep id)."""
    sweeps = [(r, r.id, "") for r in cfg.regimes] if own else []
    sweeps += [(s, cfg.vlm_regime, s.id) for s in (*cfg.variants, *(c.regime for c in cfg.cells))]
    return [per_seed_table(verdicts.subset(data, s.run), cfg.thresholds, cfg.window).assign(regime=r, variant=v)
            for s, r, v in sweeps]


def finished_per_seed(cfg: StudyConfig) -> pd.DataFrame | None:
    """The per-seed table of the study's runs already FINISHED in the store, read-only (None: none yet)."""
    uri = store.resolve_tracking_uri(cfg.base.tracking_uri)
    if uri.startswith("sqlite:///") and not Path(uri.removeprefix("sqlite:///")).exists():
        return None  # read-only: no store is created
    client = store.connect(uri)  # a store that does not answer raises BadInput here
    try:
        data = load_experiment(client, cfg.base.experiment)
    except BadInput:  # no such experiment, or no finished training run yet
        return None
    table = study_per_seed([f for f in _sweep_frames(cfg, data, own=True) if len(f)], cfg.thresholds)
    return table if len(table) else None


#: The columns of ``per_seed.csv``, after the steps to each threshold and whether each was reached.
PER_SEED_COLUMNS = ["regime", "variant", "arm", "seed", "config_hash", "run_id", "budget"]
PER_SEED_TAIL = ["auc", "final_return", "detached_success", "eval_success_rate", "eval_mean_length"]


def missing_runs(cfg: StudyConfig, per_seed: pd.DataFrame) -> dict[str, int]:
    """Per sweep (regime, variant or cell), how many of its jobs have no FINISHED run in ``per_seed``."""
    have = finished_keys(per_seed)
    out = {}
    for sweep in cfg.all_regimes():
        n = sum((j.arm.name, j.seed, j.config_hash) not in have for j in sweep.run.jobs())
        if n:
            out[sweep.id] = n
    return out


def study_per_seed(frames: Sequence[pd.DataFrame], thresholds: Sequence[float]) -> pd.DataFrame:
    """``per_seed.csv``: one row per run of the study (a run shared by two sweeps once, under the first;
    ``variant`` empty for a regime's own arms), with steps to each threshold (NaN = DNF) and ``reached_*``."""
    if not frames:
        return pd.DataFrame(columns=PER_SEED_COLUMNS)
    df = pd.concat(frames, ignore_index=True).drop_duplicates("run_id", keep="first")
    steps = []
    for t in thresholds:
        key = f"steps_{t:g}"
        df[f"reached_{t:g}"] = censored.reached(df[key].to_numpy(dtype=float), df["budget"].to_numpy(dtype=float))
        steps += [key, f"reached_{t:g}"]
    return df[PER_SEED_COLUMNS + steps + PER_SEED_TAIL].reset_index(drop=True)


#: The sd of log steps assumed for power before any run has finished (the 2026-11-29 study's: 0.15-0.25).
DEFAULT_SD_LOG = 0.2


def _planned_pairs(cfg: StudyConfig) -> list[tuple[str, str]]:
    return [(a, b) for a, b, _ in verdicts.MAP_PAIRS if a in cfg.base.arms and b in cfg.base.arms]


def planned_family(cfg: StudyConfig) -> int:
    """The family the finished study holds: its arm pairs (per regime) and its controls."""
    return max(1, len(_planned_pairs(cfg)) * len(cfg.regimes) + len(verdicts.controls(cfg.cells, cfg.regimes)))


def power_lines(cfg: StudyConfig, per_seed: pd.DataFrame | None = None, made: int | None = None) -> list[str]:
    """What the study can detect at 80% power per comparison (docs/commands/study.md); ``made``: the
    family a finished study adjusted. No finished run: an assumed spread (``DEFAULT_SD_LOG``), 60%."""
    n, family = len(cfg.base.seeds), _power_family(cfg, made)
    budget = float(cfg.base.budget)
    lines = [_power_head(cfg, made)]
    main = per_seed[per_seed["variant"] == ""] if per_seed is not None and len(per_seed) else None
    if main is None or not len(main):
        rate, sd = 0.6, DEFAULT_SD_LOG
        mde = power.detectable_speedup(cfg.seed, n, sd, rate, budget, cfg.alpha, family)
        mu = math.log(power.reference_median(rate, sd, budget, n))
        ratio = f"{power.restricted_ratio(mu, sd, budget, mde):.2f}x" if math.isfinite(mde) else "none up to 4x"
        lines.append(f"- no run has finished: assuming an sd of log steps of {DEFAULT_SD_LOG} and the paper's "
                     f"baseline reliability 60% for every reference, each of the {family} comparison(s) at {n} seeds "
                     f"per arm detects a restricted-mean ratio of {ratio}"
                     + (f" (a median ratio of {mde:.2f}x)." if math.isfinite(mde) else "."))
        return lines
    regimes = list(dict.fromkeys(main["regime"]))
    for regime in regimes:
        rows = main[main["regime"] == regime]
        where = f" [{regime}]" if len(regimes) > 1 else ""
        lines += [f"- {a} vs {b}{where}: " + _pair_power(cfg, rows, a, b, family) for a, b in _planned_pairs(cfg)]
    return lines


def _power_family(cfg: StudyConfig, made: int | None) -> int:
    """The family size power is sized for: ``made``, else the planned family; 1 with ``--adjust none``."""
    return (planned_family(cfg) if made is None else max(1, made)) if cfg.adjust != "none" else 1


def _power_head(cfg: StudyConfig, made: int | None) -> str:
    """The power paragraph's first line: the simulation, the level and the family."""
    comparisons, planned, family = _planned_pairs(cfg), planned_family(cfg), _power_family(cfg, made)
    controls = [c.name for c in verdicts.controls(cfg.cells, cfg.regimes)]
    pairs = (f"{len(comparisons)} arm pairs in each of {len(cfg.regimes)} regimes" if len(cfg.regimes) > 1
             else f"{len(comparisons)} arm pairs")
    which = (f"{pairs} and {len(controls)} controls" if made is None or made == planned else
             f"the comparisons made, of {planned} planned ({pairs} and {len(controls)} controls): the others have "
             "no test")
    level = (f"alpha {cfg.alpha:g} / {family} (Holm's first step over the family of {family} comparisons: "
             f"{which})" if family > 1 else f"alpha {cfg.alpha:g}")
    return (f"Power (80%) per comparison, simulated on censored steps to {cfg.top:g} "
            f"({power.DEFAULT_N_SIMS:,} simulated studies each): each arm of the comparison fitted as a log-normal "
            f"with its DNFs right-censored at the budget ({float(cfg.base.budget):,.0f} steps), each with its own "
            f"spread; the rank test (normal approximation) at {level} "
            "and the 95% interval above 1. Effects are ratios of restricted mean steps (a DNF at the budget), the "
            "tables' unit, with the median ratio each corresponds to:")


def _pair_power(cfg: StudyConfig, rows: pd.DataFrame, a: str, b: str, family: int) -> str:
    """What the comparison of arm ``a`` with its reference ``b`` detects, from their finished runs in ``rows``."""
    n, budget = len(cfg.base.seeds), float(cfg.base.budget)
    key, hit = f"steps_{cfg.top:g}", f"reached_{cfg.top:g}"
    ref = rows[rows["arm"] == b].drop_duplicates("run_id")
    if not len(ref):
        return f"no finished run of {b} yet."
    reached = int(ref[hit].sum())
    fit = power.fit_censored_lognormal(ref[key].to_numpy(dtype=float), ref["budget"].to_numpy(dtype=float))
    rate = reached / len(ref)
    fisher = _reliability_power(rate, n, cfg.alpha) if rate < 1 else ""
    if fit is None:
        return (f"{b} reached {cfg.top:g} on {reached}/{len(ref)} seeds, too few finishes to fit a spread: no "
                f"speedup power stated{fisher}.")
    mu, sd = fit
    own = rows[rows["arm"] == a].drop_duplicates("run_id")
    arm_fit = power.fit_censored_lognormal(own[key].to_numpy(dtype=float), own["budget"].to_numpy(dtype=float))
    sd_a = arm_fit[1] if arm_fit is not None else sd
    spread = f"{a}'s {sd_a:.2f}" if arm_fit is not None else f"{a}'s taken as {b}'s ({a} has too few finishes to fit)"
    fitted = power.lognormal_reliability(mu, sd, budget)
    mde = power.detectable_speedup(cfg.seed, n, sd, fitted, budget, cfg.alpha, family, sd_log_arm=sd_a)
    if math.isfinite(mde):
        rm_ratio = power.restricted_ratio(mu, sd, budget, mde, sd_a)
        effect = f"a restricted-mean ratio of {rm_ratio:.2f}x or more (a median ratio of {mde:.2f}x)"
    else:
        effect = "no speedup up to a median ratio of 4x (the budget censors too many seeds)"
    return (f"{b}'s fit: median {math.exp(mu):,.0f} steps, sd of log steps {sd:.2f} ({spread}), reliability "
            f"{100 * fitted:.0f}% (observed {reached}/{len(ref)}); at {n} seeds per arm it detects {effect}{fisher}.")


def _reliability_power(rate: float, n: int, alpha: float) -> str:
    """The power line's clause on the smallest reliability Fisher's test tells from ``rate``."""
    found = power.detectable_reliability(rate, n, alpha)
    what = f"{100 * found:.0f}% or more" if found is not None else "no reliability up to 100%"
    return (f"; in reliability, Fisher's exact test (alpha {alpha:g}, unadjusted) detects {what} against its "
            f"{100 * rate:.0f}% at {n} seeds per arm")


def _probe_variants(cfg: StudyConfig) -> dict[str, float]:
    """Each variant's MCQ accuracy, from `vlmrl taxonomy` run in-process on the variant's VLM knobs."""
    accuracy = {}
    for variant in cfg.variants:
        probe = run_taxonomy(TaxonomyConfig(
            vlm=variant.run.vlm, states=cfg.states, out=cfg.out / "taxonomy" / slug(variant.id),
            tracking_uri=cfg.base.tracking_uri, experiment=f"{cfg.base.experiment}-taxonomy",
        ))
        accuracy[variant.id] = float(probe.sweep.get("mcq.accuracy", math.nan))
    return accuracy


def identity(cfg: StudyConfig) -> dict[str, Any]:
    """What makes two studies the same: every sweep's job hashes, the statistics' settings."""
    return {
        "regimes": [[r.id, [j.config_hash for j in r.run.jobs()]] for r in cfg.all_regimes()],
        "vlm_regime": cfg.vlm_regime, "thresholds": list(cfg.thresholds), "states": cfg.states,
        "window": cfg.window, "ci": cfg.ci, "alpha": cfg.alpha, "n_boot": cfg.n_boot, "seed": cfg.seed,
    }



"""`vlmrl study` end to end: train every regime and VLM variant through the resumable sweep, probe
each variant's VLM with the taxonomy, read the runs back from MLflow, write the outputs.

Outputs in ``cfg.out``: ``regime_map.md``/``.csv`` (per regime: each arm's reliability and steps
to the top threshold, the hybrid's speedups over the baseline and the kinematic arm, verdicts),
``vlm_quality.csv``/``.png`` (the hybrid's speedup against the VLM's measured MCQ accuracy),
``hacking.csv``, ``report.md`` (a summary generated from the numbers first) and ``manifest.json``
(commit, versions, command, wall time per stage), also logged as artifacts of one MLflow run
tagged ``vlmrl.kind=study``; ``taxonomy/<variant>/`` holds each variant's Table 1.
"""

from __future__ import annotations

import json
import math
import re
import time
from collections.abc import Callable, Mapping, Sequence
from contextlib import AbstractContextManager
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from string import Template
from typing import Any

import pandas as pd

from vlmrl_cli.analysis import multiplicity, stats
from vlmrl_cli.analysis.censored import RATIO_INTERVAL, RULE, equivalent
from vlmrl_cli.analysis.load import load_experiment
from vlmrl_cli.calibration.regimes import Regime
from vlmrl_cli.core import tables
from vlmrl_cli.core.errors import BadInput
from vlmrl_cli.core.paths import check_out_folder
from vlmrl_cli.core.provenance import config_hash, git_commit, package_versions
from vlmrl_cli.probe.taxonomy import TaxonomyConfig, run_taxonomy
from vlmrl_cli.report import hacking
from vlmrl_cli.report.table2 import per_seed_table
from vlmrl_cli.report.writer import check_paths
from vlmrl_cli.study import verdicts
from vlmrl_cli.study.config import StudyConfig
from vlmrl_cli.sweep import cost as cost_model
from vlmrl_cli.sweep.cost import CostEstimate
from vlmrl_cli.sweep.multi import log_summary_run, runs_of, train_sweeps, wall_s
from vlmrl_cli.sweep.runner import JobResult, SweepReporter, vlm_identity
from vlmrl_cli.tracking import schema, store

KIND = schema.KIND_STUDY
def estimate_cost(cfg: StudyConfig) -> CostEstimate:
    """The study's cost, read without writing (``training.cost.estimate_sweeps`` of its regimes)."""
    return cost_model.estimate_sweeps([regime.run for regime in cfg.all_regimes()])


def _existing_experiment(cfg: StudyConfig) -> tuple[Any, Any] | None:
    """The client and the study's experiment, read-only: None when the store or the experiment does
    not exist (nothing is created)."""
    uri = store.resolve_tracking_uri(cfg.base.tracking_uri)
    if uri.startswith("sqlite:///") and not Path(uri.removeprefix("sqlite:///")).exists():
        return None
    client = store.connect(uri)
    exp = client.get_experiment_by_name(cfg.base.experiment)
    return None if exp is None or exp.lifecycle_stage == "deleted" else (client, exp)


@dataclass
class StudyResult:
    regime_map: pd.DataFrame = field(default_factory=pd.DataFrame)
    vlm_points: pd.DataFrame = field(default_factory=pd.DataFrame)
    controls: pd.DataFrame = field(default_factory=pd.DataFrame)
    per_seed: pd.DataFrame = field(default_factory=pd.DataFrame)
    power: list[str] = field(default_factory=list)
    missing: dict[str, int] = field(default_factory=dict)  # sweep -> jobs without a FINISHED run
    summary: list[str] = field(default_factory=list)
    files: list[Path] = field(default_factory=list)
    run_id: str | None = None
    stages: list[dict[str, Any]] = field(default_factory=list)
    trained: int = 0
    failed: list[JobResult] = field(default_factory=list)
    runs_wall_s: float = 0.0  # the own wall times of every run the study reads (each run once)
    runs: int = 0  # how many runs that is

    @property
    def wall_s(self) -> float:
        return float(sum(s["wall_s"] for s in self.stages))


def auc_margin(cfg: StudyConfig) -> float:
    """The equivalence margin of the study's learning-curve areas: its task's (``Task.auc_margin``)."""
    return cfg.base.task_plugin.auc_margin


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
    """Train what is missing, probe each variant's VLM, then analyse and write. Failed runs stop
    before the analysis; a rerun resumes. ``train=False`` analyses the runs already FINISHED (a
    long study's progress): the report names what is missing, and no comparison lacking a side is made."""
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
    result.files = _write(cfg, result, hack_frame, simulated, command, cost)
    label, sim = vlm_identity(cfg.base)
    result.run_id = log_summary_run(client, data.experiment_id, KIND, config_hash(identity(cfg)),
                                    {"regimes": " | ".join(f"{r.id}: {r.label}" for r in cfg.regimes),
                                     "variants": " | ".join(v.id for v in cfg.variants),
                                     "vlm_regime": cfg.vlm_regime, "thresholds": str(list(cfg.thresholds))},
                                    result.files, (label, sim))
    return result


def _analyse(cfg: StudyConfig, result: StudyResult, client: Any, data: Any, accuracy: Mapping[str, float]
             ) -> pd.DataFrame:
    """Fill ``result`` from the study's runs in ``data``: the regime map, the controls (both adjusted
    as one family), the per-seed table, what is missing, the power, the VLM points and the summary;
    return the reward-hacking table."""
    streams = stats.Streams(cfg.seed)
    rows, hack, seeds, hacking_answers = [], [], [], {}
    for regime in cfg.regimes:
        sub = verdicts.subset(data, regime.run)
        row, per_seed = verdicts.regime_row(regime.id, sub, cfg.thresholds, streams, cfg.n_boot, cfg.ci, cfg.alpha,
                                            cfg.margin, cfg.window, auc_margin(cfg))
        row["overrides"] = regime.label
        row["train_wall_s"] = sum(wall_s(client, r) for r in per_seed["run_id"])
        rows.append(row)
        hack.append(hacking.hacking_frame(per_seed, sub.eval_episodes, cfg.ci, regime.run.task_plugin.max_steps)
                    .assign(regime=regime.id))
        seeds.append(per_seed.assign(regime=regime.id, variant=""))
        answer = verdicts.hacking_answer(per_seed, streams(f"study/hacking/{regime.id}"), cfg.alpha, cfg.n_boot, cfg.ci)
        if answer:
            hacking_answers[regime.id] = answer
    result.per_seed = study_per_seed(seeds + _other_sweep_frames(cfg, data), cfg.thresholds)
    result.missing = missing_runs(cfg, result.per_seed)
    # the cost of everything reported, not only of the regimes' runs (cells and variants too; a run that
    # two cells share counts once)
    every_run = result.per_seed["run_id"].drop_duplicates() if len(result.per_seed) else []
    result.runs, result.runs_wall_s = len(every_run), float(sum(wall_s(client, r) for r in every_run))
    ready = [c for c in verdicts.controls(cfg.cells, cfg.regimes)
             if all(len(runs_of(data.runs, side.regime.run)) >= 2 for side in (c.a, c.b))]
    control_rows = [verdicts.control_row(c, data, cfg.thresholds, streams, cfg.n_boot, cfg.ci, cfg.alpha, cfg.margin,
                                         cfg.window, auc_margin(cfg)) for c in ready]
    rows, control_rows = verdicts.adjust_family(rows, control_rows, cfg.adjust, cfg.alpha, cfg.margin)
    result.controls = pd.DataFrame(control_rows)
    # a finished study sizes its power for the family it adjusted (the comparisons made); a partial one for the plan
    made = None if any(result.missing.values()) else verdicts.family_size(rows, control_rows)
    result.power = power_lines(cfg, result.per_seed, made)
    reference = next(r for r in cfg.regimes if r.id == cfg.vlm_regime)
    points = [verdicts.vlm_point(v.id, verdicts.paired(data, reference.run, v.run), cfg.top, accuracy[v.id], streams,
                                 cfg.n_boot, cfg.ci) for v in cfg.variants]
    result.regime_map = pd.DataFrame(rows)
    result.vlm_points = pd.DataFrame(points, columns=["variant", "mcq_accuracy", "speedup", "low", "high", "p",
                                                      "hybrid_seeds", "baseline_seeds"])
    result.summary = verdicts.summary(rows, result.vlm_points, cfg.top, cfg.alpha, cfg.vlm_regime, control_rows,
                                      cfg.margin, cfg.adjust, cfg.ci, hacking=hacking_answers,
                                      planned=planned_family(cfg)) + verdicts.twin_lines(cfg.cells, cfg.regimes)
    return pd.concat(hack, ignore_index=True) if hack else pd.DataFrame()


def _other_sweep_frames(cfg: StudyConfig, data: Any) -> list[pd.DataFrame]:
    """The per-seed tables of the VLM variants and control cells (in the VLM regime), by sweep id."""
    return [per_seed_table(verdicts.subset(data, sweep.run), cfg.thresholds, cfg.window).assign(regime=cfg.vlm_regime,
                                                                                     variant=sweep.id)
            for sweep in (*cfg.variants, *(c.regime for c in cfg.cells))]


def finished_per_seed(cfg: StudyConfig) -> pd.DataFrame | None:
    """The per-seed table of the study's runs already FINISHED in the store (read-only: None when the
    store or the experiment does not exist, or holds no finished training run)."""
    found_exp = _existing_experiment(cfg)
    if found_exp is None:
        return None
    try:
        data = load_experiment(found_exp[0], cfg.base.experiment)
    except BadInput:  # no finished training run yet
        return None
    frames = [per_seed_table(verdicts.subset(data, r.run), cfg.thresholds, cfg.window).assign(regime=r.id, variant="")
              for r in cfg.regimes]
    frames += _other_sweep_frames(cfg, data)
    table = study_per_seed([f for f in frames if len(f)], cfg.thresholds)
    return table if len(table) else None


#: The columns of ``per_seed.csv``, after the steps to each threshold and whether each was reached.
PER_SEED_COLUMNS = ["regime", "variant", "arm", "seed", "config_hash", "run_id", "budget"]
PER_SEED_TAIL = ["auc", "final_return", "detached_success", "eval_success_rate", "eval_mean_length"]


def finished_keys(per_seed: pd.DataFrame) -> set[tuple[str, int, str]]:
    """The (arm, seed, config hash) of every run in ``per_seed``: the jobs that have a FINISHED run."""
    if not len(per_seed):
        return set()
    return set(zip(per_seed["arm"], per_seed["seed"].astype(int), per_seed["config_hash"], strict=True))


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
    """One row per run of the study (a run shared by two sweeps once, under the first): regime, variant
    (the VLM variant or control cell, empty for the regime's own arms), arm, seed, config hash, run id,
    budget, steps to each threshold (NaN = DNF) and whether it was reached within the budget, the
    learning-curve area, final return, and the detached evaluation."""
    from vlmrl_cli.analysis import censored

    if not frames:
        return pd.DataFrame(columns=PER_SEED_COLUMNS)
    df = pd.concat(frames, ignore_index=True).drop_duplicates("run_id", keep="first")
    steps = []
    for t in thresholds:
        key = f"steps_{t:g}"
        df[f"reached_{t:g}"] = censored.reached(df[key].to_numpy(dtype=float), df["budget"].to_numpy(dtype=float))
        steps += [key, f"reached_{t:g}"]
    return df[PER_SEED_COLUMNS + steps + PER_SEED_TAIL].reset_index(drop=True)


#: The spread of log steps to the top threshold assumed for power when no run has finished yet: the
#: committed 2026-11-29 study's arms ranged from 0.15 to 0.25 (issue 18's audit).
DEFAULT_SD_LOG = 0.2


def _planned_pairs(cfg: StudyConfig) -> list[tuple[str, str]]:
    return [(a, b) for a, b, _ in verdicts.MAP_PAIRS if a in cfg.base.arms and b in cfg.base.arms]


def planned_family(cfg: StudyConfig) -> int:
    """The family the finished study holds: its arm pairs (per regime) and its controls, the family
    the power line sizes the study for; a partial study's verdicts are adjusted within those measured."""
    return max(1, len(_planned_pairs(cfg)) * len(cfg.regimes) + len(verdicts.controls(cfg.cells, cfg.regimes)))


def power_lines(cfg: StudyConfig, per_seed: pd.DataFrame | None = None, made: int | None = None) -> list[str]:
    """What the study can detect at 80% power, per comparison, simulated on censored data as the
    verdict sees it (``analysis.power``): each comparison's two arms' steps to the top threshold,
    each fitted as a log-normal with its DNFs right-censored at the budget
    (``power.fit_censored_lognormal``; the arm's spread is its own, the reference's when it has too
    few finishes), the rank test at Holm's first step over the study's family
    (``alpha / m``, ``m`` the comparisons ``made`` when the study is finished, else the planned
    family; ``--adjust none``: ``alpha``) and the 95% interval above 1; each detectable
    effect stated as a ratio of restricted mean steps (a DNF at the budget), the tables' unit, with
    the median ratio it corresponds to. Before any run has finished (a dry run): one line on an
    assumed spread (``DEFAULT_SD_LOG``) and the paper's 60% reliability, said as such."""
    from vlmrl_cli.analysis import power

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
    """The family size power is sized for: the comparisons ``made`` (a finished study), else the
    planned family; 1 with ``--adjust none``."""
    return (planned_family(cfg) if made is None else max(1, made)) if cfg.adjust != "none" else 1


def _power_head(cfg: StudyConfig, made: int | None) -> str:
    """The power paragraph's first line: the simulation, the level and the family it is sized for."""
    from vlmrl_cli.analysis import power

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
    from vlmrl_cli.analysis import power

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
    """The power line's reliability clause: the smallest reliability Fisher's test (unadjusted, as
    reliability differences are judged) tells from the reference's ``rate`` at 80% power."""
    from vlmrl_cli.analysis import power

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
    """What makes two studies the same: every sweep's job hashes and seeds, the statistics' settings."""
    return {
        "regimes": [[r.id, [j.config_hash for j in r.run.jobs()]] for r in cfg.all_regimes()],
        "vlm_regime": cfg.vlm_regime, "thresholds": list(cfg.thresholds), "states": cfg.states,
        "window": cfg.window, "ci": cfg.ci, "alpha": cfg.alpha, "n_boot": cfg.n_boot, "seed": cfg.seed,
    }


def _vlm_table(points: pd.DataFrame, top: float) -> str:
    rows = []
    for r in points.itertuples(index=False):
        speed = f"{r.speedup:.2f}x" if math.isfinite(r.speedup) else "—"
        if math.isfinite(r.low) and math.isfinite(r.high):
            speed += f" [{r.low:.2f}, {r.high:.2f}]"
        p = f"{r.p:.2g}" if math.isfinite(r.p) else "—"
        rows.append([r.variant, f"{r.mcq_accuracy:.2f}", speed, p, f"{r.hybrid_seeds}/{r.baseline_seeds}"])
    header = ["Variant", "MCQ accuracy", f"Speedup to {top:g}, hybrid / baseline [95% CI]", "rank p", "Seeds (h/b)"]
    return "\n".join(tables.markdown_rows(header, rows)) + "\n"


def to_markdown(cfg: StudyConfig, result: StudyResult, hack_frame: pd.DataFrame, simulated: bool,
                cost: CostEstimate | None, history: Sequence[Mapping[str, Any]] = ()) -> str:
    """``report.md``: the generated summary first, then the regime map, VLM quality, reward hacking, method."""
    return "\n".join([*_head_lines(cfg, result, simulated), *_map_lines(cfg, result), *_controls_lines(cfg, result),
                      *_vlm_lines(cfg, result), *_hacking_lines(cfg, hack_frame), *_method_lines(cfg, result),
                      *_cost_lines(result, cost), *_history_lines(history)])


def _head_lines(cfg: StudyConfig, result: StudyResult, simulated: bool) -> list[str]:
    """The title, which VLM answered, and what is missing from a study still training."""
    vlm_line = ("**VLM: the SIMULATED VLM (a pixel-reading stand-in), not a real model: nothing here is evidence "
                "about a real VLM.**" if simulated else "VLM: a real backend (see the runs' vlmrl.vlm tags).")
    lines = ["# Study: where does the hybrid's advantage hold?", "", vlm_line, ""]
    if result.missing:
        jobs = {(j.arm.name, j.seed, j.config_hash) for s in cfg.all_regimes() for j in s.run.jobs()}
        lines += [prose("partial", missing=len(jobs - finished_keys(result.per_seed)), jobs=len(jobs),
                        per_sweep="; ".join(f"`{k}` {v}" for k, v in result.missing.items())), ""]
    return lines


def _map_lines(cfg: StudyConfig, result: StudyResult) -> list[str]:
    """The summary, the regime map, the regimes' overrides and the notes on the grid."""
    lines = ["## Summary", "", *result.summary, ""]
    lines += ["## Regime map", "", verdicts.map_markdown(result.regime_map.to_dict("records"), cfg.top, cfg.ci,
                                                       cfg.margin, cfg.adjust)]
    lines += ["Regimes (overrides over the study's defaults): "
              + "; ".join(f"`{r.id}` = {r.label}" for r in cfg.regimes) + ".", ""]
    return lines + [f"- {n}" for n in cfg.notes] + ([""] if cfg.notes else [])


def _controls_lines(cfg: StudyConfig, result: StudyResult) -> list[str]:
    """The placebo, dose-response and lock controls, when the study has any."""
    if not len(result.controls):
        return []
    return ["## Controls: placebo, dose-response, the lock", "", prose("controls", vlm_regime=cfg.vlm_regime), "",
            verdicts.controls_markdown(result.controls.to_dict("records"), cfg.top, cfg.margin, cfg.ci, cfg.adjust)]


def _vlm_lines(cfg: StudyConfig, result: StudyResult) -> list[str]:
    """The hybrid's speedup against each VLM variant's measured accuracy, and its figure."""
    return ["## VLM quality", "", prose("vlm_quality", vlm_regime=cfg.vlm_regime, states=cfg.states), "",
            _vlm_table(result.vlm_points, cfg.top) if len(result.vlm_points) else "No VLM variant was run.\n",
            "![VLM quality](vlm_quality.png)", ""]


def _hacking_lines(cfg: StudyConfig, hack_frame: pd.DataFrame) -> list[str]:
    """Reward hacking per regime, with the hovering diagnostic where the task has one."""
    tasks = {regime.id: regime.run.task_plugin for regime in cfg.regimes}
    hover_from = next((task.hover_from for task in tasks.values() if task.hover_diagnostic), None)
    lines = ["## Reward hacking", "", hacking.definition(hover_from), ""]
    for regime in cfg.regimes:
        part = hack_frame[hack_frame["regime"] == regime.id] if len(hack_frame) else hack_frame
        lines += [f"### `{regime.id}`", "",
                  hacking.hacking_markdown(part, cfg.ci, tasks[regime.id].hover_diagnostic) if len(part)
                  else "no runs\n"]
    return lines


def _method_lines(cfg: StudyConfig, result: StudyResult) -> list[str]:
    """How every number was computed: the DNF rule, the tests, the family, the verdict rule; then the power."""
    family = verdicts.family_size(result.regime_map.to_dict("records"), result.controls.to_dict("records"))
    return ["## Method", "",
            prose("method", rule=RULE, top=f"{cfg.top:g}", ratio_interval=RATIO_INTERVAL,
                  family_line=multiplicity.family_line(cfg.adjust, family, verdicts.FAMILY_WHAT),
                  alpha=f"{cfg.alpha:g}", ci=f"{100 * cfg.ci:g}", equivalent=equivalent(cfg.margin),
                  tost=f"{100 * (1 - 2 * cfg.alpha):g}", margin=f"{cfg.margin:g}",
                  auc_margin=f"{auc_margin(cfg):.3g}"), "",
            *result.power, ""]


def _cost_lines(result: StudyResult, cost: CostEstimate | None) -> list[str]:
    """This invocation's wall time, the worker time of every run the report reads, and the estimate."""
    train = sum(r.get("train_wall_s", 0.0) for r in result.regime_map.to_dict("records"))
    estimate = (" " + prose("estimate", pending=cost.pending, minutes=f"{cost.total_s / 60:.0f}", how=cost.how)
                if cost else "")
    return [prose("cost", wall_s=f"{result.wall_s:,.0f}", trained=result.trained, runs=result.runs,
                  runs_wall_s=f"{result.runs_wall_s:,.0f}", runs_wall_h=f"{result.runs_wall_s / 3600:.1f}",
                  train=f"{train:,.0f}", estimate=estimate), ""]


def _history_lines(history: Sequence[Mapping[str, Any]]) -> list[str]:
    """The earlier invocations of a resumed study, oldest first (none: no line)."""
    if not history:
        return []
    earlier = "; ".join(
        f"commit {str(h.get('git_commit', '?'))[:7]} on {str(h.get('written_at', '?'))[:10]}: "
        f"{h.get('runs_trained_now', '?')} run(s) trained, {float(h.get('wall_s', math.nan)):,.0f} s"
        for h in history)
    return [prose("history", earlier=earlier), ""]


def _sections() -> dict[str, Template]:
    """The report's prose, from ``report.md`` in this package: section name -> its paragraph."""
    text = resources.files("vlmrl_cli.study").joinpath("report.md").read_text(encoding="utf-8")
    parts = re.split(r"^<!-- (\w+) -->\n", text, flags=re.MULTILINE)[1:]
    return {name: Template(" ".join(body.split("\n")).strip()) for name, body in zip(parts[::2], parts[1::2],
                                                                                     strict=True)}


def prose(section: str, **values: object) -> str:
    """The paragraph ``section`` of the report's prose with ``values`` filled in."""
    return _sections()[section].substitute(values)


#: The fields of a manifest that say what one invocation did; earlier invocations keep only these.
INVOCATION_FIELDS = ("command", "git_commit", "versions", "stages", "wall_s", "runs_trained_now", "written_at")


def earlier_invocations(previous: Any, experiment: str, tracking_uri: str) -> list[dict[str, Any]]:
    """The invocations behind an earlier manifest in ``--out``, oldest first, when it describes the same
    store and experiment (a resumed study); [] otherwise, or when it is not a manifest.

    A resumed study trains only what was missing, so the runs in its tables may come from earlier
    invocations; their commands, commits and wall times stay on record.

    Example:
        >>> old = {"experiment": "e", "tracking_uri": "u", "command": "vlmrl study", "wall_s": 7417.0}
        >>> earlier_invocations(old, "e", "u"), earlier_invocations(old, "e", "other")
        ([{'command': 'vlmrl study', 'wall_s': 7417.0}], [])
    """
    if not isinstance(previous, dict) or (previous.get("experiment"), previous.get("tracking_uri")) != (
            experiment, tracking_uri):
        return []
    history = [h for h in previous.get("earlier_invocations", []) if isinstance(h, dict)]
    return [*history, {k: previous[k] for k in INVOCATION_FIELDS if k in previous}]


def _read_manifest(path: Path) -> Any:
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None


#: The files a study writes into ``--out``, in the order they are listed and logged.
OUTPUTS = ("regime_map.md", "regime_map.csv", "vlm_quality.csv", "vlm_quality.png", "hacking.csv", "report.md",
           "manifest.json", "per_seed.csv", "controls.csv", "controls.md")


def _write(cfg: StudyConfig, result: StudyResult, hack_frame: pd.DataFrame, simulated: bool, command: str,
           cost: CostEstimate | None) -> list[Path]:
    out = cfg.out
    out.mkdir(parents=True, exist_ok=True)
    path = {name: out / name for name in OUTPUTS}
    tracking_uri = store.resolve_tracking_uri(cfg.base.tracking_uri)
    history = earlier_invocations(_read_manifest(path["manifest.json"]), cfg.base.experiment, tracking_uri)
    vlm_note = "SIMULATED VLM, not a real model." if simulated else ""
    heading = " (SIMULATED VLM)" if simulated else ""
    path["regime_map.md"].write_text(f"# Regime map{heading}\n\n"
                                     + verdicts.map_markdown(result.regime_map.to_dict("records"), cfg.top, cfg.ci,
                                                             cfg.margin, cfg.adjust)
                                     + "\n" + "\n".join(f"- {n}" for n in cfg.notes) + "\n", encoding="utf-8")
    result.regime_map.drop(columns=[c for c in result.regime_map if c.endswith("_text")]).assign(
        vlm=vlm_note).to_csv(path["regime_map.csv"], index=False)
    result.vlm_points.assign(vlm=vlm_note).to_csv(path["vlm_quality.csv"], index=False)
    verdicts.vlm_figure(result.vlm_points, cfg.top, cfg.vlm_regime, simulated).savefig(path["vlm_quality.png"],
                                                                                       dpi=150)
    hack_frame.to_csv(path["hacking.csv"], index=False)
    path["report.md"].write_text(to_markdown(cfg, result, hack_frame, simulated, cost, history), encoding="utf-8")
    result.per_seed.assign(vlm=vlm_note).to_csv(path["per_seed.csv"], index=False)
    result.controls.assign(vlm=vlm_note).to_csv(path["controls.csv"], index=False)
    path["controls.md"].write_text(f"# Controls{heading}\n\n"
                                   + (verdicts.controls_markdown(result.controls.to_dict("records"), cfg.top,
                                                                 cfg.margin, cfg.ci, cfg.adjust)
                                      if len(result.controls) else "No control cell was run.\n"), encoding="utf-8")
    manifest = _manifest(cfg, result, simulated, command, cost, tracking_uri, history)
    path["manifest.json"].write_text(json.dumps(manifest, indent=2) + "\n", encoding="utf-8")
    return list(path.values())


def _manifest(cfg: StudyConfig, result: StudyResult, simulated: bool, command: str, cost: CostEstimate | None,
              tracking_uri: str, history: list[dict[str, Any]]) -> dict[str, Any]:
    """``manifest.json``: what was run, by which command and commit, at what cost, with which hashes."""
    return {
        "what": "vlmrl study" + (" with the SIMULATED VLM, not a real model" if simulated else ""),
        "command": command,
        "git_commit": git_commit(),
        "versions": package_versions(),
        "stages": result.stages,
        "wall_s": round(result.wall_s, 1),
        "runs_trained_now": result.trained,
        "cost_estimate": None if cost is None else cost.__dict__,
        "experiment": cfg.base.experiment,
        "tracking_uri": tracking_uri,
        "regimes": [{"id": r.id, "overrides": r.label, "config_hashes": sorted({j.config_hash for j in r.run.jobs()})}
                    for r in cfg.regimes],
        "variants": [{"id": v.id, "overrides": v.label, "config_hash": v.run.jobs()[0].config_hash}
                     for v in cfg.variants],
        "missing_runs": result.missing,
        "cells": [{"id": c.regime.id, "kind": c.kind, "arm": c.arm, "overrides": c.regime.label,
                   "config_hash": c.regime.run.jobs()[0].config_hash} for c in cfg.cells],
        "margin": cfg.margin,
        "adjust": cfg.adjust,
        "vlm_regime": cfg.vlm_regime,
        "notes": list(cfg.notes),
        "written_at": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
        "earlier_invocations": history,
    }

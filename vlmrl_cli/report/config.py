"""The configurations of `vlmrl report` and `vlmrl compare` and their checks, in a module that loads
no numpy, scipy, pandas or matplotlib: the commands check their flags here before the analysis
stack loads (seconds), and ``report/writer.py`` and ``report/compare.py`` check them again."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

from vlmrl_cli.analysis.defaults import DEFAULT_MARGIN, DEFAULT_N_BOOT, DEFAULT_N_PERM, DETACHED_SUCCESS_CUT
from vlmrl_cli.analysis.multiplicity import DEFAULT_ADJUST, METHODS
from vlmrl_cli.core.errors import BadInput, first_repeated
from vlmrl_cli.core.names import experiment_problem, tracking_uri_problem
from vlmrl_cli.tasks.zoo import SOURCE as ZOO_SOURCE

#: The most bootstrap resamples of a comparison.
MAX_N_BOOT = 100_000

NORMALISATIONS: dict[str, str] = {
    "random-zoo": "min-max per task from a uniformly random policy's measured score (0) to the published PPO "
                  f"score of {ZOO_SOURCE} (1): fixed references, the same whichever arms are compared",
    "baseline-best": "min-max per task from the baseline arm's mean score (0) to the best compared arm's mean "
                     "score (1)",
}
DEFAULT_NORMALISATION = "random-zoo"
#: Normalisations whose anchors are estimated from the runs compared: their outputs say so first.
ESTIMATED = {"baseline-best"}
ESTIMATED_BANNER = ("> **ANCHORS ESTIMATED FROM THE DATA.** This normalisation sets 0 and 1 at arms' own mean "
                    "scores: they move with the runs and the arms compared, a task whose arms differ little is "
                    "magnified without bound, and adding or removing an arm changes every other arm's scores. "
                    "Read the default `random-zoo` normalisation (fixed references) for any verdict.")


@dataclass(frozen=True)
class ReportConfig:
    """Everything one report depends on (logged whole as the report run's params)."""

    experiment: str = "vlmrl"  # MLflow experiment holding the training runs
    tracking_uri: str | None = None  # MLflow store (None: $MLFLOW_TRACKING_URI or sqlite:///mlflow.db)
    out: Path = Path("results/report")  # output folder
    # reward targets (rolling mean native return); None: the runs' task's own (MountainCar's
    # -190, -160, -130)
    thresholds: tuple[float, ...] | None = None
    window: int | None = None  # episodes in the rolling mean; None: the task's own (MountainCar's 100)
    min_episodes: int = 1  # fewest completed episodes before a rolling mean counts
    ci: float = 0.95  # confidence level of every interval
    n_boot: int = DEFAULT_N_BOOT  # bootstrap resamples
    n_perm: int = DEFAULT_N_PERM  # rank tests count up to this many splits of the seeds exactly
    seed: int = 0  # seed of the random streams (one per report section and metric)
    margin: float = DEFAULT_MARGIN  # equivalence margin of a speedup (TOST within [1/margin, margin])
    # multiplicity adjustment of the speedups' p-values, one family per report: holm | bh | none
    adjust: str = DEFAULT_ADJUST
    detached_cut: float = DETACHED_SUCCESS_CUT  # a seed succeeds detached when this share of its episodes do
    reported: Path | None = None  # the paper's numbers (default: the packaged vlmrl_cli/paper/reported.json)
    log_to_mlflow: bool = True  # log the outputs as artifacts of a vlmrl.kind=report run
    # compare runs computed on different numeric paths (core.numeric_pin) instead of refusing
    allow_mixed_paths: bool = False


def check_report(cfg: ReportConfig) -> None:
    """``BadInput`` for the first setting of ``cfg`` a report cannot run with."""
    problem = experiment_problem(cfg.experiment) or tracking_uri_problem(cfg.tracking_uri)
    if problem:
        raise BadInput(problem + ".")
    if cfg.adjust not in METHODS:
        raise BadInput(f"--adjust is one of {', '.join(METHODS)}, got '{cfg.adjust}'.")
    if not cfg.margin > 1 or not math.isfinite(cfg.margin):
        raise BadInput(f"the equivalence margin is a ratio above 1 (e.g. 1.15), got {cfg.margin}.")
    if cfg.thresholds is not None:
        check_thresholds(cfg.thresholds)
    if cfg.window is not None and cfg.window < 1:
        raise BadInput(f"--window must be at least 1, got {cfg.window}.")
    if cfg.min_episodes < 1 or (cfg.window is not None and cfg.min_episodes > cfg.window):
        window = cfg.window if cfg.window is not None else "the task's"
        raise BadInput(f"min_episodes must be between 1 and the window ({window}), got {cfg.min_episodes}.")
    if not 0.0 < cfg.ci < 1.0:
        raise BadInput(f"the confidence level must be between 0 and 1, got {cfg.ci}.")
    if cfg.n_boot < 10:
        raise BadInput(f"use at least 10 bootstrap resamples, got {cfg.n_boot}.")
    if cfg.n_perm < 10:
        raise BadInput(f"use at least 10 rank-test permutations, got {cfg.n_perm}.")
    if not 0.0 < cfg.detached_cut <= 1.0:
        raise BadInput(f"the detached success cut must be in (0, 1], got {cfg.detached_cut}.")


def check_thresholds(thresholds: tuple[float, ...]) -> None:
    """``BadInput`` unless ``thresholds`` are finite and distinct (a repeated one would add a copy of
    its comparisons to the multiplicity family); any number of them, in any order.

    Example:
        >>> check_thresholds((-190.0, -130.0))
        >>> check_thresholds((-190.0, -190.0))  # doctest: +ELLIPSIS
        Traceback (most recent call last):
        ...
        vlmrl_cli.core.errors.BadInput: --thresholds lists -190 twice; list each threshold once ...
    """
    if not thresholds:
        raise BadInput("no reward threshold given; pass --thresholds like -190,-160,-130.")
    bad = [t for t in thresholds if not math.isfinite(t)]
    if bad:
        raise BadInput(f"--thresholds must be finite numbers like -190,-160,-130, got {bad[0]}.")
    twice = first_repeated(thresholds)
    if twice is not None:
        raise BadInput(f"--thresholds lists {twice:g} twice; list each threshold once (a repeated one adds its "
                       "comparisons to the multiplicity family again).")


@dataclass(frozen=True)
class CompareConfig:
    """Everything `vlmrl compare` does, in one object."""

    files: tuple[Path, ...]
    out: Path
    normalise: str = DEFAULT_NORMALISATION
    config_hashes: tuple[str, ...] = ()
    n_boot: int = DEFAULT_N_BOOT
    ci: float = 0.95
    seed: int = 0
    n_taus: int = 201
    # compare runs computed on different numeric paths (core.numeric_pin) instead of refusing, as `report`
    allow_mixed_paths: bool = False


def check_compare(cfg: CompareConfig) -> None:
    """``BadInput`` for the first setting of ``cfg`` a comparison cannot run with."""
    if not cfg.files:
        raise BadInput("name at least one export file (written by `vlmrl export --out FILE`).")
    missing = [p for p in cfg.files if not p.is_file()]
    if missing:
        raise BadInput(f"there is no export file {missing[0]}; write one with `vlmrl export --out FILE`.")
    if cfg.normalise not in NORMALISATIONS:
        raise BadInput(f"--normalise must be one of {', '.join(NORMALISATIONS)}, got '{cfg.normalise}'.")
    if any(not h.strip() for h in cfg.config_hashes):
        raise BadInput("--config-hash is empty; give a config hash or its first characters (the export's runs list "
                       "them: `vlmrl run --dry-run` prints each job's), or leave the flag out for the configuration "
                       "with the most runs.")
    if cfg.n_boot < 100:
        raise BadInput(f"the bootstrap needs at least 100 resamples, got {cfg.n_boot}.")
    if cfg.n_boot > MAX_N_BOOT:
        raise BadInput(f"--n-boot {cfg.n_boot:,} is too many: at most {MAX_N_BOOT:,} (each resample recomputes every "
                       f"arm's aggregates and profile; the default is {DEFAULT_N_BOOT:,}).")
    if not 0 < cfg.ci < 1:
        raise BadInput(f"the interval's coverage must lie strictly between 0 and 1, got {cfg.ci}.")
    if cfg.out.exists() and not cfg.out.is_dir():
        raise BadInput(f"--out {cfg.out} is a file; name a folder.")

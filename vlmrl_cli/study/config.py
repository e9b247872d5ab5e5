"""The configuration of `vlmrl study`: named PPO regimes x arms x seeds, and VLM-quality variants.

A *regime* is a name and a set of overrides (dotted keys, as ``--set`` takes them), often just a
preset (``{"preset": "paper"}``); each is an ordinary `vlmrl run` configuration of every arm,
built by ``calibration.regimes.resolve_regime``. A *variant* is the hybrid arm alone in the VLM
regime with other simulated-VLM knobs: a named profile (``vlm.sim.profile``) or a flicker rate.
Regimes come from ``--regime`` flags, else ``[study.regimes]`` in TOML, else ``DEFAULT_REGIMES``
(a default regime whose preset does not exist yet is skipped with a note)::

    [study]
    profiles = ["ideal", "default", "llava-table1"]
    flickers = [0.0, 0.1, 0.3, 0.5]
    vlm_regime = "paper-calibrated"

    [study.regimes]
    paper = "paper"                                     # a preset name
    hard = { "ppo.normalize_obs" = false, "ppo.normalize_reward" = false }
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from vlmrl_cli.analysis.multiplicity import DEFAULT_ADJUST, METHODS
from vlmrl_cli.analysis.stats import DEFAULT_N_BOOT
from vlmrl_cli.calibration.regimes import Regime, resolve_regime
from vlmrl_cli.core.errors import BadInput, did_you_mean
from vlmrl_cli.probe.scoring import DEFAULT_STATES
from vlmrl_cli.shaping.arms import BASELINE, DENSE, METHOD, NO_LOCK, PLACEBO_OF, POTENTIAL_ONLY
from vlmrl_cli.tasks.registry import get_task
from vlmrl_cli.training.config import RunConfig, resolve
from vlmrl_cli.training.overrides import dotted, parse_assignment, parse_value
from vlmrl_cli.vlm.config import SIM_PROFILES

DEFAULT_EXPERIMENT = "vlmrl-study"
DEFAULT_SEEDS = 20
PLACEBO_ARM = PLACEBO_OF[METHOD]
# hybrid and its placebo first: a study stopped part-way has the comparison it exists for
DEFAULT_ARMS = (BASELINE, METHOD, PLACEBO_ARM, DENSE, POTENTIAL_ONLY)
VARIANT_ARM = METHOD
CALIBRATED = "paper-unreliable"
#: The dose-response grid (issue 18): PBRS scales x kinematic scales, in the VLM regime. alpha 0 is
#: the dense term alone (the kinematic arm; with kin_scale 0 the baseline), kin_scale 0 the VLM's
#: potential alone (the semantic arm: the paper's "deadlock" case where only the VLM can help). At
#: alpha 100 the potential pays about as much per episode as R_kin at its default scale (~45).
DEFAULT_ALPHAS: tuple[float, ...] = (5.0, 25.0, 100.0)
DEFAULT_KIN_SCALES: tuple[float, ...] = (0.0, 0.5, 2.0)
#: Per-query (temporal) flicker rates at which the hybrid and hybrid-no-lock are compared: what
#: the hysteresis lock is for.
DEFAULT_QUERY_FLICKERS: tuple[float, ...] = (0.3,)
LOCK_ARMS: tuple[str, ...] = (METHOD, NO_LOCK)
#: The default grid: the calibrated regime whose baseline fails on some seeds (reliability is
#: testable there), where every arm, the placebo and the controls run. The study of 2026-11-29
#: (results/study/2026-11-29/) ran `paper`, `paper-calibrated` and `hard` at 10 seeds; pass them
#: with --regime to add them again.
DEFAULT_REGIMES: dict[str, Mapping[str, Any]] = {
    CALIBRATED: {"preset": CALIBRATED},
}
#: The VLM-quality variants are off by default since the dose-response and placebo controls came:
#: the study of 2026-11-29 (results/study/2026-11-29/) ran them at 10 seeds and found no dependence
#: it could detect; ``--profiles ideal,default,llava-table1 --flickers 0,0.1,0.3,0.5`` runs them again.
DEFAULT_PROFILES: tuple[str, ...] = ()
DEFAULT_FLICKERS: tuple[float, ...] = ()
_STUDY_KEYS = ("regimes", "profiles", "flickers", "vlm_regime", "alphas", "kin_scales", "query_flickers")


@dataclass(frozen=True)
class Cell:
    """One control sweep in the VLM regime: a dose-response point (``kind`` ``dose``: the arm that
    pays ``alpha`` x PBRS + ``kin_scale`` x R_kin, or its placebo) or a temporal-flicker point
    (``query-flicker``: one of ``LOCK_ARMS`` at ``query_flicker``). ``regime.run`` lists one arm."""

    kind: str
    arm: str
    regime: Regime
    alpha: float = math.nan
    kin_scale: float = math.nan
    query_flicker: float = 0.0

    @property
    def placebo(self) -> bool:
        return self.arm == PLACEBO_ARM


def dose_point(alpha: float, kin_scale: float, placebo: bool = False) -> tuple[str, dict[str, Any]]:
    """The arm and overrides that pay ``alpha`` x PBRS + ``kin_scale`` x R_kin. A term at 0 is
    dropped by choosing the arm without it, and a knob the arm ignores is not set, so a point that
    an ordinary arm already is (alpha 0 = kinematic, kin_scale 0 = semantic) shares its runs.

    Example:
        >>> dose_point(0, 0), dose_point(0, 2.0), dose_point(25, 0)
        (('baseline', {}), ('kinematic', {'shaping.kin_scale': 2.0}), ('semantic', {'shaping.alpha': 25.0}))
        >>> dose_point(5, 0.5), dose_point(100, 0, placebo=True)[0]
        (('hybrid', {'shaping.alpha': 5.0, 'shaping.kin_scale': 0.5}), 'hybrid-shuffled')
    """
    if placebo:  # there is no semantic placebo arm: the placebo with kin_scale 0 pays the same
        return PLACEBO_ARM, {"shaping.alpha": float(alpha), "shaping.kin_scale": float(kin_scale)}
    if alpha == 0:
        return (BASELINE, {}) if kin_scale == 0 else (DENSE, {"shaping.kin_scale": float(kin_scale)})
    if kin_scale == 0:
        return POTENTIAL_ONLY, {"shaping.alpha": float(alpha)}
    return METHOD, {"shaping.alpha": float(alpha), "shaping.kin_scale": float(kin_scale)}


def control_points(alphas: Sequence[float], kin_scales: Sequence[float], query_flickers: Sequence[float]
                   ) -> list[tuple[str, str, dict[str, Any], dict[str, float]]]:
    """The control sweeps, as (name, arm, overrides, knobs) in training order: per kin_scale, the
    dense-only point, every alpha, then the placebo at the largest alpha; then each query-flicker
    rate for both ``LOCK_ARMS``. Points at (0, 0) are the baseline; they are listed too, so the
    dose-response table is complete, and resume finds their runs."""
    points: list[tuple[str, str, dict[str, Any], dict[str, float]]] = []
    for kin in kin_scales:
        for alpha in (0.0, *alphas):
            arm, over = dose_point(alpha, kin)
            points.append((f"dose alpha={alpha:g} kin={kin:g}", arm, over, {"alpha": alpha, "kin_scale": kin}))
        if alphas:
            top = max(alphas)
            arm, over = dose_point(top, kin, placebo=True)
            points.append((f"dose alpha={top:g} kin={kin:g} placebo", arm, over, {"alpha": top, "kin_scale": kin}))
    for q in query_flickers:
        for arm in LOCK_ARMS:
            points.append((f"query-flicker {q:g} {arm}", arm, {"vlm.sim.query_flicker": float(q)},
                           {"query_flicker": float(q)}))
    return points


@dataclass(frozen=True)
class StudyConfig:
    """Everything one `vlmrl study` does, as one value."""

    regimes: tuple[Regime, ...]
    variants: tuple[Regime, ...] = ()  # the hybrid with other VLM knobs, in ``vlm_regime``
    cells: tuple[Cell, ...] = ()  # dose-response and temporal-flicker controls, in ``vlm_regime``
    vlm_regime: str = ""  # id of the regime whose baseline the variants are compared with
    notes: tuple[str, ...] = ()  # what was left out of the grid, and why
    out: Path = Path("results/study")
    thresholds: tuple[float, ...] = (-190.0, -160.0, -130.0)
    states: int = DEFAULT_STATES  # taxonomy sweep positions per variant
    window: int = 100
    ci: float = 0.95
    alpha: float = 0.05  # significance level of the verdicts
    margin: float = 1.15  # equivalence margin of a speedup (TOST: within [1/margin, margin])
    # multiplicity adjustment of the speedups' p-values, the study's comparisons one family: holm | bh | none
    adjust: str = DEFAULT_ADJUST
    n_boot: int = DEFAULT_N_BOOT
    seed: int = 0  # seed of the statistics' random streams
    extra: dict[str, Any] = field(default_factory=dict)  # free-form provenance (the command)

    @property
    def base(self) -> RunConfig:
        return self.regimes[0].run

    @property
    def top(self) -> float:
        return max(self.thresholds)

    def all_regimes(self) -> tuple[Regime, ...]:
        """Every sweep to train: the regimes, then the variants, then the control cells."""
        return (*self.regimes, *self.variants, *(c.regime for c in self.cells))


def parse_regime(text: str) -> tuple[str, dict[str, Any]]:
    """A ``--regime`` flag: ``NAME`` (a preset of that name), ``NAME=PRESET``, or
    ``NAME=KEY=VALUE [KEY=VALUE ...]`` (``--set`` assignments separated by spaces or ``;``).

    Example:
        >>> parse_regime("zoo")
        ('zoo', {'preset': 'zoo'})
        >>> parse_regime("hard=preset=paper ppo.normalize_obs=false; ppo.normalize_reward=false")
        ('hard', {'preset': 'paper', 'ppo.normalize_obs': False, 'ppo.normalize_reward': False})
    """
    name, sep, spec = text.partition("=")
    name = name.strip()
    if not name:
        raise BadInput(f"--regime takes NAME, NAME=PRESET or NAME=KEY=VALUE ..., got '{text}'.")
    if not sep:
        return name, {"preset": name}
    parts = [p for p in re.split(r"[;\s]+", spec.strip()) if p]
    if len(parts) == 1 and "=" not in parts[0]:
        return name, {"preset": parts[0]}
    point: dict[str, Any] = {}
    for part in parts:
        key, value = parse_assignment(part, "--regime")
        point[key] = parse_value(value)
    if not point:
        raise BadInput(f"--regime {name}= names no preset and no override; e.g. --regime {name}=paper.")
    return name, point


def study_section(raw: Any) -> dict[str, Any]:
    """A config file's ``[study]`` table, checked: regimes as ``{name: point}``, the rest as given."""
    if not isinstance(raw, Mapping):
        raise BadInput("[study] must be a table (regimes, profiles, flickers, vlm_regime).")
    unknown = [k for k in raw if k not in _STUDY_KEYS]
    if unknown:
        raise BadInput(f"unknown key 'study.{unknown[0]}'{did_you_mean(unknown[0], _STUDY_KEYS)}; "
                       f"[study] holds {', '.join(_STUDY_KEYS)}.")
    out = dict(raw)
    regimes = raw.get("regimes")
    if regimes is not None:
        if not isinstance(regimes, Mapping) or not regimes:
            raise BadInput("study.regimes must be a table of NAME = \"preset\" or NAME = { key = value, ... }.")
        out["regimes"] = {
            str(name): {"preset": spec} if isinstance(spec, str) else dotted(spec) if isinstance(spec, Mapping)
            else _bad_regime(str(name))
            for name, spec in regimes.items()
        }
    for key, kind in (("profiles", str), ("flickers", (int, float)), ("alphas", (int, float)),
                      ("kin_scales", (int, float)), ("query_flickers", (int, float))):
        values = raw.get(key)
        if values is not None and (not isinstance(values, list) or not all(isinstance(v, kind) for v in values)):
            raise BadInput(f"study.{key} must be a list of {'names' if kind is str else 'numbers'}.")
    return out


def _bad_regime(name: str) -> dict[str, Any]:
    raise BadInput(f"study.regimes.{name} must be a preset name or a table of overrides.")


def task_name_of(layers: Sequence[Mapping[str, Any]]) -> str:
    """The task the layers (file, ``--set``, flags) name: the ``task`` key, or MountainCar."""
    return resolve([*layers]).task


def task_regimes(task: str) -> dict[str, dict[str, Any]]:
    """Another task's default regime: its study preset (calibrated: the baseline slow or unreliable),
    else its default preset, under the preset's name."""
    t = get_task(task)
    preset = t.study_preset or t.default_preset
    return {preset: {"preset": preset}}


def choose_regimes(flags: Sequence[str], file_regimes: Mapping[str, Mapping[str, Any]] | None,
                   task: str) -> tuple[dict[str, dict[str, Any]], list[str]]:
    """The regimes to run (name -> overrides) and notes on the defaults left out: ``--regime``
    flags, else the file's, else ``DEFAULT_REGIMES`` without those whose preset does not exist yet
    (another task: ``task_regimes``)."""
    if flags:
        chosen = dict(parse_regime(f) for f in flags)
        if len(chosen) < len(flags):
            raise BadInput("two --regime flags share a name; give each regime its own name.")
        return chosen, []
    if file_regimes:
        return {k: dict(v) for k, v in file_regimes.items()}, []
    return task_regimes(task), []


def _label(point: Mapping[str, Any]) -> str:
    return " ".join(f"{k}={v}" for k, v in point.items())


def build_study(
    layers: Sequence[Mapping[str, Any]],
    regimes: Mapping[str, Mapping[str, Any]],
    profiles: Sequence[str] = DEFAULT_PROFILES,
    flickers: Sequence[float] = DEFAULT_FLICKERS,
    vlm_regime: str | None = None,
    alphas: Sequence[float] = DEFAULT_ALPHAS,
    kin_scales: Sequence[float] = DEFAULT_KIN_SCALES,
    query_flickers: Sequence[float] = DEFAULT_QUERY_FLICKERS,
    notes: Sequence[str] = (),
    **settings: Any,
) -> StudyConfig:
    """One validated ``StudyConfig``: every regime's run of every arm (``layers`` above the study's
    defaults, the regime's overrides above them), the hybrid's VLM variants and the control cells
    (``control_points``) in ``vlm_regime`` (default: the calibrated regime, else the first).
    Anything invalid is ``BadInput`` now."""
    if not regimes:
        raise BadInput("the study has no regime; pass --regime NAME[=...] or drop the [study.regimes] table.")
    unknown = [p for p in profiles if p not in SIM_PROFILES]
    if unknown:
        raise BadInput(f"unknown simulated-VLM profile '{unknown[0]}'{did_you_mean(unknown[0], SIM_PROFILES)}; "
                       f"choose from {', '.join(SIM_PROFILES)}.")
    base = {"experiment": DEFAULT_EXPERIMENT, "seeds": list(range(DEFAULT_SEEDS)), "arms": list(DEFAULT_ARMS)}
    built = tuple(resolve_regime(name, point, [base, *layers], {"regime": name}) for name, point in regimes.items())
    tasks = sorted({r.run.task for r in built})
    if len(tasks) > 1:
        raise BadInput(f"the regimes span tasks {', '.join(tasks)}; a study covers one task (--task).")
    task = built[0].run.task_plugin
    if (profiles or flickers) and not task.probes_floats:
        raise BadInput(f"task {tasks[0]}: the VLM-quality variants (--profiles, --flickers) take their accuracy "
                       "from the float and box taxonomy probe, which this task has not; pass --profiles none "
                       "--flickers none.")
    settings.setdefault("thresholds", task.thresholds)
    settings.setdefault("window", task.window)
    notes = list(notes)
    preferred = task.study_preset if task.study_preset in regimes else None
    target = vlm_regime or preferred or next(iter(regimes))
    if target not in regimes:
        raise BadInput(f"--vlm-regime '{target}' is not a regime of this study{did_you_mean(target, regimes)}.")
    variants: list[Regime] = []
    reference = next(r for r in built if r.id == target)
    margin = settings.get("margin", 1.15)
    if not (math.isfinite(margin) and margin > 1):
        raise BadInput(f"--margin is a ratio above 1 (e.g. 1.15), got {margin}.")
    adjust = settings.get("adjust", DEFAULT_ADJUST)
    if adjust not in METHODS:
        raise BadInput(f"--adjust is one of {', '.join(METHODS)}, got '{adjust}'.")
    for name, values in (("alphas", alphas), ("kin_scales", kin_scales), ("query_flickers", query_flickers)):
        bad = [v for v in values if not (math.isfinite(v) and v >= 0)]
        if bad:
            raise BadInput(f"{name} must be finite and >= 0, got {bad[0]}.")
    if reference.run.vlm.backend != "sim" and query_flickers:
        notes.append(f"no query-flicker cells: the VLM backend is '{reference.run.vlm.backend}', and query_flicker "
                     "is a knob of the simulated VLM.")
        query_flickers = ()
    cells = tuple(
        Cell(kind="dose" if "query_flicker" not in knobs else "query-flicker", arm=arm,
             regime=resolve_regime(name, {**regimes[target], **over}, [base, *layers],
                                   {"regime": f"{target} {name}", "arms": [arm]}), **knobs)
        for name, arm, over, knobs in control_points(alphas, kin_scales, query_flickers)
    )
    if reference.run.vlm.backend != "sim":
        notes.append(f"no VLM-quality variants: the VLM backend is '{reference.run.vlm.backend}', and profiles and "
                     "flicker are knobs of the simulated VLM.")
    else:
        points: list[tuple[str, dict[str, Any]]] = [("profile " + p, {"vlm.sim.profile": p}) for p in profiles]
        points += [(f"flicker {f:g}", {"vlm.sim.flicker": float(f)}) for f in flickers]
        seen: dict[str, int] = {}
        for name, extra in points:
            variant = resolve_regime(name, {**regimes[target], **extra}, [base, *layers],
                                     {"regime": f"{target} {_label(extra)}", "arms": [VARIANT_ARM]})
            key = variant.run.jobs()[0].config_hash
            if key in seen:  # the same knobs reached twice (profile default = flicker 0.1): one point
                first = variants[seen[key]]
                variants[seen[key]] = Regime(f"{first.id} = {name}", first.overrides, first.run)
                continue
            seen[key] = len(variants)
            variants.append(variant)
    return StudyConfig(regimes=built, variants=tuple(variants), cells=cells, vlm_regime=target, notes=tuple(notes),
                       **settings)

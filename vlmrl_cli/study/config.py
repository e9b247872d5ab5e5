"""The configuration of `vlmrl study`: named regimes (``--set`` overrides, often a preset) x arms x
seeds, the hybrid's VLM-quality variants and the control cells, built from ``StudySettings``
layered file < ``--set`` < flags. See docs/commands/study.md.
"""

from __future__ import annotations

import math
import re
import typing
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from vlmrl_cli.analysis.defaults import DEFAULT_N_BOOT
from vlmrl_cli.analysis.multiplicity import DEFAULT_ADJUST, METHODS
from vlmrl_cli.calibration.regimes import Regime, resolve_regime
from vlmrl_cli.core.errors import BadInput, did_you_mean
from vlmrl_cli.shaping.arms import BASELINE, DENSE, METHOD, NO_LOCK, POTENTIAL_ONLY
from vlmrl_cli.study.settings import (
    DEFAULT_ALPHAS,
    DEFAULT_ARMS,
    DEFAULT_EXPERIMENT,
    DEFAULT_FLICKERS,
    DEFAULT_KIN_SCALES,
    DEFAULT_MARGIN,
    DEFAULT_OUT,
    DEFAULT_PROFILES,
    DEFAULT_QUERY_FLICKERS,
    DEFAULT_SEEDS,
    DEFAULT_STATES,
    PLACEBO_ARM,
    StudySettings,
)
from vlmrl_cli.tasks.base import Task, TaskLookup
from vlmrl_cli.training.config import RunConfig, once, resolve, source_layers
from vlmrl_cli.training.overrides import dotted, parse_assignment, parse_value
from vlmrl_cli.vlm.config import profile_problem

VARIANT_ARM = METHOD
LOCK_ARMS: tuple[str, ...] = (METHOD, NO_LOCK)


@dataclass(frozen=True)
class Cell:
    """One control sweep of one arm in the VLM regime: a ``dose`` point (``alpha`` x PBRS +
    ``kin_scale`` x R_kin, or its placebo) or a ``query-flicker`` point of one of ``LOCK_ARMS``."""

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
    """The arm and overrides that pay ``alpha`` x PBRS + ``kin_scale`` x R_kin; a term at 0 picks the
    arm without it, so a point that an ordinary arm already is shares its runs.

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
    """The control sweeps as (name, arm, overrides, knobs), in training order: per kin_scale, alpha 0,
    every alpha, the placebo at the largest; then each query-flicker rate for both ``LOCK_ARMS``."""
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
    out: Path = DEFAULT_OUT
    thresholds: tuple[float, ...] = (-190.0, -160.0, -130.0)
    states: int = DEFAULT_STATES  # taxonomy sweep positions per variant
    window: int = 100
    ci: float = 0.95
    alpha: float = 0.05  # significance level of the verdicts
    margin: float = DEFAULT_MARGIN  # equivalence margin of a speedup (TOST: within [1/margin, margin])
    # multiplicity adjustment of the speedups' p-values, the study's comparisons one family: holm | bh | none
    adjust: str = DEFAULT_ADJUST
    n_boot: int = DEFAULT_N_BOOT
    seed: int = 0  # seed of the statistics' random streams
    extra: dict[str, Any] = field(default_factory=dict)  # free-form provenance (the command)

    @classmethod
    def from_sources(cls, file: Path | None, flags: Mapping[str, Any] | None = None, overrides: Iterable[str] = (),
                     tasks: TaskLookup | None = None) -> StudyConfig:
        """The validated study of a TOML ``file`` (or None), ``--set`` ``overrides`` and ``flags`` (dotted keys,
        the study's under ``study.``), layered preset < file < overrides < flags; one task lookup."""
        layers = source_layers(file, flags or {}, overrides)
        settings = settings_of([layer.pop("study", {}) for layer in layers])
        tasks = once(tasks)
        regimes = settings.regimes or task_regimes(task_in(layers, tasks))
        return build_study(layers, regimes, tasks=tasks, profiles=settings.profiles, flickers=settings.flickers,
                           vlm_regime=settings.vlm_regime, alphas=settings.alphas, kin_scales=settings.kin_scales,
                           query_flickers=settings.query_flickers, out=settings.out,
                           margin=settings.margin, adjust=settings.adjust, states=settings.states)

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


def regimes_of(flags: Sequence[str]) -> dict[str, dict[str, Any]]:
    """The regimes of ``--regime`` flags (``parse_regime``), name -> overrides, each name once.

    Example:
        >>> regimes_of(["a=smoke", "b"])
        {'a': {'preset': 'smoke'}, 'b': {'preset': 'b'}}
    """
    chosen = dict(parse_regime(f) for f in flags)
    if len(chosen) < len(flags):
        raise BadInput("two --regime flags share a name; give each regime its own name.")
    return chosen


def study_section(raw: Any) -> dict[str, Any]:
    """A layer's ``[study]`` table with its regimes as ``{name: point}`` (checked by ``settings_of``)."""
    if not isinstance(raw, Mapping):
        raise BadInput("[study] must be a table (regimes, profiles, flickers, vlm_regime).")
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
    return out


def settings_of(tables: Sequence[Any]) -> StudySettings:
    """The checked ``StudySettings`` of the layers' ``[study]`` tables, lowest first, each key replacing whole."""
    from vlmrl_cli.training.validation import validate_as

    merged: dict[str, Any] = {}
    for table in tables:
        merged |= study_section(table)
    return typing.cast(StudySettings, validate_as(StudySettings, merged, at="study"))


def _bad_regime(name: str) -> dict[str, Any]:
    raise BadInput(f"study.regimes.{name} must be a preset name or a table of overrides.")


def task_in(layers: Sequence[Mapping[str, Any]], tasks: TaskLookup | None = None) -> Task:
    """The Task the layers name (the ``task`` key, or the default task), looked up by ``tasks``."""
    return resolve([*layers], tasks).task_plugin


def task_regimes(task: Task) -> dict[str, dict[str, Any]]:
    """A task's default regime: its study preset, else its default preset, under the preset's name."""
    preset = task.study_preset or task.default_preset
    return {preset: {"preset": preset}}


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
    tasks: TaskLookup | None = None,
    **settings: Any,
) -> StudyConfig:
    """One validated ``StudyConfig`` (``BadInput`` now if invalid): every regime's run of every arm, the
    hybrid's VLM variants and the control cells in ``vlm_regime`` (default: the study preset, else the first)."""
    if not regimes:
        raise BadInput("the study has no regime; pass --regime NAME[=...] or drop the [study.regimes] table.")
    base = {"experiment": DEFAULT_EXPERIMENT, "seeds": list(range(DEFAULT_SEEDS)), "arms": list(DEFAULT_ARMS)}
    tasks = once(tasks)
    built = tuple(resolve_regime(name, point, [base, *layers], {"regime": name}, tasks)
                  for name, point in regimes.items())
    names = sorted({r.run.task for r in built})
    if len(names) > 1:
        raise BadInput(f"the regimes span tasks {', '.join(names)}; a study covers one task (--task).")
    task = built[0].run.task_plugin
    _check_variants(task, profiles, flickers)
    settings.setdefault("thresholds", task.thresholds)
    settings.setdefault("window", task.window)
    notes: list[str] = []
    preferred = task.study_preset if task.study_preset in regimes else None
    target = vlm_regime or preferred or next(iter(regimes))
    if target not in regimes:
        raise BadInput(f"--vlm-regime '{target}' is not a regime of this study{did_you_mean(target, regimes)}.")
    reference = next(r for r in built if r.id == target)
    adjust = settings.get("adjust", DEFAULT_ADJUST)
    if adjust not in METHODS:
        raise BadInput(f"--adjust is one of {', '.join(METHODS)}, got '{adjust}'.")
    if reference.run.vlm.backend != "sim" and query_flickers:
        notes.append(f"no query-flicker cells: the VLM backend is '{reference.run.vlm.backend}', and query_flicker "
                     "is a knob of the simulated VLM.")
        query_flickers = ()
    cells = tuple(
        Cell(kind="dose" if "query_flicker" not in knobs else "query-flicker", arm=arm,
             regime=resolve_regime(name, {**regimes[target], **over}, [base, *layers],
                                   {"regime": f"{target} {name}", "arms": [arm]}, tasks), **knobs)
        for name, arm, over, knobs in control_points(alphas, kin_scales, query_flickers)
    )
    variants: list[Regime] = []
    if reference.run.vlm.backend != "sim":
        notes.append(f"no VLM-quality variants: the VLM backend is '{reference.run.vlm.backend}', and profiles and "
                     "flicker are knobs of the simulated VLM.")
    else:
        points: list[tuple[str, dict[str, Any]]] = [("profile " + p, {"vlm.sim.profile": p}) for p in profiles]
        points += [(f"flicker {f:g}", {"vlm.sim.flicker": float(f)}) for f in flickers]
        variants = _variants(points, target, regimes[target], [base, *layers], tasks)
    return StudyConfig(regimes=built, variants=tuple(variants), cells=cells, vlm_regime=target, notes=tuple(notes),
                       **settings)


def _check_variants(task: Task, profiles: Sequence[str], flickers: Sequence[float]) -> None:
    """``BadInput`` when ``task`` cannot run the VLM-quality variants, or lacks one of ``profiles``."""
    if (profiles or flickers) and not task.probes_floats:
        raise BadInput(f"task {task.name}: the VLM-quality variants (--profiles, --flickers) take their accuracy "
                       "from the float and box taxonomy probe, which this task has not; pass --profiles none "
                       "--flickers none.")
    problem = next(filter(None, (profile_problem(p, task) for p in profiles)), None)
    if problem:
        raise BadInput(problem + ".")


def _variants(points: Sequence[tuple[str, dict[str, Any]]], target: str, point: Mapping[str, Any],
              layers: Sequence[Mapping[str, Any]], tasks: TaskLookup) -> list[Regime]:
    """The hybrid in regime ``target`` (overrides ``point``) at each VLM variant's knobs; the same
    knobs reached twice (profile default = flicker 0.1) are one variant with both names."""
    variants: list[Regime] = []
    seen: dict[str, int] = {}
    for name, extra in points:
        variant = resolve_regime(name, {**point, **extra}, layers,
                                 {"regime": f"{target} {_label(extra)}", "arms": [VARIANT_ARM]}, tasks)
        key = variant.run.jobs()[0].config_hash
        if key in seen:
            first = variants[seen[key]]
            variants[seen[key]] = Regime(f"{first.id} = {name}", first.overrides, first.run)
            continue
        seen[key] = len(variants)
        variants.append(variant)
    return variants

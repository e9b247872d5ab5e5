"""What a user chooses about `vlmrl study`, declared once: ``StudySettings``, whose fields are the
``[study]`` keys and the command's options. Light on purpose: `vlmrl --help` reads it.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from annotated_types import Ge
from pydantic import AfterValidator

from vlmrl_cli.analysis.defaults import DEFAULT_MARGIN
from vlmrl_cli.analysis.multiplicity import DEFAULT_ADJUST, METHODS
from vlmrl_cli.core.errors import first_repeated
from vlmrl_cli.core.fields import AtMost, one_of
from vlmrl_cli.probe.states import DEFAULT_STATES, MAX_STATES
from vlmrl_cli.shaping.arms import BASELINE, DENSE, METHOD, PLACEBO_OF, POTENTIAL_ONLY

DEFAULT_EXPERIMENT = "vlmrl-study"
DEFAULT_SEEDS = 20
PLACEBO_ARM = PLACEBO_OF[METHOD]
# hybrid and its placebo first: a study stopped part-way has the comparison it exists for
DEFAULT_ARMS = (BASELINE, METHOD, PLACEBO_ARM, DENSE, POTENTIAL_ONLY)
#: The dose-response grid (issue 18): PBRS scales x kinematic scales, in the VLM regime.
DEFAULT_ALPHAS: tuple[float, ...] = (5.0, 25.0, 100.0)
DEFAULT_KIN_SCALES: tuple[float, ...] = (0.0, 0.5, 2.0)
#: Per-query flicker rates at which the hybrid and hybrid-no-lock are compared (the lock's test).
DEFAULT_QUERY_FLICKERS: tuple[float, ...] = (0.3,)
#: The VLM-quality variants are off by default (the 2026-11-29 study found no dependence on them).
DEFAULT_PROFILES: tuple[str, ...] = ()
DEFAULT_FLICKERS: tuple[float, ...] = ()
DEFAULT_OUT = Path("results/study")

#: A study's regimes: name -> overrides (dotted keys, as ``--set`` takes them).
Regimes = dict[str, dict[str, Any]] | None


def _distinct(values: tuple[Any, ...]) -> tuple[Any, ...]:
    """The values, each once (a repeated point would count twice in the verdicts' family)."""
    twice = first_repeated(list(values))
    if twice is not None:
        raise ValueError(f"lists {listed((twice,))} twice; list each value once (a repeated value adds its "
                         "comparisons to the multiplicity family again)")
    return values


def _nonnegative(values: tuple[float, ...]) -> tuple[float, ...]:
    bad = [v for v in values if v < 0]
    if bad:
        raise ValueError(f"must be finite and >= 0, got {bad[0]:g}")
    return values


def _no_zero(alphas: tuple[float, ...]) -> tuple[float, ...]:
    if 0 in alphas:  # a second copy of each alpha-0 cell, and of its comparisons in the verdicts' family
        raise ValueError("lists 0, which the dose-response always includes (the dense term alone; with kin_scale 0, "
                         "the baseline); drop it")
    return alphas


def _ratio_above_one(margin: float) -> float:
    if not margin > 1:
        raise ValueError("must be a ratio above 1 (e.g. 1.15)")
    return margin


_POINTS = (AfterValidator(_distinct), AfterValidator(_nonnegative))


def listed(values: Sequence[float | str]) -> str:
    """Values as a flag takes them: ``5,25,100``; ``none`` for no value.

    Example:
        >>> listed((5.0, 25.0, 100.0)), listed(("ideal",)), listed(())
        ('5,25,100', 'ideal', 'none')
    """
    return ",".join(v if isinstance(v, str) else f"{v:g}" for v in values) or "none"


@dataclass(frozen=True)
class StudySettings:
    """Everything a user sets about a study beyond its runs' own configuration; ``help``: the option's
    help text, ``flag``: the option's name where it is not the field's."""

    regimes: Regimes = field(default=None, metadata={"flag": "--regime", "help": (
        "A regime, repeatable: NAME (the preset of that name), NAME=PRESET, or NAME='KEY=VALUE KEY=VALUE' "
        "(--set assignments, e.g. hard='preset=paper ppo.normalize_obs=false ppo.normalize_reward=false'). "
        "Replaces the study.regimes table of --config and the default (the task's study preset, else its "
        "default preset).")})
    profiles: tuple[str, ...] = field(default=DEFAULT_PROFILES, metadata={"rules": (AfterValidator(_distinct),),
                                                                        "help": (
        "Simulated-VLM profiles of the hybrid's VLM-quality runs, comma-separated, or 'none' "
        f"(default: {listed(DEFAULT_PROFILES)}).")})
    flickers: tuple[float, ...] = field(default=DEFAULT_FLICKERS, metadata={"rules": (AfterValidator(_distinct),),
                                                                          "help": (
        f"Flicker rates of the hybrid's VLM-quality runs (default profile), or 'none' "
        f"(default: {listed(DEFAULT_FLICKERS)}).")})
    alphas: tuple[float, ...] = field(default=DEFAULT_ALPHAS, metadata={"rules": (*_POINTS, AfterValidator(_no_zero)),
                                                                      "help": (
        f"PBRS scales of the dose-response cells, comma-separated, or 'none' (default: {listed(DEFAULT_ALPHAS)}; "
        "alpha 0, the dense term alone, is always included).")})
    kin_scales: tuple[float, ...] = field(default=DEFAULT_KIN_SCALES, metadata={"rules": _POINTS, "help": (
        f"Kinematic scales of the dose-response cells, or 'none' (default: {listed(DEFAULT_KIN_SCALES)}; "
        "0 is the VLM's potential alone).")})
    query_flickers: tuple[float, ...] = field(default=DEFAULT_QUERY_FLICKERS, metadata={"rules": _POINTS, "help": (
        "Per-query (temporal) flicker rates at which hybrid and hybrid-no-lock are compared, or 'none' "
        f"(default: {listed(DEFAULT_QUERY_FLICKERS)}).")})
    vlm_regime: str | None = field(default=None, metadata={"help": (
        "Regime of the VLM-quality runs and the control cells (default: the task's study preset when it is "
        "a regime of the study, else the first).")})
    states: int = field(default=DEFAULT_STATES, metadata={"rules": (Ge(2), AtMost(MAX_STATES, (
        "each position is rendered and probed with three prompts"))), "help": (
        f"Taxonomy sweep positions per VLM variant (default {DEFAULT_STATES}).")})
    margin: float = field(default=DEFAULT_MARGIN, metadata={"rules": (AfterValidator(_ratio_above_one),),
                                                          "help": (
        "Equivalence margin of a speedup, a ratio above 1: 'equivalent' when the 90% interval lies inside "
        f"[1/margin, margin] (default: {DEFAULT_MARGIN:g}).")})
    adjust: str = field(default=DEFAULT_ADJUST, metadata={"rules": (AfterValidator(one_of(METHODS, (
        "multiplicity adjustment"))),), "help": (
        "Multiplicity adjustment of the speedups' p-values within the command's family of comparisons: holm "
        "(Holm's step-down, the family-wise error rate), bh (Benjamini-Hochberg, the false discovery rate) or none; "
        f"verdicts use the adjusted p (default: {DEFAULT_ADJUST}).")})
    out: Path = field(default=DEFAULT_OUT, metadata={"help": (
        f"Output folder of the regime map, figure, report and manifest (default: {DEFAULT_OUT}).")})


"""The arms of the experiment, in one registry: each one's reward terms, its comparisons in the
report and the study, and its place in the report's order."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass
from enum import StrEnum

from vlmrl_cli.core.errors import BadInput


class PotentialSource(StrEnum):
    NONE = "none"
    MCQ = "mcq"  # macro-semantic milestones (the paper's method)
    FLOAT = "float"  # the VLM's float regression of x (the paper's failing "pure vision" PBRS)


#: The arms with a role in the report's and the study's text, named once.
BASELINE = "baseline"  # native reward only: the reference of every speedup
METHOD = "hybrid"  # the paper's method
DENSE = "kinematic"  # the dense kinematic term alone, no VLM
POTENTIAL_ONLY = "semantic"  # the VLM potential alone, no kinematic term
NO_LOCK = "hybrid-no-lock"  # the method without the hysteresis lock
PURE_VISION = "vision-float"  # PBRS on the VLM's float regression (the paper's failing setting)
PLACEBO = "hybrid-shuffled"  # the method with its label map shuffled per seed
DENSE_POTENTIAL = "hybrid-dense-pbrs"  # the method with Eq. 1's dense term in potential form
#: The placebo of each arm that has one.
PLACEBO_OF: Mapping[str, str] = {METHOD: PLACEBO}


@dataclass(frozen=True)
class Comparison:
    """One comparison of the report (and of the study's regime map unless ``in_study`` is False)."""

    reference: str
    isolates: str
    in_study: bool = True


@dataclass(frozen=True)
class ArmSpec:
    """Reward of one arm: R_env [+ R_kin] [+ alpha (gamma Phi(s') - Phi(s))]."""

    name: str
    description: str
    kinematic: bool
    potential: PotentialSource
    rbf: bool = True
    lock: bool = True
    # Added after results existed: ``identity`` leaves these out while False, so older arms keep their hashes.
    placebo: bool = False  # labels mapped through a per-seed shuffled label map (shaping/placebo.py)
    dense_potential: bool = False  # the dense term paid as a potential (shaping/wrapper.py, issue 41)
    # How the arm is reported, not how it is rewarded: ``identity`` always leaves these out.
    compared_with: tuple[Comparison, ...] = ()  # this arm against each reference, in the report's order
    report_order: int = 100  # position in the report's tables and figures (lower first; ties: registry order)

    @property
    def uses_vlm(self) -> bool:
        return self.potential is not PotentialSource.NONE

    def identity(self) -> dict[str, object]:
        """The arm as it enters config hashes: every reward field, ``placebo`` only when set
        (``compared_with`` and ``report_order`` never: they say how the arm is reported)."""
        fields = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)
                  if f.name not in ("compared_with", "report_order")}
        for late in ("placebo", "dense_potential"):  # fields added after results existed
            if not fields[late]:
                del fields[late]
        return {k: v.value if isinstance(v, PotentialSource) else v for k, v in fields.items()}


ARMS: dict[str, ArmSpec] = {
    a.name: a
    for a in (
        ArmSpec(BASELINE, "native reward only (standard PPO)", False, PotentialSource.NONE, report_order=1),
        ArmSpec(METHOD, "VLM milestone PBRS (RBF + lock) + kinematic (the paper's method)", True,
                PotentialSource.MCQ, report_order=0,
                compared_with=(Comparison(BASELINE, "the whole method"),
                               Comparison(DENSE, "what the VLM itself adds"),
                               Comparison(PLACEBO, "the labels' content (placebo: the same labels through a "
                                          "shuffled map)"))),
        ArmSpec(DENSE, "native + kinematic dense reward, no VLM", True, PotentialSource.NONE, report_order=2,
                compared_with=(Comparison(BASELINE, "what the dense kinematic term adds"),)),
        ArmSpec(POTENTIAL_ONLY, "native + VLM milestone PBRS, no kinematic reward", False, PotentialSource.MCQ,
                report_order=3,
                # the study's regime map runs it as a dose (alpha with no kinematic term), not as a pair
                compared_with=(Comparison(BASELINE, "the VLM potential alone", in_study=False),)),
        ArmSpec("hybrid-no-rbf", "hybrid without RBF smoothing (potential steps with labels)", True,
                PotentialSource.MCQ, rbf=False, report_order=4),
        ArmSpec(NO_LOCK, "hybrid without the hysteresis lock", True, PotentialSource.MCQ,
                lock=False, report_order=5),
        ArmSpec(PURE_VISION, "PBRS on the VLM's float regression of x (pure-vision setting)", False,
                PotentialSource.FLOAT, rbf=False, lock=False, report_order=6),
        ArmSpec(PLACEBO, "placebo: the hybrid with its label map shuffled per seed (same labels, "
                "no information)", True, PotentialSource.MCQ, placebo=True, report_order=7),
        ArmSpec(DENSE_POTENTIAL, "the hybrid with the dense term in potential form (PBRS on Eq. 1's "
                "coordinate, gamma-discounted: lingering cannot pay)", True, PotentialSource.MCQ,
                dense_potential=True, report_order=8,
                compared_with=(Comparison(BASELINE, "the method with a potential-form dense term"),
                               Comparison(METHOD, "Eq. 1's non-potential form (what lingering is paid)"))),
    )
}


def report_order(registry: Mapping[str, ArmSpec] = ARMS) -> list[str]:
    """The registry's arms in the report's order (``report_order``, ties in the registry's order)."""
    return sorted(registry, key=lambda name: registry[name].report_order)


def comparisons(registry: Mapping[str, ArmSpec] = ARMS, study: bool = False
                ) -> list[tuple[str, str, str]]:
    """``(arm, reference, what the difference isolates)`` of every comparison, in the report's order
    (``study``: only those the study's regime map makes too)."""
    return [(name, c.reference, c.isolates) for name in report_order(registry)
            for c in registry[name].compared_with if c.in_study or not study]


def parse_arms(text: str, registry: Mapping[str, ArmSpec] = ARMS) -> tuple[ArmSpec, ...]:
    """``"baseline,hybrid"`` -> the arm specs of ``registry``; unknown or repeated names are ``BadInput``."""
    names = [n.strip() for n in text.split(",") if n.strip()]
    if not names:
        raise BadInput(f"no arm given; choose from {', '.join(registry)}.")
    unknown = [n for n in names if n not in registry]
    if unknown:
        raise BadInput(f"unknown arm '{unknown[0]}'; choose from {', '.join(registry)}.")
    if len(set(names)) != len(names):
        raise BadInput("an arm is listed twice; list each arm once.")
    return tuple(registry[n] for n in names)

"""The arms of the experiment, in one registry: which reward terms each one uses."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from enum import StrEnum

from vlmrl_cli.core.errors import BadInput


class PotentialSource(StrEnum):
    NONE = "none"
    MCQ = "mcq"  # macro-semantic milestones (the paper's method)
    FLOAT = "float"  # the VLM's float regression of x (the paper's failing "pure vision" PBRS)


@dataclass(frozen=True)
class ArmSpec:
    """Reward of one arm: R_env [+ R_kin] [+ alpha (gamma Phi(s') - Phi(s))]."""

    name: str
    description: str
    kinematic: bool
    potential: PotentialSource
    rbf: bool = True
    lock: bool = True
    # Added after results existed: ``identity`` below leaves it out while False, so the seven
    # original arms keep their config hashes (tests/training/test_pinned_hashes.py).
    placebo: bool = False  # labels mapped through a per-seed shuffled label map (shaping/placebo.py)

    @property
    def uses_vlm(self) -> bool:
        return self.potential is not PotentialSource.NONE

    def identity(self) -> dict[str, object]:
        """The arm as it enters config hashes: every field, ``placebo`` only when set.

        Example:
            >>> "placebo" in ARMS["hybrid"].identity(), ARMS["hybrid-shuffled"].identity()["placebo"]
            (False, True)
        """
        fields = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        if not self.placebo:
            del fields["placebo"]
        return {k: v.value if isinstance(v, PotentialSource) else v for k, v in fields.items()}


ARMS: dict[str, ArmSpec] = {
    a.name: a
    for a in (
        ArmSpec("baseline", "native reward only (standard PPO)", False, PotentialSource.NONE),
        ArmSpec("hybrid", "VLM milestone PBRS (RBF + lock) + kinematic (the paper's method)", True,
                PotentialSource.MCQ),
        ArmSpec("kinematic", "native + kinematic dense reward, no VLM", True, PotentialSource.NONE),
        ArmSpec("semantic", "native + VLM milestone PBRS, no kinematic reward", False, PotentialSource.MCQ),
        ArmSpec("hybrid-no-rbf", "hybrid without RBF smoothing (potential steps with labels)", True,
                PotentialSource.MCQ, rbf=False),
        ArmSpec("hybrid-no-lock", "hybrid without the hysteresis lock", True, PotentialSource.MCQ,
                lock=False),
        ArmSpec("vision-float", "PBRS on the VLM's float regression of x (pure-vision setting)", False,
                PotentialSource.FLOAT, rbf=False, lock=False),
        ArmSpec("hybrid-shuffled", "placebo: the hybrid with its label map shuffled per seed (same labels, "
                "no information)", True, PotentialSource.MCQ, placebo=True),
    )
}


def parse_arms(text: str) -> tuple[ArmSpec, ...]:
    """``"baseline,hybrid"`` -> the arm specs; unknown or repeated names are ``BadInput``.

    Example:
        >>> [a.name for a in parse_arms("baseline, hybrid")]
        ['baseline', 'hybrid']
    """
    names = [n.strip() for n in text.split(",") if n.strip()]
    if not names:
        raise BadInput(f"no arm given; choose from {', '.join(ARMS)}.")
    unknown = [n for n in names if n not in ARMS]
    if unknown:
        raise BadInput(f"unknown arm '{unknown[0]}'; choose from {', '.join(ARMS)}.")
    if len(set(names)) != len(names):
        raise BadInput("an arm is listed twice; list each arm once.")
    return tuple(ARMS[n] for n in names)

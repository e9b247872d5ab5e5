"""The placebo control (arm ``hybrid-shuffled``): the VLM's labels through a label map shuffled
per seed by a balanced Latin square, a pure function of the seed (see docs/method.md)."""

from __future__ import annotations

import dataclasses
import hashlib

from vlmrl_cli.shaping.arms import ArmSpec
from vlmrl_cli.shaping.config import ShapingConfig

LabelMap = tuple[tuple[str, float], ...]  # (label, raw potential), in the task's label order


def permutation(n: int, seed: int, salt: str = "vlmrl-placebo") -> tuple[int, ...]:
    """A permutation of ``range(n)``, a pure function of ``(seed, salt)``: index ``i`` goes to rank
    ``i`` of the sha256 digests of ``f"{salt}:{seed}:{j}"``."""
    digests = [hashlib.sha256(f"{salt}:{seed}:{j}".encode()).digest() for j in range(n)]
    return tuple(sorted(range(n), key=lambda j: digests[j]))


def latin_permutation(n: int, seed: int) -> tuple[int, ...]:
    """Seed ``seed``'s row of a random Latin square (block ``seed // n``, row ``seed % n``): over the
    ``n`` seeds of a block, every ``i`` meets every value once."""
    if n == 0:
        return ()
    block, k = divmod(seed, n)
    r = permutation(n, block, salt="vlmrl-placebo-rows")
    c = permutation(n, block, salt="vlmrl-placebo-cols")
    return tuple(c[(r[i] + k) % n] for i in range(n))


def placebo_map(label_potentials: LabelMap, seed: int) -> LabelMap:
    """``label_potentials`` with label ``i`` given the potential of label ``latin_permutation[i]``."""
    order = latin_permutation(len(label_potentials), seed)
    values = [p for _, p in label_potentials]
    return tuple((zone, values[j]) for (zone, _), j in zip(label_potentials, order, strict=True))


def oracle_shaping(arm: ArmSpec, shaping: ShapingConfig, seed: int) -> ShapingConfig:
    """``shaping``, with ``placebo_map`` of its label map for a placebo arm."""
    if not arm.placebo:
        return shaping
    return dataclasses.replace(shaping, label_potentials=placebo_map(shaping.label_potentials, seed))


def describe_map(label_potentials: LabelMap) -> str:
    """``"HANGING=0 LOW_SWING=0.2 ..."``: a label map as one loggable line."""
    return " ".join(f"{label}={p:g}" for label, p in label_potentials)

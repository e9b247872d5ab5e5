"""The placebo control (arm ``hybrid-shuffled``): the VLM's labels through a shuffled label map.

The placebo keeps everything of the hybrid but what the labels *mean*: the same VLM answers the
same queries on the same schedule (so the flicker, the parse failures and the query cost are
the hybrid's), the same multiset of raw potentials is paid, the RBF and the lock run as usual,
but each label's potential is another label's, by a permutation drawn once per seed and fixed
within the run. One fixed permutation would not do, since a single map can be informative by
accident (one that pays for the left peak pays for momentum). The permutations are balanced:
seeds come in blocks of n (the number of labels), each block a random Latin square, so within
a block every label takes every potential exactly once and its mean potential over the block is
the mean of the map; the potential then carries no information about progress on average over
seeds, exactly rather than only in expectation. The permutation is a pure function of the seed
(sha256 ranks, no numpy stream), so it is the same on every machine and numpy version, and it
is logged with the run (tag ``vlmrl.placebo_map``).
"""

from __future__ import annotations

import dataclasses
import hashlib

from vlmrl_cli.shaping.arms import ArmSpec
from vlmrl_cli.shaping.config import ShapingConfig

LabelMap = tuple[tuple[str, float], ...]  # (label, raw potential), in the task's label order


def permutation(n: int, seed: int, salt: str = "vlmrl-placebo") -> tuple[int, ...]:
    """A permutation of ``range(n)``, a pure function of ``(seed, salt)``: index ``i`` goes to rank
    ``i`` of the sha256 digests of ``f"{salt}:{seed}:{j}"``.

    Example:
        >>> sorted(permutation(6, seed=3)) == list(range(6))
        True
        >>> permutation(6, seed=3) == permutation(6, seed=3)
        True
    """
    if n < 0:
        raise ValueError(f"n must be >= 0, got {n}")
    digests = [hashlib.sha256(f"{salt}:{seed}:{j}".encode()).digest() for j in range(n)]
    return tuple(sorted(range(n), key=lambda j: digests[j]))


def latin_permutation(n: int, seed: int) -> tuple[int, ...]:
    """Seed ``seed``'s row of a random Latin square: block ``b = seed // n`` draws row and column
    orders ``r, c`` (``permutation`` with two salts), and row ``k = seed % n`` maps ``i`` to
    ``c[(r[i] + k) % n]``. Over the ``n`` seeds of a block, every ``i`` meets every value once.

    Example:
        >>> rows = [latin_permutation(4, s) for s in range(4, 8)]   # one block
        >>> all(sorted(r[i] for r in rows) == [0, 1, 2, 3] for i in range(4))
        True
    """
    if n == 0:
        return ()
    block, k = divmod(seed, n)
    r = permutation(n, block, salt="vlmrl-placebo-rows")
    c = permutation(n, block, salt="vlmrl-placebo-cols")
    return tuple(c[(r[i] + k) % n] for i in range(n))


def placebo_map(label_potentials: LabelMap, seed: int) -> LabelMap:
    """``label_potentials`` with the potentials permuted among the labels by ``latin_permutation``.

    Labels keep their order; label ``i`` gets the potential of label ``latin_permutation[i]``.
    The multiset of potentials is unchanged (dimensionless raw potentials, as the map's).

    Example:
        >>> m = (("BOTTOM", 0.0), ("LEFT_PEAK", 0.3), ("GOAL", 1.0))
        >>> shuffled = placebo_map(m, seed=0)
        >>> [z for z, _ in shuffled] == [z for z, _ in m], sorted(p for _, p in shuffled)
        (True, [0.0, 0.3, 1.0])
    """
    order = latin_permutation(len(label_potentials), seed)
    values = [p for _, p in label_potentials]
    return tuple((zone, values[j]) for (zone, _), j in zip(label_potentials, order, strict=True))


def oracle_shaping(arm: ArmSpec, shaping: ShapingConfig, seed: int) -> ShapingConfig:
    """The shaping config the arm's oracle maps labels with: ``shaping`` itself, or for a placebo
    arm the same config with ``placebo_map(shaping.label_potentials, seed)``."""
    if not arm.placebo:
        return shaping
    return dataclasses.replace(shaping, label_potentials=placebo_map(shaping.label_potentials, seed))


def describe_map(label_potentials: LabelMap) -> str:
    """``"HANGING=0 LOW_SWING=0.2 ..."``: a label map as one loggable line.

    Example:
        >>> describe_map((("BOTTOM", 0.0), ("GOAL", 1.0)))
        'BOTTOM=0 GOAL=1'
    """
    return " ".join(f"{label}={p:g}" for label, p in label_potentials)

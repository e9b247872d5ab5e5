"""How many sweep positions a taxonomy probes by default and may probe, in a light module (no
numpy or scipy) that `vlmrl taxonomy` and `vlmrl study` read their ``--states`` with before
anything heavy loads."""

from __future__ import annotations

# 101 sweep positions (+ the paper's two frames): a rank correlation of 0 over 103 frames has a 95%
# interval of about +-0.2 (25 positions gave +-0.4, too wide to tell "no rank signal" from a weak
# one), and on MountainCar no position falls within 2 px of a zone edge, where a reader off by a
# fraction of a pixel flips the label (25 positions put three frames exactly on edges).
DEFAULT_STATES = 101

#: The most positions: each is rendered and probed with three prompts (seconds each on a real VLM),
#: and 10,000 already space the positions 0.0002 apart on MountainCar's track.
MAX_STATES = 10_000


def states_problem(states: int) -> str | None:
    """Why a sweep of ``states`` positions cannot run (None when it can).

    Example:
        >>> states_problem(101) is None, states_problem(1)
        (True, '--states 1 is too few: a sweep needs at least 2 positions')
        >>> states_problem(10**8)
        '--states 100,000,000 is too many: at most 10,000 (each position is rendered and probed with three prompts)'
    """
    if states < 2:
        return f"--states {states} is too few: a sweep needs at least 2 positions"
    if states > MAX_STATES:
        return (f"--states {states:,} is too many: at most {MAX_STATES:,} (each position is rendered and probed with "
                "three prompts)")
    return None

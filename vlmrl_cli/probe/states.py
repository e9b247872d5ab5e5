"""How many sweep positions a taxonomy probes (a light module: read before anything heavy loads)."""

from __future__ import annotations

# 101 positions (+ the paper's two frames): a rank correlation of 0 has a 95% interval of about +-0.2,
# and on MountainCar no position falls within 2 px of a zone edge (25 put three frames on edges)
DEFAULT_STATES = 101
#: The most positions: each is probed with three prompts (seconds each on a real VLM).
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

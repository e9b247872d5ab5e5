"""The default knobs of the statistics, in a module that loads nothing: the configuration objects of
`vlmrl report`, `compare`, `study` and `calibrate` take their defaults from here, so that a bad flag
is refused before numpy, scipy or pandas load. Each analysis module imports its own from here."""

from __future__ import annotations

#: Bootstrap resamples of an interval.
DEFAULT_N_BOOT = 2000
#: Bootstrap resamples of each simulated study's interval in a power figure (``analysis/power.py``):
#: fewer than a report's, as each figure simulates a thousand studies.
DEFAULT_POWER_N_BOOT = 200
#: Permutations of the rank test; small experiments (<= this many splits) are enumerated exactly.
DEFAULT_N_PERM = 9999
#: The equivalence margin of a speedup (TOST within [1/margin, margin]).
DEFAULT_MARGIN = 1.15
#: A seed counts as a detached success when at least this fraction of its detached evaluation
#: episodes reached the flag. Trained MountainCar policies are bimodal (about 0% or 100% of
#: episodes), so the claim "the baseline fails 40%" is read per seed and the cut rarely matters.
DETACHED_SUCCESS_CUT = 0.9

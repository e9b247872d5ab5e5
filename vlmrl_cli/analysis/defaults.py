"""The default knobs of the statistics, in a module that loads nothing: the configuration objects of
`vlmrl report`, `compare`, `study` and `calibrate` take their defaults from here, so that a bad flag
is refused before numpy, scipy or pandas load. Each analysis module imports its own from here."""

from __future__ import annotations

#: Bootstrap resamples of an interval.
DEFAULT_N_BOOT = 2000
#: Bootstrap resamples of each simulated study's interval in a power figure (``analysis/power.py``), for
#: callers that still pass one: the interval is no longer a bootstrap (``censored.log_ratio_bounds``).
DEFAULT_POWER_N_BOOT = 200
#: The rank test is exact (every split of the seeds counted) up to this many splits: C(60, 30), whose
#: counts still fit int64. The splits are counted by their rank sums, not one by one, so 10 vs 10
#: (C(20, 10) = 184,756 splits) takes a millisecond; beyond, the normal approximation, labelled so.
DEFAULT_N_PERM = 118264581564861424
#: The equivalence margin of a speedup (TOST within [1/margin, margin]).
DEFAULT_MARGIN = 1.15
#: A seed counts as a detached success when at least this fraction of its detached evaluation
#: episodes reached the flag. Trained MountainCar policies are bimodal (about 0% or 100% of
#: episodes), so the claim "the baseline fails 40%" is read per seed and the cut rarely matters.
DETACHED_SUCCESS_CUT = 0.9

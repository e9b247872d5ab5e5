"""The statistics' default knobs, in a module that loads nothing (so a bad flag is refused before
numpy, scipy or pandas load)."""

from __future__ import annotations

#: Bootstrap resamples of an interval.
DEFAULT_N_BOOT = 2000
#: The rank test is exact up to this many splits of the seeds, C(60, 30) (its counts fit int64);
#: beyond, the normal approximation, labelled so.
DEFAULT_N_PERM = 118264581564861424
#: The equivalence margin of a speedup (TOST within [1/margin, margin]).
DEFAULT_MARGIN = 1.15
#: A seed is a detached success when at least this share of its detached episodes succeeded
#: (trained policies are bimodal, about 0% or 100%, so the cut rarely matters).
DETACHED_SUCCESS_CUT = 0.9

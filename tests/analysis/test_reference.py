"""The zoo-reference rule: equivalence within 10% of the random-to-zoo span, TOST on >= 10 seeds."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from vlmrl_cli.analysis.reference import CANNOT_TELL, MET, NOT_MET, reference_equivalence


def test_three_seeds_within_the_old_overlap_are_no_longer_met() -> None:
    # the old rule met MountainCar on 3 seeds whose t interval overlapped -110.4 +/- 19.5: any mean within +-32
    v = reference_equivalence([-135.0, -145.0, -140.0], -110.423, -200.0)
    assert v.verdict == NOT_MET
    assert reference_equivalence([-106.19, -105.88, -114.89], -110.423, -200.0).verdict == CANNOT_TELL


def test_doorkeys_ten_study_seeds_meet_the_zoo() -> None:
    scores = [0.964] * 8 + [0.9, 0.92]
    v = reference_equivalence(scores, 0.964, 0.0295)
    assert v.verdict == MET and v.n == 10 and abs(v.delta - 0.09345) < 1e-9 and v.p_tost < 0.05


@settings(max_examples=60, deadline=None)
@given(st.lists(st.floats(-150.0, -70.0), min_size=10, max_size=20))
def test_met_iff_the_tost_rejects(scores: list[float]) -> None:
    v = reference_equivalence(scores, -110.423, -200.0)
    if np.isfinite(v.p_tost):
        assert (v.verdict == MET) == (v.p_tost < 0.05)
        band = (-110.423 - v.delta, -110.423 + v.delta)
        assert (v.verdict == MET) == (band[0] < v.low and v.high < band[1])

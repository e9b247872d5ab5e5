from __future__ import annotations

import pytest

from vlmrl_cli.analysis.stats import Estimate
from vlmrl_cli.report.claims import INCONCLUSIVE, NOT_REPRODUCED, REPRODUCED, verdict


@pytest.mark.parametrize(
    ("est", "paper", "null", "direction", "expected"),
    [
        (Estimate(1.5, 1.2, 1.9, n=5), 1.4, 1.0, ">", REPRODUCED),  # CI above 1, contains 1.4
        (Estimate(2.5, 2.1, 2.9, n=5), 1.4, 1.0, ">", REPRODUCED),  # effect there, magnitude differs
        (Estimate(0.8, 0.6, 1.0, n=5), 1.4, 1.0, ">", NOT_REPRODUCED),  # CI at/below the null
        (Estimate(1.05, 0.9, 1.2, n=5), 1.4, 1.0, ">", NOT_REPRODUCED),  # contains null, excludes 1.4
        (Estimate(1.2, 0.8, 1.7, n=5), 1.4, 1.0, ">", INCONCLUSIVE),  # contains null and 1.4
        (Estimate(1.5, 1.2, 1.9, n=2), 1.4, 1.0, ">", INCONCLUSIVE),  # too few seeds
        (Estimate(1.5, n=5), 1.4, 1.0, ">", INCONCLUSIVE),  # no CI
        (Estimate(-5.0, -9.0, -1.0, n=5), None, 0.0, "<", REPRODUCED),  # narrower spread
        (Estimate(5.0, 1.0, 9.0, n=5), None, 0.0, "<", NOT_REPRODUCED),
        (Estimate(1.0, 0.44, 1.0, n=3), 1.0, None, ">", REPRODUCED),  # absolute: 3/3 vs 100%
        (Estimate(0.2, 0.05, 0.5, n=5), 1.0, None, ">", NOT_REPRODUCED),
        (Estimate(1.0, 0.566, 1.0, n=5), 0.6, None, ">", INCONCLUSIVE),  # 5/5 vs a claimed 60%: CI too wide
        (Estimate(0.62, 0.3, 0.9, n=5), 0.6, None, ">", REPRODUCED),  # estimate close to the claim
    ],
)
def test_verdict_rule(est, paper, null, direction, expected):
    assert verdict(est, paper, null, direction)[0] == expected


def test_approximate_value_gets_tolerance():
    est = Estimate(135.0, 134.0, 136.0, n=3)
    assert verdict(est, 125.0, approximate=True)[0] == REPRODUCED
    assert verdict(est, 125.0, approximate=False)[0] == NOT_REPRODUCED
    beyond = Estimate(140.0, 139.0, 141.0, n=3)  # outside even the tolerance around 125
    assert verdict(beyond, 125.0, approximate=True)[0] == NOT_REPRODUCED

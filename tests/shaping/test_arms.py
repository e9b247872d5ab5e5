"""The arm registry: what each arm is compared with, the report's order, and what stays out of hashes."""

from __future__ import annotations

import dataclasses

from vlmrl_cli.shaping import arms
from vlmrl_cli.shaping.arms import ARMS, ArmSpec, Comparison, PotentialSource


def test_every_comparison_names_a_registered_arm_other_than_its_own() -> None:
    for name, spec in ARMS.items():
        for c in spec.compared_with:
            assert c.reference in ARMS and c.reference != name


def test_the_role_names_are_registered_arms() -> None:
    roles = [arms.BASELINE, arms.METHOD, arms.DENSE, arms.POTENTIAL_ONLY, arms.NO_LOCK, arms.PURE_VISION,
             arms.PLACEBO, *arms.PLACEBO_OF, *arms.PLACEBO_OF.values()]
    assert set(roles) <= set(ARMS)
    assert all(ARMS[p].placebo for p in arms.PLACEBO_OF.values())


def test_report_order_is_a_permutation_that_puts_unordered_arms_last_in_registry_order() -> None:
    extra = {n: ArmSpec(n, "test", False, PotentialSource.NONE) for n in ("zz-first", "aa-second")}
    order = arms.report_order({**ARMS, **extra})
    assert sorted(order) == sorted([*ARMS, *extra])
    assert order[-2:] == ["zz-first", "aa-second"]
    assert order[:2] == [arms.METHOD, arms.BASELINE]


def test_reporting_fields_never_enter_the_identity() -> None:
    spec = ARMS[arms.DENSE]
    moved = dataclasses.replace(spec, compared_with=(Comparison(arms.METHOD, "anything"),), report_order=-5)
    assert moved.identity() == spec.identity()
    assert {"compared_with", "report_order"}.isdisjoint(spec.identity())


def test_study_comparisons_are_a_subsequence_of_the_report_s() -> None:
    every, study = arms.comparisons(), arms.comparisons(study=True)
    assert [c for c in every if c in study] == study
    assert len(study) < len(every)


def test_parse_arms_reads_the_registry_it_is_given() -> None:
    extra = ArmSpec("x-new", "test", False, PotentialSource.NONE)
    assert arms.parse_arms("x-new, baseline", {**ARMS, "x-new": extra}) == (extra, ARMS[arms.BASELINE])

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from vlmrl_cli.shaping.rbf import RBFField, rbf_potential

D = 4
coords = st.floats(-5.0, 5.0)
bandwidths = st.floats(0.01, 10.0)


@st.composite
def prototype_sets(draw: st.DrawFn) -> tuple[np.ndarray, np.ndarray]:
    n = draw(st.integers(1, 12))
    feats = draw(arrays(np.float64, (n, D), elements=coords))
    pots = draw(arrays(np.float64, (n,), elements=st.floats(-1.0, 1.0)))
    return feats, pots


@given(arrays(np.float64, (D,), elements=coords), prototype_sets(), bandwidths)
def test_result_lies_within_the_prototype_potentials(f: np.ndarray, protos: tuple[np.ndarray, np.ndarray],
                                                      h: float) -> None:
    feats, pots = protos
    value = rbf_potential(f, feats, pots, h)
    assert math.isfinite(value)
    assert pots.min() <= value <= pots.max()


@given(prototype_sets(), bandwidths, st.data())
def test_equals_the_prototype_potential_on_a_prototype_when_the_others_are_far(
    protos: tuple[np.ndarray, np.ndarray], h: float, data: st.DataObject
) -> None:
    feats, pots = protos
    i = data.draw(st.integers(0, len(pots) - 1))
    # move every other prototype at least 40 bandwidths away
    far = feats.copy()
    for j in range(len(far)):
        if j != i:
            far[j] = feats[i] + 40.0 * h + 1.0 + j
    assert rbf_potential(far[i], far, pots, h) == pytest.approx(pots[i], abs=1e-12)


@given(arrays(np.float64, (D,), elements=coords), prototype_sets(), bandwidths, st.randoms())
def test_permutation_invariant(f: np.ndarray, protos: tuple[np.ndarray, np.ndarray], h: float, rnd) -> None:
    feats, pots = protos
    order = list(range(len(pots)))
    rnd.shuffle(order)
    assert rbf_potential(f, feats[order], pots[order], h) == pytest.approx(rbf_potential(f, feats, pots, h),
                                                                          abs=1e-12)


def test_no_prototype_means_zero_potential() -> None:
    assert rbf_potential(np.zeros(D), np.empty((0, D)), np.empty(0), 0.5) == 0.0


def test_underflowing_weights_fall_back_to_the_nearest_prototype() -> None:
    feats = np.array([[100.0, 0.0], [0.0, 130.0]])
    # raw weights exp(-100^2 / 2e-6) underflow to 0 for both; the nearest (first) wins
    assert rbf_potential(np.zeros(2), feats, np.array([0.3, 1.0]), bandwidth=1e-3) == 0.3


def test_midpoint_of_two_prototypes_is_their_mean() -> None:
    feats = np.array([[0.0], [1.0]])
    assert rbf_potential(np.array([0.5]), feats, np.array([0.0, 0.6]), 0.3) == pytest.approx(0.3)


@pytest.mark.parametrize("h", [0.0, -1.0])
def test_bandwidth_must_be_positive(h: float) -> None:
    with pytest.raises(ValueError, match="bandwidth"):
        rbf_potential(np.zeros(1), np.zeros((1, 1)), np.zeros(1), h)


@settings(deadline=None, max_examples=60)
@given(st.lists(st.tuples(st.booleans(), st.integers(0, 7), arrays(np.float64, (D,), elements=coords),
                          st.floats(0.0, 1.0)), min_size=1, max_size=40),
       st.floats(0.05, 3.0))
def test_incremental_field_matches_recomputing_from_scratch(ops, bandwidth: float) -> None:  # type: ignore[no-untyped-def]
    """Any interleaving of prototype additions and queries gives what ``rbf_potential`` gives
    over the prototypes present at query time."""
    field = RBFField(bandwidth, D)
    frames: dict[int, np.ndarray] = {}
    protos: list[np.ndarray] = []
    potentials: list[float] = []
    for add, key, feature, potential in ops:
        if add:
            field.add_prototype(feature, potential)
            protos.append(feature)
            potentials.append(potential)
        else:
            frames.setdefault(key, feature)
            expected = rbf_potential(frames[key], np.array(protos).reshape(-1, D), np.array(potentials), bandwidth)
            assert math.isclose(field.value(str(key), frames[key]), expected, rel_tol=1e-9, abs_tol=1e-9)

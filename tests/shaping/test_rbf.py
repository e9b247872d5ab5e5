from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from vlmrl_cli.core.fp import exp_scalar
from vlmrl_cli.shaping.features import FEATURE_DIM, FEATURE_UNIT
from vlmrl_cli.shaping.rbf import RBFField
from vlmrl_cli.tasks.mountain_car.camera import Camera

D = 4
coords = st.floats(-5.0, 5.0)
bandwidths = st.floats(0.01, 10.0)


def fresh_value(f: np.ndarray, feats: np.ndarray, pots: np.ndarray, h: float) -> float:
    """The value of a field that held every prototype before the query: computed from scratch."""
    field = RBFField(h, feats.shape[1])
    for row, p in zip(feats, pots, strict=True):
        field.add_prototype(row, float(p))
    return field.value("query", f)


@st.composite
def prototype_sets(draw: st.DrawFn) -> tuple[np.ndarray, np.ndarray]:
    n = draw(st.integers(1, 12))
    feats = draw(arrays(np.float64, (n, D), elements=coords))
    pots = draw(arrays(np.float64, (n,), elements=st.floats(-1.0, 1.0)))
    return feats, pots


@given(arrays(np.float64, (D,), elements=coords), prototype_sets(), bandwidths)
def test_result_lies_within_the_prototype_potentials(
    f: np.ndarray, protos: tuple[np.ndarray, np.ndarray], h: float
) -> None:
    feats, pots = protos
    value = fresh_value(f, feats, pots, h)
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
    assert fresh_value(far[i], far, pots, h) == pytest.approx(pots[i], abs=1e-12)


@given(arrays(np.float64, (D,), elements=coords), prototype_sets(), bandwidths, st.randoms())
def test_permutation_invariant(f: np.ndarray, protos: tuple[np.ndarray, np.ndarray], h: float, rnd) -> None:
    feats, pots = protos
    order = list(range(len(pots)))
    rnd.shuffle(order)
    assert fresh_value(f, feats[order], pots[order], h) == pytest.approx(fresh_value(f, feats, pots, h), abs=1e-12)


def test_no_prototype_means_zero_potential() -> None:
    assert fresh_value(np.zeros(D), np.empty((0, D)), np.empty(0), 0.5) == 0.0


def test_underflowing_weights_fall_back_to_the_nearest_prototype() -> None:
    feats = np.array([[100.0, 0.0], [0.0, 130.0]])
    # raw weights exp(-100^2 / 2e-6) underflow to 0 for both; the nearest (first) wins
    assert fresh_value(np.zeros(2), feats, np.array([0.3, 1.0]), 1e-3) == 0.3


def test_midpoint_of_two_prototypes_is_their_mean() -> None:
    feats = np.array([[0.0], [1.0]])
    assert fresh_value(np.array([0.5]), feats, np.array([0.0, 0.6]), 0.3) == pytest.approx(0.3)


@pytest.mark.parametrize("h", [0.0, -1.0])
def test_bandwidth_must_be_positive(h: float) -> None:
    with pytest.raises(ValueError, match="bandwidth"):
        RBFField(h, 1)


@settings(deadline=None, max_examples=60)
@given(
    st.lists(
        st.tuples(st.booleans(), st.integers(0, 7), arrays(np.float64, (D,), elements=coords), st.floats(0.0, 1.0)),
        min_size=1,
        max_size=40,
    ),
    st.floats(0.05, 3.0),
)
def test_incremental_field_matches_recomputing_from_scratch(ops, bandwidth: float) -> None:  # type: ignore[no-untyped-def]
    """Any interleaving of prototype additions and queries gives what a field built from scratch
    gives over the prototypes present at query time."""
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
            expected = fresh_value(frames[key], np.array(protos).reshape(-1, D), np.array(potentials), bandwidth)
            assert math.isclose(field.value(str(key), frames[key]), expected, rel_tol=1e-9, abs_tol=1e-9)


class _ScalarField:
    """``RBFField`` re-done with Python ints and floats, one operation at a time, in the same
    order: the reference its vectorised path must equal bit for bit."""

    def __init__(self, bandwidth: float, unit: float) -> None:
        self.scale = 1.0 / (2.0 * bandwidth * bandwidth)
        self.unit = unit
        self.protos: list[list[int]] = []
        self.pots: list[float] = []
        self.keys: dict[str, list[float]] = {}  # key -> [num, den, ref]
        self.feats: dict[str, list[int]] = {}

    def sq(self, a: list[int], b: list[int]) -> float:
        return float(sum((x - y) * (x - y) for x, y in zip(a, b, strict=True))) / (self.unit * self.unit)

    def add(self, feature: list[int], potential: float) -> None:
        self.protos.append(feature)
        self.pots.append(potential)
        for key, state in self.keys.items():
            num, den, ref = state
            sq = self.sq(self.feats[key], feature)
            rescale = exp_scalar(-max(ref - sq, 0.0) * self.scale)
            num, den = num * rescale, den * rescale
            ref = sq if sq < ref else ref
            w = exp_scalar(-(sq - ref) * self.scale)
            self.keys[key] = [num + w * potential, den + w, ref]

    def set(self, index: int, potential: float) -> None:
        old, self.pots[index] = self.pots[index], potential
        if potential == old:
            return
        for key, state in self.keys.items():
            num, _, ref = state
            sq = self.sq(self.feats[key], self.protos[index])
            state[0] = num + exp_scalar(-(sq - ref) * self.scale) * (potential - old)

    def value(self, key: str, feature: list[int]) -> float:
        if not self.protos:
            return 0.0
        if key not in self.keys:
            sqs = [self.sq(p, feature) for p in self.protos]
            ref = min(sqs)
            ws = [exp_scalar(-(s - ref) * self.scale) for s in sqs]
            num = math.fsum(w * p for w, p in zip(ws, self.pots, strict=True))
            self.keys[key] = [num, math.fsum(ws), ref]
            self.feats[key] = feature
        num, den, _ = self.keys[key]
        return min(max(num / den, min(self.pots)), max(self.pots))


def test_field_on_recorded_frames_equals_a_scalar_reference_bit_for_bit() -> None:
    """300 camera frames along a random walk, a prototype every 7th: the vectorised field and the
    scalar reference agree exactly (not approximately)."""
    rng = np.random.default_rng(0)
    xs = np.clip(np.cumsum(rng.normal(0, 0.04, 300)) - 0.5, -1.2, 0.6)
    camera = Camera(render_quantum=0.003)
    views = [camera.view(float(x)) for x in xs]
    camera.close()
    field = RBFField(0.3, FEATURE_DIM, unit=FEATURE_UNIT)
    ref = _ScalarField(0.3, FEATURE_UNIT)
    for i, view in enumerate(views):
        counts = view.features.tolist()
        if i % 7 == 0:
            potential = float(rng.choice([0.0, 0.3, 0.5, 0.7, 1.0]))
            field.add_prototype(view.features, potential)
            ref.add(counts, potential)
        assert field.value(view.key, view.features) == ref.value(view.key, counts)


@given(prototype_sets(), bandwidths, st.data())
@settings(max_examples=60)
def test_set_potential_equals_a_field_built_with_the_new_potential(
    protos: tuple[np.ndarray, np.ndarray], h: float, data: st.DataObject
) -> None:
    feats, pots = protos
    n = feats.shape[0]
    index = data.draw(st.integers(0, n - 1))
    new = data.draw(st.floats(-1.0, 1.0))
    queries = data.draw(arrays(np.float64, (3, D), elements=coords))
    field = RBFField(h, D)
    for f, p in zip(feats, pots, strict=True):
        field.add_prototype(f, float(p))
    before = [field.value(str(i), q) for i, q in enumerate(queries)]  # keys stored, then updated
    assert all(math.isfinite(v) for v in before)
    field.set_potential(index, new)
    changed = pots.copy()
    changed[index] = new
    for i, q in enumerate(queries):
        assert field.value(str(i), q) == pytest.approx(fresh_value(q, feats, changed, h), abs=1e-9)


def test_set_potential_refuses_an_unknown_prototype() -> None:
    field = RBFField(0.5, 1)
    with pytest.raises(IndexError):
        field.set_potential(0, 1.0)


def test_a_known_spread_skips_only_a_check_and_a_wide_one_still_refuses_overflow() -> None:
    from vlmrl_cli.shaping.rbf import squared_distances

    rng = np.random.default_rng(3)
    points = rng.integers(0, 10**8, size=(7, 600), dtype=np.int64)
    feature = rng.integers(0, 10**8, size=600, dtype=np.int64)
    assert np.array_equal(squared_distances(points, feature, 5.0, spread=10**8),
                          squared_distances(points, feature, 5.0))
    huge = np.array([[0, 2**40]], dtype=np.int64)
    with pytest.raises(ValueError, match="too large"):
        squared_distances(huge, np.array([2**40, 0], dtype=np.int64), spread=2**40)


@given(st.lists(st.tuples(st.booleans(), st.integers(0, 5), st.floats(0.0, 1.0)), min_size=1, max_size=30),
       st.sampled_from([3, 10**4, 10**9, 2**61]), st.integers(0, 2**32 - 1))
def test_integer_field_equals_the_scalar_reference_bit_for_bit_at_any_magnitude(ops, high: int, seed: int) -> None:  # type: ignore[no-untyped-def]
    """Integer features from tiny to near int64 overflow (where the norm shortcut must step aside):
    the field equals the scalar reference exactly, or refuses the overflow as the reference's
    exact arithmetic would not fit int64."""
    rng = np.random.default_rng(seed)
    dim = 4
    field, ref = RBFField(0.7, dim, unit=float(high)), _ScalarField(0.7, float(high))
    feats = {k: rng.integers(0, high, size=dim, endpoint=True).astype(np.int64) for k in range(6)}
    try:
        for add, key, potential in ops:
            f = feats[key]
            if add:
                field.add_prototype(f, potential)
                ref.add(f.tolist(), potential)
            else:
                assert field.value(str(key), f) == ref.value(str(key), f.tolist())
    except ValueError as exc:
        assert "too large" in str(exc) and high == 2**61


@given(st.lists(st.tuples(st.sampled_from(["add", "set", "value"]), st.integers(0, 7), st.floats(-1.0, 1.0)),
                min_size=1, max_size=60), st.integers(0, 2**32 - 1))
@settings(max_examples=150)
def test_changed_potentials_and_late_lookups_equal_the_scalar_reference_bit_for_bit(ops, seed: int) -> None:  # type: ignore[no-untyped-def]
    """Prototypes added, potentials changed (a stochastic VLM's newest answer) and keys looked up in
    any order, some keys not for many events: every value equals the eager scalar reference exactly."""
    rng = np.random.default_rng(seed)
    dim, high = 6, 10**6
    field, ref = RBFField(0.4, dim, unit=float(high)), _ScalarField(0.4, float(high))
    feats = {k: rng.integers(0, high, size=dim, endpoint=True).astype(np.int64) for k in range(8)}
    for op, key, potential in ops:
        if op == "add":
            field.add_prototype(feats[key], potential)
            ref.add(feats[key].tolist(), potential)
        elif op == "set" and ref.pots:
            index = key % len(ref.pots)
            field.set_potential(index, potential)
            ref.set(index, potential)
        elif op == "value":
            assert field.value(str(key), feats[key]) == ref.value(str(key), feats[key].tolist())
    for key, f in feats.items():  # every key at the end, however long since it was last seen
        assert field.value(str(key), f) == ref.value(str(key), f.tolist())

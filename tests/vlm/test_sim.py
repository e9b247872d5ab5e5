"""The simulated VLM reads the car from pixels only, and answers deterministically."""

from __future__ import annotations

import time

import numpy as np
import pytest

from tests.mountain_car_helpers import parse_box, parse_float, parse_mcq, sim_vlm
from vlmrl_cli.frames.render import Frame
from vlmrl_cli.tasks.mountain_car import geometry
from vlmrl_cli.tasks.mountain_car.prompts import PROMPTS
from vlmrl_cli.tasks.mountain_car.reader import REFUSAL, WheelReader, wheel_column
from vlmrl_cli.tasks.mountain_car.render import FrameRenderer
from vlmrl_cli.vlm.base import Backend
from vlmrl_cli.vlm.config import SimKnobs
from vlmrl_cli.vlm.parsers import ParseStatus
from vlmrl_cli.vlm.prompts import Milestones, PromptKind, mcq_prompt
from vlmrl_cli.vlm.sim import TASK_REFUSAL, SimulatedVLM

EXACT = SimKnobs(flicker=0.0, float_noise=0.0, box_noise_px=0.0, box_failure=0.0)


@pytest.fixture(scope="module")
def renderer():
    with FrameRenderer() as r:
        yield r


def test_is_a_backend_and_says_it_is_simulated() -> None:
    vlm = sim_vlm()
    assert isinstance(vlm, Backend)
    assert vlm.simulated is True and vlm.name == "sim"
    assert "SIMULATED" in (SimulatedVLM.__doc__ or "")


def test_blank_frame_gets_a_refusal() -> None:
    blank = Frame.from_pixels(np.full((400, 600, 3), 255, dtype=np.uint8), frame_id="x=-0.50")
    vlm = sim_vlm(EXACT)
    for kind in PromptKind:
        assert vlm.answer(PROMPTS[kind], blank) == REFUSAL
    assert parse_float(REFUSAL).status is ParseStatus.FORMAT_COLLAPSE
    assert parse_mcq(REFUSAL).status is ParseStatus.FORMAT_COLLAPSE


def test_frame_id_is_never_read(renderer: FrameRenderer) -> None:
    vlm = sim_vlm()
    a = renderer.render(-0.5, frame_id="x=-0.50")
    b = renderer.render(-0.5, frame_id="x=0.40")  # a lying tag must change nothing
    for kind in PromptKind:
        assert vlm.answer(PROMPTS[kind], a) == vlm.answer(PROMPTS[kind], b)


@pytest.mark.parametrize("x", np.round(np.linspace(-1.15, 0.55, 12), 3).tolist())
def test_noise_free_estimate_is_within_one_patch(renderer: FrameRenderer, x: float) -> None:
    vlm = sim_vlm(EXACT)
    frame = renderer.render(x)
    parsed = parse_float(vlm.answer(PROMPTS[PromptKind.FLOAT], frame))
    assert parsed.status is ParseStatus.OK and parsed.value is not None
    assert abs(parsed.value - x) <= EXACT.patch_px / geometry.SCALE
    box = parse_box(vlm.answer(PROMPTS[PromptKind.BOX], frame))
    assert box.status is ParseStatus.OK


def test_wheel_column_tracks_the_car(renderer: FrameRenderer) -> None:
    for x in (-1.0, -0.5, 0.0, 0.4):
        column = wheel_column(renderer.render(x).pixels)
        assert column is not None
        assert abs(column - (x - geometry.MIN_POSITION) * geometry.SCALE) <= 3


def test_same_inputs_same_answer_and_seed_matters(renderer: FrameRenderer) -> None:
    frame = renderer.render(-0.3)
    a, b = sim_vlm(SimKnobs(seed=1)), sim_vlm(SimKnobs(seed=1))
    answers = [a.answer(PROMPTS[k], frame) for k in PromptKind]
    assert answers == [b.answer(PROMPTS[k], frame) for k in PromptKind]
    others = {sim_vlm(SimKnobs(seed=s)).answer(PROMPTS[PromptKind.FLOAT], frame) for s in range(8)}
    assert len(others) > 1


def test_model_name_changes_with_answer_shaping_knobs() -> None:
    assert sim_vlm(SimKnobs(seed=0)).model != sim_vlm(SimKnobs(seed=1)).model
    assert sim_vlm(SimKnobs()).model == sim_vlm(SimKnobs(latency_s=0.5)).model


def test_box_failure_one_always_collapses(renderer: FrameRenderer) -> None:
    vlm = sim_vlm(SimKnobs(box_failure=1.0))
    assert parse_box(vlm.answer(PROMPTS[PromptKind.BOX], renderer.render(-0.4))).status is (
        ParseStatus.FORMAT_COLLAPSE)


def test_flicker_gives_a_neighbouring_label(renderer: FrameRenderer) -> None:
    frame = renderer.render(-0.5)
    labels = {parse_mcq(sim_vlm(SimKnobs(flicker=1.0, seed=s)).answer(PROMPTS[PromptKind.MCQ], frame)).label
              for s in range(20)}
    assert labels <= {geometry.Zone.LEFT_SLOPE, geometry.Zone.RIGHT_SLOPE}


@pytest.mark.parametrize("knobs", [SimKnobs(flicker=1.5), SimKnobs(patch_px=0), SimKnobs(float_noise=-1)])
def test_rejects_bad_knobs(knobs: SimKnobs) -> None:
    with pytest.raises(ValueError):
        sim_vlm(knobs)


def test_is_fast(renderer: FrameRenderer) -> None:
    vlm = sim_vlm()
    frame = renderer.render(-0.2)
    start = time.perf_counter()
    for _ in range(50):
        for kind in PromptKind:
            vlm.answer(PROMPTS[kind], frame)
    per_call = (time.perf_counter() - start) / 150
    assert per_call < 0.01  # budget is 2 ms; loose bound so a loaded CI machine does not flake


def test_default_profile_is_todays_knobs_and_keeps_its_digest() -> None:
    from vlmrl_cli.tasks.mountain_car import MOUNTAIN_CAR
    from vlmrl_cli.vlm.config import sim_profiles
    from vlmrl_cli.vlm.sim import knobs_digest

    assert SimKnobs.of_profile("default") == SimKnobs()
    assert (SimKnobs().flicker, SimKnobs().float_noise, SimKnobs().box_noise_px, SimKnobs().box_failure,
            SimKnobs().patch_px) == (0.1, 0.25, 20.0, 0.2, 28)
    assert knobs_digest(SimKnobs()) == "144d03c0"  # the digest before profiles existed: cached answers stay valid
    offered = sim_profiles(MOUNTAIN_CAR)
    digests = {knobs_digest(SimKnobs.of_profile(name, MOUNTAIN_CAR)) for name in offered}
    assert len(digests) == len(offered) == 3
    # llava-table1's digest (so its cached answers) as when the profile lived in vlm/config.py
    assert knobs_digest(SimKnobs.of_profile("llava-table1", MOUNTAIN_CAR)) == "042db052"


def test_explicit_knobs_beat_the_profile_and_unknown_profiles_fail() -> None:
    from vlmrl_cli.tasks.mountain_car import MOUNTAIN_CAR

    knobs = SimKnobs.of_profile("llava-table1", MOUNTAIN_CAR, flicker=0.3)
    assert knobs.flicker == 0.3 and knobs.float_anchor == 0.38 and knobs.profile == "llava-table1"
    with pytest.raises(ValueError, match="choose from ideal, default, llava-table1"):
        SimKnobs.of_profile("lava", MOUNTAIN_CAR)
    with pytest.raises(ValueError, match=r"choose from ideal, default\.$"):  # a task's own profile needs its task
        SimKnobs.of_profile("llava-table1")
    with pytest.raises(ValueError, match="a simulated-VLM profile is a name"):
        SimKnobs(profile="")


def test_widened_bottom_zone_and_anchors(renderer: FrameRenderer) -> None:
    from vlmrl_cli.tasks.mountain_car import MOUNTAIN_CAR

    vlm = sim_vlm(SimKnobs.of_profile("llava-table1", MOUNTAIN_CAR))
    for x in (-0.69, -0.5, -0.3):
        frame = renderer.render(x)
        assert parse_mcq(vlm.answer(PROMPTS[PromptKind.MCQ], frame)).label == geometry.Zone.BOTTOM
        value = parse_float(vlm.answer(PROMPTS[PromptKind.FLOAT], frame)).value
        assert value is not None and abs(value - 0.38) < 0.03
    assert parse_mcq(vlm.answer(PROMPTS[PromptKind.MCQ], renderer.render(0.55))).label == geometry.Zone.GOAL


def test_query_flicker_zero_keeps_the_deterministic_answers_and_model_name(renderer: FrameRenderer) -> None:
    frame = renderer.render(-0.45)
    plain, zero = sim_vlm(SimKnobs()), sim_vlm(SimKnobs(query_flicker=0.0), stream=7)
    assert not zero.stochastic and zero.model == plain.model
    prompt = PROMPTS[PromptKind.MCQ]
    assert [zero.answer(prompt, frame) for _ in range(5)] == [plain.answer(prompt, frame)] * 5


def test_query_flicker_draws_afresh_per_query_and_reproduces_per_stream(renderer: FrameRenderer) -> None:
    frame = renderer.render(-0.5)  # BOTTOM: both neighbours exist
    prompt = PROMPTS[PromptKind.MCQ]
    knobs = SimKnobs(flicker=0.0, query_flicker=0.5)

    def labels(stream: int) -> list[str | None]:
        vlm = sim_vlm(knobs, stream=stream)
        assert vlm.stochastic
        return [parse_mcq(vlm.answer(prompt, frame)).label for _ in range(200)]

    first = labels(0)
    assert set(first) == {geometry.Zone.LEFT_SLOPE, geometry.Zone.BOTTOM, geometry.Zone.RIGHT_SLOPE}
    assert 0.4 < first.count(geometry.Zone.BOTTOM) / 200 < 0.6  # P(kept) = 1 - 0.5
    assert labels(0) == first and labels(1) != first


def test_a_stochastic_backend_is_never_cached(tmp_path) -> None:
    from vlmrl_cli.vlm.config import VLMConfig
    from vlmrl_cli.vlm.registry import build_client

    client = build_client(VLMConfig(cache_path=tmp_path / "c.sqlite", sim=SimKnobs(query_flicker=0.3)), stream=1,
                          reader=WheelReader())
    try:
        assert client.stochastic and client.cache is None
    finally:
        client.close()
    steady = build_client(VLMConfig(cache_path=tmp_path / "c.sqlite"), reader=WheelReader())
    try:
        assert not steady.stochastic and steady.cache is not None
    finally:
        steady.close()


class _TwoLabels:
    """A task reader for the test: LEFT when the car is left of the valley, else RIGHT."""

    name = "two"
    milestones = Milestones(("LEFT", "RIGHT"), mcq_prompt("Where is the car?", ("LEFT", "RIGHT")))

    def read(self, pixels: np.ndarray) -> str | None:
        column = wheel_column(pixels)
        return None if column is None else ("LEFT" if column < 200 else "RIGHT")


def test_a_task_reader_answers_its_own_labels_with_flicker_and_no_numbers() -> None:
    reader = _TwoLabels()
    with FrameRenderer() as renderer:
        left, right = renderer.render(-1.0), renderer.render(0.3)
    steady = sim_vlm(SimKnobs(flicker=0.0), reader=reader)
    assert steady.model.startswith("pixel-reader-v1-two/") and steady.simulated
    prompt = reader.milestones.prompt
    assert parse_mcq(steady.answer(prompt, left), reader.milestones.labels).label == "LEFT"
    assert parse_mcq(steady.answer(prompt, right), reader.milestones.labels).label == "RIGHT"
    assert parse_float(steady.answer(PROMPTS[PromptKind.FLOAT], left)).value is None  # MCQ only
    blank = Frame.from_pixels(np.full((400, 600, 3), 255, dtype=np.uint8))
    assert steady.answer(prompt, blank) == TASK_REFUSAL
    noisy = sim_vlm(SimKnobs(flicker=1.0), reader=reader)  # every answer moves to the neighbour
    assert parse_mcq(noisy.answer(prompt, left), reader.milestones.labels).label == "RIGHT"
    assert sim_vlm(SimKnobs()).model != steady.model  # cached answers never mix

"""``training.session``: a hybrid run's labelling rounds against a real (loopback) OpenAI-compatible
server: eight requests in flight against one, the same labels, several times less VLM wall time."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import pytest

from tests.vlm.fake_openai import FakeServer, mcq_by_image
from vlmrl_cli.shaping.config import ShapingConfig
from vlmrl_cli.tasks.mountain_car.prompts import PROMPTS
from vlmrl_cli.tasks.registry import get_task
from vlmrl_cli.training.callbacks import EpisodeTracker
from vlmrl_cli.training.config import RunConfig
from vlmrl_cli.training.presets import preset_of
from vlmrl_cli.training.session import session
from vlmrl_cli.vlm.config import VLMConfig
from vlmrl_cli.vlm.prompts import PromptKind

# per request, as a served 7B VLM's round trip is a few hundred ms; the client's own work per frame (PNG,
# base64, JSON, ~15 ms on a busy 2-core machine) runs one frame at a time and caps the speedup below 8
LATENCY_S = 0.4
LABELS = PROMPTS[PromptKind.MCQ].options or ()


def _hybrid(url: str, concurrency: int, transcript: Path) -> tuple[dict[str, float], list[str]]:
    """A smoke hybrid (8 envs, 1,024 steps) asking the loopback server with ``concurrency`` requests in
    flight: its VLM figures and the labels of its transcript, in order."""
    ppo = dataclasses.replace(preset_of(get_task("mountain-car"), "smoke"), n_envs=8, n_steps=64, batch_size=64)
    vlm = VLMConfig(backend="openai", model="m", base_url=url, use_cache=False, max_concurrency=concurrency,
                    mcq_mode="generate", retries=0, timeout_s=10.0)
    # a label every 16 steps and no reuse within a radius: each round's 8 frames are mostly new
    shaping = ShapingConfig(query_every=16, reuse_radius=0.0)
    job = RunConfig(arms=("hybrid",), seeds=(0,), preset="smoke", ppo=ppo, vlm=vlm, shaping=shaping,
                    workers=1).jobs()[0]
    with session(job, transcript=transcript) as built:
        assert built.oracle is not None
        built.model.learn(total_timesteps=job.timesteps, callback=EpisodeTracker(job.name, job.timesteps))
        stats = built.oracle.stats()
    labels = [json.loads(line)["answer"] for line in transcript.read_text().splitlines()]
    return stats, labels


@pytest.mark.slow
def test_a_round_of_eight_in_flight_takes_a_fraction_of_the_vlm_time_and_gives_the_same_labels(
        tmp_path: Path) -> None:
    with FakeServer(chat=mcq_by_image(LABELS, latency_s=LATENCY_S)) as server:
        one, one_labels = _hybrid(server.url, 1, tmp_path / "one.jsonl")
        eight, eight_labels = _hybrid(server.url, 8, tmp_path / "eight.jsonl")
    speedup = one["vlm/backend_s"] / eight["vlm/backend_s"]
    print(f"\nhybrid smoke, 8 envs, {LATENCY_S * 1000:.0f} ms a request: {int(one['vlm/backend_frames'])} frames in "
          f"{int(one['vlm/backend_calls'])} rounds (largest {int(one['vlm/largest_batch'])}); VLM wall time "
          f"{one['vlm/backend_s']:.2f} s with 1 in flight, {eight['vlm/backend_s']:.2f} s with 8: {speedup:.1f}x")
    assert one_labels == eight_labels and len(set(one_labels)) > 1
    assert one["vlm/backend_frames"] == eight["vlm/backend_frames"] and one["vlm/largest_batch"] >= 6
    # one at a time would give about 1x; an idle 2-core machine measures about 5x, a loaded one 4x: the
    # bar asks that the requests overlap, not for a figure (benchmarks/bench_vlm.py measures that)
    assert speedup >= 2.5


def test_the_block_closes_the_env_stack_and_with_it_a_cameras_renderer() -> None:
    """A Pusher hybrid's MuJoCo renderer is closed when the session ends, not at the interpreter's exit
    (where it outlived its EGL display and printed two tracebacks after `vlmrl verify`)."""
    from vlmrl_cli.tasks import pusher

    if pusher.gl_problem() is not None:
        pytest.skip(pusher.gl_problem() or "")
    ppo = dataclasses.replace(preset_of(get_task("pusher"), "smoke"), timesteps=64, n_envs=2, n_steps=32,
                              batch_size=64)
    job = RunConfig(task="pusher", plugin=get_task("pusher"), arms=("hybrid",), seeds=(0,), preset="smoke",
                    ppo=ppo, workers=1).jobs()[0]
    with session(job) as built:
        built.model.learn(total_timesteps=job.timesteps)
        cameras = built.env.get_attr("camera")
        assert any(c._renderer is not None for c in cameras)  # it drew frames
    assert all(c._renderer is None for c in cameras)

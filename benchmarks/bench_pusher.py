"""Performance figures of the Pusher task (issue 54). Prints measurements; not a test.

Trains each arm in-process (one torch thread, no MLflow, the simulated VLM) for ``--timesteps``
steps with the ``pusher`` preset (8 envs, n_steps 256, batch 64, 10 epochs, VecNormalize) and
prints, per arm: steps per CPU-second and per wall-second; for the VLM arms the render share (CPU
time inside the camera's renderer over the run's CPU time), the reader's share (the simulated
VLM answering) and the RBF field's (smoothing the labels over the prototypes), the camera's
renders and cells, the VLM's queries and prototype label reuses;
each count also per 100,000 steps, scaled linearly from the measured run (so a count that grows
faster than linearly, like the RBF field's cost per new frame, is underestimated: the steps per
CPU-second of the run's first and second halves are printed to show it). Last, the CPU time a
300,000-step run would take at the measured rate (the same linear scaling).

Usage: python benchmarks/bench_pusher.py [--timesteps 20480] [--arms kinematic,hybrid] [--seed 0]
"""

from __future__ import annotations

from vlmrl_cli.core.numeric_pin import apply as pin_numeric_path

pin_numeric_path()  # before torch and numpy load: the kernels every run of vlmrl computes with

import argparse
import contextlib
import dataclasses
import functools
import os
import time
from collections.abc import Callable
from typing import Any
from unittest import mock

os.environ.setdefault("MUJOCO_GL", "egl")  # as vlmrl's entry point: before mujoco is imported

import torch
from stable_baselines3.common.callbacks import BaseCallback

from vlmrl_cli.core.provenance import package_versions
from vlmrl_cli.shaping.arms import ARMS
from vlmrl_cli.shaping.rbf import RBFField
from vlmrl_cli.tasks.registry import get_task
from vlmrl_cli.tracking import schema
from vlmrl_cli.training.envs import make_train_env
from vlmrl_cli.training.model import make_model
from vlmrl_cli.training.presets import preset_of
from vlmrl_cli.vlm.config import VLMConfig
from vlmrl_cli.vlm.registry import build_client

PER = 100_000
FULL_RUN = 300_000


class Clock(BaseCallback):  # type: ignore[misc]
    """(steps, CPU seconds) at the end of every rollout."""

    def __init__(self) -> None:
        super().__init__()
        self.marks: list[tuple[int, float]] = []

    def _on_step(self) -> bool:
        return True

    def _on_rollout_end(self) -> None:
        self.marks.append((self.num_timesteps, time.process_time()))


def timed(fn: Callable[..., Any], spent: list[float]) -> Callable[..., Any]:
    """``fn``, adding the CPU time of each call to ``spent[0]``."""

    @functools.wraps(fn)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        start = time.process_time()
        try:
            return fn(*args, **kwargs)
        finally:
            spent[0] += time.process_time() - start

    return wrapper


def measure(arm_name: str, timesteps: int, seed: int) -> dict[str, Any]:
    task = get_task("pusher")
    arm = ARMS[arm_name]
    ppo = dataclasses.replace(preset_of(task, "pusher"), timesteps=timesteps)
    client = build_client(VLMConfig(backend="sim", use_cache=False), reader=task.reader) if arm.uses_vlm else None
    render, read, rbf = [0.0], [0.0], [0.0]
    with contextlib.ExitStack() as patched:  # the class's methods, for this run only (envs look ``value`` up once)
        for name in ("value", "add_prototype", "set_potential"):
            patched.enter_context(mock.patch.object(RBFField, name, timed(getattr(RBFField, name), rbf)))
        start, cpu_start = time.perf_counter(), time.process_time()
        env, oracle = make_train_env(arm, ppo, task.default_shaping(), client, seed, task)
        camera = env.get_attr("camera", [0])[0] if arm.uses_vlm else None
        if camera is not None:
            camera._draw = timed(camera._draw, render)  # type: ignore[method-assign]
        if client is not None:  # one frame at a time, or a round's frames at once
            client.ask = timed(client.ask, read)  # type: ignore[method-assign]
            client.ask_many = timed(client.ask_many, read)  # type: ignore[method-assign]
        model = make_model(ppo, env, seed)
        clock = Clock()
        model.learn(total_timesteps=timesteps, callback=clock)
        wall, cpu = time.perf_counter() - start, time.process_time() - cpu_start
    env.close()
    stats = oracle.stats() if oracle is not None else {}
    return {"arm": arm_name, "steps": model.num_timesteps, "wall": wall, "cpu": cpu, "render": render[0],
            "read": read[0], "rbf": rbf[0], "renders": camera.renders if camera else 0,
            "cells": camera.cells if camera else 0,
            "stats": stats, "marks": [(0, cpu_start), *clock.marks]}


def halves(marks: list[tuple[int, float]]) -> tuple[float, float]:
    """Steps per CPU-second over the first and the second half of the run's rollouts."""
    mid = len(marks) // 2
    (s0, t0), (s1, t1), (s2, t2) = marks[0], marks[mid], marks[-1]
    return (s1 - s0) / (t1 - t0), (s2 - s1) / (t2 - t1)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--timesteps", type=int, default=20_480)
    parser.add_argument("--arms", default="kinematic,hybrid")
    parser.add_argument("--seed", type=int, default=0)
    opts = parser.parse_args()
    torch.set_num_threads(1)
    versions = package_versions()
    print(f"Pusher benchmark: preset pusher, {opts.timesteps:,} steps per arm, seed {opts.seed}, 1 torch thread, "
          f"MUJOCO_GL={os.environ.get('MUJOCO_GL')}, mujoco {versions['mujoco']}, Mesa {versions['mesa']}; "
          "counts per 100k steps scaled linearly from the run")
    for arm in opts.arms.split(","):
        run = measure(arm, opts.timesteps, opts.seed)
        steps, cpu = run["steps"], run["cpu"]
        scale = PER / steps
        first, second = halves(run["marks"])
        line = (f"{arm}: {steps:,} steps in {cpu:.1f} CPU-s ({steps / cpu:.0f} steps/CPU-s; "
                f"{steps / run['wall']:.0f} steps/wall-s); first half {first:.0f}, second half {second:.0f} "
                "steps/CPU-s")
        if run["stats"]:
            queries = run["stats"][schema.METRIC_VLM_QUERIES]
            reuses = run["stats"][schema.METRIC_VLM_LABEL_REUSES]
            line += (f"; render share {run['render'] / cpu:.1%} ({run['renders']:,} renders, {run['cells']:,} cells), "
                     f"reader share {run['read'] / cpu:.1%}, RBF field share {run['rbf'] / cpu:.1%}; "
                     f"per 100k steps: {queries * scale:,.0f} VLM queries, "
                     f"{reuses * scale:,.0f} prototype reuses, {run['renders'] * scale:,.0f} renders")
        line += f"; a {FULL_RUN:,}-step run at this rate: {FULL_RUN / steps * cpu / 60:.1f} CPU-min"
        print(line, flush=True)


if __name__ == "__main__":
    main()

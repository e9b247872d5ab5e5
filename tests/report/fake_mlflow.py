"""A fake ``vlmrl run`` experiment in a temporary sqlite MLflow store, following the tracking contract.

Episode ``i`` (0-based) of every run ends at global step ``1000 * (i + 1)``; returns are -200
until episode ``k`` and then ``plateau``. With a rolling window of 20, the mean after ``j``
plateau episodes is ``-200 + j * (200 + plateau) / 20``, so steps to each threshold are easy
to compute by hand (see ``EXPECTED``).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
from mlflow.entities import Metric, Param
from mlflow.tracking import MlflowClient

WINDOW = 20
N_EPISODES = 80
BUDGET = 1000 * N_EPISODES
VLM = "sim:pixel-reader-v1 (SIMULATED VLM, not a real model)"


@dataclass(frozen=True)
class FakeRun:
    arm: str
    seed: int
    k: int  # first episode at the plateau
    plateau: float
    eval_success: float
    eval_length: float
    status: str = "FINISHED"
    per_episode_eval: bool = False
    hover: float | None = None  # eval/hover_fraction, logged by runs since the hovering diagnostic


HYBRID = [FakeRun("hybrid", s, k, -100.0, 1.0, length, per_episode_eval=True)
          for s, k, length in [(0, 20, 120.0), (1, 25, 125.0), (2, 30, 130.0)]]
BASELINE = [FakeRun("baseline", 0, 30, -100.0, 1.0, 150.0), FakeRun("baseline", 1, 40, -100.0, 1.0, 160.0),
            FakeRun("baseline", 2, 35, -150.0, 0.0, 200.0)]
# runs that must be ignored: an older finished duplicate and a failed run
STALE = FakeRun("hybrid", 0, 60, -150.0, 0.0, 200.0)
FAILED = FakeRun("baseline", 0, 10, -100.0, 1.0, 110.0, status="FAILED")

# Steps to -190 / -160 / -130 per seed, by hand from the formula in the module docstring.
EXPECTED: dict[str, dict[int, list[int | None]]] = {
    "hybrid": {-190: [22000, 27000, 32000], -160: [28000, 33000, 38000], -130: [34000, 39000, 44000]},
    "baseline": {-190: [32000, 42000, 39000], -160: [38000, 48000, 51000], -130: [44000, 54000, None]},
}


def _episode_returns(run: FakeRun) -> np.ndarray:
    return np.where(np.arange(N_EPISODES) < run.k, -200.0, run.plateau)


def _log(client: MlflowClient, exp_id: str, parent: str, run: FakeRun) -> str:
    tags = {
        "mlflow.parentRunId": parent, "vlmrl.kind": "train", "vlmrl.arm": run.arm, "vlmrl.seed": str(run.seed),
        "vlmrl.config_hash": f"cfg-{run.arm}", "vlmrl.vlm": VLM, "vlmrl.simulated": "true", "vlmrl.preset": "fake",
    }
    r = client.create_run(exp_id, tags=tags, run_name=f"{run.arm}-s{run.seed}")
    rid = r.info.run_id
    returns = _episode_returns(run)
    metrics = []
    for i, ret in enumerate(returns):
        step = 1000 * (i + 1)
        metrics += [Metric("episode/native_return", float(ret), i, step),
                    Metric("episode/length", float(-ret), i, step),
                    Metric("episode/success", float(ret > -200), i, step),
                    Metric("episode/shaped_return", float(ret + 50), i, step)]
    metrics += [Metric("eval/success_rate", run.eval_success, 0, BUDGET),
                Metric("eval/mean_length", run.eval_length, 0, BUDGET),
                Metric("eval/mean_return", -run.eval_length, 0, BUDGET)]
    if run.hover is not None:
        metrics += [Metric("eval/hover_fraction", run.hover, 0, BUDGET),
                    Metric("eval/dwell_right_steps", 200 * run.hover, 0, BUDGET)]
    if run.per_episode_eval:
        lengths = run.eval_length + np.array([-2.0, -1.0, 0.0, 1.0, 2.0])
        metrics += [Metric("eval/episode_length", float(v), 0, e) for e, v in enumerate(lengths)]
    for i in range(0, len(metrics), 1000):
        client.log_batch(rid, metrics=metrics[i : i + 1000])
    client.log_batch(rid, params=[Param("timesteps", str(BUDGET)), Param("ppo.gamma", "0.99")])
    client.set_terminated(rid, status=run.status)
    time.sleep(0.01)  # distinct end times
    return rid


# Every seed of every arm succeeds (5/5 vs 5/5); the kinematic arm hovers in detached evaluation.
ALL_SUCCEED = [FakeRun(arm, s, 20 + 2 * s + shift, -100.0, 1.0, 120.0 + s, per_episode_eval=True, hover=hover)
               for arm, shift, hover in [("hybrid", 0, 0.0), ("baseline", 20, 0.0), ("kinematic", 10, 0.4)]
               for s in range(5)]


def build_fake_experiment(uri: str, name: str, arms: tuple[str, ...] = ("hybrid", "baseline"),
                          runs: list[FakeRun] | None = None) -> dict[str, str]:
    """Create experiment ``name`` at ``uri`` from ``runs`` (default: ``HYBRID`` and ``BASELINE`` with a stale
    duplicate and a failed run); returns {"arm-seed": run_id} of the runs a report must use."""
    client = MlflowClient(tracking_uri=uri)
    exp_id = client.create_experiment(name)
    parent = client.create_run(exp_id, tags={"vlmrl.kind": "sweep"}).info.run_id
    if runs is None:
        _log(client, exp_id, parent, STALE)  # older duplicate of hybrid seed 0
    kept: dict[str, str] = {}
    for run in runs if runs is not None else [*HYBRID, *BASELINE]:
        if run.arm in arms:
            kept[f"{run.arm}-{run.seed}"] = _log(client, exp_id, parent, run)
    if runs is None:
        _log(client, exp_id, parent, FAILED)
    client.set_terminated(parent)
    return kept

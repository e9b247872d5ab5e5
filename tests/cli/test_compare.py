"""`vlmrl compare` on small synthetic export files (the format of ``tracking.transfer``)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy import stats as sps
from typer.testing import CliRunner

from vlmrl_cli.cli.app import app
from vlmrl_cli.cli.compare import NORMALISE_CHOICES
from vlmrl_cli.report.compare import NORMALISATIONS
from vlmrl_cli.tracking.transfer import FORMAT, write_records

runner = CliRunner()

# task -> arm -> detached evaluation scores of its runs; kinematic is on mountain-car only
SCORES = {
    "mountain-car": {"baseline": [-150.0, -130.0], "hybrid": [-120.0, -100.0], "kinematic": [-125.0, -115.0]},
    "acrobot": {"baseline": [-100.0, -90.0, -80.0], "hybrid": [-85.0, -75.0]},
}


def _record(task: str | None, arm: str, seed: int, score: float, config_hash: str = "") -> dict[str, object]:
    tags = {"vlmrl.kind": "train", "vlmrl.arm": arm, "vlmrl.seed": str(seed),
            "vlmrl.config_hash": config_hash or f"{task}-{arm}-hash",
            "vlmrl.simulated": "true" if arm == "hybrid" else "false"}
    if task is not None:  # runs from before tasks carry no task tag: mountain-car
        tags["vlmrl.task"] = task
    return {"format": FORMAT, "source_run_id": f"{task}-{arm}-{seed}-{config_hash}", "run_name": f"{arm}-s{seed}",
            "start_time": 0, "end_time": 1, "tags": tags, "params": {},
            "latest": {"eval/mean_return": [0, 1, score], "eval/success_rate": [0, 1, 1.0]},
            "histories": {"episode/native_return": {"step": [1], "ts": [1], "value": [score]}}, "artifacts": {},
            "binary": {}}


def _write(path: Path, records: Sequence[dict[str, object]]) -> Path:
    write_records(path, records)
    return path


def _files(tmp_path: Path, scores: dict[str, dict[str, list[float]]] = SCORES) -> list[str]:
    # one file per task, as `vlmrl export` of one study per task writes them
    return [str(_write(tmp_path / f"{task}.jsonl.gz",
                       [_record(None if task == "mountain-car" else task, arm, seed, s)
                        for arm, values in arms.items() for seed, s in enumerate(values)]))
            for task, arms in scores.items()]


def _compare(*args: str):
    return runner.invoke(app, ["compare", *args, "--n-boot", "200"])


def test_compare_writes_every_output_with_hand_computed_scores(tmp_path: Path) -> None:
    out = tmp_path / "cmp"
    res = _compare(*_files(tmp_path), "--out", str(out), "--normalise", "baseline-best")
    assert res.exit_code == 0, res.output
    assert "left out: kinematic (missing on acrobot)" in res.output and "SIMULATED VLM" in res.output
    assert "ANCHORS ESTIMATED FROM THE DATA" in res.output
    per_task = pd.read_csv(out / "per_task.csv")
    # baseline-best: mountain-car 0 at the baseline mean -140, 1 at hybrid's -110; acrobot -90 and -80
    hybrid = per_task[per_task["arm"] == "hybrid"].sort_values(["task", "seed"])
    assert hybrid["normalised"].tolist() == pytest.approx([0.5, 1.5, 2 / 3, 4 / 3])
    assert set(per_task["arm"]) == {"baseline", "hybrid"} and (per_task["vlm"].str.contains("SIMULATED VLM")).all()
    table = pd.read_csv(out / "aggregate.csv").set_index("arm")
    assert table.loc["hybrid", "iqm"] == pytest.approx(float(sps.trim_mean([0.5, 1.5, 2 / 3, 4 / 3], 0.25)))
    assert table.loc["hybrid", "mean"] == pytest.approx(np.mean([1.0, 1.0]))
    assert table.loc["baseline", "mean"] == pytest.approx(0.0)
    # mountain-car: every hybrid run beats every baseline run (1); acrobot: -85 beats 2 of 3, -75 all 3 (5/6)
    poi = table.loc["hybrid", ["poi_over_baseline_low", "poi_over_baseline", "poi_over_baseline_high"]].tolist()
    assert poi[1] == pytest.approx((1 + 5 / 6) / 2) and poi[0] <= poi[1] <= poi[2] <= 1.0
    assert table.loc["hybrid", "iqm_low"] <= table.loc["hybrid", "iqm"] <= table.loc["hybrid", "iqm_high"]
    assert table.loc["hybrid", "tasks"] == 2 and table.loc["hybrid", "runs"] == 4
    assert (table["vlm"].str.contains("SIMULATED VLM")).all() and (table["normalisation"] == "baseline-best").all()
    md = (out / "aggregate.md").read_text(encoding="utf-8")
    assert "SIMULATED VLM" in md and "baseline-best" in md and "kinematic (missing on acrobot)" in md
    assert md.index("ANCHORS ESTIMATED FROM THE DATA") < md.index("## Aggregates")
    assert (out / "performance_profile.png").stat().st_size > 0


def test_the_default_normalisation_runs_from_the_random_policy_to_the_zoo(tmp_path: Path) -> None:
    out = tmp_path / "fixed"
    res = _compare(*_files(tmp_path), "--out", str(out))
    assert res.exit_code == 0, res.output
    per_task = pd.read_csv(out / "per_task.csv")
    pairs = per_task.drop_duplicates("task").set_index("task")
    assert pairs.loc["mountain-car", ["lo", "hi"]].tolist() == [-200.0, -110.423]
    assert pairs.loc["acrobot", ["lo", "hi"]].tolist() == [-497.37, -73.506]
    row = per_task[(per_task["task"] == "mountain-car") & (per_task["arm"] == "baseline") & (per_task["seed"] == 0)]
    assert row["normalised"].item() == pytest.approx((-150.0 + 200.0) / (-110.423 + 200.0))
    md = (out / "aggregate.md").read_text(encoding="utf-8")
    assert "rl-baselines3-zoo" in md and "random policy (200 episodes from seed 0" in md
    assert "ANCHORS ESTIMATED" not in md and "ANCHORS ESTIMATED" not in res.output
    assert "0 = -497.4 (random policy" in res.output and "1 = -73.51 (zoo PPO Acrobot-v1" in res.output


def test_adding_or_removing_an_arm_leaves_every_other_arms_scores_unchanged(tmp_path: Path) -> None:
    # issue 51: fixed anchors, so no arm's normalised score depends on which other arms are compared
    more = {t: {**arms, "semantic": [max(arms["baseline"]) + 40.0, max(arms["baseline"]) + 50.0]}
            for t, arms in SCORES.items()}
    fewer = {t: {a: v for a, v in arms.items() if a != "kinematic"} for t, arms in SCORES.items()}
    outs = {}
    for name, scores in (("same", SCORES), ("more", more), ("fewer", fewer)):
        (tmp_path / name).mkdir()
        out = tmp_path / name / "cmp"
        assert _compare(*_files(tmp_path / name, scores), "--out", str(out)).exit_code == 0
        outs[name] = pd.read_csv(out / "per_task.csv").set_index(["task", "arm", "seed"])["normalised"]
    for name in ("more", "fewer"):
        shared = outs["same"].index.intersection(outs[name].index)
        assert len(shared) == len(outs["same"])
        pd.testing.assert_series_equal(outs[name].loc[shared], outs["same"].loc[shared])
    # the estimated anchors do move: the new best arm on each task rescales the others
    for name, scores in (("same", SCORES), ("more", more)):
        out = tmp_path / name / "est"
        assert _compare(*_files(tmp_path / name, scores), "--out", str(out), "--normalise",
                        "baseline-best").exit_code == 0
    same, moved = (pd.read_csv(tmp_path / n / "est" / "per_task.csv").set_index(["task", "arm", "seed"])["normalised"]
                   for n in ("same", "more"))
    assert not np.allclose(same.loc[("acrobot", "hybrid")], moved.loc[("acrobot", "hybrid")])


def test_a_task_without_a_baseline_is_refused_in_one_line(tmp_path: Path) -> None:
    scores = {**SCORES, "acrobot": {"hybrid": [-85.0, -75.0]}}
    res = _compare(*_files(tmp_path, scores), "--out", str(tmp_path / "x"))
    assert res.exit_code == 2
    assert res.output.strip().splitlines() == [res.output.strip()] and "task acrobot has no baseline arm" in res.output
    assert not (tmp_path / "x").exists()


def test_tied_configurations_are_refused_until_one_is_named(tmp_path: Path) -> None:
    files = _files(tmp_path)
    tagged = [_record(None, "baseline", s, -199.0, "otherconfig1") for s in (0, 1)]
    for r in tagged:
        r["tags"]["vlmrl.regime"] = "hard"  # type: ignore[index]
    other = _write(tmp_path / "other.jsonl.gz", tagged)
    res = _compare(*files, str(other), "--out", str(tmp_path / "tie"))
    assert res.exit_code == 2 and "--config-hash" in res.output
    assert "otherconfig1 (hard)" in res.output and "None-baseline-hash (no regime tag)" in res.output
    res = _compare(*files, str(other), "--out", str(tmp_path / "named"), "--config-hash", "otherconf")
    assert res.exit_code == 0, res.output
    per_task = pd.read_csv(tmp_path / "named" / "per_task.csv")
    assert set(per_task.loc[(per_task["task"] == "mountain-car") & (per_task["arm"] == "baseline"), "config_hash"]) \
        == {"otherconfig1"}
    res = _compare(*files, "--out", str(tmp_path / "typo"), "--config-hash", "nosuchhash")
    assert res.exit_code == 2 and "matches no run" in res.output


def test_a_configuration_left_out_is_said_in_one_line(tmp_path: Path) -> None:
    # the configuration with fewer runs was dropped without a word (issue 50)
    files = _files(tmp_path)
    other = _write(tmp_path / "other.jsonl.gz", [_record("acrobot", "baseline", 9, -199.0, "fewerruns1")])
    res = _compare(*files, str(other), "--out", str(tmp_path / "cmp"))
    assert res.exit_code == 0, res.output
    lines = [line for line in res.output.splitlines() if line.startswith("not compared:")]
    assert lines == ["not compared: 1 other configuration(s), the arm's configuration with the most runs kept (name "
                     "one with --config-hash): baseline on acrobot: fewerruns1 (1 run)"]
    assert "not compared" not in _compare(*files, "--out", str(tmp_path / "all")).output


def test_a_file_that_is_not_an_export_is_refused(tmp_path: Path) -> None:
    bad = tmp_path / "bad.jsonl.gz"
    _write(bad, [{"format": "something-else"}])
    res = _compare(str(bad), "--out", str(tmp_path / "o"))
    assert res.exit_code == 2 and "not a vlmrl run export" in res.output
    res = _compare(str(tmp_path / "missing.jsonl.gz"), "--out", str(tmp_path / "o"))
    assert res.exit_code == 2 and "no export file" in res.output


def test_the_cli_lists_the_libraries_normalisations() -> None:
    assert tuple(NORMALISATIONS) == NORMALISE_CHOICES


def test_a_run_two_exports_hold_counts_once(tmp_path: Path) -> None:
    """A study's and a calibration's export of one task both hold baseline seeds 0 and 1 (same config
    hash, different source runs): they count once, and the command says how many were dropped."""
    files = _files(tmp_path)
    calibration = _write(tmp_path / "acrobot-calibration.jsonl.gz",
                         [{**_record("acrobot", "baseline", seed, s), "source_run_id": f"calib-{seed}"}
                          for seed, s in enumerate([-100.0, -90.0])])
    out = tmp_path / "cmp"
    res = _compare(*files, str(calibration), "--out", str(out))
    assert res.exit_code == 0, res.output
    assert "counted once: 2 run(s)" in res.output
    per_task = pd.read_csv(out / "per_task.csv")
    base = per_task[(per_task["task"] == "acrobot") & (per_task["arm"] == "baseline")]
    assert sorted(base["seed"]) == [0, 1, 2]
    assert "2 run(s) held by a second file" in (out / "aggregate.md").read_text(encoding="utf-8")


def test_every_task_weighs_the_same_in_the_iqm(tmp_path: Path) -> None:
    """Acrobot's baseline with 6 runs (each of its 3 scores twice, other seeds) against mountain-car's 2:
    the aggregates are those of the 3-run export, not pulled towards acrobot."""
    doubled = {**SCORES, "acrobot": {**SCORES["acrobot"], "baseline": SCORES["acrobot"]["baseline"] * 2}}
    a, b = tmp_path / "a", tmp_path / "b"
    (a / "in").mkdir(parents=True)
    (b / "in").mkdir(parents=True)
    assert _compare(*_files(a / "in"), "--out", str(a / "cmp")).exit_code == 0
    assert _compare(*_files(b / "in", doubled), "--out", str(b / "cmp")).exit_code == 0
    one, two = (pd.read_csv(d / "cmp" / "aggregate.csv").set_index("arm") for d in (a, b))
    for col in ("iqm", "mean"):
        assert two.loc["baseline", col] == pytest.approx(one.loc["baseline", col], abs=1e-9)
    assert "every task weighs the same" in (b / "cmp" / "aggregate.md").read_text(encoding="utf-8")


def test_without_out_each_compare_writes_a_new_git_ignored_folder(tmp_path: Path,
                                                                  monkeypatch: pytest.MonkeyPatch) -> None:
    files = _files(tmp_path)
    monkeypatch.chdir(tmp_path)  # as if run from a checkout, whose results/compare/ is committed
    for _ in range(2):
        assert _compare(*files).exit_code == 0
    made = sorted((tmp_path / "results" / "_scratch" / "compare").iterdir())
    assert len(made) == 2 and all((m / "aggregate.md").is_file() for m in made)  # the second did not overwrite
    assert not (tmp_path / "results" / "compare").exists()
    root = Path(__file__).resolve().parents[2]
    assert "results/_scratch/" in (root / ".gitignore").read_text(encoding="utf-8").splitlines()

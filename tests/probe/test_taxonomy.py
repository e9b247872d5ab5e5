"""The probe end to end (library level): frames planned, answers scored, outputs staged."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from tests.mountain_car_helpers import sim_vlm
from vlmrl_cli.core.errors import BadInput
from vlmrl_cli.probe.scoring import frame_id_of, plan_frames, sweep_statistics, x_of_frame_id
from vlmrl_cli.probe.taxonomy import TaxonomyConfig, run_taxonomy
from vlmrl_cli.tasks.mountain_car.probe import NUMBER_PROBE
from vlmrl_cli.vlm.config import SimKnobs, VLMConfig
from vlmrl_cli.vlm.parsers import ParseStatus
from vlmrl_cli.vlm.replay import ReplayBackend


@pytest.fixture(scope="module")
def tracking_uri(tmp_path_factory: pytest.TempPathFactory) -> str:
    """One MLflow database for the module (creating one costs seconds); tests use own experiments."""
    return f"sqlite:///{tmp_path_factory.mktemp('mlflow')}/mlflow.db"


def _cfg(tmp_path: Path, **vlm: object) -> VLMConfig:
    return VLMConfig(cache_path=tmp_path / "cache.sqlite", **vlm)  # type: ignore[arg-type]


def test_frame_ids_round_trip() -> None:
    for x in (-0.5, -0.69, -1.125, 0.6, -1.2):
        assert x_of_frame_id(frame_id_of(x), NUMBER_PROBE) == pytest.approx(x)
    assert x_of_frame_id("frame-7", NUMBER_PROBE) is None and x_of_frame_id("x=5", NUMBER_PROBE) is None


def test_plan_always_includes_the_paper_frames() -> None:
    planned, is_sweep = plan_frames(5, sim_vlm(), NUMBER_PROBE)
    assert is_sweep and len(planned) == 7
    assert [p.panel for p in planned if p.panel] == ["b", "a"]  # sorted by x: -0.69 first
    xs = [p.x for p in planned]
    assert xs == sorted(xs)


def test_replay_without_states_probes_only_its_frames() -> None:
    backend = ReplayBackend.from_config(VLMConfig(backend="replay"))
    planned, is_sweep = plan_frames(None, backend, NUMBER_PROBE)
    assert not is_sweep and [p.frame_id for p in planned] == ["x=-0.69", "x=-0.50"]


def test_states_must_be_at_least_two(tmp_path: Path) -> None:
    with pytest.raises(BadInput):
        TaxonomyConfig(states=1, out=tmp_path)


def test_sim_run_writes_everything_and_one_finished_run(tmp_path: Path, tracking_uri: str) -> None:
    from mlflow.tracking import MlflowClient

    out = tmp_path / "out"
    uri = tracking_uri
    calls: list[tuple[int, int]] = []
    result = run_taxonomy(TaxonomyConfig(vlm=_cfg(tmp_path), states=4, out=out, tracking_uri=uri, experiment="e1"),
                          progress=lambda d, t: calls.append((d, t)))
    assert calls[-1] == (6, 6) and len(result.probes) == 6
    for name in ("table1.md", "table1.csv", "table1.tex", "figure1.png", "transcript.jsonl", "metrics.json"):
        assert (out / name).is_file()
    assert not list(tmp_path.glob(".out.partial-*"))
    summary = json.loads((out / "metrics.json").read_text())
    assert summary["simulated"] is True and summary["metrics"]["states"] == 6
    lines = (out / "transcript.jsonl").read_text().splitlines()
    assert len(lines) == 18
    client = MlflowClient(tracking_uri=uri)
    runs = client.search_runs([client.get_experiment_by_name("e1").experiment_id])  # type: ignore[union-attr]
    assert len(runs) == 1 and runs[0].info.status == "FINISHED"
    assert runs[0].data.tags["vlmrl.simulated"] == "true"
    assert "taxonomy.mcq.accuracy" in runs[0].data.metrics
    assert runs[0].data.params["backend"] == "sim"
    artifacts = {a.path for a in client.list_artifacts(runs[0].info.run_id)}
    assert {"table1.md", "figure1.png", "transcript.jsonl", "metrics.json"} <= artifacts

    again = run_taxonomy(TaxonomyConfig(vlm=_cfg(tmp_path), states=4, out=out, tracking_uri=uri, experiment="e1b"))
    assert again.cache_hits == 18 and again.cache_misses == 0
    assert [p.answers for p in again.probes] == [p.answers for p in result.probes]


def test_noise_free_sim_is_nearly_perfect(tmp_path: Path, tracking_uri: str) -> None:
    exact = SimKnobs(flicker=0.0, float_noise=0.0, box_noise_px=0.0, box_failure=0.0, patch_px=1)
    result = run_taxonomy(TaxonomyConfig(vlm=_cfg(tmp_path, sim=exact), states=12, out=tmp_path / "o",
                                         tracking_uri=tracking_uri, experiment="e2"))
    s = result.sweep
    assert s["float.spearman"] > 0.99 and s["float.mae_x"] < 0.02
    assert s["box.mean_iou"] > 0.7 and s["mcq.accuracy"] > 0.9
    assert s["mcq.dphi.sign_disagreement"] <= 0.1


def test_missing_replay_answers_become_no_answer(tmp_path: Path, tracking_uri: str) -> None:
    result = run_taxonomy(TaxonomyConfig(vlm=_cfg(tmp_path, backend="replay"), states=3, out=tmp_path / "o",
                                         tracking_uri=tracking_uri, experiment="e3"))
    unknown = [p for p in result.probes if p.panel is None]
    assert unknown and all(p.mcq_result.status is ParseStatus.NO_ANSWER for p in unknown)
    assert result.panel("a") is not None and result.panel("a").answers  # type: ignore[union-attr]


def test_sweep_statistics_of_nothing_are_nan() -> None:
    stats = sweep_statistics([])
    assert all(math.isnan(v) for k, v in stats.items() if k != "states" and not k.endswith("n_pairs"))


def test_bad_backend_leaves_nothing_and_no_run(tmp_path: Path) -> None:
    out = tmp_path / "out"
    with pytest.raises(BadInput):
        run_taxonomy(TaxonomyConfig(vlm=_cfg(tmp_path, backend="nonsense"), out=out,
                                    tracking_uri=f"sqlite:///{tmp_path}/m.db"))
    assert not out.exists() and not list(tmp_path.glob(".out.partial-*"))
    assert not (tmp_path / "m.db").exists()


def test_failure_mid_probe_marks_the_run_failed(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, tracking_uri: str
) -> None:
    from mlflow.tracking import MlflowClient

    import vlmrl_cli.probe.taxonomy as taxonomy

    def boom(*args: object, **kwargs: object) -> None:
        raise BadInput("the server went away; start it again.")

    monkeypatch.setattr(taxonomy, "probe_frame", boom)
    uri = tracking_uri
    with pytest.raises(BadInput):
        run_taxonomy(TaxonomyConfig(vlm=_cfg(tmp_path), states=2, out=tmp_path / "out", tracking_uri=uri,
                                    experiment="e4"))
    assert not (tmp_path / "out").exists()
    client = MlflowClient(tracking_uri=uri)
    runs = client.search_runs([client.get_experiment_by_name("e4").experiment_id])  # type: ignore[union-attr]
    assert [r.info.status for r in runs] == ["FAILED"]


@pytest.mark.slow  # builds the tiny LLaVA and probes six frames through it
def test_a_backend_that_scores_reports_the_mcq_both_ways(tmp_path: Path, tracking_uri: str) -> None:
    from mlflow.tracking import MlflowClient

    from tests.vlm.tiny_llava import build_tiny_llava

    model = build_tiny_llava(tmp_path / "llava", image_gain=30.0)
    vlm = VLMConfig(backend="hf", model=str(model), device="cpu", cache_path=None, max_new_tokens=8)
    out = tmp_path / "out"
    run_taxonomy(TaxonomyConfig(vlm=vlm, states=4, out=out, tracking_uri=tracking_uri, experiment="both"))
    summary = json.loads((out / "metrics.json").read_text())
    assert summary["mcq.mode"] == "logprob" and "MCQ by option log-probability" in summary["label"]
    assert summary["mcq.generate.format_failure_rate"] == 1.0  # the random model's decoded text is garbage
    assert summary["metrics"]["mcq.format_failure_rate"] == 0.0  # a scored answer is always a label
    records = [json.loads(line) for line in (out / "transcript.jsonl").read_text().splitlines()]
    assert sum("confidence" in r for r in records) == 6  # the six scored MCQs, not the generated ones
    client = MlflowClient(tracking_uri=tracking_uri)
    (run,) = client.search_runs([client.get_experiment_by_name("both").experiment_id])  # type: ignore[union-attr]
    assert run.data.metrics["taxonomy.mcq.modes_agree"] == 0.0

"""The study's grid: regimes from flags, file or defaults; VLM variants deduplicated by their knobs."""

from __future__ import annotations

import pytest

from vlmrl_cli.core.errors import BadInput
from vlmrl_cli.study.config import build_study, settings_of, study_section, task_regimes
from vlmrl_cli.tasks.registry import get_task


def test_the_default_regime_is_the_unreliable_calibrated_one() -> None:
    assert task_regimes(get_task("mountain-car")) == {"paper-unreliable": {"preset": "paper-unreliable"}}


def test_the_default_grid_has_the_placebo_the_dose_response_and_the_lock_test() -> None:
    cfg = build_study([], task_regimes(get_task("mountain-car")))
    assert cfg.base.seeds == tuple(range(20)) and "hybrid-shuffled" in cfg.base.arms
    doses = [c for c in cfg.cells if c.kind == "dose"]
    assert {(c.alpha, c.kin_scale) for c in doses if not c.placebo} == {
        (a, k) for a in (0.0, 5.0, 25.0, 100.0) for k in (0.0, 0.5, 2.0)}
    assert {(c.alpha, c.kin_scale) for c in doses if c.placebo} == {(100.0, 0.0), (100.0, 0.5), (100.0, 2.0)}
    main = {j.arm.name: j.config_hash for j in cfg.regimes[0].run.jobs() if j.seed == 0}

    def cell_hash(alpha: float, kin: float) -> str:
        (cell,) = [c for c in doses if (c.alpha, c.kin_scale) == (alpha, kin) and not c.placebo]
        return cell.regime.run.jobs()[0].config_hash

    # the corners are the ordinary arms, so their runs are shared, not trained twice
    assert cell_hash(0.0, 0.0) == main["baseline"] and cell_hash(0.0, 2.0) == main["kinematic"]
    assert cell_hash(5.0, 0.0) == main["semantic"] and cell_hash(5.0, 2.0) == main["hybrid"]
    flicker = [c for c in cfg.cells if c.kind == "query-flicker"]
    assert [(c.arm, c.query_flicker) for c in flicker] == [("hybrid", 0.3), ("hybrid-no-lock", 0.3)]
    assert all(c.regime.run.vlm.sim.query_flicker == 0.3 for c in flicker)


def test_file_regimes_and_variants() -> None:
    section = study_section({"regimes": {"a": "smoke", "b": {"preset": "smoke", "ppo": {"normalize_obs": False}}}})
    cfg = build_study([], section["regimes"], profiles=["ideal", "default"], flickers=[0.1, 0.5])
    assert [r.id for r in cfg.regimes] == ["a", "b"] and cfg.vlm_regime == "a"
    assert not cfg.regimes[1].run.ppo_config.normalize_obs
    # profile default and flicker 0.1 are the same knobs: one variant, both names
    assert [v.id for v in cfg.variants] == ["profile ideal", "profile default = flicker 0.1", "flicker 0.5"]
    assert all(v.run.arms == ("hybrid",) for v in cfg.variants)
    assert cfg.variants[0].run.vlm.sim.patch_px == 1
    assert cfg.variants[1].run.jobs()[0].config_hash == next(
        j for j in cfg.regimes[0].run.jobs() if j.arm.name == "hybrid").config_hash


@pytest.mark.parametrize("raw", [{"regimes": {"a": 3}}, {"regimez": {}}, {"flickers": ["x"]}])
def test_bad_study_tables(raw: dict) -> None:  # type: ignore[type-arg]
    with pytest.raises(BadInput):
        settings_of([raw])


def test_a_study_of_another_task_takes_its_study_preset_thresholds_and_window() -> None:
    from vlmrl_cli.study.config import task_in
    from vlmrl_cli.tasks.registry import get_task

    layers = [{"task": "acrobot"}]
    assert task_in(layers).name == "acrobot" and task_in([]).name == "mountain-car"
    task = get_task("acrobot")
    chosen = task_regimes(task)
    preset = task.study_preset or task.default_preset
    assert chosen == {preset: {"preset": preset}}
    cfg = build_study(layers, chosen, profiles=(), flickers=(), alphas=(), kin_scales=(), query_flickers=())
    assert cfg.thresholds == task.thresholds and cfg.window == task.window
    assert all(r.run.task == "acrobot" for r in cfg.all_regimes())
    with pytest.raises(BadInput, match="VLM-quality variants"):
        build_study(layers, chosen, profiles=("ideal",), flickers=())
    with pytest.raises(BadInput, match="a study covers one task"):
        build_study([], {"a": {"preset": "smoke"}, "b": {"preset": "smoke", "task": "acrobot"}})


def test_the_study_table_layers_file_then_set_then_flags(tmp_path) -> None:  # type: ignore[no-untyped-def]
    from vlmrl_cli.study.config import StudyConfig

    path = tmp_path / "study.toml"
    path.write_text('seeds = [0, 1]\n[study]\nalphas = [25]\nkin_scales = [0, 2]\nquery_flickers = []\n'
                    'margin = 1.2\nstates = 7\nout = "elsewhere"\n'
                    '[study.regimes]\npaper = "smoke"\nhard = { preset = "smoke", ppo = { normalize_obs = false } }\n')
    cfg = StudyConfig.from_sources(path)
    assert [r.id for r in cfg.regimes] == ["paper", "hard"] and not cfg.regimes[1].run.ppo_config.normalize_obs
    assert cfg.base.seeds == (0, 1) and (cfg.margin, cfg.states, str(cfg.out)) == (1.2, 7, "elsewhere")
    assert {c.alpha for c in cfg.cells if not c.placebo} == {0.0, 25} and not [c for c in cfg.cells
                                                                              if c.kind == "query-flicker"]
    # --set beats the file, a flag beats both; a flag's regimes replace the file's table whole
    over = StudyConfig.from_sources(path, {"study.regimes": {"x": {"preset": "smoke"}}, "study.margin": 1.3},
                                    ["study.margin=1.25", "study.kin_scales=[]"])
    assert [r.id for r in over.regimes] == ["x"] and over.margin == 1.3 and not over.cells


@pytest.mark.parametrize(("raw", "needle"), [({"states": 1}, "study.states = 1: input should be greater than or "
                                                               "equal to 2"),
                                             ({"states": 2.5}, "study.states"), ({"margin": "big"}, "study.margin"),
                                             ({"adjust": 3}, "study.adjust"), ({"out": 3}, "study.out"),
                                             ({"adjust": "holmm"}, "did you mean 'holm'"),
                                             ({"margn": 1.2}, "did you mean 'study.margin'")])
def test_bad_study_settings(raw: dict, needle: str) -> None:  # type: ignore[type-arg]
    with pytest.raises(BadInput, match=needle):
        settings_of([raw])

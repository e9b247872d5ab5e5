"""Each simulated-VLM profile shows its taxonomy pattern on a small sweep (issue 9, item 7)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tests.mountain_car_helpers import parse_float, sim_vlm
from vlmrl_cli.probe import metrics
from vlmrl_cli.probe.scoring import DEFAULT_STATES, sweep_positions
from vlmrl_cli.probe.taxonomy import TaxonomyConfig, TaxonomyResult, run_taxonomy
from vlmrl_cli.tasks.mountain_car import MOUNTAIN_CAR
from vlmrl_cli.tasks.mountain_car.geometry import SCALE, ZONE_EDGES, Zone
from vlmrl_cli.tasks.mountain_car.probe import NUMBER_PROBE, PAPER_FRAMES
from vlmrl_cli.tasks.mountain_car.prompts import PROMPTS
from vlmrl_cli.tasks.mountain_car.render import FrameRenderer
from vlmrl_cli.vlm.config import SimKnobs, VLMConfig, sim_profiles
from vlmrl_cli.vlm.parsers import ParseStatus
from vlmrl_cli.vlm.prompts import PromptKind

# No sweep position of 12 falls on a zone edge, where a pixel reader off by a fraction of a pixel
# gives the neighbouring label (25 positions put three frames on edges; the default 101 puts none).
STATES = 12


@pytest.fixture(scope="module")
def results(tmp_path_factory: pytest.TempPathFactory) -> dict[str, TaxonomyResult]:
    root = tmp_path_factory.mktemp("profiles")
    out = {}
    for name in sim_profiles(MOUNTAIN_CAR):  # the generic profiles and MountainCar's llava-table1
        vlm = VLMConfig(sim=SimKnobs.of_profile(name, MOUNTAIN_CAR), cache_path=root / "cache.sqlite")
        out[name] = run_taxonomy(TaxonomyConfig(vlm=vlm, states=STATES, out=root / name,
                                                tracking_uri=f"sqlite:///{root}/mlflow.db"))
    return out


def test_ideal_reads_the_car(results: dict[str, TaxonomyResult]) -> None:
    s = results["ideal"].sweep
    assert s["float.spearman"] > 0.99 and s["float.mae_x"] < 0.02
    assert s["box.format_failure_rate"] == 0 and s["box.mean_iou"] > 0.8
    assert s["mcq.accuracy"] >= 0.9


def test_default_is_noisy_but_tracks_position(results: dict[str, TaxonomyResult]) -> None:
    s = results["default"].sweep
    assert 0.5 < s["float.spearman"] < 0.99 and s["float.mae_x"] > 0.1
    assert s["mcq.accuracy"] > 0.75


def test_llava_table1_shows_the_papers_failures(results: dict[str, TaxonomyResult]) -> None:
    r = results["llava-table1"]
    s = r.sweep
    # float: nearly constant about 0.38 whatever the position, so a large error and no rank signal
    values = [p.float_result.value for p in r.probes if p.float_result.ok]
    assert values and all(abs(v - 0.38) < 0.03 for v in values if v is not None)
    assert s["float.mae_x"] > 0.5 and abs(s["float.spearman"]) < 0.6
    # MCQ: BOTTOM on both of Table 1's frames (the dead zone covers x = -0.69)
    for panel in ("a", "b"):
        probe = r.panel(panel)
        assert probe is not None and probe.mcq_result.label == Zone.BOTTOM
    assert s["mcq.accuracy"] <= results["default"].sweep["mcq.accuracy"] - 0.15
    # boxes: collapse or land far from the car
    assert s["box.format_failure_rate"] >= 0.3 and s["box.mean_iou_all"] < 0.1
    for panel in ("a", "b"):
        probe = r.panel(panel)
        assert probe is not None
        assert probe.box_result.status is ParseStatus.FORMAT_COLLAPSE or (
            probe.box_result.box is not None and abs(probe.box_result.box[0] - probe.truth.box_px[0]) > 100)


def test_flicker_still_works_on_a_profile(results: dict[str, TaxonomyResult], tmp_path: Path) -> None:
    vlm = VLMConfig(sim=SimKnobs.of_profile("ideal", flicker=1.0), cache_path=tmp_path / "c.sqlite")
    r = run_taxonomy(TaxonomyConfig(vlm=vlm, states=STATES, out=tmp_path / "o", tracking_uri=f"sqlite:///{tmp_path}/m.db"))
    assert r.sweep["mcq.accuracy"] < 0.2


def test_the_default_sweep_keeps_clear_of_zone_edges() -> None:
    # a frame on an edge gets either label from a reader off by a fraction of a pixel
    gaps = [abs(x - edge) * SCALE for x in sweep_positions(DEFAULT_STATES, NUMBER_PROBE) for edge in ZONE_EDGES]
    assert min(gaps) >= 1.5  # pixels


def test_llava_table1_float_answers_carry_no_rank_signal_on_the_default_sweep() -> None:
    """Over 20 simulator seeds the float Spearman scatters around 0 as a null correlation does:
    mean within +-0.06 (3 standard errors of 0.1 / sqrt(20)), and 95% intervals that hold 0 for at
    least 17 of 20 seeds. A reader whose answers followed the position would fail both."""
    xs = sweep_positions(DEFAULT_STATES, NUMBER_PROBE) + [x for _, x, _ in PAPER_FRAMES]
    prompt = PROMPTS[PromptKind.FLOAT]
    with FrameRenderer() as renderer:
        frames = [renderer.render(x) for x in xs]
    rhos, covered = [], 0
    for seed in range(20):
        vlm = sim_vlm(SimKnobs.of_profile("llava-table1", MOUNTAIN_CAR, seed=seed))
        values = [parse_float(vlm.answer(prompt, f)).value for f in frames]
        rho = metrics.spearman([np.nan if v is None else v for v in values], xs)
        lo, hi = metrics.spearman_ci(rho, len(xs))
        rhos.append(rho)
        covered += lo <= 0.0 <= hi
    assert abs(float(np.mean(rhos))) < 0.06
    assert covered >= 17

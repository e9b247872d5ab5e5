"""Table 1 from the paper's replayed outputs: the computed consequences match the paper's claims."""

from __future__ import annotations

from pathlib import Path

import pytest

from vlmrl_cli.core.tables import latex_escape
from vlmrl_cli.core.tables import markdown as markdown_table
from vlmrl_cli.probe.scoring import FrameProbe, _Planned, empty_sweep_statistics, probe_frame
from vlmrl_cli.probe.table1 import pair_consequence, taxonomy_frame, write_tables
from vlmrl_cli.tasks.mountain_car import MOUNTAIN_CAR
from vlmrl_cli.tasks.mountain_car.probe import NUMBER_PROBE, PAPER_FRAMES
from vlmrl_cli.tasks.mountain_car.render import FrameRenderer
from vlmrl_cli.vlm.client import VLMClient
from vlmrl_cli.vlm.config import VLMConfig
from vlmrl_cli.vlm.prompts import PromptKind
from vlmrl_cli.vlm.replay import ReplayBackend


@pytest.fixture(scope="module")
def paper_pair() -> tuple[FrameProbe, FrameProbe]:
    client = VLMClient(ReplayBackend.from_config(VLMConfig(backend="replay")))
    with FrameRenderer() as renderer:
        a, b = (probe_frame(client, MOUNTAIN_CAR, renderer, _Planned(x, f"x={x:.2f}", panel, cap))
                for panel, x, cap in PAPER_FRAMES)
    return a, b


def test_paper_consequences_are_computed(paper_pair: tuple[FrameProbe, FrameProbe]) -> None:
    a, b = paper_pair
    mcq = pair_consequence(PromptKind.MCQ, a, b)
    assert mcq.dphi == 0.0 and mcq.true_dphi > 0  # the semantic dead zone
    assert mcq.describe().startswith("ΔΦ = 0.0 (dead zone")
    flt = pair_consequence(PromptKind.FLOAT, a, b)
    assert flt.dphi > 0 > flt.true_dphi  # the float noise points the wrong way
    assert "sign WRONG" in flt.describe()
    assert "undefined" in pair_consequence(PromptKind.BOX, a, b).describe()  # (a) collapsed


def test_tables_hold_the_raw_outputs(paper_pair: tuple[FrameProbe, FrameProbe], tmp_path: Path) -> None:
    paths = write_tables(list(paper_pair), empty_sweep_statistics(), tmp_path, NUMBER_PROBE, label="replay:m",
                         provenance="replayed", simulated=False)
    md = paths[0].read_text()
    for snippet in ("0.378", "0.386", "Error [0, 0, 0, 0]", "Box [450, 210, 480, 230]", "BOTTOM", "ΔΦ = 0.0",
                    "n/a", "(120px,450px)"):
        assert snippet in md
    assert "SIMULATED" not in md
    tex = paths[2].read_text()
    assert r"\begin{tabular}" in tex and "LEFT\\_SLOPE" in tex
    assert len(taxonomy_frame(*paper_pair, NUMBER_PROBE)) == 3


def test_simulated_tables_say_so(paper_pair: tuple[FrameProbe, FrameProbe], tmp_path: Path) -> None:
    write_tables(list(paper_pair), empty_sweep_statistics(), tmp_path, NUMBER_PROBE, label="sim:x", provenance="p",
                 simulated=True)
    assert "SIMULATED VLM (not a real model)" in (tmp_path / "table1.md").read_text()


def test_markdown_escapes_pipes() -> None:
    import pandas as pd

    md = markdown_table(pd.DataFrame({"a|b": ["x|y"]}))
    assert md.splitlines()[0] == "| a\\|b |" and md.splitlines()[2] == "| x\\|y |"


def test_latex_escape() -> None:
    assert latex_escape("50% & $x_1$ → ΔΦ") == r"50\% \& \$x\_1\$ $\rightarrow$ $\Delta$$\Phi$"


from hypothesis import given  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

from vlmrl_cli.core.tables import printable  # noqa: E402


@given(st.text())
def test_printable_never_lets_control_characters_through(text: str) -> None:
    shown = printable(text)
    assert shown.isprintable()
    assert "\n" not in shown


def test_with_ci_shows_the_interval_only_when_it_is_defined() -> None:
    import math

    from vlmrl_cli.probe.table1 import with_ci

    assert with_ci({"r": 0.25, "r_low": -0.1, "r_high": 0.5}, "r") == "0.250 [95% CI -0.100, 0.500]"
    assert with_ci({"r": 1.0, "r_low": math.nan, "r_high": math.nan}, "r") == "1.000"
    assert with_ci({}, "r") == "n/a"

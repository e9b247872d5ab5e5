"""Figure 1 draws both panels with the object API and saves a PNG."""

from __future__ import annotations

from pathlib import Path

from vlmrl_cli.probe.figure1 import figure1, save_figure1
from vlmrl_cli.probe.scoring import _Planned, probe_frame
from vlmrl_cli.tasks.mountain_car import MOUNTAIN_CAR
from vlmrl_cli.tasks.mountain_car.probe import PAPER_FRAMES
from vlmrl_cli.tasks.mountain_car.render import FrameRenderer
from vlmrl_cli.vlm.client import VLMClient
from vlmrl_cli.vlm.config import VLMConfig
from vlmrl_cli.vlm.replay import ReplayBackend


def _probes() -> list:
    client = VLMClient(ReplayBackend.from_config(VLMConfig(backend="replay")))
    with FrameRenderer() as renderer:
        return [probe_frame(client, MOUNTAIN_CAR, renderer, _Planned(x, f"x={x:.2f}", panel, cap))
                for panel, x, cap in PAPER_FRAMES]


def test_figure_has_two_panels_and_names_the_backend(tmp_path: Path) -> None:
    import matplotlib.pyplot as plt

    before = plt.get_fignums()
    probes = _probes()
    fig = figure1(probes, label="sim:m", simulated=True)
    assert len(fig.axes) == 2
    assert "SIMULATED VLM" in fig._suptitle.get_text()
    # (a) has a collapsed box: only the true box; (b) has both
    assert [len(ax.patches) for ax in fig.axes] == [1, 2]
    assert "0.378" in fig.axes[0].get_xlabel() and "BOTTOM" in fig.axes[1].get_xlabel()
    # the MCQ verdict compares the label with the task's truth: (a) BOTTOM is right, (b) BOTTOM is not
    assert "MCQ: BOTTOM [parsed; correct (true BOTTOM)]" in fig.axes[0].get_xlabel()
    assert "[parsed; wrong (true LEFT_SLOPE)]" in fig.axes[1].get_xlabel()
    path = save_figure1(probes, tmp_path / "f.png", label="replay:m", simulated=False)
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert plt.get_fignums() == before  # no pyplot state touched

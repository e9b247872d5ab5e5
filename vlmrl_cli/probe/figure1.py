"""Figure 1 of the paper, redrawn: the two frames, the true box and the VLM's box and answers."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

from vlmrl_cli.core.tables import printable
from vlmrl_cli.probe.scoring import FrameProbe
from vlmrl_cli.vlm.prompts import PromptKind

TRUE_COLOUR = "tab:green"
VLM_COLOUR = "tab:red"


def _short(text: str | None, limit: int = 34) -> str:
    if text is None:
        return "(no answer)"
    flat = printable(text)
    return flat if len(flat) <= limit else flat[: limit - 1] + "…"


def draw_panel(ax: Any, probe: FrameProbe) -> Any:
    """Draw one frame with its true box (green) and the parsed VLM box (red) on ``ax``."""
    from matplotlib.patches import Rectangle

    if probe.frame is None:
        raise ValueError(f"frame {probe.frame_id} was not kept; Figure 1 needs the panel frames' pixels.")
    ax.imshow(probe.frame.pixels, interpolation="nearest")
    x0, y0, x1, y1 = probe.truth.box_px
    ax.add_patch(Rectangle((x0, y0), x1 - x0, y1 - y0, fill=False, edgecolor=TRUE_COLOUR, linewidth=2,
                           label="true box"))
    box = probe.box_result.box
    if box is not None:
        bx0, by0, bx1, by1 = box
        style = "-" if probe.box_result.ok else ":"  # dotted: parsed but out of range
        ax.add_patch(Rectangle((bx0, by0), bx1 - bx0, by1 - by0, fill=False, edgecolor=VLM_COLOUR, linewidth=2,
                               linestyle=style, label="VLM box"))
    ax.set_xticks([])
    ax.set_yticks([])
    ax.set_title(f"({probe.panel}) {probe.caption or ''} (x = {probe.truth.x:.2f})", fontsize=10)
    rows = ((PromptKind.FLOAT, "float"), (PromptKind.BOX, "box"), (PromptKind.MCQ, "MCQ"))
    ax.set_xlabel("\n".join(f"{name}: {_short(probe.answers.get(kind))} [{_verdict(probe, kind)}]"
                            for kind, name in rows), fontsize=8)
    return ax


def _verdict(probe: FrameProbe, kind: PromptKind) -> str:
    """Whether the answer parsed and, if so, how it compares with the truth."""
    f, b, truth = probe.float_result, probe.box_result, probe.truth
    if not probe.result(kind).ok:
        return f"not parsed: {probe.result(kind).status.value}"
    if kind is PromptKind.FLOAT and f.value is not None:
        return f"parsed; off by {abs(f.value - truth.x):.2f} x units (true x {truth.x:.2f})"
    if kind is PromptKind.BOX and b.box is not None:
        (x0, y0, x1, y1), (cx, cy) = b.box, truth.centre_px
        return "parsed; " + ("holds" if x0 <= cx <= x1 and y0 <= cy <= y1 else "misses") + " the true centre"
    correct = probe.mcq_result.label == truth.label
    return f"parsed; {'correct' if correct else 'wrong'} (true {truth.label})"


def figure1(probes: Sequence[FrameProbe], *, label: str, simulated: bool, note: str = "") -> Any:
    """A ``matplotlib.figure.Figure`` of the task's panel frames side by side; ``label``: the backend."""
    from matplotlib.figure import Figure
    from matplotlib.lines import Line2D

    panels = sorted((p for p in probes if p.panel is not None), key=lambda p: p.panel or "")
    if not panels:
        raise ValueError("Figure 1 needs the task's panel frames (NumberProbe.panels) among the probes.")
    fig = Figure(figsize=(6.0 * len(panels), 5.2), layout="constrained")
    axes = fig.subplots(1, len(panels), squeeze=False)[0]
    for ax, probe in zip(axes, panels, strict=True):
        draw_panel(ax, probe)
    flag = "SIMULATED VLM (not a real model) - " if simulated else ""
    fig.suptitle(f"Figure 1 (recomputed): {flag}{label}{' - ' + note if note else ''}", fontsize=11,
                 color="darkred" if simulated else "black")
    handles = [Line2D([], [], color=TRUE_COLOUR, lw=2, label="true box (gymnasium geometry)"),
               Line2D([], [], color=VLM_COLOUR, lw=2, label="VLM box (parsed)")]
    fig.legend(handles=handles, loc="outside lower center", ncol=2, fontsize=8, frameon=False)
    return fig


def save_figure1(
    probes: Sequence[FrameProbe], path: Path, *, label: str, simulated: bool, note: str = "", dpi: int = 150
) -> Path:
    """Draw Figure 1 and save it as PNG at ``dpi``; returns ``path``."""
    fig = figure1(probes, label=label, simulated=simulated, note=note)
    fig.savefig(path, dpi=dpi, format="png")
    return path

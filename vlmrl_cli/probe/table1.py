"""Table 1 of the paper, recomputed: raw outputs, ground truth and the dPhi each answer gives PBRS."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from vlmrl_cli.core import tables
from vlmrl_cli.probe import metrics
from vlmrl_cli.probe.scoring import FrameProbe, phi_series
from vlmrl_cli.vlm.parsers import ParseStatus
from vlmrl_cli.vlm.prompts import NumberProbe, PromptKind

TAXONOMY_ROWS: tuple[tuple[PromptKind, str], ...] = (
    (PromptKind.FLOAT, "I. Float Regression"),
    (PromptKind.BOX, "II. Box Grounding"),
    (PromptKind.MCQ, "III. Semantic MCQ"),
)


@dataclass(frozen=True)
class PairConsequence:
    """dPhi = Phi(b) - Phi(a) of one prompt kind for the pair (a) -> (b), VLM and truth."""

    kind: PromptKind
    phi_a: float
    phi_b: float
    true_dphi: float

    @property
    def dphi(self) -> float:
        return self.phi_b - self.phi_a

    def describe(self) -> str:
        """The Consequence cell, e.g. ``dPhi = 0.0 (dead zone; true dPhi = +0.100)``."""
        true_txt = f"true ΔΦ = {self.true_dphi:+.3f}"
        if not (math.isfinite(self.phi_a) and math.isfinite(self.phi_b)):
            missing = " and ".join(n for n, v in (("(a)", self.phi_a), ("(b)", self.phi_b)) if not math.isfinite(v))
            return f"ΔΦ undefined: no potential for {missing} (unparsed answer); {true_txt}"
        if abs(self.dphi) <= metrics.DPHI_ZERO_TOL:
            moving = "the truth moves" if abs(self.true_dphi) > metrics.DPHI_ZERO_TOL else "the truth is flat too"
            return f"ΔΦ = 0.0 (dead zone; {true_txt}; {moving})"
        if abs(self.true_dphi) <= metrics.DPHI_ZERO_TOL:
            return f"ΔΦ = {self.dphi:+.4f} ({true_txt}: spurious gradient)"
        agree = math.copysign(1, self.dphi) == math.copysign(1, self.true_dphi)
        verdict = "sign right" if agree else "sign WRONG (noise)"
        return f"ΔΦ = {self.dphi:+.4f} ({true_txt}: {verdict}, |error| {abs(self.dphi - self.true_dphi):.4f})"


def pair_consequence(kind: PromptKind, a: FrameProbe, b: FrameProbe) -> PairConsequence:
    """The dPhi that the answers of ``kind`` for frames a and b give, against the truth."""

    vlm, true = phi_series([a, b], kind)
    return PairConsequence(kind, float(vlm[0]), float(vlm[1]), float(true[1] - true[0]))


def _parsed(probe: FrameProbe, kind: PromptKind) -> str:
    f, b, m = probe.float_result, probe.box_result, probe.mcq_result
    if kind is PromptKind.FLOAT:
        value = f"{f.value:.3f}" if f.value is not None else "-"
    elif kind is PromptKind.BOX:
        value = "(" + ", ".join(f"{v:.0f}" for v in b.box) + ")" if b.box is not None else "-"
    else:
        value = str(m.label) if m.label is not None else "-"
    status = probe.result(kind).status
    return f"{value} [{'parsed' if status is ParseStatus.OK else 'not parsed: ' + status.value}]"


def _answer_error(probe: FrameProbe, kind: PromptKind) -> str:
    if kind is PromptKind.FLOAT:
        f = probe.float_result
        return f"|x err| {abs(f.value - probe.truth.x):.3f}" if f.ok and f.value is not None else "n/a"
    if kind is PromptKind.BOX:
        b = probe.box_result
        if not b.ok or b.box is None:
            return "n/a"
        return (f"IoU {metrics.iou(b.box, probe.truth.box_px):.2f}, "
                f"centre off {metrics.centre_error_px(b.box, probe.truth.box_px):.0f} px")
    m = probe.mcq_result
    if not m.ok:
        return "n/a"
    return "correct" if m.label == probe.truth.label else f"wrong (true {probe.truth.label})"


def _truth(kind: PromptKind, a: FrameProbe, b: FrameProbe, numbers: NumberProbe) -> str:
    if kind is PromptKind.FLOAT:
        return f"x = {a.truth.x:.2f} → {b.truth.x:.2f}"
    if kind is PromptKind.BOX:
        (ca, ra), (cb, rb) = metrics.box_centre(a.truth.box_px), metrics.box_centre(b.truth.box_px)
        return (f"True box centre (col, row): ({ca:.0f}px, {ra:.0f}px) → ({cb:.0f}px, {rb:.0f}px) "
                f"[our {numbers.width}x{numbers.height} frame]")
    return f"True zone: {a.truth.label} → {b.truth.label} (velocity-free)"


def _raw(probe: FrameProbe, kind: PromptKind) -> str:
    text = probe.answers.get(kind)
    return "(no answer recorded)" if text is None else " ".join(text.split())


def taxonomy_frame(a: FrameProbe, b: FrameProbe, numbers: NumberProbe) -> pd.DataFrame:
    """Table 1's rows (one per error taxonomy) for the pair (a) -> (b), cells as strings."""
    label_a = f"VLM raw output (a) {a.caption or ''} ({a.frame_id})".replace("  ", " ")
    label_b = f"VLM raw output (b) {b.caption or ''} ({b.frame_id})".replace("  ", " ")
    return pd.DataFrame([{
        "Error taxonomy": name,
        label_a: _raw(a, kind),
        label_b: _raw(b, kind),
        "Parsed (a) → (b)": f"{_parsed(a, kind)} → {_parsed(b, kind)}",
        "Answer error (a); (b)": f"{_answer_error(a, kind)}; {_answer_error(b, kind)}",
        "Kinematic truth / grounding": _truth(kind, a, b, numbers),
        "Consequence on PBRS ΔΦ (computed, Φ(b) − Φ(a))": pair_consequence(kind, a, b).describe(),
    } for kind, name in TAXONOMY_ROWS])


def _fmt(value: float, digits: int = 3) -> str:
    return "n/a" if not math.isfinite(value) else f"{value:.{digits}f}"


def with_ci(stats: Mapping[str, float], key: str, digits: int = 3) -> str:
    """``stats[key]`` with its 95% interval from ``key_low`` / ``key_high`` when both are defined."""
    value = _fmt(stats.get(key, math.nan), digits)
    low, high = stats.get(f"{key}_low", math.nan), stats.get(f"{key}_high", math.nan)
    if not (math.isfinite(low) and math.isfinite(high)):
        return value
    return f"{value} [95% CI {_fmt(low, digits)}, {_fmt(high, digits)}]"


def sweep_frame(sweep: Mapping[str, float]) -> pd.DataFrame:
    """Sweep statistics per prompt kind (n/a where no sweep was probed), cells as strings."""

    def get(key: str) -> float:
        return sweep.get(key, math.nan)

    quality = {
        PromptKind.FLOAT: f"MAE {_fmt(get('float.mae_x'))} x; Spearman {with_ci(sweep, 'float.spearman')}",
        PromptKind.BOX: (f"IoU {_fmt(get('box.mean_iou'))} (parsed), {_fmt(get('box.mean_iou_all'))} (all); "
                         f"centre error {_fmt(get('box.centre_error_px'), 1)} px"),
        PromptKind.MCQ: f"accuracy {_fmt(get('mcq.accuracy'))}",
    }
    return pd.DataFrame([{
        "Error taxonomy": name,
        "States": _fmt(get("states"), 0) if math.isfinite(get(f"{kind}.ok_fraction")) else "n/a",
        "Parsed OK": _fmt(get(f"{kind}.ok_fraction")),
        "Format failures": _fmt(get(f"{kind}.format_failure_rate")),
        "Answer quality": quality[kind],
        "ΔΦ dead zone": _fmt(get(f"{kind}.dphi.dead_zone")),
        "ΔΦ dead while truth moves": _fmt(get(f"{kind}.dphi.dead_zone_while_truth_moves")),
        "ΔΦ sign disagrees": _fmt(get(f"{kind}.dphi.sign_disagreement")),
        "mean |ΔΦ − ΔΦ_true|": _fmt(get(f"{kind}.dphi.mean_abs_dphi_error"), 4),
        "Φ unavailable": _fmt(get(f"{kind}.dphi.phi_unavailable")),
    } for kind, name in TAXONOMY_ROWS])


def latex_table(df: pd.DataFrame, caption: str, label: str) -> str:
    """A ``table`` float of ragged-right paragraph columns (the cells are long text)."""
    width = f"{0.95 / max(1, len(df.columns)):.3f}"
    spec = "".join(f">{{\\raggedright\\arraybackslash}}p{{{width}\\linewidth}}" for _ in df.columns)
    return tables.latex(df, caption, label=label, colspec=spec, setup=(r"\centering\scriptsize",),
                        rules=tables.HLINES)


def write_tables(
    probes: Sequence[FrameProbe],
    sweep: Mapping[str, float],
    folder: Path,
    numbers: NumberProbe,
    *,
    label: str,
    provenance: str,
    simulated: bool,
) -> list[Path]:
    """Write table1.md, .csv, .tex, table1_sweep.csv and probes.csv into ``folder``."""
    (first, _, _), (second, _, _) = numbers.panels[:2]
    a, b = (next((p for p in probes if p.panel == panel), None) for panel in (first, second))
    if a is None or b is None:
        raise ValueError(f"Table 1 needs the task's frames ({first}) and ({second}) (NumberProbe.panels) among "
                         "the probes.")
    main, stats = taxonomy_frame(a, b, numbers), sweep_frame(sweep)
    cap_main = (f"Table 1 (recomputed). Taxonomy of pure vision failures on the consecutive micro-states "
                f"(a) x = {a.truth.x:.2f} -> (b) x = {b.truth.x:.2f}. Backend {label}. {provenance}")
    flag = " SIMULATED VLM (not a real model)." if simulated else ""
    cap_sweep = (f"Table 1b. The same statistics over a sweep of readings sorted along the task's range "
                 f"(consecutive pairs). Backend {label}.{flag}")
    notes = [*numbers.notes,
             f"Φ mappings: MCQ label -> raw potential (the task's label_potentials); float: x "
             f"normalised to [0, 1] over [{numbers.low:g}, {numbers.high:g}]; box: box centre column / "
             f"{numbers.width}. The truth applies the same mapping to the ground truth."]
    md = [f"**{cap_main}**", "", tables.markdown(main), "", *(f"- {n}" for n in notes), "",
          f"**{cap_sweep}**", "", tables.markdown(stats), ""]
    if simulated:
        md.insert(0, "> **SIMULATED VLM (not a real model)**: these numbers test the pipeline, not a VLM.\n")
    md_path, csv, tex_path, sweep_csv, per_frame = (folder / name for name in (
        "table1.md", "table1.csv", "table1.tex", "table1_sweep.csv", "probes.csv"))
    md_path.write_text("\n".join(md), encoding="utf-8")
    # CSVs carry no caption: every row names the backend instead, SIMULATED said plainly
    vlm = f"{label} (SIMULATED VLM, not a real model)" if simulated and "SIMULATED" not in label else label
    main.assign(vlm=vlm).to_csv(csv, index=False)
    tex = [f"% {cap_main}", *(f"% {n}" for n in notes), latex_table(main, cap_main, "tab:taxonomy"), "",
           latex_table(stats, cap_sweep, "tab:taxonomy-sweep"), ""]
    tex_path.write_text("\n".join(tex), encoding="utf-8")
    stats.assign(vlm=vlm).to_csv(sweep_csv, index=False)
    probes_frame(probes).assign(vlm=vlm).to_csv(per_frame, index=False)
    return [md_path, csv, tex_path, sweep_csv, per_frame]


def probes_frame(probes: Sequence[FrameProbe]) -> pd.DataFrame:
    return pd.DataFrame([{
        "frame_id": p.frame_id, "x": p.truth.x, "true_zone": p.truth.label,
        "true_box": list(p.truth.box_px), "panel": p.panel or "",
        "float_raw": p.answers.get(PromptKind.FLOAT), "float_status": p.float_result.status.value,
        "float_value": p.float_result.value,
        "box_raw": p.answers.get(PromptKind.BOX), "box_status": p.box_result.status.value,
        "box_value": list(p.box_result.box) if p.box_result.box is not None else None,
        "mcq_raw": p.answers.get(PromptKind.MCQ), "mcq_status": p.mcq_result.status.value,
        "mcq_label": str(p.mcq_result.label) if p.mcq_result.label is not None else None,
    } for p in sorted(probes, key=lambda q: q.truth.x)])

"""Figures 2-4 of the paper, the performance profile and the reward-hacking figure, drawn with
matplotlib's object API (no pyplot state): each ``figure*`` builds a ~7-inch-wide figure with the VLM
backend named in its suptitle, fonts >= 8 pt; each ``plot_*`` draws on a given ``ax``."""

from __future__ import annotations

import textwrap
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
from matplotlib import colormaps
from matplotlib.axes import Axes
from matplotlib.colors import to_hex
from matplotlib.figure import Figure
from matplotlib.lines import Line2D

from vlmrl_cli.analysis import stats
from vlmrl_cli.analysis.ranks import performance_profile
from vlmrl_cli.analysis.thresholds import rolling_mean_return
from vlmrl_cli.report.table2 import Table2, order_arms, threshold_key

WIDTH_IN = 7.0
SMALL = 8
_PALETTE = ("tab:blue", "tab:orange", "tab:green", "tab:red", "tab:purple", "tab:brown", "tab:pink", "tab:gray")


def arm_color(arm: str, arms: Sequence[str]) -> str:
    """A stable colour per arm, by its position in ``order_arms(arms)``."""
    ordered = order_arms(arms)
    return _PALETTE[ordered.index(arm) % len(_PALETTE)] if arm in ordered else "black"


@dataclass(frozen=True)
class SeedCurve:
    """One seed's rolling mean return: ``steps`` and ``mean`` of shape ``(K,)`` (see ``rolling_mean_return``)."""

    arm: str
    seed: int
    steps: np.ndarray
    mean: np.ndarray


def seed_curves(episodes: pd.DataFrame, window: int = 100, min_episodes: int = 1) -> list[SeedCurve]:
    """Rolling mean native return per run, from the tidy ``episodes`` frame of ``load_experiment``."""
    curves = []
    for (arm, seed, _), ep in episodes.groupby(["arm", "seed", "run_id"], sort=True):
        steps, mean = rolling_mean_return(ep["timestep"].to_numpy(), ep["native_return"].to_numpy(), window,
                                          min_episodes)
        curves.append(SeedCurve(str(arm), int(seed), steps, mean))
    return curves


def on_grid(curve: SeedCurve, grid: np.ndarray) -> np.ndarray:
    """The curve's value at each grid step (shape ``(G,)``): the last value at or before it (the rolling
    mean is a step function of time), NaN before the first completed episode."""
    idx = np.searchsorted(curve.steps, grid, side="right") - 1
    out = np.where(idx >= 0, curve.mean[np.clip(idx, 0, None)] if curve.mean.size else np.nan, np.nan)
    return np.asarray(out, dtype=float)


def _style(ax: Axes) -> None:
    ax.tick_params(labelsize=SMALL)
    ax.grid(alpha=0.3, linewidth=0.5)


def seed_color(seed: int) -> str:
    """A fixed colour per seed (tab10, cycling), shared by every panel of Figure 3."""
    return to_hex(colormaps["tab10"](seed % 10))


def plot_mean_curve(grid: np.ndarray, mean: np.ndarray, low: np.ndarray, high: np.ndarray, ax: Axes,
                    color: str = "tab:blue", label: str | None = None) -> None:
    """Figure 4 layer: mean learning curve (shape ``(G,)``) with its band ``[low, high]``."""
    ax.plot(grid, mean, color=color, linewidth=1.5, label=label)
    ax.fill_between(grid, low, high, color=color, alpha=0.25, linewidth=0)
    _style(ax)


def _suptitle(fig: Figure, title: str, vlm_note: str) -> None:
    # wrapped so a long backend label never runs off the figure's edges
    fig.suptitle(f"{title}\n" + "\n".join(textwrap.wrap(vlm_note, 110)), fontsize=SMALL + 1)


def figure2(table: Table2, vlm_note: str) -> Figure:
    """Figure 2: steps to each threshold per arm with CI error bars, ``DNF k/n`` annotated, the paper's
    values as hollow markers, on a log axis (the paper's steps can be 20x ours)."""
    fig = Figure(figsize=(WIDTH_IN, 3.4), layout="constrained")
    ax = fig.subplots()
    thresholds = list(table.thresholds)
    arms = list(table.arms)
    x = np.arange(len(thresholds), dtype=float)
    width = 0.7 / max(len(arms), 1)
    ymax, ymin = 0.0, np.inf
    for i, arm in enumerate(arms):
        color = arm_color(arm, arms)
        offset = (i - (len(arms) - 1) / 2) * width
        for j, t in enumerate(thresholds):
            c = table.cell(threshold_key(t), arm)
            if c is None:
                continue
            val, lo, hi = c["value"], c["ci_low"], c["ci_high"]
            if np.isfinite(val):
                yerr = [[val - lo], [hi - val]] if np.isfinite(lo) and np.isfinite(hi) else None
                ax.errorbar(x[j] + offset, val, yerr=yerr, fmt="o", color=color, capsize=3, markersize=5,
                            label=f"{arm} (ours)" if j == 0 else None)
                ymax = max(ymax, hi if np.isfinite(hi) else val)
                ymin = min(ymin, lo if np.isfinite(lo) and lo > 0 else val)
            if c["n_reached"] < c["n"]:
                y = val if np.isfinite(val) else np.nan
                dnf = f"DNF {int(c['n']) - int(c['n_reached'])}/{int(c['n'])}"
                ax.annotate(dnf, (x[j] + offset, y if np.isfinite(y) else (ymin if np.isfinite(ymin) else 1.0)),
                            xytext=(0, 8), textcoords="offset points", ha="center", fontsize=SMALL, color=color,
                            annotation_clip=False)
            paper = table.paper.get(threshold_key(t), {}).get(arm)
            if paper is not None:
                ax.plot(x[j] + offset, float(paper), marker="D", markersize=7, markerfacecolor="none",
                        markeredgecolor=color, linestyle="none", label=f"{arm} (paper)" if j == 0 else None)
                ymax = max(ymax, float(paper))
                ymin = min(ymin, float(paper))
    ax.set_xticks(x, [f"{t:g}" for t in thresholds])
    ax.set_xlabel("reward threshold (rolling mean native return)", fontsize=SMALL + 1)
    ax.set_ylabel("timesteps to reach (log scale)", fontsize=SMALL + 1)
    ax.set_yscale("log")
    if ymax > 0 and np.isfinite(ymin) and ymin > 0:
        ax.set_ylim(ymin / 1.6, ymax * 1.6)
    ax.legend(fontsize=SMALL, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0)
    _style(ax)
    _suptitle(fig, "Steps to reach reward thresholds (restricted mean: a DNF counts at the budget; 95% CI)", vlm_note)
    return fig


def figure3(curves: Sequence[SeedCurve], vlm_note: str, thresholds: Sequence[float] = (), window: int = 100
            ) -> Figure:
    """Figure 3: per-seed training curves, one panel per arm, shared axes, one colour per seed."""
    arms = order_arms(sorted({c.arm for c in curves}))
    fig = Figure(figsize=(WIDTH_IN, 3.4), layout="constrained")
    axes = np.atleast_1d(fig.subplots(1, max(len(arms), 1), sharex=True, sharey=True, squeeze=False)[0])
    for ax, arm in zip(axes, arms, strict=False):
        mine = [c for c in curves if c.arm == arm]
        for c in mine:
            ax.plot(c.steps, c.mean, color=seed_color(c.seed), alpha=0.9, linewidth=1.0, label=f"seed {c.seed}")
        for t in thresholds:
            ax.axhline(t, color="gray", linestyle="--", linewidth=0.7)
        _style(ax)
        ax.set_title(f"{arm} ({len(mine)} seeds)", fontsize=SMALL + 1)
        ax.set_xlabel("timestep", fontsize=SMALL + 1)
        ax.xaxis.get_offset_text().set_fontsize(SMALL)
        ax.ticklabel_format(axis="x", style="sci", scilimits=(0, 0))
    axes[0].set_ylabel(f"mean return (last {window} ep.)", fontsize=SMALL + 1)
    seeds = sorted({c.seed for c in curves})
    handles = [Line2D([], [], color=seed_color(seed), linewidth=1.5, label=f"seed {seed}") for seed in seeds]
    if handles:
        fig.legend(handles=handles, loc="outside lower center", ncols=min(len(handles), 10), fontsize=SMALL,
                   frameon=False)
    _suptitle(fig, "Individual training trajectories by seed", vlm_note)
    return fig


def mean_curves(curves: Sequence[SeedCurve], rng: np.random.Generator, n_points: int = 200,
                n_boot: int = stats.DEFAULT_N_BOOT, ci: float = 0.95
                ) -> tuple[np.ndarray, Mapping[str, tuple[np.ndarray, np.ndarray, np.ndarray]]]:
    """Common grid (shape ``(n_points,)``) and per arm ``(mean, low, high)`` over seeds on it."""
    end = max((float(c.steps[-1]) for c in curves if c.steps.size), default=1.0)
    grid = np.linspace(0.0, end, n_points)
    out = {}
    for arm in order_arms(sorted({c.arm for c in curves})):
        values = np.stack([on_grid(c, grid) for c in curves if c.arm == arm])
        out[arm] = stats.mean_band(values, rng, n_boot, ci)
    return grid, out


def figure4(curves: Sequence[SeedCurve], vlm_note: str, rng: np.random.Generator, thresholds: Sequence[float] = (),
            window: int = 100, n_boot: int = stats.DEFAULT_N_BOOT, ci: float = 0.95) -> Figure:
    """Figure 4: aggregated learning curve per arm, mean over seeds with a pointwise bootstrap band."""
    grid, bands = mean_curves(curves, rng, n_boot=n_boot, ci=ci)
    arms = list(bands)
    fig = Figure(figsize=(WIDTH_IN, 3.2), layout="constrained")
    ax = fig.subplots()
    for arm, (mean, low, high) in bands.items():
        n = sum(c.arm == arm for c in curves)
        plot_mean_curve(grid, mean, low, high, ax, arm_color(arm, arms), f"{arm} (n={n})")
    for t in thresholds:
        ax.axhline(t, color="gray", linestyle="--", linewidth=0.7)
    ax.set_xlabel("timestep", fontsize=SMALL + 1)
    ax.set_ylabel(f"mean return (last {window} ep.)", fontsize=SMALL + 1)
    ax.ticklabel_format(axis="x", style="sci", scilimits=(0, 0))
    ax.xaxis.get_offset_text().set_fontsize(SMALL)
    ax.legend(fontsize=SMALL, loc="lower right")
    _suptitle(fig, f"Aggregated training return (mean over seeds, {100 * ci:g}% bootstrap band)", vlm_note)
    return fig


def save_figure(fig: Figure, out: Path, stem: str, dpi: int = 200) -> list[Path]:
    """Save ``fig`` as ``out/stem.png`` and ``out/stem.pdf``; returns both paths."""
    paths = [out / f"{stem}.png", out / f"{stem}.pdf"]
    fig.savefig(paths[0], dpi=dpi)
    fig.savefig(paths[1])
    return paths


def figure_performance_profile(final_returns: Mapping[str, np.ndarray], vlm_note: str, ci: float = 0.95,
                               n_points: int = 200) -> Figure:
    """The performance profile of the final return: per arm (``final_returns``: arm -> shape ``(n_seeds,)``,
    NaN dropped), the fraction of seeds whose final return is at least ``tau``, with a pointwise Wilson band."""
    fig = Figure(figsize=(WIDTH_IN, 3.2), layout="constrained")
    ax = fig.subplots()
    _suptitle(fig, f"Performance profile of the final return ({100 * ci:g}% Wilson band over seeds)", vlm_note)
    arms = list(final_returns)
    finite = {a: v[np.isfinite(v)] for a, v in ((a, np.asarray(v, dtype=float)) for a, v in final_returns.items())}
    every = np.concatenate([v for v in finite.values()] or [np.zeros(0)])
    if every.size == 0:
        return fig
    pad = max(1.0, 0.05 * float(every.max() - every.min()))
    taus = np.linspace(float(every.min()) - pad, float(every.max()) + pad, n_points)
    for arm, values in finite.items():
        if values.size == 0:
            continue
        frac = performance_profile(values, taus)
        bands = [stats.wilson_ci(round(float(f) * values.size), int(values.size), ci) for f in frac]
        color = arm_color(arm, arms)
        ax.step(taus, frac, where="post", color=color, linewidth=1.5, label=f"{arm} (n={values.size})")
        ax.fill_between(taus, [b.low for b in bands], [b.high for b in bands], step="post", color=color, alpha=0.15,
                        linewidth=0)
    ax.set_xlabel("final return threshold tau (mean native return, last window)", fontsize=SMALL + 1)
    ax.set_ylabel("fraction of seeds >= tau", fontsize=SMALL + 1)
    ax.set_ylim(-0.02, 1.02)
    ax.legend(fontsize=SMALL, loc="lower left")
    _style(ax)
    return fig


def plot_per_arm(values: Mapping[str, np.ndarray], ax: Axes, ylabel: str = "", box: bool = False) -> None:
    """One column per arm (``values``: arm -> shape ``(n,)``, NaN dropped): every value as a dot, spread
    evenly, with a box plot if ``box``."""
    arms = list(values)
    for i, arm in enumerate(arms):
        v = np.asarray(values[arm], dtype=float)
        v = v[np.isfinite(v)]
        if v.size == 0:
            ax.annotate("not logged", (i, 0.5), xycoords=("data", "axes fraction"), ha="center", fontsize=SMALL)
            continue
        if box:
            ax.boxplot(v, positions=[i], widths=0.5, showfliers=False, medianprops={"color": "black"})
        offsets = np.linspace(-0.18, 0.18, v.size) if v.size > 1 else np.zeros(1)
        ax.plot(i + offsets, v, "o", color=arm_color(arm, arms), markersize=3, alpha=0.6)
    ax.set_xticks(range(len(arms)), arms)
    ax.set_xlim(-0.6, len(arms) - 0.4)
    ax.set_ylabel(ylabel, fontsize=SMALL + 1)
    _style(ax)


def figure_hacking(eval_lengths: Mapping[str, np.ndarray], hover: Mapping[str, np.ndarray],
                   gap: Mapping[str, np.ndarray], vlm_note: str, hover_flag: float, timeout: int = 200) -> Figure:
    """Reward-hacking diagnostic: detached episode lengths (``timeout``: the task's time limit),
    hover fraction per seed, shaped minus native return."""
    fig = Figure(figsize=(WIDTH_IN, 3.0), layout="constrained")
    ax_len, ax_hover, ax_gap = fig.subplots(1, 3)
    plot_per_arm(eval_lengths, ax_len, "detached episode length (steps)", box=True)
    ax_len.axhline(timeout, color="gray", linestyle="--", linewidth=0.7)
    ax_len.set_title(f"detached episodes ({timeout} = timeout)", fontsize=SMALL + 1)
    plot_per_arm(hover, ax_hover, "hover fraction of detached steps")
    ax_hover.axhline(hover_flag, color="tab:red", linestyle="--", linewidth=0.7)
    ax_hover.set_title("per seed (dashed: flag)", fontsize=SMALL + 1)
    plot_per_arm(gap, ax_gap, "shaped - native return (last window)")
    ax_gap.set_title("per seed, training", fontsize=SMALL + 1)
    for ax in (ax_len, ax_hover, ax_gap):
        ax.tick_params(axis="x", labelrotation=30)
    _suptitle(fig, "Reward-hacking diagnostic: does the policy hover short of the flag?", vlm_note)
    return fig


def plot_normalised_profile(taus: np.ndarray, profile: np.ndarray, low: np.ndarray, high: np.ndarray, arm: str,
                            arms: Sequence[str], ax: Axes) -> None:
    """One arm's performance profile across tasks (``vlmrl compare``), arrays of shape ``(n_taus,)``;
    ``arms``: the figure's, for a stable colour."""
    color = arm_color(arm, arms)
    ax.plot(taus, profile, color=color, linewidth=1.5, label=arm)
    ax.fill_between(taus, low, high, color=color, alpha=0.15, linewidth=0)
    ax.set_ylabel("fraction of runs > tau", fontsize=SMALL + 1)
    ax.set_ylim(-0.02, 1.02)
    ax.legend(fontsize=SMALL, loc="lower left")
    _style(ax)

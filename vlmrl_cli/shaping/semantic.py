"""The macro-semantic potential Phi(s) (paper Section 3.2), from camera views only: one oracle per
run (prototype cache, VLM), one ``EpisodePotential`` per env (schedule, lock). See docs/method.md."""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable

import numpy as np

from vlmrl_cli.shaping.arms import PotentialSource
from vlmrl_cli.shaping.camera import FrameView
from vlmrl_cli.shaping.config import ShapingConfig
from vlmrl_cli.shaping.features import FEATURE_UNIT
from vlmrl_cli.shaping.hysteresis import LockState, lock_step
from vlmrl_cli.shaping.rbf import RBFField, squared_distances
from vlmrl_cli.tracking import schema
from vlmrl_cli.vlm.base import Answer
from vlmrl_cli.vlm.client import VLMClient
from vlmrl_cli.vlm.parsers import parse_float, parse_mcq
from vlmrl_cli.vlm.prompts import Milestones, NumberQuestions


class SemanticOracle:
    """The VLM behind a visual prototype cache, shared by the envs of one run: ``source`` picks the
    prompt, ``MCQ`` (the task's milestones) or ``FLOAT`` (its float question, ``numbers``)."""

    def __init__(self, client: VLMClient, cfg: ShapingConfig, source: PotentialSource, milestones: Milestones,
                 feature_dim: int, rbf: bool = True, numbers: NumberQuestions | None = None,
                 max_queries: int | None = None) -> None:
        if source is PotentialSource.NONE:
            raise ValueError("a SemanticOracle needs a potential source (MCQ or FLOAT); arms without one need none.")
        if not (math.isfinite(cfg.reuse_radius) and cfg.reuse_radius >= 0):
            raise ValueError(f"ShapingConfig.reuse_radius must be >= 0 (0 disables reuse), got {cfg.reuse_radius}.")
        if cfg.query_every < 1 or cfg.confirm < 1:
            raise ValueError(
                f"ShapingConfig.query_every and confirm must be >= 1, got {cfg.query_every} and {cfg.confirm}."
            )
        self.client = client
        self.cfg = cfg
        self.source = source
        self.rbf = rbf
        self.max_queries = max_queries
        if source is PotentialSource.MCQ:
            unknown = sorted(set(milestones.labels) ^ {label for label, _ in cfg.label_potentials})
            if unknown:
                raise ValueError(f"the label map and the task's labels differ in {', '.join(unknown)}; give a "
                                 "potential for every label of the task, and for no other")
        if source is PotentialSource.FLOAT and numbers is None:
            raise ValueError("a FLOAT potential needs the task's float question (Task.numbers)")
        self._numbers = numbers
        self._prompt = milestones.prompt if numbers is None or source is PotentialSource.MCQ else numbers.float_prompt
        self._labels = milestones.labels
        self._potential_of = dict(cfg.label_potentials)
        self._row_of: dict[str, int] = {}  # each labelled frame's prototype
        # A stochastic VLM is asked every time: reusing a frame's label would freeze its first draw.
        self._stochastic = bool(getattr(client, "stochastic", False))
        self._field = RBFField(cfg.bandwidth, feature_dim, unit=FEATURE_UNIT)
        self._queries = 0
        self._cache_hits = 0
        self._reuses = 0
        self._parse_failures = 0
        self._budget_labels = 0
        self._requests: list[FrameView] = []
        # the round's answers: by frame key (a deterministic VLM), or in the order asked (a stochastic one)
        self._fetched: dict[str, Answer] = {}
        self._fetched_in_order: deque[tuple[str, Answer]] = deque()

    def __deepcopy__(self, memo: dict[int, object]) -> SemanticOracle:
        # gymnasium's RecordConstructorArgs deep-copies wrapper arguments: a copied env shares the oracle
        return self

    @property
    def prototypes(self) -> int:
        return self._field.prototypes

    def request(self, view: FrameView) -> None:
        """Say that ``view`` is labelled in this vector step, in the order labels are then taken."""
        self._requests.append(view)

    def fetch(self) -> None:
        """Ask the VLM, in one call, about every requested view whose label may need it (all of
        them for a stochastic VLM), within the budget; ``label`` then reads the answers."""
        views, self._requests = self._requests, []
        self._fetched.clear()  # what an earlier round fetched and no label took
        self._fetched_in_order.clear()
        need = views if self._stochastic else list({  # each new frame once, in the order first requested
            v.key: v for v in views if v.key not in self._row_of and self._nearby(v) is None}.values())
        if self.max_queries is not None:
            need = need[: max(self.max_queries - self._queries, 0)]
        if not need:
            return
        answers = self.client.ask_many(self._prompt, [view.frame() for view in need])
        if self._stochastic:
            self._fetched_in_order.extend((view.key, answer) for view, answer in zip(need, answers, strict=True))
        else:
            self._fetched.update((view.key, answer) for view, answer in zip(need, answers, strict=True))

    def label(self, view: FrameView) -> float | None:
        """The raw potential of the view's label (reused or asked), or None if unparsed; a
        stochastic VLM is asked every time, its newest answer replacing the prototype's potential."""
        if not self._stochastic:  # the frame's own label, else (reuse_radius > 0) a near prototype's
            row = self._row_of.get(view.key)
            row = self._nearby(view) if row is None else row
            if row is not None:
                self._reuses += 1
                return float(self._field.potentials[row])
        if self.max_queries is not None and self._queries >= self.max_queries:  # the nearest prototype's
            if not self.prototypes:
                return None
            self._budget_labels += 1
            return float(self._field.potentials[self._nearest(view)[0]])
        potential = self._ask(view)
        if potential is None:
            self._parse_failures += 1
            return None
        if not self._stochastic:  # its label is known for good: its pixels are not asked for again
            view.release()
        self._add(view, potential)
        return potential

    def _nearby(self, view: FrameView) -> int | None:
        """The row of the nearest prototype within ``reuse_radius`` of ``view``, else None."""
        if not self.prototypes or self.cfg.reuse_radius <= 0:
            return None
        nearest, sq = self._nearest(view)
        return nearest if math.sqrt(sq) < self.cfg.reuse_radius else None

    def _nearest(self, view: FrameView) -> tuple[int, float]:
        """The row of the prototype nearest to ``view`` and its squared feature distance."""
        sq = squared_distances(self._field.features, view.features, unit=FEATURE_UNIT)
        row = int(np.argmin(sq))
        return row, float(sq[row])

    def _answer(self, view: FrameView) -> Answer:
        """The VLM's answer about ``view``: the round's (``fetch``), else asked now."""
        if self._stochastic:
            if self._fetched_in_order and self._fetched_in_order[0][0] == view.key:
                return self._fetched_in_order.popleft()[1]
        elif view.key in self._fetched:
            return self._fetched.pop(view.key)
        return self.client.ask(self._prompt, view.frame())

    def _ask(self, view: FrameView) -> float | None:
        answer = self._answer(view)
        self._queries += 1
        self._cache_hits += int(answer.cached)
        if self.source is PotentialSource.MCQ:
            mcq = parse_mcq(answer.text, self._labels)
            if not mcq.ok or mcq.label is None:
                return None
            return float(self._potential_of[mcq.label])
        numbers = self._numbers
        assert numbers is not None  # checked in __init__
        number = parse_float(answer.text, numbers.low, numbers.high)
        if not number.ok or number.value is None or not math.isfinite(number.value):
            return None
        return numbers.potential(number.value)

    def _add(self, view: FrameView, potential: float) -> None:
        row = self._row_of.get(view.key)
        if row is not None:  # only a stochastic VLM asks about a known frame again: its newest answer wins
            self._field.set_potential(row, potential)
            return
        self._row_of[view.key] = self._field.prototypes
        self._field.add_prototype(view.features, potential)

    def phi_rbf(self, view: FrameView) -> float:
        """RBF-smoothed potential of the view over the prototypes (0.0 before the first one)."""
        return self._field.value(view.key, view.features)

    @property
    def field_value(self) -> Callable[[str, np.ndarray], float]:
        """``phi_rbf`` as a function of (key, features): the RBF field's own ``value``."""
        return self._field.value

    def stats(self) -> dict[str, float]:
        """Counters since construction."""
        return {
            schema.METRIC_VLM_QUERIES: float(self._queries),
            schema.METRIC_VLM_CACHE_HITS: float(self._cache_hits),
            schema.METRIC_VLM_PROTOTYPES: float(self.prototypes),
            schema.METRIC_VLM_LABEL_REUSES: float(self._reuses),
            schema.METRIC_VLM_PARSE_FAILURES: float(self._parse_failures),
            schema.METRIC_VLM_BACKEND_CALLS: float(self.client.stats.backend_calls),
            schema.METRIC_VLM_BACKEND_FRAMES: float(self.client.stats.backend_frames),
            schema.METRIC_VLM_LARGEST_BATCH: float(self.client.stats.largest_batch),
            schema.METRIC_VLM_BACKEND_S: float(self.client.stats.backend_seconds),
            schema.METRIC_VLM_BUDGET_LABELS: float(self._budget_labels),
            schema.METRIC_VLM_SCORED: float(self.client.stats.scored),
            schema.METRIC_VLM_GENERATED: float(self.client.stats.generated),
        }


class EpisodePotential:
    """Phi(s) of one env: ``reset(view)`` at an episode's start (it labels step 0 and resets the
    lock), ``step(view)`` with every next state's view; both return Phi of that state."""

    def __init__(self, oracle: SemanticOracle, lock: bool) -> None:
        self.oracle = oracle
        self.lock = lock
        self.query_every = oracle.cfg.query_every
        self.confirm = oracle.cfg.confirm
        self.lock_state = LockState()
        self.held = 0.0  # the latest label's raw potential, held between labels
        self.steps_since_label = 0
        # the oracle's RBF field's value(key, features), looked up once (None without the RBF)
        self._rbf_value = oracle.field_value if oracle.rbf else None

    def request_step(self, view: FrameView) -> None:
        """Register the next step's label with the oracle's round, when that step labels."""
        if self.steps_since_label + 1 >= self.query_every:
            self.oracle.request(view)

    def reset(self, view: FrameView) -> float:
        self.lock_state = LockState()
        self.held = 0.0
        self.steps_since_label = self.query_every - 1  # so that ``step`` labels the reset's view
        return self.step(view)

    def step(self, view: FrameView) -> float:
        self.steps_since_label += 1
        if self.steps_since_label >= self.query_every:
            self.steps_since_label = 0
            self._label(view)
        base = self._rbf_value(view.key, view.features) if self._rbf_value is not None else self.held
        return max(self.lock_state.level, base) if self.lock else base

    def _label(self, view: FrameView) -> None:
        potential = self.oracle.label(view)
        if potential is None:  # unparsed: keep the previous potential, the lock sees nothing
            return
        self.held = potential
        if self.lock:
            self.lock_state = lock_step(self.lock_state, potential, self.confirm)

"""Parse raw VLM text (the formats small VLMs emit) into typed answers; a parser never raises."""

from __future__ import annotations

import contextlib
import functools
import json
import math
import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from enum import StrEnum
from typing import Concatenate, ParamSpec, TypeVar

Box = tuple[float, float, float, float]
P = ParamSpec("P")


class ParseStatus(StrEnum):
    """How a raw answer parsed; only ``OK`` carries a usable value. FORMAT_COLLAPSE: nothing
    parseable or ``Error [0, 0, 0, 0]``; OUT_OF_RANGE: outside the task's range or frame, or a
    degenerate box; AMBIGUOUS: several different answers; NO_ANSWER: no text (replay had none)."""

    OK = "ok"
    FORMAT_COLLAPSE = "format_collapse"
    OUT_OF_RANGE = "out_of_range"
    AMBIGUOUS = "ambiguous"
    EMPTY = "empty"
    NO_ANSWER = "no_answer"


@dataclass(frozen=True)
class _Parsed:
    status: ParseStatus

    @property
    def ok(self) -> bool:
        return self.status is ParseStatus.OK


@dataclass(frozen=True)
class FloatResult(_Parsed):
    """A parsed number (the task's units). ``value`` is set for OK and OUT_OF_RANGE, else None."""

    value: float | None = None


@dataclass(frozen=True)
class BoxResult(_Parsed):
    """A parsed box (x0, y0, x1, y1, pixels) for OK and OUT_OF_RANGE; ``normalised``: given as 0-1."""

    box: Box | None = None
    normalised: bool = False


@dataclass(frozen=True)
class MCQResult(_Parsed):
    """A parsed zone label, set only for OK."""

    label: str | None = None


R = TypeVar("R", bound=_Parsed)


def _guarded(result: type[R]) -> Callable[[Callable[Concatenate[str, P], R]], Callable[Concatenate[str | None, P], R]]:
    """A parser that answers NO_ANSWER for None, EMPTY for blank text and FORMAT_COLLAPSE for any error."""

    def wrap(parse: Callable[Concatenate[str, P], R]) -> Callable[Concatenate[str | None, P], R]:
        @functools.wraps(parse)
        def parser(text: str | None, *args: P.args, **kwargs: P.kwargs) -> R:
            if text is None:
                return result(ParseStatus.NO_ANSWER)
            if not text.strip():
                return result(ParseStatus.EMPTY)
            try:
                return parse(text, *args, **kwargs)
            except Exception:  # a parser must never take the probe down; odd input is a collapse
                return result(ParseStatus.FORMAT_COLLAPSE)

        return parser

    return wrap


_NUM = r"[-+\u2212]?(?:\d+(?:\.\d*)?|\.\d+)(?:[eE][-+]?\d+)?"
_NUMBER = re.compile(_NUM)
# "x = -0.5", "x: -0.5", "x ≈ -0.5", "position is -0.5"
_ASSIGNED = re.compile(rf"(?:\bx\b|position)\s*(?:=|:|≈|~|is(?:\s+about|\s+approximately)?)\s*({_NUM})", re.I)
_SEP = r"\s*[,;]\s*|\s+"
_BOX = re.compile(
    rf"[\[(]\s*({_NUM})(?:{_SEP})({_NUM})(?:{_SEP})({_NUM})(?:{_SEP})({_NUM})\s*[\])]"
)
_JSON_OBJECT = re.compile(r"\{[^{}]*\}")
_JSON_KEYS: tuple[tuple[str, str, str, str], ...] = (
    ("x_min", "y_min", "x_max", "y_max"),
    ("xmin", "ymin", "xmax", "ymax"),
    ("x0", "y0", "x1", "y1"),
    ("x1", "y1", "x2", "y2"),
    ("left", "top", "right", "bottom"),
)


def _to_float(token: str) -> float | None:
    try:
        value = float(token.replace("\u2212", "-"))
    except (ValueError, OverflowError):
        return None
    return None if math.isnan(value) else value


@_guarded(FloatResult)
def parse_float(text: str, low: float, high: float) -> FloatResult:
    """The one number in a float answer (``x = ...`` wins); outside ``[low, high]``: OUT_OF_RANGE."""
    assigned = [v for v in (_to_float(m) for m in _ASSIGNED.findall(text)) if v is not None]
    candidates = assigned or [v for v in (_to_float(m) for m in _NUMBER.findall(text)) if v is not None]
    distinct = list(dict.fromkeys(candidates))
    if not distinct:
        return FloatResult(ParseStatus.FORMAT_COLLAPSE)
    if len(distinct) > 1:
        return FloatResult(ParseStatus.AMBIGUOUS)
    value = distinct[0]
    if not (math.isfinite(value) and low <= value <= high):
        return FloatResult(ParseStatus.OUT_OF_RANGE, value)
    return FloatResult(ParseStatus.OK, value)


def _json_boxes(text: str) -> list[tuple[float, ...]]:
    boxes: list[tuple[float, ...]] = []
    for blob in _JSON_OBJECT.findall(text):
        try:
            obj = json.loads(blob)
        except ValueError:
            continue
        if not isinstance(obj, dict):
            continue
        lowered = {str(k).lower(): v for k, v in obj.items()}
        for keys in _JSON_KEYS:
            if all(k in lowered for k in keys):
                with contextlib.suppress(TypeError, ValueError, OverflowError):
                    boxes.append(tuple(float(lowered[k]) for k in keys))
                break
    return boxes


def _validate_box(raw: tuple[float, ...], width: int, height: int) -> BoxResult:
    if any(math.isnan(v) for v in raw) or all(v == 0 for v in raw):  # all 0: "Error [0, 0, 0, 0]", it gave up
        return BoxResult(ParseStatus.FORMAT_COLLAPSE)
    normalised = all(0.0 <= v <= 1.0 for v in raw)
    if normalised:  # 0-1 coordinates (fractions of width and height) are scaled to pixels
        raw = (raw[0] * width, raw[1] * height, raw[2] * width, raw[3] * height)
    x0, y0, x1, y1 = raw
    box = (float(x0), float(y0), float(x1), float(y1))
    inside = x0 >= 0 and y0 >= 0 and x1 <= width and y1 <= height
    if not inside or x1 <= x0 or y1 <= y0:
        return BoxResult(ParseStatus.OUT_OF_RANGE, box, normalised)
    return BoxResult(ParseStatus.OK, box, normalised)


@_guarded(BoxResult)
def parse_box(text: str, width: int, height: int) -> BoxResult:
    """The box (x0, y0, x1, y1, pixels) in an answer: a list, JSON or four numbers; 0-1 ones are fractions."""
    boxes: list[tuple[float, ...]] = _json_boxes(text)
    if not boxes:
        for match in _BOX.finditer(text):
            values = tuple(_to_float(g) for g in match.groups())
            if all(v is not None for v in values):
                boxes.append(tuple(float(v) for v in values if v is not None))
    if not boxes:
        numbers = [_to_float(m) for m in _NUMBER.findall(text)]
        if len(numbers) == 4 and all(v is not None for v in numbers):
            boxes.append(tuple(float(v) for v in numbers if v is not None))
    distinct = list(dict.fromkeys(boxes))
    if not distinct:
        return BoxResult(ParseStatus.FORMAT_COLLAPSE)
    if len(distinct) > 1:
        return BoxResult(ParseStatus.AMBIGUOUS)
    return _validate_box(distinct[0], width, height)


@functools.lru_cache(maxsize=16)
def _label_patterns(labels: tuple[str, ...]) -> tuple[re.Pattern[str], re.Pattern[str]]:
    """The (``Choice = X``, bare label) patterns of a vocabulary, longest label first (``NEAR TOP``)."""
    words = sorted((re.escape(_normalise_label_text(label)) for label in labels), key=len, reverse=True)
    alternatives = "|".join(words)
    return (re.compile(rf"\b(?:CHOICE|ANSWER|LABEL|ZONE)\s*(?:=|:|IS)\s*({alternatives})\b"),
            re.compile(rf"\b({alternatives})\b"))


def _normalise_label_text(text: str) -> str:
    return re.sub(r"[\s_\-]+", " ", text.upper())


@_guarded(MCQResult)
def parse_mcq(text: str, labels: Sequence[str]) -> MCQResult:
    """The one label of ``labels`` in an MCQ answer, in any case and word separator; ``Choice = X`` wins."""
    norm = _normalise_label_text(text)
    choice, label = _label_patterns(tuple(labels))
    chosen = list(dict.fromkeys(choice.findall(norm))) or list(dict.fromkeys(label.findall(norm)))
    if not chosen:
        return MCQResult(ParseStatus.FORMAT_COLLAPSE)
    if len(chosen) > 1:
        return MCQResult(ParseStatus.AMBIGUOUS)
    return MCQResult(ParseStatus.OK, chosen[0].replace(" ", "_"))

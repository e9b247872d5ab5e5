"""Parse raw VLM text into typed answers; a parser never raises, it reports a status.

Each parser accepts the formats small VLMs actually emit (bare values, values in prose,
``x = -0.5``, ``Box [..]``, JSON, ``Choice = BOTTOM``) and classifies everything else:

- ``FORMAT_COLLAPSE``: nothing parseable, or the all-zero ``Error [0, 0, 0, 0]`` box;
- ``OUT_OF_RANGE``: a float outside the task's range (``NumberQuestions``), a box outside the
  frame or degenerate (zero or negative width/height);
- ``AMBIGUOUS``: several different answers in one text (two labels, two numbers, two boxes);
- ``EMPTY``: blank text; ``NO_ANSWER``: there was no text at all (replay had no record).
"""

from __future__ import annotations

import contextlib
import functools
import json
import math
import re
from collections.abc import Sequence
from dataclasses import dataclass
from enum import StrEnum

Box = tuple[float, float, float, float]


class ParseStatus(StrEnum):
    """How a raw answer parsed; only ``OK`` answers carry a usable value."""

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
    """A parsed box (x0, y0, x1, y1) in image pixels, set for OK and OUT_OF_RANGE, else None.

    ``normalised`` is True when the text gave 0-1 coordinates, which were scaled to pixels.
    """

    box: Box | None = None
    normalised: bool = False


@dataclass(frozen=True)
class MCQResult(_Parsed):
    """A parsed zone label, set only for OK."""

    label: str | None = None


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


def parse_float(text: str | None, low: float, high: float) -> FloatResult:
    """The number in a float answer; outside ``[low, high]`` (the task's range) it is OUT_OF_RANGE.

    An explicit ``x = ...`` wins; otherwise the text must hold exactly one distinct number.

    Example:
        >>> parse_float("The car is at approximately -0.52.", -1.2, 0.6)
        FloatResult(status=<ParseStatus.OK: 'ok'>, value=-0.52)
        >>> parse_float("7", -1.2, 0.6).status, parse_float("no idea", -1.2, 0.6).status
        (<ParseStatus.OUT_OF_RANGE: 'out_of_range'>, <ParseStatus.FORMAT_COLLAPSE: 'format_collapse'>)
    """
    try:
        if text is None:
            return FloatResult(ParseStatus.NO_ANSWER)
        if not text.strip():
            return FloatResult(ParseStatus.EMPTY)
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
    except Exception:  # a parser must never take the probe down; odd input is a collapse
        return FloatResult(ParseStatus.FORMAT_COLLAPSE)


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
    if any(math.isnan(v) for v in raw):
        return BoxResult(ParseStatus.FORMAT_COLLAPSE)
    if all(v == 0 for v in raw):
        return BoxResult(ParseStatus.FORMAT_COLLAPSE)  # "Error [0, 0, 0, 0]": the model gave up
    normalised = all(0.0 <= v <= 1.0 for v in raw)
    if normalised:  # 0-1 coordinates (fractions of width and height) are scaled to pixels
        raw = (raw[0] * width, raw[1] * height, raw[2] * width, raw[3] * height)
    x0, y0, x1, y1 = raw
    box = (float(x0), float(y0), float(x1), float(y1))
    inside = x0 >= 0 and y0 >= 0 and x1 <= width and y1 <= height
    if not inside or x1 <= x0 or y1 <= y0:
        return BoxResult(ParseStatus.OUT_OF_RANGE, box, normalised)
    return BoxResult(ParseStatus.OK, box, normalised)


def parse_box(text: str | None, width: int, height: int) -> BoxResult:
    """The box (x0, y0, x1, y1) in image pixels in a box answer about a ``width`` x ``height`` frame.

    Accepts ``[a, b, c, d]``, ``(a, b, c, d)``, ``Box [..]``, JSON objects with ``x_min``..
    ``y_max`` (or ``xmin``.., ``x1``..``y2``, ``left``..``bottom``), and four bare numbers.
    Boxes whose four coordinates all lie in [0, 1] are read as fractions of the frame's width
    and height and scaled to pixels (``normalised=True``).

    Example:
        >>> parse_box("Box [450, 210, 480, 230]", 600, 400).box
        (450.0, 210.0, 480.0, 230.0)
        >>> parse_box("Error [0, 0, 0, 0]", 600, 400).status
        <ParseStatus.FORMAT_COLLAPSE: 'format_collapse'>
        >>> parse_box('{"x_min": 0.5, "y_min": 0.5, "x_max": 0.75, "y_max": 1.0}', 600, 400).box
        (300.0, 200.0, 450.0, 400.0)
    """
    try:
        if text is None:
            return BoxResult(ParseStatus.NO_ANSWER)
        if not text.strip():
            return BoxResult(ParseStatus.EMPTY)
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
    except Exception:  # a parser must never take the probe down; odd input is a collapse
        return BoxResult(ParseStatus.FORMAT_COLLAPSE)


@functools.lru_cache(maxsize=16)
def _label_patterns(labels: tuple[str, ...]) -> tuple[re.Pattern[str], re.Pattern[str]]:
    """The (choice, label) patterns of a vocabulary: ``Choice = X`` (or ``Answer:``, ``Label is``,
    ``Zone:``) and a bare label; longer labels first, so that ``NEAR TOP`` is not read as ``TOP``."""
    words = sorted((re.escape(_normalise_label_text(label)) for label in labels), key=len, reverse=True)
    alternatives = "|".join(words)
    return (re.compile(rf"\b(?:CHOICE|ANSWER|LABEL|ZONE)\s*(?:=|:|IS)\s*({alternatives})\b"),
            re.compile(rf"\b({alternatives})\b"))


def _normalise_label_text(text: str) -> str:
    return re.sub(r"[\s_\-]+", " ", text.upper())


def parse_mcq(text: str | None, labels: Sequence[str]) -> MCQResult:
    """The label of the task's vocabulary ``labels`` (upper-case, ``_`` between words) in an MCQ
    answer, in any case, with ``_``, ``-`` or spaces inside.

    ``Choice = X`` / ``Answer: X`` wins; otherwise exactly one distinct label must appear
    (a text naming two labels, e.g. an echo of the choices, is AMBIGUOUS).

    Example:
        >>> stages = ("LOW", "HALF_WAY", "NEAR_TOP", "TOP")
        >>> parse_mcq("Choice = LOW", stages).label, parse_mcq("near-top.", stages).label
        ('LOW', 'NEAR_TOP')
        >>> parse_mcq("LOW or HALF_WAY", stages).status
        <ParseStatus.AMBIGUOUS: 'ambiguous'>
        >>> parse_mcq("Answer: above bar", ("HANGING", "ABOVE_BAR")).label
        'ABOVE_BAR'
    """
    try:
        if text is None:
            return MCQResult(ParseStatus.NO_ANSWER)
        if not text.strip():
            return MCQResult(ParseStatus.EMPTY)
        norm = _normalise_label_text(text)
        choice, label = _label_patterns(tuple(labels))
        chosen = list(dict.fromkeys(choice.findall(norm))) or list(dict.fromkeys(label.findall(norm)))
        if not chosen:
            return MCQResult(ParseStatus.FORMAT_COLLAPSE)
        if len(chosen) > 1:
            return MCQResult(ParseStatus.AMBIGUOUS)
        return MCQResult(ParseStatus.OK, chosen[0].replace(" ", "_"))
    except Exception:  # a parser must never take the probe down; odd input is a collapse
        return MCQResult(ParseStatus.FORMAT_COLLAPSE)

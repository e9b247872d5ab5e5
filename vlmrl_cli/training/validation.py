"""The typed input schema of a run's configuration (pydantic models of the frozen dataclasses and
their fields' ``rules``), checked whole before anything runs: one ``BadInput`` naming the key."""

from __future__ import annotations

import dataclasses
import functools
import json
import typing
from collections.abc import Callable
from typing import Annotated, Any

from pydantic import BaseModel, ConfigDict, ValidationError, create_model
from pydantic import model_validator as _model_validator

from vlmrl_cli.core.errors import BadInput, did_you_mean
from vlmrl_cli.core.fields import is_carried, rules_of
from vlmrl_cli.core.provenance import to_jsonable


def batch_sizes_near(rollout: int, batch_size: int) -> list[int]:
    """The minibatch sizes SB3's PPO takes whole for a rollout of ``rollout`` samples (divisors of
    it, at least 2) nearest to ``batch_size``: the largest below it and the smallest above it.

    Example:
        >>> batch_sizes_near(256, 3), batch_sizes_near(128, 100), batch_sizes_near(128, 1)
        ([2, 4], [64, 128], [2])
    """
    sizes = [d for d in range(2, rollout + 1) if rollout % d == 0]
    below = [d for d in sizes if d < batch_size]
    above = [d for d in sizes if d > batch_size]
    return [*below[-1:], *above[:1]]


def _ppo_consistent(ppo: Any) -> Any:
    """SB3's PPO's rules over several knobs, refused before a run starts: a rollout of at least 2
    samples, cut into whole minibatches of at least 2 (it normalises each one's advantages)."""
    rollout = ppo.n_envs * ppo.n_steps
    product = f"ppo.n_envs x ppo.n_steps ({ppo.n_envs} x {ppo.n_steps} = {rollout})"
    if ppo.batch_size > rollout:
        raise ValueError(f"ppo.batch_size ({ppo.batch_size}) exceeds {product}; lower batch_size or raise n_steps")
    if rollout < 2:
        raise ValueError("ppo.n_envs x ppo.n_steps must be at least 2 (PPO needs two samples per rollout)")
    fits = " or ".join(map(str, batch_sizes_near(rollout, ppo.batch_size)))
    if ppo.batch_size < 2:
        raise ValueError(f"ppo.batch_size ({ppo.batch_size}) must be at least 2 (SB3's PPO normalises the "
                         f"advantages of each minibatch); use a batch_size that divides {rollout}, e.g. {fits}")
    if rollout % ppo.batch_size:
        raise ValueError(f"ppo.batch_size ({ppo.batch_size}) does not divide {product}: SB3 would train on a "
                         f"truncated last minibatch of {rollout % ppo.batch_size}; use a batch_size that divides "
                         f"{rollout}, e.g. {fits}, or n_envs x n_steps a multiple of {ppo.batch_size}")
    return ppo


#: Rules over several fields of one section (the section's dotted prefix -> check).
CHECKS: dict[str, Callable[[Any], Any]] = {"ppo": _ppo_consistent}


@functools.cache
def _model(cls: type, prefix: str = "") -> type[BaseModel]:
    """A pydantic model of dataclass ``cls`` (nested ones nested), its fields' rules and ``CHECKS``."""
    hints = typing.get_type_hints(cls)
    fields: dict[str, Any] = {}
    for f in dataclasses.fields(cls):
        if is_carried(f):  # resolved from the other fields, never read from a file
            continue
        key = f"{prefix}{f.name}"
        tp = hints[f.name]
        nested = _dataclass_in(tp)
        if nested is not None:
            sub = _model(nested, f"{key}.")
            tp = sub | None if type(None) in typing.get_args(tp) else sub
        rules = rules_of(f)
        if rules:
            tp = Annotated[tp, *rules]
        default: Any = f.default_factory() if f.default_factory is not dataclasses.MISSING else f.default
        default = ... if default is dataclasses.MISSING else default
        if dataclasses.is_dataclass(default) and not isinstance(default, type):
            default = _model(type(default), f"{key}.").model_validate_json(json.dumps(to_jsonable(default)))
        fields[f.name] = (tp, default)
    validators: dict[str, Any] = {}
    check = CHECKS.get(prefix.removesuffix("."))
    if check is not None:
        validators["consistent"] = _model_validator(mode="after")(check)
    return create_model(  # type: ignore[call-overload,no-any-return]
        f"{cls.__name__}Input",
        # no knob means anything at NaN or infinity: refused here, before any store or run exists
        __config__=ConfigDict(extra="forbid", strict=True, frozen=True, allow_inf_nan=False),
        __validators__=validators,
        **fields,
    )


def _dataclass_in(tp: Any) -> type | None:
    """The dataclass type in ``X`` or ``X | None``, else None."""
    for t in (tp, *typing.get_args(tp)):
        if isinstance(t, type) and dataclasses.is_dataclass(t):
            return t
    return None


def _to_dataclass(cls: type, model: BaseModel, carried: dict[str, Any] | None = None) -> Any:
    hints = typing.get_type_hints(cls)
    kwargs: dict[str, Any] = dict(carried or {})
    for f in dataclasses.fields(cls):
        if is_carried(f):
            continue
        value = getattr(model, f.name)
        nested = _dataclass_in(hints[f.name])
        if nested is not None and isinstance(value, BaseModel):
            value = _to_dataclass(nested, value)
        kwargs[f.name] = value
    return cls(**kwargs)


def _sentence(err: Any, cls: type, at: str = "") -> str:
    rel = [str(part) for part in err["loc"] if not isinstance(part, int)]
    loc = [*filter(None, at.split(".")), *rel]
    key = ".".join(loc)
    if err["type"] == "extra_forbidden":
        section = loc[:-1]
        known = [".".join([*section, k]) for k in _section_fields(cls, rel[:-1])]
        where = f"[{'.'.join(section)}]" if section else "the top level"
        return (
            f"unknown key '{key}'{did_you_mean(key, known)}; known keys in {where}: "
            f"{', '.join(k.rsplit('.', 1)[-1] for k in known)}."
        )
    msg = str(err["msg"]).removeprefix("Value error, ")
    msg = msg[:1].lower() + msg[1:]
    if err["type"] == "value_error" and rel and rel[0] in CHECKS and len(rel) == 1 and not at:
        return f"inconsistent [{key}]: {msg}."
    shown = json.dumps(err.get("input"), default=str)
    shown = shown if len(shown) <= 60 else shown[:57] + "..."
    return f"invalid {key or 'configuration'} = {shown}: {msg}."


def _section_fields(cls: type, section: list[str]) -> list[str]:
    """The keys of the table ``section`` of ``cls`` (none when it is no table)."""
    for part in section:
        nested = _dataclass_in(typing.get_type_hints(cls)[part])
        if nested is None:
            return []
        cls = nested
    return [f.name for f in dataclasses.fields(cls) if not is_carried(f)]


def validate_as(cls: type, raw: dict[str, Any], at: str = "", **carried: Any) -> Any:
    """``raw`` (plain values, as TOML gives them) checked against dataclass ``cls`` and built into it
    with its ``CARRIED`` fields from ``carried``; else ``BadInput`` naming the first wrong key."""
    try:
        blob = json.dumps(to_jsonable(raw))
    except (TypeError, ValueError) as exc:
        raise BadInput(f"the configuration holds a value that is no number, string, boolean or list ({exc}).") from exc
    try:
        model = _model(cls).model_validate_json(blob)
    except ValidationError as exc:
        raise BadInput(_sentence(exc.errors()[0], cls, at)) from None
    return _to_dataclass(cls, model, carried)

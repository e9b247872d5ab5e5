"""The typed input schema of a run's configuration, checked whole before anything runs.

Field names, types and defaults come from the frozen dataclasses themselves (``RunConfig``,
``PPOConfig``, ``VLMConfig``, ``SimKnobs``, ``ShapingConfig``); the ranges and the cross-field
rules are declared here, once, in ``RULES`` and ``CHECKS``. pydantic builds one model per
dataclass from both and validates a raw configuration (the merged layers of preset, config file,
``--set`` and flags) with TOML's typing: strict JSON mode, so ``alpha = "big"`` or
``n_envs = 1.5`` is an error, while an integer is a valid float.

Every failure becomes one ``BadInput`` sentence that names the dotted key, e.g.
``invalid ppo.gamma = 1.5: input should be less than or equal to 1.`` or
``unknown key 'ppo.nenvs' (did you mean 'ppo.n_envs'?).``
"""

from __future__ import annotations

import dataclasses
import functools
import json
import typing
from collections.abc import Callable
from typing import Annotated, Any

from annotated_types import Ge, Gt, Interval
from pydantic import AfterValidator, BaseModel, BeforeValidator, ConfigDict, ValidationError, create_model
from pydantic import model_validator as _model_validator

from vlmrl_cli.core.errors import BadInput, did_you_mean
from vlmrl_cli.core.names import experiment_problem, tracking_uri_problem
from vlmrl_cli.frames.geometry import Zone
from vlmrl_cli.shaping.arms import parse_arms
from vlmrl_cli.shaping.config import DEFAULT_LABEL_POTENTIALS
from vlmrl_cli.training.events import EXECUTORS
from vlmrl_cli.training.presets import PRESETS
from vlmrl_cli.vlm.config import BACKENDS, SIM_PROFILES


def _known_arms(arms: tuple[str, ...]) -> tuple[str, ...]:
    try:
        parse_arms(",".join(arms))
    except BadInput as exc:
        raise ValueError(str(exc).removesuffix(".")) from None
    return arms


def _distinct_seeds(seeds: tuple[int, ...]) -> tuple[int, ...]:
    if not seeds:
        raise ValueError("no seed given; pass --seeds N (N >= 1) or --seed-list 0,1,2")
    if len(set(seeds)) != len(seeds):
        raise ValueError("a seed is listed twice; list each seed once")
    if any(s < 0 for s in seeds):
        raise ValueError("seeds must be non-negative integers")
    return seeds


def _one_of(choices: tuple[str, ...] | dict[str, Any], what: str) -> Callable[[str], str]:
    def check(value: str) -> str:
        if value not in choices:
            hint = did_you_mean(value, choices)
            raise ValueError(f"unknown {what} '{value}'{hint}; choose from {', '.join(choices)}")
        return value

    return check


def _name(value: str) -> str:
    problem = experiment_problem(value)
    if problem:
        raise ValueError(problem)
    return value


def _uri(value: str | None) -> str | None:
    problem = tracking_uri_problem(value)
    if problem:
        raise ValueError(problem)
    return value


def _layer_sizes(sizes: tuple[int, ...]) -> tuple[int, ...]:
    if any(n < 1 for n in sizes):
        raise ValueError("every hidden layer needs at least 1 unit")
    return sizes


def _label_table(value: Any) -> Any:
    """TOML writes the label map as a table of the labels it changes (the others keep their
    default); a full config gives ``[[label, potential], ...]``. Either way the result is the
    tuple of ``(Zone, potential)`` pairs the strict check expects."""
    if isinstance(value, dict):
        value = list(({zone.value: p for zone, p in DEFAULT_LABEL_POTENTIALS} | value).items())
    if not isinstance(value, (list, tuple)) or not all(isinstance(p, (list, tuple)) and len(p) == 2 for p in value):
        raise ValueError("give a table of label = potential")
    unknown = [label for label, _ in value if label not in Zone.__members__]
    if unknown:
        raise ValueError(f"unknown label '{unknown[0]}'; known: {', '.join(Zone)}")
    if any(isinstance(p, bool) or not isinstance(p, (int, float)) for _, p in value):
        raise ValueError("every label's potential must be a number")
    return tuple((Zone(label), float(p)) for label, p in value)


def _all_labels(pairs: tuple[tuple[Zone, float], ...]) -> tuple[tuple[Zone, float], ...]:
    missing = set(Zone) - {z for z, _ in pairs}
    if missing:
        raise ValueError(f"no potential for {sorted(missing)[0]}; give a potential for every label")
    return pairs


#: Ranges and value checks per dotted key. Keys not listed take any value of their type.
RULES: dict[str, tuple[Any, ...]] = {
    "arms": (AfterValidator(_known_arms),),
    "seeds": (AfterValidator(_distinct_seeds),),
    "preset": (AfterValidator(_one_of(PRESETS, "preset")),),
    "workers": (Ge(1),),
    "experiment": (AfterValidator(_name),),
    "tracking_uri": (AfterValidator(_uri),),
    "executor": (AfterValidator(_one_of(EXECUTORS, "executor")),),
    "max_retries": (Ge(0),),
    "heartbeat_s": (Gt(0),),
    "stale_after_s": (Gt(0),),
    "ppo.n_envs": (Ge(1),),
    "ppo.n_steps": (Ge(1),),
    "ppo.batch_size": (Ge(1),),
    "ppo.n_epochs": (Ge(1),),
    "ppo.learning_rate": (Gt(0),),
    "ppo.gamma": (Interval(gt=0, le=1),),
    "ppo.gae_lambda": (Interval(ge=0, le=1),),
    "ppo.clip_range": (Gt(0),),
    "ppo.ent_coef": (Ge(0),),
    "ppo.vf_coef": (Ge(0),),
    "ppo.max_grad_norm": (Gt(0),),
    "ppo.net_arch_pi": (AfterValidator(_layer_sizes),),
    "ppo.net_arch_vf": (AfterValidator(_layer_sizes),),
    "ppo.timesteps": (Ge(1),),
    "ppo.eval_episodes": (Ge(1),),
    "vlm.backend": (AfterValidator(_one_of(BACKENDS, "VLM backend")),),
    "vlm.max_new_tokens": (Ge(1),),
    "vlm.timeout_s": (Gt(0),),
    "vlm.retries": (Ge(0),),
    "vlm.sim.flicker": (Interval(ge=0, le=1),),
    "vlm.sim.query_flicker": (Interval(ge=0, le=1),),
    "vlm.sim.float_noise": (Ge(0),),
    "vlm.sim.box_noise_px": (Ge(0),),
    "vlm.sim.box_failure": (Interval(ge=0, le=1),),
    "vlm.sim.patch_px": (Ge(1),),
    "vlm.sim.latency_s": (Ge(0),),
    "vlm.sim.profile": (AfterValidator(_one_of(SIM_PROFILES, "simulated-VLM profile")),),
    "vlm.sim.mcq_bottom_halfwidth": (Ge(0),),
    "shaping.label_potentials": (BeforeValidator(_label_table), AfterValidator(_all_labels)),
    "shaping.gamma": (Interval(gt=0, le=1),),
    "shaping.alpha": (Ge(0),),
    "shaping.query_every": (Ge(1),),
    "shaping.confirm": (Ge(1),),
    "shaping.bandwidth": (Gt(0),),
    "shaping.reuse_radius": (Ge(0),),
    "shaping.render_quantum": (Gt(0),),
}


def _ppo_consistent(ppo: Any) -> Any:
    rollout = ppo.n_envs * ppo.n_steps
    if ppo.batch_size > rollout:
        raise ValueError(
            f"ppo.batch_size ({ppo.batch_size}) exceeds ppo.n_envs x ppo.n_steps "
            f"({ppo.n_envs} x {ppo.n_steps} = {rollout}); lower batch_size or raise n_steps"
        )
    if rollout < 2:
        raise ValueError("ppo.n_envs x ppo.n_steps must be at least 2 (PPO needs two samples per rollout)")
    return ppo


#: Rules over several fields of one section (the section's dotted prefix -> check).
CHECKS: dict[str, Callable[[Any], Any]] = {"ppo": _ppo_consistent}


@functools.cache
def _model(cls: type, prefix: str = "") -> type[BaseModel]:
    """A pydantic model with the fields of dataclass ``cls``, its nested dataclasses as nested
    models, and the ``RULES``/``CHECKS`` of keys under ``prefix``."""
    hints = typing.get_type_hints(cls)
    fields: dict[str, Any] = {}
    for f in dataclasses.fields(cls):
        key = f"{prefix}{f.name}"
        tp = hints[f.name]
        nested = _dataclass_in(tp)
        if nested is not None:
            sub = _model(nested, f"{key}.")
            tp = sub | None if type(None) in typing.get_args(tp) else sub
        rules = RULES.get(key, ())
        if rules:
            tp = Annotated[tp, *rules]
        if f.default is not dataclasses.MISSING:
            default = f.default
        elif f.default_factory is not dataclasses.MISSING:
            default = f.default_factory()
        else:
            default = ...
        if dataclasses.is_dataclass(default) and not isinstance(default, type):
            default = _model(type(default), f"{key}.").model_validate_json(json.dumps(_jsonable(default)))
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


def _jsonable(obj: Any) -> Any:
    from vlmrl_cli.core.provenance import to_jsonable

    return to_jsonable(obj)


def _to_dataclass(cls: type, model: BaseModel) -> Any:
    hints = typing.get_type_hints(cls)
    kwargs: dict[str, Any] = {}
    for f in dataclasses.fields(cls):
        value = getattr(model, f.name)
        nested = _dataclass_in(hints[f.name])
        if nested is not None and isinstance(value, BaseModel):
            value = _to_dataclass(nested, value)
        kwargs[f.name] = value
    return cls(**kwargs)


def _sentence(err: Any, cls: type) -> str:
    loc = [str(part) for part in err["loc"] if not isinstance(part, int)]
    key = ".".join(loc)
    if err["type"] == "extra_forbidden":
        section = loc[:-1]
        known = [".".join([*section, k]) for k in _section_fields(cls, section)]
        where = f"[{'.'.join(section)}]" if section else "the top level"
        return (
            f"unknown key '{key}'{did_you_mean(key, known)}; known keys in {where}: "
            f"{', '.join(k.rsplit('.', 1)[-1] for k in known)}."
        )
    msg = str(err["msg"]).removeprefix("Value error, ")
    msg = msg[:1].lower() + msg[1:]
    if err["type"] == "value_error" and loc and loc[0] in CHECKS and len(loc) == 1:
        return f"inconsistent [{key}]: {msg}."
    shown = json.dumps(err.get("input"), default=str)
    shown = shown if len(shown) <= 60 else shown[:57] + "..."
    return f"invalid {key or 'configuration'} = {shown}: {msg}."


def _section_fields(cls: type, section: list[str]) -> list[str]:
    model = _model(cls)
    for part in section:
        annotation = model.model_fields[part].annotation
        sub = next(
            (t for t in (annotation, *typing.get_args(annotation)) if isinstance(t, type) and issubclass(t, BaseModel)),
            None,
        )
        if sub is None:
            return []
        model = sub
    return list(model.model_fields)


def validate_as(cls: type, raw: dict[str, Any]) -> Any:
    """``raw`` (nested plain values, as TOML gives them) checked against the schema of dataclass
    ``cls`` and built into it; ``BadInput`` naming the first wrong key otherwise."""
    try:
        blob = json.dumps(_jsonable(raw))
    except (TypeError, ValueError) as exc:
        raise BadInput(f"the configuration holds a value that is no number, string, boolean or list ({exc}).") from exc
    try:
        model = _model(cls).model_validate_json(blob)
    except ValidationError as exc:
        raise BadInput(_sentence(exc.errors()[0], cls)) from None
    return _to_dataclass(cls, model)

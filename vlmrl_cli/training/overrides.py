"""Merge a run's configuration layers (preset < config file < ``--set`` < flags) into one raw
nested dict, before ``training/validation.py`` checks it (docs/commands/run.md)."""

from __future__ import annotations

import tomllib
from collections.abc import Iterable, Mapping
from typing import TYPE_CHECKING, Any

from vlmrl_cli.core.errors import BadInput
from vlmrl_cli.core.provenance import to_jsonable
from vlmrl_cli.training.presets import preset_of
from vlmrl_cli.vlm.config import resolve_sim_profile

if TYPE_CHECKING:
    from vlmrl_cli.tasks.base import Task

#: Top-level keys of older config files that now live in ``[ppo]``.
MOVED_TO_PPO = ("timesteps", "eval_episodes")


def parse_value(text: str) -> Any:
    """A ``--set`` value: a TOML value if it parses as one, else a list if it has commas, else a string."""
    text = text.strip()
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        pass
    if "," in text:
        return [parse_value(part) for part in text.split(",")]
    return text


def parse_values(text: str) -> list[Any]:
    """A ``--grid`` value list: comma-separated TOML values (``1,4,16``), bare words as strings."""
    try:
        return list(tomllib.loads(f"v = [{text}]")["v"])
    except tomllib.TOMLDecodeError:
        return [parse_value(part) for part in text.split(",")]


def parse_assignment(text: str, flag: str = "--set") -> tuple[str, str]:
    """``"ppo.n_envs=4"`` -> ``("ppo.n_envs", "4")``; ``BadInput`` when there is no ``=`` or key."""
    key, sep, value = text.partition("=")
    key = key.strip()
    if not sep or not key or any(not part for part in key.split(".")):
        raise BadInput(f"{flag} takes KEY=VALUE with a dotted key (e.g. {flag} ppo.n_envs=4), got '{text}'.")
    return key, value


def nest(assignments: Iterable[tuple[str, Any]]) -> dict[str, Any]:
    """Dotted keys -> a nested dict; later assignments win."""
    tree: dict[str, Any] = {}
    for key, value in assignments:
        *path, leaf = key.split(".")
        node = tree
        for i, part in enumerate(path):
            child = node.setdefault(part, {})
            if not isinstance(child, dict):
                raise BadInput(f"'{'.'.join(path[: i + 1])}' is a value, not a table; it has no key '{leaf}'.")
            node = child
        if isinstance(node.get(leaf), dict):
            raise BadInput(f"'{key}' is a table, set its keys one by one (e.g. {key}.KEY=VALUE).")
        node[leaf] = value
    return tree


def dotted(table: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    """A nested table -> ``{dotted key: value}`` (``nest``'s inverse; an empty table sets nothing)."""
    out: dict[str, Any] = {}
    for key, value in table.items():
        if isinstance(value, Mapping):
            out.update(dotted(value, f"{prefix}{key}."))
        else:
            out[f"{prefix}{key}"] = value
    return out


def merge(base: Mapping[str, Any], top: Mapping[str, Any]) -> dict[str, Any]:
    """``top`` laid over ``base``: tables merge key by key, any other value replaces."""
    out = dict(base)
    for key, value in top.items():
        if isinstance(value, Mapping) and isinstance(out.get(key), Mapping):
            out[key] = merge(out[key], value)
        else:
            out[key] = value
    return out


def _lift_moved(layer: Mapping[str, Any]) -> dict[str, Any]:
    """Top-level ``timesteps``/``eval_episodes`` (older files, ``--set timesteps=N``) -> ``[ppo]``."""
    out = dict(layer)
    for key in MOVED_TO_PPO:
        if key in out:
            ppo = out.get("ppo", {})
            if not isinstance(ppo, Mapping):
                break  # the schema reports the malformed [ppo]
            if key in ppo:
                raise BadInput(f"'{key}' is set both at the top level and in [ppo]; set ppo.{key} once.")
            out["ppo"] = {**ppo, key: out.pop(key)}
    return out


def task_ref(layers: Iterable[Mapping[str, Any]], default: str) -> Any:
    """The task the highest layer that names one names (``default`` when none does): a name for
    the command's registry to resolve, or whatever a file wrote there (the schema refuses it).

    Example:
        >>> task_ref([{"task": "acrobot"}, {"seeds": [0]}], "mountain-car"), task_ref([{}], "mountain-car")
        ('acrobot', 'mountain-car')
    """
    ref: Any = default
    for layer in layers:
        ref = layer.get("task", ref)
    return ref


def resolve_raw(layers: Iterable[Mapping[str, Any]], task: Task | None) -> dict[str, Any]:
    """The merged raw configuration of ``layers`` (lowest first) over the named preset's ``[ppo]``,
    for ``task`` (None when the layers name none that resolves: the schema says what is wrong)."""
    lifted = [_lift_moved(layer) for layer in layers]
    preset: Any = None
    for layer in lifted:
        preset = layer.get("preset", preset)
    if preset is None and task is not None:  # else the config's own default preset
        preset = task.default_preset
    raw: dict[str, Any] = {} if preset is None else {"preset": preset}
    if isinstance(preset, str) and task is not None:  # else the schema says what is wrong
        raw["ppo"] = to_jsonable(preset_of(task, preset))
    if task is not None and task.scales is not None:  # the task's scales: the bottom layer of [shaping]
        raw["shaping"] = task.scales.knobs()
    for layer in lifted:
        raw = merge(raw, layer)
    shaping = raw.get("shaping")
    if task is not None and isinstance(shaping, Mapping) and isinstance(shaping.get("label_potentials"), Mapping):
        # a table of the labels it changes: the task's other labels keep the task's default
        table = {str(label): p for label, p in task.label_potentials} | dict(shaping["label_potentials"])
        raw["shaping"] = {**shaping, "label_potentials": [[label, p] for label, p in table.items()]}
    vlm = raw.get("vlm")
    if isinstance(vlm, Mapping) and isinstance(vlm.get("sim"), Mapping):
        raw["vlm"] = {**vlm, "sim": resolve_sim_profile(vlm["sim"], task)}  # the generic profiles and the task's
    return raw

"""PPO hyperparameters: one frozen ``PPOConfig`` and the task's named presets that fill it."""

from __future__ import annotations

import functools
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Literal

from annotated_types import Ge, Gt, Interval
from pydantic import AfterValidator

from vlmrl_cli.core.errors import BadInput, did_you_mean
from vlmrl_cli.core.fields import AtMost
from vlmrl_cli.core.provenance import to_jsonable

if TYPE_CHECKING:
    from vlmrl_cli.tasks.base import Task

LrSchedule = Literal["constant", "linear"]


def _layer_sizes(sizes: tuple[int, ...]) -> tuple[int, ...]:
    if any(n < 1 for n in sizes):
        raise ValueError("every hidden layer needs at least 1 unit")
    return sizes


@dataclass(frozen=True)
class PPOConfig:
    """Every PPO knob (SB3 names) and the budget. New knobs default to SB3's own defaults."""

    n_envs: int = field(default=16, metadata={"rules": (Ge(1), AtMost(256, (
        "the envs of a run are copies of the task stepped in turn in one process (a DummyVecEnv), so more only "
        "slow each update down; the tuned presets use at most 16"))), "help": "parallel envs in one DummyVecEnv"})
    n_steps: int = field(default=16, metadata={"rules": (Ge(1), AtMost(65_536, (
        "the rollout buffer holds n_envs x n_steps samples in memory; the tuned presets use at most 2,048"))),
        "help": "steps per env per rollout"})
    batch_size: int = field(default=64, metadata={"rules": (Ge(1),),
                                                  "help": "minibatch size; at most n_envs x n_steps"})
    n_epochs: int = field(default=4, metadata={"rules": (Ge(1), AtMost(100, (
        "each epoch is a full pass of gradient steps over the rollout; the tuned presets use at most 10"))),
        "help": "passes over each rollout"})
    learning_rate: float = field(default=3e-4, metadata={"rules": (Gt(0),),
                                                         "help": "Adam step size (initial, if linear)"})
    lr_schedule: LrSchedule = field(
        default="constant", metadata={"help": "constant, or linear: learning_rate decays to 0 at the budget"}
    )
    gamma: float = field(default=0.99, metadata={"rules": (Interval(gt=0, le=1),), "help": "discount"})
    gae_lambda: float = field(default=0.98, metadata={"rules": (Interval(ge=0, le=1),), "help": "GAE lambda"})
    clip_range: float = field(default=0.2, metadata={"rules": (Gt(0),), "help": "PPO ratio clip"})
    ent_coef: float = field(default=0.0, metadata={"rules": (Ge(0),), "help": "entropy bonus coefficient"})
    vf_coef: float = field(default=0.5, metadata={"rules": (Ge(0),), "help": "value loss coefficient"})
    max_grad_norm: float = field(default=0.5, metadata={"rules": (Gt(0),), "help": "gradient clip (global norm)"})
    normalize_obs: bool = field(default=True, metadata={"help": "VecNormalize observations"})
    normalize_reward: bool = field(default=True, metadata={"help": "VecNormalize rewards (by the discounted return)"})
    net_arch_pi: tuple[int, ...] = field(default=(64, 64), metadata={"rules": (AfterValidator(_layer_sizes),),
                                                                     "help": "policy MLP hidden sizes"})
    net_arch_vf: tuple[int, ...] = field(default=(64, 64), metadata={"rules": (AfterValidator(_layer_sizes),),
                                                                     "help": "value MLP hidden sizes"})
    timesteps: int = field(default=300_000, metadata={"rules": (Ge(1), AtMost(100_000_000, (
        "a run that long takes hours per seed and arm even at PPO's measured ~6,500 steps/s without a VLM; the "
        "tuned budgets here are at most 1,000,000"))), "help": "training budget, env steps"})
    eval_episodes: int = field(default=100, metadata={"rules": (Ge(1), AtMost(10_000, (
        "each is a whole episode after training; 100 give a success rate to within about 0.1"))),
        "help": "detached evaluation episodes"})
    # Added with the continuous tasks: ``ppo_identity`` leaves them out at these neutral values (older hashes).
    use_sde: bool = field(default=False, metadata={"help": "generalised state-dependent exploration "
                                                           "(continuous actions only)"})
    log_std_init: float = field(default=0.0, metadata={"help": "initial log std of a continuous policy"})
    ortho_init: bool = field(default=True, metadata={"help": "orthogonal initialisation of the networks"})

    @property
    def policy_kwargs(self) -> dict[str, object]:
        """SB3's ``policy_kwargs``: the networks, and the knobs added later only off their defaults."""
        kwargs: dict[str, object] = {"net_arch": {"pi": list(self.net_arch_pi), "vf": list(self.net_arch_vf)}}
        if self.log_std_init != 0.0:
            kwargs["log_std_init"] = self.log_std_init
        if not self.ortho_init:
            kwargs["ortho_init"] = False
        return kwargs


#: Knobs added after runs existed, with the value that leaves training as it was.
NEUTRAL_PPO_KNOBS: dict[str, object] = {"use_sde": False, "log_std_init": 0.0, "ortho_init": True}


def ppo_identity(ppo: PPOConfig) -> dict[str, object]:
    """The PPO knobs as they enter config hashes: every field, the later ones only off neutral.

    Example:
        >>> "use_sde" in ppo_identity(PPOConfig()), ppo_identity(PPOConfig(use_sde=True))["use_sde"]
        (False, True)
    """
    ident: dict[str, object] = to_jsonable(ppo)
    for key, neutral in NEUTRAL_PPO_KNOBS.items():
        if ident.get(key) == neutral:
            del ident[key]
    return ident


def preset_of(task: Task, name: str) -> PPOConfig:
    """The PPO preset ``name`` of ``task``, checked like a config file (``BadInput`` if unknown)."""
    table = task.presets
    if name not in table:
        raise BadInput(f"unknown preset '{name}' for task {task.name}{did_you_mean(name, table)}; "
                       f"choose from {', '.join(table)}.")
    items = tuple(sorted(table[name].items()))
    try:
        return _memo(items)
    except TypeError:  # a value that cannot be hashed (a list): checked without the memo
        return _validated(items)


def _validated(items: tuple[tuple[str, object], ...]) -> PPOConfig:
    from vlmrl_cli.training.validation import validate_as

    ppo: PPOConfig = validate_as(PPOConfig, dict(items))  # a plug-in's table is checked like a config file
    return ppo


_memo = functools.lru_cache(maxsize=256)(_validated)

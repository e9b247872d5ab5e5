"""How a configuration field declares itself once: its type, help text and rules in its metadata
(``metadata={"rules": (Ge(1),), "help": "parallel envs"}``), read by the input schema, the docs'
configuration reference and the commands' options (``cli/options.field_option``)."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Collection
from dataclasses import dataclass
from typing import Any

from vlmrl_cli.core.errors import did_you_mean

#: The metadata of a field that carries a value resolved from the config's other fields (the
#: ``Task`` a ``task`` name names): not read from a file, not written, not hashed.
CARRIED: dict[str, Any] = {"carried": True}


def is_carried(f: dataclasses.Field[Any]) -> bool:
    """Whether ``f`` is ``CARRIED``: left out of the config's serialised form and its schema."""
    return bool(f.metadata.get("carried"))


def rules_of(f: dataclasses.Field[Any]) -> tuple[Any, ...]:
    """The validation rules a dataclass field declares (none: any value of its type)."""
    return tuple(f.metadata.get("rules", ()))


def help_of(f: dataclasses.Field[Any]) -> str:
    """The help text a dataclass field declares ("" when it has none)."""
    return str(f.metadata.get("help", ""))


def number(value: float) -> str:
    """``value`` as a bound is written in a message: whole numbers with thousands separators.

    Example:
        >>> number(256), number(100_000_000), number(1e6), number(0.5)
        ('256', '100,000,000', '1,000,000', '0.5')
    """
    return f"{int(value):,}" if float(value).is_integer() else f"{value:g}"


@dataclass(frozen=True)
class AtMost:
    """An upper bound ``le`` (``annotated_types.Le``'s name, read by the docs) refused with its reason.

    Example:
        >>> AtMost(256, "each env is stepped in turn").check(300)
        Traceback (most recent call last):
        ...
        ValueError: at most 256; each env is stepped in turn
    """

    le: float
    why: str

    def check(self, value: Any) -> Any:
        if value > self.le:
            raise ValueError(f"at most {number(self.le)}; {self.why}")
        return value

    def __get_pydantic_core_schema__(self, source: Any, handler: Callable[[Any], Any]) -> Any:
        from pydantic_core import core_schema

        return core_schema.no_info_after_validator_function(self.check, handler(source))


def one_of(choices: Collection[str] | Callable[[], Collection[str]], what: str) -> Callable[[str], str]:
    """A validator accepting only ``choices`` (or what a callable returns), with a did-you-mean hint.

    Example:
        >>> one_of(("sim", "hf"), "backend")("sim")
        'sim'
    """
    def check(value: str) -> str:
        known = choices() if callable(choices) else choices
        if value not in known:
            raise ValueError(f"unknown {what} '{value}'{did_you_mean(value, known)}; choose from {', '.join(known)}")
        return value

    return check

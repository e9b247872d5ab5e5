"""MkDocs hook: the CLI reference from the Typer app and the configuration reference from the
config dataclasses, generated at build time so they cannot drift from the code."""

from __future__ import annotations

import dataclasses
import typing
from typing import Any

CLI_MARKER = "<!-- vlmrl:cli-reference -->"
CONFIG_MARKER = "<!-- vlmrl:configuration -->"


def cli_reference() -> str:
    import typer

    from vlmrl_cli.cli.app import app

    root: Any = typer.main.get_command(app)
    context = type(typer.Context(root))  # typer's own click Context (typer may vendor click)
    parts = []
    for name in sorted(root.commands):
        command = root.commands[name]
        ctx = context(command, info_name=f"vlmrl {name}", terminal_width=100, max_content_width=100)
        parts += [f"## `vlmrl {name}`", "", "```text", command.get_help(ctx), "```", ""]
    return "\n".join(parts)


def _type_name(tp: Any) -> str:
    text = getattr(tp, "__name__", None) if not typing.get_args(tp) else None
    return (text or str(tp).replace("typing.", "")).replace(" | ", " or ")


def _range(rule: Any) -> str:
    """An annotated-types bound in words (``>= 1``, ``[0, 1]``); '' for validators."""
    bounds = [(op, getattr(rule, name, None)) for op, name in ((">=", "ge"), (">", "gt"), ("<=", "le"), ("<", "lt"))]
    return ", ".join(f"{op} {value:g}" for op, value in bounds if value is not None)


def _rows(cls: type, section: str) -> list[str]:
    from vlmrl_cli.core.fields import help_of, rules_of

    hints = typing.get_type_hints(cls)
    rows = []
    for f in dataclasses.fields(cls):
        if f.metadata.get("carried"):  # resolved from the other keys, never written in a file
            continue
        if dataclasses.is_dataclass(hints[f.name]) or f.name in ("ppo", "vlm", "shaping", "sim"):
            continue
        if f.default is not dataclasses.MISSING:
            default = repr(f.default)
        elif f.default_factory is not dataclasses.MISSING:
            default = "(computed)"
        else:
            default = "(required)"
        key = f"{section}.{f.name}" if section else f.name
        rules = ", ".join(filter(None, (_range(r) for r in rules_of(f))))
        help_text = help_of(f).replace("|", "\\|")
        rows.append(f"| `{key}` | `{_type_name(hints[f.name])}` | `{default}` | {rules} | {help_text} |")
    return rows


def configuration_reference() -> str:
    from vlmrl_cli.shaping.config import ShapingConfig
    from vlmrl_cli.training.config import RunConfig
    from vlmrl_cli.training.presets import PPOConfig
    from vlmrl_cli.vlm.config import SimKnobs, VLMConfig

    parts = []
    for title, cls, section in (("Top level", RunConfig, ""), ("`[ppo]`", PPOConfig, "ppo"),
                                ("`[shaping]`", ShapingConfig, "shaping"), ("`[vlm]`", VLMConfig, "vlm"),
                                ("`[vlm.sim]` (the SIMULATED VLM)", SimKnobs, "vlm.sim")):
        parts += [f"## {title}", "", "| key | type | default | range | meaning |", "| --- | --- | --- | --- | --- |",
                  *_rows(cls, section), ""]
    return "\n".join(parts)


def on_page_markdown(markdown: str, **_: Any) -> str:
    if CLI_MARKER in markdown:
        markdown = markdown.replace(CLI_MARKER, cli_reference())
    if CONFIG_MARKER in markdown:
        markdown = markdown.replace(CONFIG_MARKER, configuration_reference())
    return markdown

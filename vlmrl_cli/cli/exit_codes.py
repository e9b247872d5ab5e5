"""The one place where exceptions become exit codes."""

from __future__ import annotations

import sys
from typing import Any

import typer
from typer.core import TyperGroup

from vlmrl_cli.core.errors import BadInput

EXIT_BAD_INPUT = 2
EXIT_INTERRUPTED = 130


class ExitCodes(TyperGroup):
    """The app's group: a command's ``BadInput`` -> its sentence on stderr and exit 2 (no traceback);
    Ctrl-C -> a short note and exit 130."""

    def invoke(self, ctx: Any) -> Any:
        try:
            return super().invoke(ctx)
        except BadInput as exc:
            print(f"error: {exc}", file=sys.stderr)
            raise typer.Exit(EXIT_BAD_INPUT) from None
        except KeyboardInterrupt:
            print("interrupted: finished runs are kept; rerun the same command to resume.", file=sys.stderr)
            raise typer.Exit(EXIT_INTERRUPTED) from None

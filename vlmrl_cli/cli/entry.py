"""The ``vlmrl`` command's entry point: pin the numeric path, then load the app.

``core.numeric_pin.apply`` must run before anything imports torch or numpy, and importing the
app imports both, so this module imports nothing else until the pin is set.
"""

from __future__ import annotations


def main() -> None:
    from vlmrl_cli.core.numeric_pin import apply

    apply()
    from vlmrl_cli.cli.app import main as app_main

    app_main()

"""The ``vlmrl`` command's entry point: pin the numeric path, choose a headless video driver,
then load the app.

``core.numeric_pin.apply`` must run before anything imports torch or numpy, and importing the
app imports both, so this module imports nothing else until the pin is set. The process's settings
are made here, where it starts, and nowhere in the library.
"""

from __future__ import annotations

import os


def main() -> None:
    from vlmrl_cli.core.numeric_pin import apply

    apply()
    # gymnasium's rgb_array renderers call pygame.display.init(), which fails on SDL builds with no
    # display and no offscreen driver; they draw on software surfaces, so frames match under any driver
    os.environ.setdefault("SDL_VIDEODRIVER", "dummy")
    from vlmrl_cli.cli.app import main as app_main

    app_main()

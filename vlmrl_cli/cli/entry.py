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
    # MuJoCo (--task pusher) draws off screen through Mesa's EGL unless the user chose a back end
    os.environ.setdefault("MUJOCO_GL", "egl")
    from vlmrl_cli.cli.app import main as app_main

    app_main()

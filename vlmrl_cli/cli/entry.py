"""The ``vlmrl`` entry point: pin the numeric path before anything imports torch or numpy, choose
headless rendering, then load the app (the process's settings are made here, not in the library)."""

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

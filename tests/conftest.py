"""Test-wide settings: headless matplotlib and pygame backends (torch's threads are set by the nox
session's OMP_NUM_THREADS/MKL_NUM_THREADS, and by each training worker itself)."""

from __future__ import annotations

import os

os.environ.setdefault("MPLBACKEND", "Agg")
os.environ.setdefault("SDL_VIDEODRIVER", "dummy")

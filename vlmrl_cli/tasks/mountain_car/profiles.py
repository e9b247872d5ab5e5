"""MountainCar-v0's own simulated-VLM profile (``Task.sim_profiles``), in the wheel reader's units
(positions in x units). Its names and values enter config hashes and the simulated VLM's cache key."""

from __future__ import annotations

from vlmrl_cli.vlm.config import SimProfile

#: The failure pattern of the paper's Table 1 (LLaVA-1.5-7B): the float answer is nearly
#: constant (0.378, 0.386 for x = -0.50, -0.69), the MCQ answers BOTTOM on both frames (a dead
#: zone around the valley reaching past x = -0.69), and boxes either collapse to
#: ``Error [0, 0, 0, 0]`` or sit far from the car (columns 450-480, i.e. x ~ 0.2).
LLAVA_TABLE1 = SimProfile("llava-table1", {
    "flicker": 0.0,
    "float_noise": 0.005,
    "float_anchor": 0.38,
    "mcq_bottom_halfwidth": 0.45,
    "box_failure": 0.5,
    "box_noise_px": 10.0,
    "box_anchor_x": 0.2,
    "patch_px": 56,
})

SIM_PROFILES: tuple[SimProfile, ...] = (LLAVA_TABLE1,)

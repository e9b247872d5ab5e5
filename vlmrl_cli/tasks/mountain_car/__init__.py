"""MountainCar-v0 (the paper's task) and MountainCarContinuous-v0: one track, one car, one camera.

``geometry`` (the renderer's answer key), ``render`` (frames at any position), ``camera``,
``reader`` (the simulated VLM's wheel reader), ``prompts`` (Table 1's three prompts), ``probe``
(what Table 1 asks of the task: ``Task.numbers``), ``profiles`` (its simulated-VLM profile,
``llava-table1``) and ``task`` (the two ``Task`` values) are everything the harness knows about
this environment.
"""

from vlmrl_cli.tasks.mountain_car.task import MOUNTAIN_CAR, MOUNTAIN_CAR_CONTINUOUS

__all__ = ["MOUNTAIN_CAR", "MOUNTAIN_CAR_CONTINUOUS"]

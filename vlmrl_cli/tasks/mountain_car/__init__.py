"""MountainCar-v0 (the paper's task) and MountainCarContinuous-v0: one track, one car, one camera."""

from vlmrl_cli.tasks.mountain_car.task import MOUNTAIN_CAR, MOUNTAIN_CAR_CONTINUOUS

__all__ = ["MOUNTAIN_CAR", "MOUNTAIN_CAR_CONTINUOUS"]

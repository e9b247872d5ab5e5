"""vlmrl: reproduce and extend 'Macro Semantics, Micro Kinematics' on MountainCar-v0."""

__version__ = "0.1.0"

"""Steps to a reward threshold (the paper's Table 2): the first global timestep at which the mean
native return of the last ``window`` completed episodes reaches the target (SB3's ``ep_rew_mean``).
Inputs are one run's episodes as aligned ``(E,)`` arrays of end timesteps and native returns.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
import pandas as pd

#: Relative tolerance when comparing a rolling mean with a threshold, so that a mean which is
#: exactly the threshold in exact arithmetic still counts after floating-point summation.
RTOL = 1e-9


def _check(timesteps: npt.ArrayLike, returns: npt.ArrayLike, window: int, min_episodes: int
           ) -> tuple[np.ndarray, np.ndarray]:
    ts = np.asarray(timesteps, dtype=np.int64).reshape(-1)
    ret = np.asarray(returns, dtype=float).reshape(-1)
    if ts.shape != ret.shape:
        raise ValueError(f"timesteps {ts.shape} and returns {ret.shape} must have the same shape (E,).")
    if window < 1:
        raise ValueError(f"window must be >= 1, got {window}.")
    if not 1 <= min_episodes <= window:
        raise ValueError(f"min_episodes must be in [1, window={window}], got {min_episodes}.")
    order = np.argsort(ts, kind="stable")
    return ts[order], ret[order]


def rolling_mean_return(
    timesteps: npt.ArrayLike, returns: npt.ArrayLike, window: int = 100, min_episodes: int = 1
) -> tuple[np.ndarray, np.ndarray]:
    """The rolling mean return as a step function of the global timestep: ``(steps, mean)``, shape
    ``(K,)`` over the distinct end steps, ``mean[k]`` over the last ``window`` episodes ended by
    ``steps[k]`` (NaN before ``min_episodes``).
    """
    ts, ret = _check(timesteps, returns, window, min_episodes)
    if ts.size == 0:
        return ts, ret
    mean = pd.Series(ret).rolling(window, min_periods=min_episodes).mean().to_numpy()
    last_of_step = np.r_[ts[1:] != ts[:-1], True]
    return ts[last_of_step], mean[last_of_step]


def steps_to_threshold(
    timesteps: npt.ArrayLike,
    returns: npt.ArrayLike,
    threshold: float,
    window: int = 100,
    min_episodes: int = 1,
) -> int | None:
    """First global timestep at which the rolling mean return reaches ``threshold`` (>=); ``None``: a DNF."""
    steps, mean = rolling_mean_return(timesteps, returns, window, min_episodes)
    tol = RTOL * max(1.0, abs(float(threshold)))
    hit = np.flatnonzero(mean >= float(threshold) - tol)  # NaN compares False
    return int(steps[hit[0]]) if hit.size else None


def full_window_steps_to_threshold(
    timesteps: npt.ArrayLike, returns: npt.ArrayLike, threshold: float, window: int = 100
) -> int | None:
    """``steps_to_threshold`` with no partial window: nothing counts before ``window`` episodes ended."""
    return steps_to_threshold(timesteps, returns, threshold, window, min_episodes=window)

"""Random numbers inside numba kernels, with the generator state owned by the caller.

xoshiro256+ (Blackman & Vigna, ACM TOMS 47(4), 2021) on a uint64[4] state array. Each simulated
object keeps its own state array, so a batch run and the same samples produced one call at a
time draw exactly the same numbers, and two plants never share a hidden global stream.

Note for developers: numba's on-disk cache does not notice edits in this module from kernels in
other modules that call it; after changing it, delete the `__pycache__/*.nbi|*.nbc` files.
"""

import math

import numpy as np
from numba import njit

_SHIFT_A = np.uint64(17)
_ROT_L = np.uint64(45)
_ROT_R = np.uint64(19)
_MANTISSA_SHIFT = np.uint64(11)
_TWO_POW_M53 = 1.0 / 9007199254740992.0


def new_state(seed: int, stream: int) -> np.ndarray:
    """(4,) uint64 generator state for (seed, stream), from numpy's SeedSequence."""
    if seed < 0 or stream < 0:
        raise ValueError(f"seed and stream must be non-negative integers, got {seed}, {stream}")
    words = np.random.SeedSequence([seed, stream]).generate_state(4, dtype=np.uint64)
    if not np.any(words):  # the all-zero state is a fixed point of xoshiro
        words[0] = np.uint64(1)
    return words


@njit(cache=True)
def uniform(state: np.ndarray) -> float:
    """One double in [0, 1) from state (advanced in place)."""
    result = state[0] + state[3]
    t = state[1] << _SHIFT_A
    state[2] ^= state[0]
    state[3] ^= state[1]
    state[1] ^= state[2]
    state[0] ^= state[3]
    state[2] ^= t
    state[3] = (state[3] << _ROT_L) | (state[3] >> _ROT_R)
    return float(result >> _MANTISSA_SHIFT) * _TWO_POW_M53


@njit(cache=True)
def normal_pair(state: np.ndarray) -> tuple[float, float]:
    """Two independent standard normal numbers (Box–Muller)."""
    u1 = 1.0 - uniform(state)  # in (0, 1], so the logarithm is finite
    u2 = uniform(state)
    radius = math.sqrt(-2.0 * math.log(u1))
    angle = 2.0 * math.pi * u2
    return radius * math.cos(angle), radius * math.sin(angle)


@njit(cache=True)
def normal(state: np.ndarray) -> float:
    """One standard normal number."""
    z, _ = normal_pair(state)
    return z

"""Tiny task functions for tests/test_parallel.py, in a module that imports only numpy, so
that spawned worker processes start fast."""

import os

import numpy as np


def square_noise(seed: int) -> float:
    """A task with float work whose exact bits would expose any difference in inputs."""
    rng = np.random.default_rng(seed)
    return float(np.sum(rng.normal(size=1000) ** 2))


def die_on_three(k: int) -> int:
    if k == 3:
        os._exit(1)                     # the worker process dies mid-task
    return k * k


def bad_input(k: int) -> int:
    """A user error raised inside a worker must reach the driver as the same error."""
    from quadsim.core.errors import InputError

    if k == 1:
        raise InputError(f"flight_{k}.csv: t: not increasing")
    return k

"""Synthetic body speeds for the preintegration and factor tests (tests/fusion/graph)."""

import numpy as np

DT = 0.015                                        # sensor period [s]
PHI = np.array([[1e-4, 2e-5], [2e-5, 5e-3]])      # speed covariance [(m/s)^2, (rad/s)^2]


def speeds(rng: np.random.Generator, n: int, *, turn: float = 0.8) -> np.ndarray:
    """``(n, 2)`` body speeds ``(v [m/s], w [rad/s])``: 0.2 m/s with noise, a turn of
    amplitude ``turn`` [rad/s] with a 4.4 s period, plus noise."""
    t = np.arange(n) * DT
    return np.column_stack([0.2 + 0.05 * rng.standard_normal(n),
                            turn * np.sin(t / 0.7) + 0.2 * rng.standard_normal(n)])

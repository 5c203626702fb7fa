"""The benchmark harness: registry, timing, and the JSON record format.

Record format (one JSON object per figure; stable, other tools read it):

``name``
    figure name, ``"<benchmark>.<figure>"``.
``value``
    the measured number (a median over repeated runs, after a warm-up).
``unit``
    unit of ``value`` (``"robot-s/s"``, ``"ms"``, ``"MB/s"``, ``"x"`` ...).
``target``
    the goal ``value`` is held to, a number in ``unit``, or ``null``.
``better``
    ``"higher"`` or ``"lower"``: which side of ``target`` meets it.
``meets``
    ``true`` or ``false`` (``null`` when there is no target).
``baseline``, ``baseline_value``, ``ratio``
    present only when a baseline ran in the same process: the baseline's
    name, its value in ``unit``, and ``value / baseline_value``.
"""

from __future__ import annotations

import importlib.util
import statistics
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType
from typing import Literal

__all__ = ["REGISTRY", "Figure", "benchmark", "load_example", "median_seconds"]


@dataclass(frozen=True)
class Figure:
    """One benchmark figure (one JSON record)."""

    name: str
    value: float
    unit: str
    target: float | None = None
    better: Literal["higher", "lower"] = "higher"
    baseline: str | None = None
    baseline_value: float | None = None

    @property
    def meets(self) -> bool | None:
        """Whether ``value`` is on the right side of ``target``."""
        if self.target is None:
            return None
        if self.better == "higher":
            return self.value >= self.target
        return self.value <= self.target

    @property
    def ratio(self) -> float | None:
        """``value / baseline_value`` when a baseline ran."""
        if self.baseline_value is None or self.baseline_value == 0:
            return None
        return self.value / self.baseline_value

    def record(self) -> dict:
        """The JSON record of this figure."""
        rec = {
            "name": self.name,
            "value": self.value,
            "unit": self.unit,
            "target": self.target,
            "better": self.better,
            "meets": self.meets,
        }
        if self.baseline is not None:
            rec.update(baseline=self.baseline, baseline_value=self.baseline_value,
                       ratio=self.ratio)
        return rec


#: Benchmark name -> function returning its figures.
REGISTRY: dict[str, Callable[[], list[Figure]]] = {}


def benchmark(name: str) -> Callable[[Callable[[], list[Figure]]], Callable[[], list[Figure]]]:
    """Register a benchmark function under ``name``."""

    def register(fn: Callable[[], list[Figure]]) -> Callable[[], list[Figure]]:
        if name in REGISTRY:
            raise ValueError(f"benchmark {name!r} registered twice")
        REGISTRY[name] = fn
        return fn

    return register


def median_seconds(fn: Callable[[], object], *, repeat: int = 7, warmup: int = 1) -> float:
    """Median wall-clock seconds of ``fn()`` over ``repeat`` runs after ``warmup`` runs."""
    for _ in range(warmup):
        fn()
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def load_example(name: str) -> ModuleType:
    """``examples/NAME.py`` as a module (once per process, kept in ``sys.modules`` as
    ``NAME_example``), for benchmarks that drive the examples' helpers."""
    key = f"{name}_example"
    if key not in sys.modules:
        path = Path(__file__).resolve().parents[1] / "examples" / f"{name}.py"
        spec = importlib.util.spec_from_file_location(key, path)
        module = importlib.util.module_from_spec(spec)
        sys.modules[key] = module
        spec.loader.exec_module(module)
    return sys.modules[key]

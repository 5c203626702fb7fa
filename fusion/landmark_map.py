"""Landmarks at known positions: the one map type of the package.

:class:`LandmarkMap` holds ``id -> (x [m], y [m])`` in the world frame; the
EKFs look positions up by id, the factor graph reads its vectorised view.
"""

from __future__ import annotations

from collections.abc import Hashable, Iterable, Mapping
from dataclasses import dataclass, field
from functools import cached_property
from types import MappingProxyType

import numpy as np

from fusion.exceptions import (
    FilterOptionError,
    LandmarkIdError,
    MeasurementShapeError,
    UnknownLandmarkError,
)

__all__ = [
    "LandmarkMap",
]



@dataclass(frozen=True)
class LandmarkMap:
    """Landmark positions by id: ``id -> (x [m], y [m])`` in the world frame.

    The one map type of the package: the EKF looks positions up by id
    (:meth:`position`), the factor graph (:mod:`fusion.graph.smoother`,
    :func:`fusion.graph.observe_landmarks`) uses the vectorised view
    :attr:`integer_ids` and :attr:`xy_m`, computed once and cached.

    Parameters
    ----------
    positions : mapping of hashable to (x, y)
        Known landmarks; ids are any hashable values (ints, marker names). The
        factor graph keys landmarks by integer (gtsam ``L(id)``), so it needs
        integer ids.

    Raises
    ------
    MeasurementShapeError
        If a position is not two numbers.
    FilterOptionError
        If a position is not finite.

    Examples
    --------
    >>> lm = LandmarkMap({1: (0.5, 0.5), "door": (4.5, 0.5)})
    >>> lm.position("door").tolist(), 7 in lm, lm.unknown([1, 7, 8])
    ([4.5, 0.5], False, (7, 8))
    >>> grid = LandmarkMap.from_arrays([3, 5], [[0.0, 1.0], [2.0, 1.0]])
    >>> grid.integer_ids.tolist(), grid.xy_m[1].tolist(), grid.position(5).tolist()
    ([3, 5], [2.0, 1.0], [2.0, 1.0])
    """

    positions: Mapping[Hashable, np.ndarray] = field(default_factory=dict)

    def __post_init__(self) -> None:
        table = {}
        for key, xy in dict(self.positions).items():
            arr = np.array(xy, dtype=float)
            if arr.shape != (2,):
                raise MeasurementShapeError(
                    f"landmark {key!r} needs a position (x, y) of shape (2,), got {arr.shape}")
            if not np.all(np.isfinite(arr)):
                raise FilterOptionError(f"landmark {key!r} has a non-finite position {arr}")
            arr.flags.writeable = False
            table[key] = arr
        object.__setattr__(self, "positions", MappingProxyType(table))

    def __contains__(self, landmark_id: object) -> bool:
        return landmark_id in self.positions

    def __len__(self) -> int:
        return len(self.positions)

    @classmethod
    def from_arrays(cls, ids: Iterable[int], xy_m: np.ndarray) -> LandmarkMap:
        """A map from integer ids and their positions, row by row.

        Parameters
        ----------
        ids : array_like of int, shape (k,)
            Distinct landmark ids (e.g. ArUco marker ids).
        xy_m : array_like, shape (k, 2)
            Positions in the world frame [m].

        Raises
        ------
        MeasurementShapeError
            If ``xy_m`` is not ``(k, 2)``.
        LandmarkIdError
            If an id repeats or is not an integer.
        FilterOptionError
            If a position is not finite.
        """
        id_list = list(np.asarray(ids).reshape(-1).tolist())
        xy = np.asarray(xy_m, dtype=float)
        if xy.shape != (len(id_list), 2):
            raise MeasurementShapeError(f"expected xy_m of shape ({len(id_list)}, 2) for "
                                        f"{len(id_list)} ids, got {xy.shape}")
        _check_integer_ids(id_list)
        if len(set(id_list)) != len(id_list):
            repeated = sorted({i for i in id_list if id_list.count(i) > 1})
            raise LandmarkIdError(f"landmark ids must be distinct; repeated: {repeated}")
        return cls(dict(zip(id_list, xy, strict=True)))

    @property
    def ids(self) -> tuple[Hashable, ...]:
        """The known ids, in insertion order."""
        return tuple(self.positions)

    @cached_property
    def integer_ids(self) -> np.ndarray:
        """The ids as a read-only ``int64`` array, shape (k,), in :attr:`ids` order.

        Raises
        ------
        LandmarkIdError
            If an id is not an integer (the factor graph keys landmarks as ``L(id)``).
        """
        ids = list(self.positions)
        _check_integer_ids(ids)
        out = np.array(ids, dtype=np.int64).reshape(-1)
        out.flags.writeable = False
        return out

    @cached_property
    def xy_m(self) -> np.ndarray:
        """The positions as a read-only array [m], shape (k, 2), in :attr:`ids` order."""
        out = np.array(list(self.positions.values()), dtype=float).reshape(-1, 2)
        out.flags.writeable = False
        return out

    def position(self, landmark_id: Hashable) -> np.ndarray:
        """Position ``(x, y)`` [m] of a landmark (read-only array).

        Raises
        ------
        UnknownLandmarkError
            If the id is not in the map; the message lists some known ids.
        """
        try:
            return self.positions[landmark_id]
        except (KeyError, TypeError):
            known = list(self.positions)[:10]
            raise UnknownLandmarkError(
                f"landmark {landmark_id!r} is not in the map (known ids: {known}"
                f"{' ...' if len(self.positions) > 10 else ''}); add it to the LandmarkMap "
                "or drop the observation") from None

    def unknown(self, landmark_ids: Iterable[Hashable]) -> tuple[Hashable, ...]:
        """The ids among ``landmark_ids`` that the map does not hold, in order, without repeats."""
        seen: dict[Hashable, None] = {}
        for key in landmark_ids:
            if key not in self.positions:
                seen.setdefault(key, None)
        return tuple(seen)


def _check_integer_ids(ids: list[Hashable]) -> None:
    bad = [i for i in ids if isinstance(i, bool) or not isinstance(i, (int, np.integer))]
    if bad:
        raise LandmarkIdError(
            f"the factor graph keys landmarks by integer id (gtsam L(id)); got {bad[:5]!r}; "
            "number the landmarks (e.g. by marker id)")

















"""Fiducial markers at known places: marker id -> pose on a wall, with JSON files.

A :class:`MarkerMap` holds square ArUco markers (Garrido-Jurado et al. 2014)
of one dictionary and one printed size, each a :class:`MarkerLandmark`: the
world position of its centre ``(x, y, z)`` [m] (``z`` up, height above the
floor) and the direction its printed face looks, ``yaw_rad`` (the outward
normal, counter-clockwise from the world ``x`` axis). Markers hang vertically.

The filters need only ``(x, y)`` (:meth:`MarkerMap.to_landmark_map` gives the
:class:`fusion.landmark_map.LandmarkMap` the EKF and the factor graph use); the
synthetic camera (:mod:`fusion.landmarks.camera`) also needs the height and the facing
direction to render the marker.

Marker frame and corners (the order ``cv2.solvePnP`` with
``SOLVEPNP_IPPE_SQUARE`` and the ArUco detector use): origin at the centre,
``x`` to the right and ``y`` up as seen by a viewer facing the marker, ``z``
out of the printed face. Corners 0..3 are top-left, top-right, bottom-right,
bottom-left.

File format (JSON; YAML is not supported, to keep PyYAML out of the
dependencies, and JSON files are valid YAML 1.2 anyway)::

    {"format": "lti-motion-marker-map", "version": 1,
     "dictionary": "DICT_4X4_50", "marker_size_m": 0.15,
     "markers": [{"id": 3, "x_m": 2.0, "y_m": 0.5, "z_m": 0.3, "yaw_rad": 3.1416}]}

``z_m`` defaults to 0.3 and ``yaw_rad`` to 0 when left out.

References
----------
S. Garrido-Jurado, R. Muñoz-Salinas, F. J. Madrid-Cuevas, M. J. Marín-Jiménez,
"Automatic generation and detection of highly reliable fiducial markers under
occlusion", Pattern Recognition 47(6), 2280-2292, 2014.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from dataclasses import KW_ONLY, dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Any

import cv2
import numpy as np

from fusion.exceptions import MarkerMapError, UnknownLandmarkError
from fusion.landmark_map import LandmarkMap
from fusion.range_bearing import RangeBearing

__all__ = [
    "FILE_FORMAT",
    "FILE_VERSION",
    "MarkerLandmark",
    "MarkerMap",
    "dictionary_size",
    "load_marker_map",
    "save_marker_map",
]

#: Value of the ``"format"`` key of a marker map file.
FILE_FORMAT = "lti-motion-marker-map"
#: Version of the file layout this module writes and reads.
FILE_VERSION = 1
_DEFAULT_Z_M = 0.3




def dictionary_size(dictionary: str) -> int:
    """Number of markers in a predefined OpenCV ArUco dictionary.

    Parameters
    ----------
    dictionary : str
        Name of a ``cv2.aruco`` predefined dictionary, e.g. ``"DICT_4X4_50"``.

    Returns
    -------
    int
        How many ids it holds (valid ids are ``0 .. size - 1``).

    Raises
    ------
    MarkerMapError
        If the name is not a predefined dictionary.

    Examples
    --------
    >>> dictionary_size("DICT_4X4_50"), dictionary_size("DICT_APRILTAG_36h11")
    (50, 587)
    """
    code = getattr(cv2.aruco, dictionary, None) if dictionary.startswith("DICT_") else None
    if not isinstance(code, int):
        raise MarkerMapError(
            f"unknown ArUco dictionary {dictionary!r}; use a cv2.aruco predefined name such as "
            "'DICT_4X4_50', 'DICT_5X5_100' or 'DICT_APRILTAG_36h11'")
    return int(cv2.aruco.getPredefinedDictionary(code).bytesList.shape[0])


@dataclass(frozen=True)
class MarkerLandmark:
    """One marker on a wall: id, centre position [m] and facing direction [rad].

    Attributes
    ----------
    marker_id : int
        Id in the map's dictionary.
    x_m, y_m : float
        Centre in the world frame [m] (the landmark position of the filters).
    z_m : float
        Height of the centre above the floor [m].
    yaw_rad : float
        Direction of the outward normal of the printed face, counter-clockwise
        from the world ``x`` axis [rad]; a marker on a wall at ``x = 3`` seen
        from the origin has ``yaw_rad = pi``.

    Examples
    --------
    >>> m = MarkerLandmark(7, 3.0, 0.0, z_m=0.3, yaw_rad=math.pi)
    >>> m.corners_world_m(0.2).round(6).tolist()[0]  # top-left, seen from the origin
    [3.0, 0.1, 0.4]
    """

    marker_id: int
    x_m: float
    y_m: float
    _: KW_ONLY
    z_m: float = _DEFAULT_Z_M
    yaw_rad: float = 0.0

    def __post_init__(self) -> None:
        if isinstance(self.marker_id, bool) or not isinstance(self.marker_id, int | np.integer):
            raise MarkerMapError(f"marker id must be an int, got {self.marker_id!r}")
        object.__setattr__(self, "marker_id", int(self.marker_id))
        for name in ("x_m", "y_m", "z_m", "yaw_rad"):
            value = float(getattr(self, name))
            if not math.isfinite(value):
                raise MarkerMapError(f"marker {self.marker_id}: {name} must be finite, got {value}")
            object.__setattr__(self, name, value)

    @property
    def position_xy_m(self) -> np.ndarray:
        """Centre ``(x, y)`` [m] in the world frame, shape (2,)."""
        return np.array([self.x_m, self.y_m])

    @property
    def position_xyz_m(self) -> np.ndarray:
        """Centre ``(x, y, z)`` [m] in the world frame, shape (3,)."""
        return np.array([self.x_m, self.y_m, self.z_m])

    def world_R_marker(self) -> np.ndarray:
        """Rotation from the marker frame (x right, y up, z out of the face) to the world, (3, 3).

        Columns: the marker's right ``(-sin yaw, cos yaw, 0)``, up ``(0, 0, 1)``
        and outward normal ``(cos yaw, sin yaw, 0)``.
        """
        c, s = math.cos(self.yaw_rad), math.sin(self.yaw_rad)
        return np.array([[-s, 0.0, c], [c, 0.0, s], [0.0, 1.0, 0.0]])

    def corners_world_m(self, side_m: float) -> np.ndarray:
        """World positions of the corners of a centred square of side ``side_m`` [m], (4, 3).

        Order top-left, top-right, bottom-right, bottom-left as seen facing the
        marker (the ArUco and ``SOLVEPNP_IPPE_SQUARE`` order).
        """
        h = 0.5 * float(side_m)
        local = np.array([[-h, h, 0.0], [h, h, 0.0], [h, -h, 0.0], [-h, -h, 0.0]])
        return local @ self.world_R_marker().T + self.position_xyz_m


@dataclass(frozen=True)
class MarkerMap:
    """Markers of one ArUco dictionary and one printed size, by id.

    Parameters
    ----------
    markers : iterable of MarkerLandmark
        The markers; ids must be unique and inside the dictionary.
    marker_size_m : float
        Side of the black square of every marker [m] (the quiet zone, the white
        border around it, is not included).
    dictionary : str
        ``cv2.aruco`` predefined dictionary name.

    Raises
    ------
    MarkerMapError
        On duplicate ids, ids outside the dictionary, an unknown dictionary or a
        size that is not a positive finite number.

    Examples
    --------
    >>> mm = MarkerMap([MarkerLandmark(1, 2.0, 0.0, yaw_rad=math.pi),
    ...                 MarkerLandmark(4, 0.0, 2.0, yaw_rad=-math.pi / 2)], marker_size_m=0.15)
    >>> mm.ids, 4 in mm, mm.marker(4).y_m
    ((1, 4), True, 2.0)
    >>> mm.to_landmark_map().position(1).tolist()
    [2.0, 0.0]
    """

    markers: tuple[MarkerLandmark, ...]
    _: KW_ONLY
    marker_size_m: float = 0.15
    dictionary: str = "DICT_4X4_50"
    _by_id: Mapping[int, MarkerLandmark] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        markers = tuple(self.markers)
        for m in markers:
            if not isinstance(m, MarkerLandmark):
                raise MarkerMapError(f"markers must be MarkerLandmark objects, got {m!r}")
        size = float(self.marker_size_m)
        if not (math.isfinite(size) and size > 0.0):
            raise MarkerMapError(f"marker_size_m must be a positive length [m], got {size}")
        n_ids = dictionary_size(self.dictionary)
        by_id: dict[int, MarkerLandmark] = {}
        for m in markers:
            if m.marker_id in by_id:
                raise MarkerMapError(f"marker id {m.marker_id} appears twice; ids must be unique")
            if not 0 <= m.marker_id < n_ids:
                raise MarkerMapError(f"marker id {m.marker_id} is outside {self.dictionary} "
                                     f"(ids 0..{n_ids - 1})")
            by_id[m.marker_id] = m
        object.__setattr__(self, "markers", markers)
        object.__setattr__(self, "marker_size_m", size)
        object.__setattr__(self, "_by_id", MappingProxyType(by_id))

    def __contains__(self, marker_id: object) -> bool:
        return marker_id in self._by_id

    def __len__(self) -> int:
        return len(self.markers)

    @property
    def ids(self) -> tuple[int, ...]:
        """The marker ids, in map order."""
        return tuple(self._by_id)

    def marker(self, marker_id: int) -> MarkerLandmark:
        """The marker with this id.

        Raises
        ------
        UnknownLandmarkError
            If the id is not in the map.
        """
        try:
            return self._by_id[marker_id]
        except (KeyError, TypeError):
            raise UnknownLandmarkError(
                f"marker {marker_id!r} is not in the map (ids {list(self._by_id)[:10]}"
                f"{' ...' if len(self) > 10 else ''}); add it or drop the observation") from None

    def split_known(self, observations: RangeBearing) -> tuple[RangeBearing, tuple[int, ...]]:
        """Separate sightings of mapped markers from those of unknown ids.

        Parameters
        ----------
        observations : RangeBearing
            Detections (:meth:`fusion.landmarks.MarkerDetector.detect`).

        Returns
        -------
        known : RangeBearing
            The rows whose id is in the map, in input order.
        unknown_ids : tuple of int
            The other ids, in order of first appearance, without repeats.

        Examples
        --------
        >>> mm = MarkerMap([MarkerLandmark(4, 1.0, 0.0)])
        >>> known, unknown = mm.split_known(RangeBearing(0, [4, 9, 4, 9], [1.0, 2.0, 1.5, 2.5],
        ...                                              [0.0, 0.1, 0.2, 0.3]))
        >>> known.range_m.tolist(), unknown
        ([1.0, 1.5], (9,))
        """
        ids = observations.landmark_id.tolist()
        mask = np.array([i in self._by_id for i in ids], dtype=bool)
        unknown = dict.fromkeys(int(i) for i, ok in zip(ids, mask.tolist(), strict=True)
                                if not ok)
        return observations.select(mask), tuple(unknown)

    def to_landmark_map(self) -> LandmarkMap:
        """The 2-D map of the EKF and the factor graph: marker id -> centre ``(x, y)`` [m]."""
        return LandmarkMap({m.marker_id: m.position_xy_m for m in self.markers})

    def to_dict(self) -> dict[str, Any]:
        """The JSON-ready dictionary of the module's file format."""
        return {"format": FILE_FORMAT, "version": FILE_VERSION, "dictionary": self.dictionary,
                "marker_size_m": self.marker_size_m,
                "markers": [{"id": m.marker_id, "x_m": m.x_m, "y_m": m.y_m, "z_m": m.z_m,
                             "yaw_rad": m.yaw_rad} for m in self.markers]}

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> MarkerMap:
        """Build a map from the module's file format (see the module docstring).

        Raises
        ------
        MarkerMapError
            If the format tag or version is wrong, or a key is missing or mistyped.
        """
        if not isinstance(data, Mapping):
            raise MarkerMapError(f"a marker map must be a JSON object, got {type(data).__name__}")
        if data.get("format") != FILE_FORMAT or data.get("version") != FILE_VERSION:
            raise MarkerMapError(
                f"expected format {FILE_FORMAT!r} version {FILE_VERSION}, got format "
                f"{data.get('format')!r} version {data.get('version')!r}")
        entries = data.get("markers")
        if not isinstance(entries, list):
            raise MarkerMapError("a marker map needs a 'markers' list")
        markers = []
        for k, entry in enumerate(entries):
            if not isinstance(entry, Mapping) or not {"id", "x_m", "y_m"} <= set(entry):
                raise MarkerMapError(f"markers[{k}] needs at least 'id', 'x_m' and 'y_m', "
                                     f"got {entry!r}")
            try:
                markers.append(MarkerLandmark(
                    entry["id"], float(entry["x_m"]), float(entry["y_m"]),
                    z_m=float(entry.get("z_m", _DEFAULT_Z_M)),
                    yaw_rad=float(entry.get("yaw_rad", 0.0))))
            except (TypeError, ValueError) as exc:
                raise MarkerMapError(f"markers[{k}] is malformed: {exc}") from exc
        try:
            size = float(data.get("marker_size_m", float("nan")))
        except (TypeError, ValueError):
            size = float("nan")
        return cls(tuple(markers), marker_size_m=size,
                   dictionary=str(data.get("dictionary", "DICT_4X4_50")))


def save_marker_map(marker_map: MarkerMap, path: str | Path) -> None:
    """Write a map as JSON (the module's file format).

    Parameters
    ----------
    marker_map : MarkerMap
        The map.
    path : str or Path
        Destination file; parent folders must exist.
    """
    Path(path).write_text(json.dumps(marker_map.to_dict(), indent=2) + "\n")


def load_marker_map(path: str | Path) -> MarkerMap:
    """Read a map written by :func:`save_marker_map` (or by hand, same format).

    Parameters
    ----------
    path : str or Path
        A ``.json`` file.

    Returns
    -------
    MarkerMap

    Raises
    ------
    MarkerMapError
        If the file is not JSON or not a valid map; the message names the file.
    FileNotFoundError
        If the file does not exist.
    """
    path = Path(path)
    try:
        data = json.loads(path.read_text())
    except json.JSONDecodeError as exc:
        raise MarkerMapError(f"{path} is not valid JSON ({exc}); marker maps are JSON files "
                             "(YAML is not supported)") from exc
    try:
        return MarkerMap.from_dict(data)
    except MarkerMapError as exc:
        raise MarkerMapError(f"{path}: {exc}") from exc

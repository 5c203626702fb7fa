"""The one observation type, fusion.range_bearing.RangeBearing: validation, read-only columns,
grouping, selection, concatenation, rows."""

import dataclasses

import numpy as np
import pytest

from fusion.exceptions import (
    CovarianceNotPositiveDefiniteError,
    FusionError,
    LandmarkGeometryError,
    LandmarkIdError,
    MeasurementShapeError,
    NonFiniteInputError,
)
from fusion.range_bearing import RangeBearing
from lti_motion.exceptions import NonFiniteError, ShapeError

COV = np.array([[4e-4, 2e-5], [2e-5, 1e-4]])


def _obs(cov: bool = False) -> RangeBearing:
    return RangeBearing([5, 2, 5, 2, 9], [1, 2, 3, 1, 2], [1.0, 2.0, 3.0, 4.0, 5.0],
                        [0.1, 0.2, 0.3, 0.4, 0.5],
                        cov=np.stack([COV * (j + 1) for j in range(5)]) if cov else None)


def test_columns_are_typed_and_read_only():
    obs = _obs(cov=True)
    assert obs.index.dtype == np.int64 and obs.landmark_id.dtype == np.int64
    assert obs.range_m.dtype == float and obs.cov.shape == (5, 2, 2)
    for name in ("index", "landmark_id", "range_m", "bearing_rad", "cov"):
        with pytest.raises(ValueError, match="read-only"):
            getattr(obs, name)[0] = 1
    with pytest.raises(dataclasses.FrozenInstanceError):
        obs.range_m = np.ones(5)  # type: ignore[misc]


def test_the_input_arrays_are_copied():
    r = np.array([1.0, 2.0])
    obs = RangeBearing([0, 1], [3, 4], r, [0.0, 0.0])
    r[0] = 7.0
    assert obs.range_m.tolist() == [1.0, 2.0]


def test_hashable_ids_are_kept_as_objects_and_one_index_fits_every_row():
    obs = RangeBearing(3, ["door", 7, ("a", 1)], [1.0, 2.0, 3.0], [0.0, 0.1, 0.2])
    assert obs.landmark_id.dtype == object
    assert obs.landmark_id.tolist() == ["door", 7, ("a", 1)]
    assert obs.index.tolist() == [3, 3, 3]
    assert [lid for lid, _, _ in obs] == ["door", 7, ("a", 1)]


def test_rows_iterate_as_id_measurement_and_covariance():
    rows = list(_obs(cov=True))
    assert len(rows) == 5
    lid, z, cov = rows[2]
    assert lid == 3 and z.tolist() == [3.0, 0.3]
    np.testing.assert_array_equal(cov, 3 * COV)
    assert all(c is None for _, _, c in _obs())


def test_grouping_by_index_keeps_the_row_order():
    groups = _obs(cov=True).by_index()
    assert list(groups) == [2, 5, 9]
    assert groups[2].landmark_id.tolist() == [2, 1] and groups[2].range_m.tolist() == [2.0, 4.0]
    np.testing.assert_array_equal(groups[5].cov, [COV, 3 * COV])
    assert groups[9].index.tolist() == [9]
    assert RangeBearing.empty().by_index() == {}


def test_select_with_index_and_concatenate():
    obs = _obs(cov=True)
    sel = obs.select(obs.landmark_id == 2)
    assert sel.index.tolist() == [2, 9] and sel.range_m.tolist() == [2.0, 5.0]
    assert sel.select(slice(1, 2)).range_m.tolist() == [5.0]
    moved = obs.with_index(np.arange(5))
    assert moved.index.tolist() == [0, 1, 2, 3, 4] and moved.cov is obs.cov
    assert obs.with_index(4).index.tolist() == [4] * 5
    with pytest.raises(MeasurementShapeError, match=r"expected \(5,\)"):
        obs.with_index([1, 2])
    both = RangeBearing.concatenate([obs.select(slice(0, 2)), RangeBearing.empty(),
                                     obs.select(slice(2, None))])
    assert both == obs
    assert RangeBearing.concatenate([]) is RangeBearing.empty()
    with pytest.raises(MeasurementShapeError, match="with and without"):
        RangeBearing.concatenate([obs, _obs()])
    mixed = RangeBearing.concatenate([_obs(), RangeBearing(1, ["door"], [1.0], [0.0])])
    assert mixed.landmark_id.dtype == object and mixed.landmark_id.tolist()[-2:] == [2, "door"]


def test_equality_compares_every_column():
    assert _obs() == _obs() and _obs(cov=True) == _obs(cov=True)
    assert _obs() != _obs(cov=True)
    assert _obs() != _obs().with_index(0)
    assert _obs() != "rows"


@pytest.mark.parametrize("kwargs, error, match", [
    ({"range_m": [1.0]}, MeasurementShapeError, r"bearing_rad has shape \(2,\), expected \(1,\)"),
    ({"landmark_id": [1]}, MeasurementShapeError, r"landmark_id has shape \(1,\), expected \(2,\)"),
    ({"index": [0, 1, 2]}, MeasurementShapeError, r"index has shape \(3,\), expected \(2,\)"),
    ({"index": [0.0, 1.0]}, MeasurementShapeError, "integers.*float64"),
    ({"range_m": [[1.0, 2.0]]}, MeasurementShapeError, r"range_m has shape \(1, 2\)"),
    ({"range_m": [1.0, np.nan]}, NonFiniteInputError, "range_m.*row 1"),
    ({"bearing_rad": [np.inf, 0.0]}, NonFiniteInputError, "bearing_rad.*row 0"),
    ({"range_m": [1.0, 0.0]}, LandmarkGeometryError, "positive.*row 1"),
    ({"landmark_id": [[1], 2]}, LandmarkIdError, "hashable"),
    ({"cov": np.stack([COV] * 3)}, MeasurementShapeError, r"cov has shape \(3, 2, 2\), "
                                                         r"expected \(2, 2, 2\)"),
    ({"cov": np.stack([COV, COV + np.array([[0, 1e-3], [0, 0]])])},
     CovarianceNotPositiveDefiniteError, "row 1"),
    ({"cov": np.stack([COV, -COV])}, CovarianceNotPositiveDefiniteError, "row 1"),
    ({"cov": np.stack([COV, [[1.0, 2.0], [2.0, 1.0]]])}, CovarianceNotPositiveDefiniteError,
     "row 1"),
    ({"cov": np.stack([COV * np.nan, COV])}, NonFiniteInputError, "cov.*row 0"),
])
def test_bad_input_names_the_column_and_the_shapes(kwargs, error, match):
    args = {"index": [0, 1], "landmark_id": [1, 2], "range_m": [1.0, 2.0],
            "bearing_rad": [0.0, 0.1], **kwargs}
    with pytest.raises(error, match=match) as info:
        RangeBearing(**args)
    assert isinstance(info.value, FusionError) and isinstance(info.value, ValueError)


def test_errors_are_the_core_packages_too():
    assert issubclass(MeasurementShapeError, ShapeError)
    assert issubclass(NonFiniteInputError, NonFiniteError)

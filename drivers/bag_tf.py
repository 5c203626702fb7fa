"""Reference poses from ``tf``: one frame's transform in ``tf2_msgs/TFMessage`` topics.

A motion-capture or simulator bag often carries its ground truth not as a
``geometry_msgs/PoseStamped`` topic but as a transform on ``/tf`` (and
``/tf_static``): ``world -> base_link``, stamped per transform. :func:`tf_truth`
picks the transforms of one (parent, child) frame pair out of the decoded
``TFMessage`` messages and returns them as stamped (x, y, quaternion) rows,
which :func:`drivers.bags.read_bag` turns into reference poses like a
``PoseStamped`` topic's.

The pair is the one published directly (a transform from ``parent`` to
``child`` in one ``TransformStamped``); chains of transforms are not composed.
Without a named pair, the first pair present among :data:`TRUTH_PARENTS` x
:data:`TRUTH_CHILDREN` (parents in that order of preference) is used. Frame
names are compared without a leading ``/`` (ROS 1 tf frames often carry one).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from drivers.exceptions import BagError

__all__ = ["TF_TYPE", "TRUTH_CHILDREN", "TRUTH_PARENTS", "TfTruth", "tf_truth"]

#: The message type of tf topics.
TF_TYPE = "tf2_msgs/msg/TFMessage"
#: Parent frames tried for reference poses, most trusted first (a fixed world frame,
#: then a map, then odometry's frame).
TRUTH_PARENTS = ("world", "map", "odom")
#: Child frames tried: the robot's body frame as REP 105 names it.
TRUTH_CHILDREN = ("base_link", "base_footprint")

#: What :func:`tf_truth` returns: stamps [ns], (x, y, qx, qy, qz, qw) rows, the pair, topics.
TfTruth = tuple[np.ndarray, np.ndarray, tuple[str, str], tuple[str, ...]]


def _frame(name: str) -> str:
    return name.lstrip("/")


def _collect(msgs: Sequence[object], recv_ns: Sequence[int], topics: Sequence[str]
             ) -> dict[tuple[str, str], tuple[list[list[float]], set[str]]]:
    """Rows (stamp, x, y, qx, qy, qz, qw) and source topics of every (parent, child) pair."""
    pairs: dict[tuple[str, str], tuple[list[list[float]], set[str]]] = {}
    for msg, recv, topic in zip(msgs, recv_ns, topics, strict=True):
        for tr in msg.transforms:
            key = (_frame(tr.header.frame_id), _frame(tr.child_frame_id))
            rows, where = pairs.setdefault(key, ([], set()))
            stamp = tr.header.stamp.sec * 1_000_000_000 + tr.header.stamp.nanosec
            p, q = tr.transform.translation, tr.transform.rotation
            rows.append([stamp or int(recv), p.x, p.y, q.x, q.y, q.z, q.w])
            where.add(topic)
    return pairs


def tf_truth(msgs: Sequence[object], recv_ns: Sequence[int], topics: Sequence[str], *,
             parent: str | None = None, child: str | None = None) -> TfTruth | None:
    """The transforms of one frame pair, in stamp order.

    Parameters
    ----------
    msgs : sequence of TFMessage
        Deserialized ``tf2_msgs/TFMessage`` messages (rosbags' classes).
    recv_ns : sequence of int
        Each message's receive time [ns]: the stamp of a transform whose header
        stamp is zero (``/tf_static`` publishers often leave it so).
    topics : sequence of str
        Each message's topic.
    parent, child : str, optional
        The frame pair; either left out is tried from :data:`TRUTH_PARENTS` /
        :data:`TRUTH_CHILDREN`.

    Returns
    -------
    tuple or None
        ``(t_ns, rows, (parent, child), topics)``: stamps [ns] (int64, shape
        (n,)), rows (x [m], y [m], qx, qy, qz, qw) of shape (n, 6), the pair and
        the topics it came from; ``None`` when no pair was named and none of the
        defaults is present.

    Raises
    ------
    BagError
        A named pair is absent; the message lists the pairs the bag's tf holds.
    """
    pairs = _collect(msgs, recv_ns, topics)
    parents = (_frame(parent),) if parent is not None else TRUTH_PARENTS
    children = (_frame(child),) if child is not None else TRUTH_CHILDREN
    found = next(((p, c) for p in parents for c in children if (p, c) in pairs), None)
    if found is None:
        if parent is None and child is None:
            return None
        held = ", ".join(f"{p} -> {c}" for p, c in sorted(pairs)) or "no transforms"
        raise BagError(f"the bag's tf has no transform {' or '.join(parents)} -> "
                       f"{' or '.join(children)}; it has {held} (choose with --truth-parent "
                       "and --truth-child)")
    rows, where = pairs[found]
    data = np.array(rows, dtype=object)
    t_ns = data[:, 0].astype(np.int64)
    order = np.argsort(t_ns, kind="stable")
    return t_ns[order], data[order, 1:].astype(float), found, tuple(sorted(where))

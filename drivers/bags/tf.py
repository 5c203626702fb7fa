"""Reference poses from ``tf``: one frame's pose in another, through a chain of transforms.

A motion-capture or simulator bag often carries its ground truth not as a
``geometry_msgs/PoseStamped`` topic but as transforms on ``/tf`` (and
``/tf_static``): ``world -> base_link`` directly, or a chain such as
``map -> odom -> base_link`` (a localiser's correction on top of odometry) or
``odom -> base_footprint -> base_link`` (with a static mount on
``/tf_static``). :func:`tf_truth` composes the chain from a parent frame to a
child frame out of the decoded ``TFMessage`` messages and returns it as stamped
(x, y, quaternion) rows, which :func:`drivers.bags.read_bag` turns into
reference poses like a ``PoseStamped`` topic's.

Rules:

- the chain is the shortest path between the two frames through the
  transforms present, each link used as published (parent to child) or
  inverted (a tree walked up then down: ``map -> odom`` and
  ``odom -> base_link`` give ``map -> base_link``; ``base_link -> laser``
  gives ``laser -> base_link``);
- a link published once, or only on ``/tf_static``, holds at all times (its
  latest transform); the others are *dynamic*;
- the poses are stamped with the stamps of the dynamic link holding the most
  transforms (the fastest; a direct pair: its own stamps), restricted to the
  span every other dynamic link covers (tf does not extrapolate), and each
  other dynamic link is interpolated at those stamps: translation linearly,
  rotation by spherical linear interpolation (Shoemake 1985, "Animating
  rotation with quaternion curves", SIGGRAPH, eq. on p. 248);
- links compose as rigid transforms, ``a_T_c = a_T_b b_T_c`` (translation
  ``t_ab + R_ab t_bc``, rotation ``R_ab R_bc``; Craig 2005, eq. 2.45), in 3-D,
  so a mount's height or tilt does not leak into x and y.

Without a named pair, the first pair joined by a chain among
:data:`TRUTH_PARENTS` x :data:`TRUTH_CHILDREN` (parents in that order of
preference) is used. Frame names are compared without a leading ``/`` (ROS 1
tf frames often carry one).
"""

from __future__ import annotations

from collections import deque
from collections.abc import Sequence

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from drivers.exceptions import BagError

__all__ = ["TF_TYPE", "TRUTH_CHILDREN", "TRUTH_PARENTS", "TfTruth", "tf_truth"]

#: The message type of tf topics.
TF_TYPE = "tf2_msgs/msg/TFMessage"
#: Parent frames tried for reference poses, most trusted first (a fixed world frame,
#: then a map, then odometry's frame).
TRUTH_PARENTS = ("world", "map", "odom")
#: Child frames tried: the robot's body frame as REP 105 names it.
TRUTH_CHILDREN = ("base_link", "base_footprint")
#: The topic whose transforms hold at all times.
_STATIC_TOPIC = "/tf_static"

#: What :func:`tf_truth` returns: stamps [ns], (x, y, qx, qy, qz, qw) rows, the pair, topics.
TfTruth = tuple[np.ndarray, np.ndarray, tuple[str, str], tuple[str, ...]]
#: One link's transforms: rows (stamp, x, y, z, qx, qy, qz, qw) and the topics they came on.
_Link = tuple[list[list[float]], set[str]]
Pair = tuple[str, str]


def _frame(name: str) -> str:
    return name.lstrip("/")


def _collect(msgs: Sequence[object], recv_ns: Sequence[int], topics: Sequence[str]
             ) -> dict[Pair, _Link]:
    """Rows (stamp, x, y, z, qx, qy, qz, qw) and source topics of every (parent, child) pair."""
    pairs: dict[Pair, _Link] = {}
    for msg, recv, topic in zip(msgs, recv_ns, topics, strict=True):
        for tr in msg.transforms:
            key = (_frame(tr.header.frame_id), _frame(tr.child_frame_id))
            rows, where = pairs.setdefault(key, ([], set()))
            stamp = tr.header.stamp.sec * 1_000_000_000 + tr.header.stamp.nanosec
            p, q = tr.transform.translation, tr.transform.rotation
            rows.append([stamp or int(recv), p.x, p.y, p.z, q.x, q.y, q.z, q.w])
            where.add(topic)
    return pairs


def _chain(pairs: dict[Pair, _Link], parent: str, child: str) -> list[tuple[Pair, bool]] | None:
    """The shortest chain of links from ``parent`` to ``child`` (breadth first), each with
    ``True`` where it is used as published, ``False`` inverted; ``None`` if none joins them."""
    step: dict[str, list[tuple[str, Pair, bool]]] = {}
    for p, c in pairs:
        step.setdefault(p, []).append((c, (p, c), True))
        step.setdefault(c, []).append((p, (p, c), False))
    if parent not in step or child not in step:
        return None
    came: dict[str, tuple[str, Pair, bool] | None] = {parent: None}
    todo = deque([parent])
    while todo:
        here = todo.popleft()
        for there, pair, forward in step[here]:
            if there not in came:
                came[there] = (here, pair, forward)
                todo.append(there)
    if child not in came:
        return None
    links, here = [], child
    while came[here] is not None:
        before, pair, forward = came[here]
        links.append((pair, forward))
        here = before
    return links[::-1]


def _top(pairs: dict[Pair, _Link], frame: str) -> str:
    """The frame reached by walking up from ``frame`` through published parents."""
    parent_of = {c: p for p, c in sorted(pairs)}
    seen = {frame}
    while frame in parent_of and parent_of[frame] not in seen:
        frame = parent_of[frame]
        seen.add(frame)
    return frame


def _missing(pairs: dict[Pair, _Link], parent: str, child: str) -> str:
    """Why no chain joins two named frames, for the error message."""
    frames = {f for pair in pairs for f in pair}
    absent = [f for f in (parent, child) if f not in frames]
    if absent:
        return f" (no frame {' nor '.join(absent)} in it)"
    top_p, top_c = _top(pairs, parent), _top(pairs, child)
    return (f" (no chain: {parent}'s transforms lead up to {top_p}, {child}'s to {top_c}; "
            f"the link {top_p} -> {top_c} is missing)")


def _arrays(link: _Link) -> tuple[np.ndarray, np.ndarray]:
    """A link's stamps [ns] (int64, stamp order) and (x, y, z, qx, qy, qz, qw) rows."""
    data = np.array(link[0], dtype=object)
    t_ns = data[:, 0].astype(np.int64)
    order = np.argsort(t_ns, kind="stable")
    return t_ns[order], data[order, 1:].astype(float)


def _link_at(t_link: np.ndarray, rows: np.ndarray, static: bool, t_ns: np.ndarray
             ) -> tuple[np.ndarray, Rotation]:
    """A link's translations and rotations at ``t_ns`` (constant if static; else linear and
    spherical linear interpolation between its transforms, module docstring)."""
    if static:
        return np.tile(rows[-1, :3], (t_ns.size, 1)), Rotation.from_quat(
            np.tile(rows[-1, 3:], (t_ns.size, 1)))
    stamps, first = np.unique(t_link, return_index=True)
    rows = rows[first]
    at, knots = (t_ns - stamps[0]).astype(float), (stamps - stamps[0]).astype(float)
    trans = np.column_stack([np.interp(at, knots, rows[:, j]) for j in range(3)])
    if knots.size == 1:
        return trans, Rotation.from_quat(np.tile(rows[0, 3:], (t_ns.size, 1)))
    return trans, Slerp(knots, Rotation.from_quat(rows[:, 3:]))(at)


def _compose(pairs: dict[Pair, _Link], chain: list[tuple[Pair, bool]]
             ) -> tuple[np.ndarray, np.ndarray]:
    """Stamps [ns] and (x, y, qx, qy, qz, qw) rows of the chain (module docstring)."""
    links = []
    for pair, forward in chain:
        t_link, rows = _arrays(pairs[pair])
        static = t_link.size == 1 or pairs[pair][1] == {_STATIC_TOPIC}
        links.append((t_link, rows, static, forward))
    dynamic = [t_link for t_link, _, static, _ in links if not static]
    if not dynamic:
        t_ns = np.array([max(int(t_link[-1]) for t_link, *_ in links)], np.int64)
    else:
        t_ns = max(dynamic, key=len)
        for t_link in dynamic:
            t_ns = t_ns[(t_ns >= t_link[0]) & (t_ns <= t_link[-1])]
    trans, rot = np.zeros((t_ns.size, 3)), Rotation.identity(t_ns.size)
    for t_link, rows, static, forward in links:
        t_ab, r_ab = _link_at(t_link, rows, static, t_ns)
        if not forward:                       # b_T_a = (a_T_b)^-1: R^T, -R^T t
            r_ab = r_ab.inv()
            t_ab = -r_ab.apply(t_ab)
        trans, rot = trans + rot.apply(t_ab), rot * r_ab     # Craig 2005 eq. 2.45
    return t_ns, np.column_stack([trans[:, :2], rot.as_quat()])


def tf_truth(msgs: Sequence[object], recv_ns: Sequence[int], topics: Sequence[str], *,
             parent: str | None = None, child: str | None = None) -> TfTruth | None:
    """The pose of one frame in another, composed along the tf chain, in stamp order.

    Parameters
    ----------
    msgs : sequence of TFMessage
        Deserialized ``tf2_msgs/TFMessage`` messages (rosbags' classes).
    recv_ns : sequence of int
        Each message's receive time [ns]: the stamp of a transform whose header
        stamp is zero (``/tf_static`` publishers often leave it so).
    topics : sequence of str
        Each message's topic (``/tf_static``: links that hold at all times).
    parent, child : str, optional
        The frame pair; either left out is tried from :data:`TRUTH_PARENTS` /
        :data:`TRUTH_CHILDREN`.

    Returns
    -------
    tuple or None
        ``(t_ns, rows, (parent, child), topics)``: stamps [ns] (int64, shape
        (n,)), rows (x [m], y [m], qx, qy, qz, qw) of shape (n, 6), the pair and
        the topics its chain came from; ``None`` when no pair was named and no
        chain joins any of the defaults.

    Raises
    ------
    BagError
        No chain joins a named pair; the message says which frame is absent or
        which link is missing, and lists the pairs the bag's tf holds.
    """
    pairs = _collect(msgs, recv_ns, topics)
    parents = (_frame(parent),) if parent is not None else TRUTH_PARENTS
    children = (_frame(child),) if child is not None else TRUTH_CHILDREN
    found = next(((p, c, chain) for p in parents for c in children if p != c
                  and (chain := _chain(pairs, p, c)) is not None), None)
    if found is None:
        if parent is None and child is None:
            return None
        held = ", ".join(f"{p} -> {c}" for p, c in sorted(pairs)) or "no transforms"
        why = _missing(pairs, parents[0], children[0]) if len(parents) == len(children) == 1 \
            else ""
        raise BagError(f"the bag's tf has no transform {' or '.join(parents)} -> "
                       f"{' or '.join(children)}{why}; it has {held} (choose with "
                       "--truth-parent and --truth-child)")
    p, c, chain = found
    where = sorted({topic for pair, _ in chain for topic in pairs[pair][1]})
    if len(chain) == 1 and chain[0][1]:       # published directly: its own transforms
        t_ns, rows = _arrays(pairs[chain[0][0]])
        rows = np.column_stack([rows[:, :2], rows[:, 3:]])
    else:
        t_ns, rows = _compose(pairs, chain)
    return t_ns, rows, (p, c), tuple(where)

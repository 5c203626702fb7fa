"""The bags wing: ROS 1 and ROS 2 bags in and out, through ``rosbags`` (no ROS install).

- :mod:`drivers.bags.reader`: :func:`read_bag`, a bag's drive as one
  :class:`~lti_motion.recordings.Recording` (topics found by message type), and
  :func:`bag_grid`, that recording on the model's grid;
- :mod:`drivers.bags.topics`: the raw per-topic series the reader starts from;
- :mod:`drivers.bags.messages`: a bag opened, the raw messages of the wanted topics;
- :mod:`drivers.bags.clocks`: header stamps against receive times, one time base;
- :mod:`drivers.bags.twist_checks`: odometry twists inconsistent with their neighbours;
- :mod:`drivers.bags.integrity`: an MCAP file's records walked, a damaged bag refused;
- :mod:`drivers.bags.fields`: numbers at field paths decoded from raw messages;
- :mod:`drivers.bags.tf`: reference poses from ``/tf``;
- :mod:`drivers.bags.imu_noise`: the gyro's noise measured from the bag;
- :mod:`drivers.bags.urdf`: a robot's wheels (separation, radius) from its URDF;
- :mod:`drivers.bags.writer`: estimates and simulated drives written as bags.

The names below load with their module on first use (:mod:`lti_motion.lazy`), so
importing the door costs nothing until a name is read.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from lti_motion.lazy import lazy_exports

__all__ = [
    "CREATE2_TICKS_PER_RAD",
    "CREATE2_WHEEL_RADIUS_M",
    "HALF_WINDOW",
    "LEFT_JOINT",
    "MAX_GAP_S",
    "MAX_LAG_S",
    "MAX_WHEEL_M_S",
    "MIN_JUMP",
    "OUTLIER_K",
    "RIGHT_JOINT",
    "ROBOT_DESCRIPTION_TOPIC",
    "STAMP_CHOICES",
    "TF_TYPE",
    "TOPIC_OPTIONS",
    "TOPIC_TYPES",
    "TRUTH_CHILDREN",
    "TRUTH_PARENTS",
    "BagAlarm",
    "BagTopics",
    "ClockCheck",
    "Damage",
    "ImuRateNoise",
    "StampedSeries",
    "TfTruth",
    "TwistOutliers",
    "UrdfWheels",
    "bag_grid",
    "bag_paths",
    "bag_topics",
    "check_bag",
    "choose_time_base",
    "command_lag_s",
    "decode_fields",
    "drop_twist_outliers",
    "field_value",
    "imu_rate_noise",
    "is_mcap",
    "mcap_damage",
    "open_bag",
    "raw_messages",
    "read_bag",
    "read_bag_urdf",
    "read_topics",
    "read_urdf_wheels",
    "tf_truth",
    "twist_outliers",
    "urdf_wheels",
    "with_rate_data",
    "write_drive_bag",
    "write_estimates_bag",
]

__getattr__, __dir__ = lazy_exports(
    __name__,
    {
        "drivers.bags.clocks": (
            "ClockCheck",
            "MAX_LAG_S",
            "STAMP_CHOICES",
            "choose_time_base",
            "command_lag_s",
        ),
        "drivers.bags.fields": (
            "decode_fields",
            "field_value",
        ),
        "drivers.bags.imu_noise": (
            "ImuRateNoise",
            "imu_rate_noise",
            "with_rate_data",
        ),
        "drivers.bags.integrity": (
            "Damage",
            "check_bag",
            "mcap_damage",
        ),
        "drivers.bags.messages": (
            "bag_paths",
            "is_mcap",
            "open_bag",
            "raw_messages",
        ),
        "drivers.bags.reader": (
            "CREATE2_TICKS_PER_RAD",
            "CREATE2_WHEEL_RADIUS_M",
            "MAX_GAP_S",
            "MAX_WHEEL_M_S",
            "bag_grid",
            "read_bag",
        ),
        "drivers.bags.tf": (
            "TF_TYPE",
            "TRUTH_CHILDREN",
            "TRUTH_PARENTS",
            "TfTruth",
            "tf_truth",
        ),
        "drivers.bags.topics": (
            "BagTopics",
            "LEFT_JOINT",
            "RIGHT_JOINT",
            "StampedSeries",
            "TOPIC_OPTIONS",
            "TOPIC_TYPES",
            "bag_topics",
            "read_topics",
        ),
        "drivers.bags.twist_checks": (
            "HALF_WINDOW",
            "MIN_JUMP",
            "OUTLIER_K",
            "TwistOutliers",
            "drop_twist_outliers",
            "twist_outliers",
        ),
        "drivers.bags.urdf": (
            "ROBOT_DESCRIPTION_TOPIC",
            "UrdfWheels",
            "read_bag_urdf",
            "read_urdf_wheels",
            "urdf_wheels",
        ),
        "drivers.bags.writer": (
            "BagAlarm",
            "write_drive_bag",
            "write_estimates_bag",
        ),
    },
    __all__,
)

if TYPE_CHECKING:
    from drivers.bags.clocks import (
        MAX_LAG_S,
        STAMP_CHOICES,
        ClockCheck,
        choose_time_base,
        command_lag_s,
    )
    from drivers.bags.fields import decode_fields, field_value
    from drivers.bags.imu_noise import ImuRateNoise, imu_rate_noise, with_rate_data
    from drivers.bags.integrity import Damage, check_bag, mcap_damage
    from drivers.bags.messages import bag_paths, is_mcap, open_bag, raw_messages
    from drivers.bags.reader import (
        CREATE2_TICKS_PER_RAD,
        CREATE2_WHEEL_RADIUS_M,
        MAX_GAP_S,
        MAX_WHEEL_M_S,
        bag_grid,
        read_bag,
    )
    from drivers.bags.tf import TF_TYPE, TRUTH_CHILDREN, TRUTH_PARENTS, TfTruth, tf_truth
    from drivers.bags.topics import (
        LEFT_JOINT,
        RIGHT_JOINT,
        TOPIC_OPTIONS,
        TOPIC_TYPES,
        BagTopics,
        StampedSeries,
        bag_topics,
        read_topics,
    )
    from drivers.bags.twist_checks import (
        HALF_WINDOW,
        MIN_JUMP,
        OUTLIER_K,
        TwistOutliers,
        drop_twist_outliers,
        twist_outliers,
    )
    from drivers.bags.urdf import (
        ROBOT_DESCRIPTION_TOPIC,
        UrdfWheels,
        read_bag_urdf,
        read_urdf_wheels,
        urdf_wheels,
    )
    from drivers.bags.writer import BagAlarm, write_drive_bag, write_estimates_bag

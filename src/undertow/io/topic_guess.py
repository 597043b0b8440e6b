"""Which topic of an unknown bag is which stream: scored by message type and name.

A topic can serve a stream only if its message type is one the stream accepts
(:data:`undertow.io.rosbag_streams.ACCEPTED`). Among those, a type that only one stream uses
(a DVL message, ``dvl_msgs/DVLDR``, ``sensor_msgs/Imu``, ``NavSatFix``) scores high on its own;
a generic type (a pose, a float, an odometry) needs a word of the stream in the topic's name
(``depth`` for a depth, ``gps`` for an odometry fix). Words that mean another quantity (``leak``
on a pressure, ``desired``/``command``/``setpoint``) count against. Each topic serves at most
one stream, the best-scoring pairs first. :func:`propose_topics` returns the choice with the
reasons, for ``undertow check`` and for the reader of a bag whose topics match none of the
defaults.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from .ros_dvl import DVL_TYPES, TWIST, TWIST_COV
from .rosbag_streams import ACCEPTED, FLOAT_TYPES, NAVSATFIX, ODOMETRY, POSE, POSE_COV

#: streams a topic is proposed for (tf_static and the raw JSON keep their names)
GUESSED = ("dvl", "dead_reckoning", "imu", "pressure", "depth", "sonar", "gps", "multibeam",
           "ground_truth", "wave_probe")  # fmt: skip
#: undertow's own recordings' topics (late records, estimates): never a sensor to propose
OWN_PREFIX = "/undertow/"
#: a proposal needs at least this score
MIN_SCORE = 5
#: (stream, type or None for any accepted type) -> points of the type alone
_TYPE_POINTS = {
    ("dvl", TWIST_COV): 2,
    ("dvl", TWIST): 2,
    ("dead_reckoning", POSE_COV): 0,
    ("depth", POSE_COV): 0,
    ("depth", POSE): 0,
    ("gps", ODOMETRY): 0,
    ("gps", NAVSATFIX): 10,
    ("ground_truth", ODOMETRY): 0,
    ("pressure", None): 6,
    ("sonar", None): 4,
    ("multibeam", None): 2,
    ("wave_probe", None): 0,
}
for _t in DVL_TYPES:
    _TYPE_POINTS.setdefault(("dvl", _t), 10)
for _t in FLOAT_TYPES:
    _TYPE_POINTS[("depth", _t)] = 0
_TYPE_POINTS[("dead_reckoning", "dvl_msgs/msg/DVLDR")] = 10
_TYPE_POINTS[("imu", "sensor_msgs/msg/Imu")] = 8

#: words of the topic name (split at / _ - .) for and against each stream
_WORDS = {
    "dvl": ({"dvl": 3, "velocity": 1, "data": 1}, {}),
    "dead_reckoning": (
        {"dead": 3, "reckoning": 3, "dr": 3, "position": 3, "dvl": 3, "local": 1},
        {"global": -2, "depth": -6},
    ),  # fmt: skip
    "imu": ({"imu": 2, "data": 1}, {"raw": -1}),
    "pressure": (
        {"pressure": 3, "baro": 3, "barometer": 3, "fluid": 1, "data": 1},
        {"leak": -8, "battery": -8, "desired": -8},
    ),  # fmt: skip
    "depth": ({"depth": 8}, {}),
    "sonar": ({"sonar": 3, "ping": 3, "echo": 2, "altitude": 2, "altimeter": 2, "range": 1}, {}),
    "gps": ({"gps": 6, "fix": 3, "gnss": 6, "navsat": 6}, {"extended": -1}),
    "multibeam": ({"mbes": 5, "multibeam": 5, "points": 1}, {}),
    "ground_truth": ({"ground": 3, "truth": 5, "mocap": 6, "qualisys": 6, "vicon": 6}, {}),
    "wave_probe": ({"wave": 6, "probe": 3}, {}),
}
_AGAINST_ALL = {"desired": -8, "command": -8, "setpoint": -8, "cmd": -8, "target": -6}


@dataclass(frozen=True)
class TopicChoice:
    """A topic proposed for a stream, its type, score and why."""

    stream: str
    topic: str
    msgtype: str
    score: int
    reason: str

    def to_dict(self) -> dict:
        return {"stream": self.stream, "topic": self.topic, "type": self.msgtype,
                "score": self.score, "reason": self.reason}  # fmt: skip


def _words(topic: str) -> list[str]:
    return [w for w in re.split(r"[/_\-.]+", topic.lower()) if w]


def score(stream: str, topic: str, msgtype: str) -> tuple[int, str]:
    """(points, reason) of ``topic`` of ``msgtype`` as ``stream``; (-1, reason) when the type
    is not one the stream accepts."""
    if msgtype not in ACCEPTED.get(stream, ()):
        return -1, "type not accepted"
    points = _TYPE_POINTS.get((stream, msgtype), _TYPE_POINTS.get((stream, None), 0))
    reasons = [f"type {msgtype.split('/')[-1]}"]
    good, bad = _WORDS.get(stream, ({}, {}))
    for word in _words(topic):
        delta = good.get(word, 0) + bad.get(word, 0) + _AGAINST_ALL.get(word, 0)
        if delta:
            points += delta
            reasons.append(f"'{word}' {delta:+d}")
    return points, ", ".join(reasons)


def propose_topics(available: dict[str, str], streams=GUESSED) -> dict[str, TopicChoice]:
    """The best topic per stream of ``available`` (topic -> type), each topic used once."""
    pairs = []
    for stream in streams:
        for topic, msgtype in available.items():
            if topic.startswith(OWN_PREFIX):
                continue
            points, reason = score(stream, topic, msgtype)
            if points >= MIN_SCORE:
                pairs.append(TopicChoice(stream, topic, msgtype, points, reason))
    pairs.sort(key=lambda c: (-c.score, streams.index(c.stream), c.topic))
    chosen: dict[str, TopicChoice] = {}
    used: set[str] = set()
    for choice in pairs:
        if choice.stream in chosen or choice.topic in used:
            continue
        chosen[choice.stream] = choice
        used.add(choice.topic)
    return {s: chosen[s] for s in streams if s in chosen}

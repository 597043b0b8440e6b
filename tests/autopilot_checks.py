"""Checks shared by the tests that drive an autopilot with ``undertow live --autopilot`` (the
virtual one of ``undertow serve --autopilot``, and ArduSub's SITL): undertow's saved estimate
put in the autopilot's clock and frame, with the error undertow sent, to hold the autopilot's
own LOCAL_POSITION_NED against."""

from __future__ import annotations

import json
import math

import numpy as np
from rosbags.highlevel import AnyReader

from undertow.io.msgdefs import dvl_typestore
from undertow.trajectory import Trajectory


def sent_records(result) -> list[dict]:
    """undertow's /autopilot/sent records, in sending order."""
    with AnyReader([result.recording], default_typestore=dvl_typestore()) as reader:
        conns = [c for c in reader.connections if c.topic == "/autopilot/sent"]
        rows = [json.loads(reader.deserialize(raw, c.msgtype).data)
                for c, _, raw in reader.messages(connections=conns)]  # fmt: skip
    return sorted(rows, key=lambda r: r["sent_at"])


class Estimate:
    """undertow's saved trajectory in the autopilot's terms: its clock (a state's time in the
    autopilot's clock is its message's time_usec) and its frame (turned by the heading offset
    undertow found and reported), and the error it sent."""

    def __init__(self, result):
        self.traj = Trajectory.load_npz(result.localization / "trajectory.npz")
        self.sent = sent_records(result)
        self.sent_at = np.array([r["time_usec"] * 1e-6 for r in self.sent])
        # undertow's estimate of the clock offset (its least arrival-minus-boot time) firms
        # up by a millisecond or two: each message carries the one it used
        self.offsets = np.array([r["state_t"] for r in self.sent]) - self.sent_at
        assert np.ptp(self.offsets) < 0.02
        dpsi = math.radians(result.summary["autopilot"]["heading_offset_deg"])
        c, s = math.cos(dpsi), math.sin(dpsi)
        self.turn = np.array([[c, -s], [s, c]])

    def position(self, t_ap: float) -> np.ndarray:
        """The trajectory's horizontal position at autopilot time ``t_ap``, north-east."""
        s = t_ap + float(np.interp(t_ap, self.sent_at, self.offsets))
        xy = [np.interp(s, self.traj.t, self.traj.x[:, k]) for k in (0, 1)]
        return self.turn @ np.array(xy)

    def record_before(self, t_ap: float) -> dict | None:
        k = int(np.searchsorted(self.sent_at, t_ap, side="right")) - 1
        return self.sent[k] if k >= 0 else None

    def span(self) -> tuple[float, float]:
        return float(self.sent_at[0]), float(self.sent_at[-1])

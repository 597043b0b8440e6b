"""Sending undertow's live estimate to the autopilot (ArduSub's EKF3) over MAVLink, safely,
and reading back what the autopilot makes of it. One job per module:

- :mod:`.covariance`: the 21-term layout, the inflation, ArduPilot's reduction, confidence;
- :mod:`.frame`: the autopilot's heading offset and clock;
- :mod:`.messages`: ODOMETRY, VISION_POSITION_ESTIMATE, VISION_POSITION_DELTA of a state;
- :mod:`.schedule`: when a message goes (fixed rate, low latency);
- :mod:`.gate`: the safety rules and reset_counter;
- :mod:`.params`, :mod:`.origin`, :mod:`.streams`, :mod:`.traffic`: parameters, EKF origin,
  message requests, other senders and EKF status;
- :mod:`.vehicle`: the conversation with the vehicle; :mod:`.stats`: the figures;
- :mod:`.bridge`: the session's hooks (``undertow live --autopilot``).
"""

from __future__ import annotations

from .bridge import AutopilotBridge, open_bridge

__all__ = ["AutopilotBridge", "open_bridge"]

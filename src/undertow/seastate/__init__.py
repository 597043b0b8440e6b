"""The sea state from the robot's own sensors (barometer, DVL, orientation): no wave probe."""

from .fit import PLATFORMS, SeaStateEstimate, WaveWindow, estimate_sea_state

__all__ = ["PLATFORMS", "SeaStateEstimate", "WaveWindow", "estimate_sea_state"]

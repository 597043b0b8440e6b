"""The sea state from the robot's own sensors (barometer, DVL, orientation): no wave probe.

Per window of about 20 wave periods, one regular linear wave (amplitude a, intrinsic angular
frequency omega, propagation direction beta) is fitted coherently to every channel at once
through the transfer functions of linear wave theory (:mod:`undertow.sim.waves`). The steps, one
module each:

- :mod:`~undertow.seastate.prepare`: the log's barometer and DVL as channels in the world frame,
  the water depth, the dead-reckoned track;
- :mod:`~undertow.seastate.signal`: moving averages, the high-pass, the encounter-frequency
  periodogram peaks;
- :mod:`~undertow.seastate.fit`: the model and its maximum-likelihood fit in one window
  (compiled), the calm test;
- :mod:`~undertow.seastate.windows`: the windows, the platform model (rigid or free) each keeps,
  and the :class:`WaveWindow` of a fit;
- :mod:`~undertow.seastate.directions`: whether a window observes the direction, and the passes
  that pool, check and lend it across windows;
- :mod:`~undertow.seastate.estimate`: :func:`estimate_sea_state`, those steps in order;
- :mod:`~undertow.seastate.online`: the same estimate over a sliding window of live records.
"""

from .estimate import estimate_sea_state
from .prepare import PLATFORMS
from .result import SeaStateEstimate, WaveWindow

__all__ = ["PLATFORMS", "SeaStateEstimate", "WaveWindow", "estimate_sea_state"]

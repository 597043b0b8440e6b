"""State estimation: the paper's 18-state UKF, wave noise profiles, smoother, calibration; the
sea state estimated from the robot's own sensors is :mod:`undertow.seastate` (its names are
importable from here too)."""

from ..seastate import SeaStateEstimate, WaveWindow, estimate_sea_state
from .calibration import Calibration, calibrate
from .config import LocalizerConfig
from .localizer import Localizer, localize
from .noise import NoiseProfile
from .online import OnlineLocalizer
from .smoother import smooth

__all__ = [
    "Calibration",
    "Localizer",
    "LocalizerConfig",
    "NoiseProfile",
    "OnlineLocalizer",
    "SeaStateEstimate",
    "WaveWindow",
    "calibrate",
    "estimate_sea_state",
    "localize",
    "smooth",
]

"""State estimation: the paper's 18-state UKF, wave noise profiles, smoother, calibration."""

from .calibration import Calibration, calibrate
from .config import LocalizerConfig
from .localizer import Localizer, localize
from .noise import NoiseProfile
from .smoother import smooth

__all__ = [
    "Calibration",
    "Localizer",
    "LocalizerConfig",
    "NoiseProfile",
    "calibrate",
    "localize",
    "smooth",
]

"""undertow: uncertainty-aware acoustic localization and seafloor mapping for underwater robots
in waves."""

from .errors import UndertowError
from .log import DeadReckoning, Dvl, GroundTruth, Imu, Log, Pressure, SonarRange, WaveProbe
from .robot import Mounting, SensorMount

__version__ = "0.1.0"

__all__ = [
    "DeadReckoning",
    "Dvl",
    "GroundTruth",
    "Imu",
    "Log",
    "Mounting",
    "Pressure",
    "SensorMount",
    "SonarRange",
    "UndertowError",
    "WaveProbe",
    "__version__",
]

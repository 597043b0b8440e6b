"""Physics-based wave-tank simulator: Airy waves, tank with a rock platform, carriage or free
vehicle motion and the BlueROV2's sensors, producing a Log with ground truth."""

from .scenario.model import Scenario, list_scenarios, load_scenario
from .simulate import SimulationResult, simulate, write_simulation

__all__ = [
    "Scenario",
    "SimulationResult",
    "list_scenarios",
    "load_scenario",
    "simulate",
    "write_simulation",
]

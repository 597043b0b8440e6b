"""Localize and map a simulated wave-tank run with the library (no CLI), then evaluate both.

Run: .venv/bin/python examples/localize_and_map.py [SCENARIO] [SEED]
"""

import sys

from undertow.estimation import Localizer, calibrate, smooth
from undertow.evaluation.cloud import evaluate_map
from undertow.evaluation.trajectory import trajectory_rmse
from undertow.mapping import build_samples, make_mapper
from undertow.sim import load_scenario, simulate

scenario = sys.argv[1] if len(sys.argv) > 1 else "wave-a0.10-f1.00"
seed = int(sys.argv[2]) if len(sys.argv) > 2 else 0

# 1. A calm run with ground truth calibrates the DVL's scale factor and its gyro drift mu_b.
calibration = calibrate(simulate(load_scenario("calm"), seed=seed + 1000).log)

# 2. The wave run: the paper's proposed filter (bias estimation + wave noise of Table I).
sim = simulate(load_scenario(scenario), seed=seed)
gt = sim.log.ground_truth
localizer = Localizer(
    variant="proposed",
    wave=sim.log.metadata["wave"],
    initial_position=tuple(gt.position[0]),
    dr_bias_drift_rad_s=calibration.dr_bias_drift_rad_s,
    dvl_scale_factor=calibration.dvl_scale_factor,
)
trajectory = smooth(localizer.run(sim.log))  # offline: URTS smoothing
errors = trajectory_rmse(trajectory, gt)
print("RMSE:", {k: round(v, 4) for k, v in errors.rmse.items()})
print(f"NEES: {errors.nees_mean:.2f} (6 = consistent)")

# 3. Adaptive BKI map from the DVL beams and the sonar; C2C against the floor scan.
mapper = make_mapper("adaptive")
mapper.integrate(build_samples(sim.log, trajectory))
occupancy = mapper.occupancy()
evaluation = evaluate_map(occupancy.points(0.5), sim.floor_cloud, resolution=0.1)
print(f"map: {evaluation.occupied_cells} occupied cells, C2C {evaluation.c2c_mean_m:.4f} m")

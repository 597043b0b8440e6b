"""The paper's own numbers, typed in from its LaTeX source and labelled as the paper's.

Nothing else in the results is typed in by hand. Sources (labels in the LaTeX source):
Table I ``tab:wave_table``, Table II ``tab:state_estimation_vals``, Table III ``tab:ablation``,
Table IV ``tab:mapping_results``. The paper does not say which wave condition Tables II-IV were
measured in; the report shows them next to every simulated condition.
"""

from __future__ import annotations

AXES = ("x_m", "y_m", "z_m", "roll_rad", "pitch_rad", "yaw_rad", "vx_m_s", "vy_m_s", "vz_m_s")

#: Table I: std. dev. of DVL velocities during waves, (vx, vy, vz) m/s, by (amplitude, frequency).
TABLE_I = {
    "wave-a0.10-f1.00": {
        "amplitude_m": 0.10, "frequency_hz": 1.00, "dvl_std_m_s": (0.025, 0.010, 0.003)
    },
    "wave-a0.10-f0.75": {
        "amplitude_m": 0.10, "frequency_hz": 0.75, "dvl_std_m_s": (0.040, 0.010, 0.003)
    },
    "wave-a0.05-f0.75": {
        "amplitude_m": 0.05, "frequency_hz": 0.75, "dvl_std_m_s": (0.011, 0.010, 0.003)
    },
}  # fmt: skip

#: Tables II and III: RMSE along the trajectory (the ablation omits v_z).
TABLE_II_III = {
    "baseline": (0.862, 0.297, 0.004, 0.003, 0.003, 0.015, 0.023, 0.007, 0.003),
    "be": (0.857, 0.015, 0.004, 0.003, 0.003, 0.003, 0.023, 0.007),
    "an": (0.865, 0.293, 0.004, 0.003, 0.003, 0.015, 0.020, 0.005),
    "proposed": (0.869, 0.012, 0.004, 0.003, 0.003, 0.003, 0.020, 0.005, 0.003),
}
TABLE_II_III = {k: dict(zip(AXES[: len(v)], v, strict=True)) for k, v in TABLE_II_III.items()}

#: Table IV: average cloud-to-cloud distance (m) and number of occupied cells.
TABLE_IV = {
    "csm/baseline": {"c2c_mean_m": 0.226, "occupied_cells": 2774},
    "csm/proposed": {"c2c_mean_m": 0.091, "occupied_cells": 2720},
    "bki/proposed": {"c2c_mean_m": 0.099, "occupied_cells": 7783},
    "adaptive/proposed": {"c2c_mean_m": 0.087, "occupied_cells": 3190},
}

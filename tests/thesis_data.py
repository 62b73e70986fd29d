"""The thesis's hardware data, typed from the thesis for the tests (independent of the defaults in twin/)."""

import numpy as np

# Table 6.3: ball position (m) against the volts measured at the I/O card.
TABLE_6_3_POSITION_M = np.array(
    [-0.323, -0.30, -0.27, -0.24, -0.21, -0.18, -0.15, -0.12, -0.09, -0.06, -0.03, 0.0,
     0.03, 0.06, 0.09, 0.12, 0.15, 0.18, 0.21, 0.24, 0.27, 0.30, 0.323]
)  # fmt: skip
TABLE_6_3_VOLTAGE_V = np.array(
    [-4.620, -4.410, -3.925, -3.460, -3.045, -2.620, -2.170, -1.747, -1.325, -0.895, -0.487, 0.0012,
     0.428, 0.840, 1.280, 1.716, 2.113, 2.470, 3.000, 3.460, 3.890, 4.340, 4.600]
)  # fmt: skip

"""Every number the thesis prints for its models and designs (chapters 3–5), exactly as printed.

One place for the printed values: the ``thesis-*`` controllers run them and the reproduction report
(scripts/reproduce_thesis.py) compares them with recomputed ones. Several are internally inconsistent; that
is reported there, not corrected here.
"""

from __future__ import annotations

import numpy as np

# --- chapter 3: models ------------------------------------------------------------------------------------
R_STAR_PRINTED_M = 4.264e-3  # Table 3.1 (its formula gives 4.676 mm)
J_BALL_PRINTED_KGM2 = 0.455e-6  # Table 3.1 (2/5 m r^2 = 5.23e-7)

A_TORQUE = np.array(
    [  # eq 3.2.8
        [0.0, 0.0, 1.0, 0.0],
        [0.0, 0.0, 0.0, 1.0],
        [-0.4471, -3.97, 0.0, 0.0],
        [-46.2004, 3.8656, 0.0, 0.0],
    ]
)
B_TORQUE = np.array([[0.0], [0.0], [2.4185], [249.9]])  # eq 3.2.9
TF_TORQUE_NUM = [2.419, 0.0, -1001.0]  # eq 3.2.11
TF_TORQUE_DEN = [1.0, 0.0, -3.419, 0.0, -185.1]
POLES_TORQUE = [3.9272, -3.9272, 3.4647j, -3.4647j]  # §3.2
ZEROS_TORQUE = [20.349, -20.349]

MOTOR_TORQUE_PER_VOLT = 0.0164  # eq 3.3.2 (0.016383 unrounded)
MOTOR_BACKEMF_AT_BEAM = 0.154

A_VOLTAGE = np.array(
    [  # eq 3.3.5
        [0.0, 0.0, 1.0, 0.0],
        [0.0, 0.0, 0.0, 1.0],
        [-0.4471, -3.97, 0.0, -0.061],
        [-46.2004, 3.8656, 0.0, -0.6311],
    ]
)
B_VOLTAGE = np.array([[0.0], [0.0], [0.0397], [4.0984]])  # eq 3.3.6
TF_VOLTAGE_NUM = [0.0397, -0.2249, -16.42]  # eq 3.3.8
TF_VOLTAGE_DEN = [1.0, 0.6311, -3.419, -2.536, -185.1]
POLES_VOLTAGE = [3.8046, -4.0681, -0.1838 + 3.4537j, -0.1838 - 3.4537j]  # §3.3
ZEROS_VOLTAGE = [23.3692, -17.7030]

PERIOD_S = 0.02  # §3.4
PHI_TORQUE = np.array(
    [  # eq 3.4.8
        [1.0, -0.0008, 0.02, 0.0],
        [-0.0092, 1.001, -0.0001, 0.02],
        [-0.0087, -0.0794, 1.0, -0.0008],
        [-0.9242, 0.0776, -0.0092, 1.0],
    ]
)
GAMMA_TORQUE = np.array([[0.001], [0.1], [0.4373], [5.002]])  # eq 3.4.9
EIG_PHI_TORQUE = [1.0819, 0.9245, 0.9977 + 0.0692j, 0.9977 - 0.0692j]
PHI_VOLTAGE = np.array(
    [  # eq 3.4.13
        [1.0, -0.0008, 0.02, 0.0],
        [-0.0092, 1.001, -0.0001, 0.0199],
        [-0.008, -0.0794, 1.0, -0.002],
        [-0.9185, 0.0772, -0.0092, 1.0],
    ]
)
GAMMA_VOLTAGE = np.array([[0.0], [0.0016], [0.000841], [0.081]])  # eq 3.4.14
EIG_PHI_VOLTAGE = [1.0766, 0.9224, 0.995 + 0.0673j, 0.995 - 0.0673j]

QC_TORQUE = np.array(
    [  # §3.5, controllability matrix, continuous, torque
        [0.0, 2.4185, 0.0, -993.1843],
        [0.0, 249.9, 0.0, 854.2778],
        [2.4185, 0.0, -993.1843, 0.0],
        [249.9, 0.0, 854.2778, 0.0],
    ]
)
DET_QC_TORQUE = -2.2631e10
QD_TORQUE = np.array(
    [
        [0.001, 0.0097, 0.018, 0.0259],
        [0.1, 0.2001, 0.3003, 0.4005],
        [0.4373, 0.4253, 0.4054, 0.3774],
        [5.002, 5.0048, 5.0075, 5.0104],
    ]
)
DET_QD_TORQUE = -6.3502e-7
WC_TORQUE = np.array(
    [
        [1.0, 0.0, 0.0, 0.0],
        [0.0, 0.0, 1.0, 0.0],
        [-0.4471, -3.97, 0.0, 0.0],
        [0.0, 0.0, -0.4471, -3.97],
    ]
)
WD_TORQUE = np.array(
    [
        [1.0, 0.0, 0.0, 0.0],
        [1.0, -0.0008, 0.02, 0.0],
        [0.9998, -0.0032, 0.04, -0.000032],
        [0.9995, -0.0072, 0.06, -0.000128],
    ]
)

# --- chapter 4: continuous designs ------------------------------------------------------------------------
SF_CONT_POLES = [-1.5 + 2.6j, -1.5 - 2.6j, -7.5, -7.5]  # §4.2
SF_CONT_CHAR_POLY = [1.0, 18.0, 110.25, 303.75, 506.25]
SF_CONT_K = np.array([[-42.13, 27.15, -18.08, 4.41]])  # voltage input (§4.2: "designed w.r.t. voltage")

# eq 4.3.1–4.3.3: τ = α·[ẍ; θ̈] + β
CLP_ALPHA_XDD = 0.000413
CLP_ALPHA_THDD = 0.004
CLP_ALPHA_THDD_X2 = 0.018848
CLP_BETA = (-0.0137, 0.1849, 0.0377, -0.000414)  # sinθ, x·cosθ, x·ẋ·θ̇, x·θ̇²
CLP_CONT_KP = np.diag([-96.8783, 140.4817])  # §4.3 (ζ = 1, ω_n = 2 stated)
CLP_CONT_KV = np.diag([-108.1, 11.81])

SMC_SLIDING_POLES = [-2.0, -2.0, -10.0]  # §4.4
SMC_TR = np.array(
    [
        [0.0, 1.0, 0.0, 0.0],
        [-0.011, 0.0, 1.0, -0.011],
        [1.0, 0.0, -0.011, 0.00013],
        [0.0, 0.0, -0.011, -1.0],
    ]
)
SMC_S = np.array([[45.25, -13.575, 10.47, -1.12]])
SMC_M = np.array([[-13.575, 9.97, -45.36]])
SMC_KEQ = np.array([[10.37, -11.21, 11.057, -3.163]])
SMC_K_MINUS, SMC_K_PLUS, SMC_ETA = -0.5, 0.5, 0.001

# --- chapter 5: discrete designs with reduced-order observers ---------------------------------------------
SF_DISC_POLES = [0.969 + 0.0504j, 0.969 - 0.0504j, 0.861, 0.861]  # §5.2.1
SF_DISC_K = np.array([[-36.34, 24.6, -15.96, 3.98]])
SF_OBS_POLES_S = [-7.63 + 1.685j, -7.63 - 1.685j]
SF_OBS_POLES_Z = [0.835 + 0.199j, 0.835 - 0.199j]
SF_OBS_G = np.array([[4.0, -8.0], [-15.0, 12.0]])

CLP_DISC_POLES = [0.9608, 0.9608]  # §5.2.2
CLP_DISC_KP = np.diag([-29.7741, 37.9376])
CLP_DISC_KV = np.diag([-23.5604, 5.1736])
CLP_OBS_POLES_Z = [0.2, 0.2]
CLP_OBS_POLES_S = [-80.4719, -80.4719]
CLP_OBS_G = np.array([[40.0, -0.227], [-0.045, 39.61]])

# --- chapter 7 claims -------------------------------------------------------------------------------------
SF_CONT_SETTLING_S = (2.5, 3.0)  # §4.2 and chapter 7: "2 < t_s < 3"
CLP_CONT_SETTLING_S = (6.0, 7.0)  # chapter 7
SF_DISC_RANGE = ((-0.25, 0.2), (0.33, 0.68))  # chapter 7: initial states brought back, [x m, θ rad]
CLP_DISC_RANGE = ((-0.25, 0.3), (0.33, 0.7))
CHAPTER4_STARTS = ((0.2, 0.3), (-0.2, 0.3))  # §4.2–4.4 and chapter 5 simulations: [±0.2 m, 0.3 rad]
HARDWARE_STARTS = {  # chapter 6 experiment figures: (x0 m, θ0 rad)
    "Fig 6.16 (state feedback)": (0.14, -0.2),
    "Fig 6.17 (state feedback)": (-0.13, 0.29),
    "Fig 6.19 (control law partitioning)": (-0.13, 0.23),
    "Fig 6.20 (control law partitioning)": (0.08, 0.18),
}

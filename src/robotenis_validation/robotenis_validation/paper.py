"""The calibration paper's reference numbers to print beside ours (mm, degrees as in the paper)."""
import numpy as np
from robotenis_kinematics import description


def table1(path):
    """Return a robot description's a, b, h (mm) and theta0 (degrees) per leg, Table 1's order."""
    d = description.load(description.config_path(path))
    legs = np.column_stack([d.a * 1e3, d.b * 1e3, d.h * 1e3, np.degrees(d.theta0)])
    return [round(float(v), 3) for v in legs.ravel()]


# Table 1, in identification.PAPER_PARAMETERS order (a, b, h, theta0 per leg; then P0). The legs
# come from the one copy of each column, the robot descriptions nominal.yaml and
# table1_calibrated.yaml; P0 is listed as the paper prints it (it is no part of a description).
TABLE1_NOMINAL = table1('nominal.yaml') + [0, 0, 750]
TABLE1_CALIBRATED = table1('table1_calibrated.yaml') + [5.31, 0.31, 743.74]
# Section 6.2.1: largest singular value of J_RC (J_RN^-1 - J_RC^-1) over the 300 x 400 mm
# cylinder.
JACOBIAN_MAX = 0.015
# Table 4: ISO 9283 repeatability, five-point loop 25 times: speed (m/s) -> (range of Xc, Yc, Zc;
# RP).
TABLE4 = {1.0: ((0.032, 0.025, 0.114), 0.07041), 2.0: ((0.039, 0.034, 0.121), 0.07512)}
# Figures 9 and 10: mean positioning distance accuracy over the five planes (real robot).
DISTANCE_ACCURACY_MEAN = {'nominal': 1.468, 'calibrated': 0.583}
# Table 5 (section 6.2.2): tracking error mean (mm) over 10 tests of 5,000 samples, per maximum
# ball speed (mm/s).
TABLE5_SPEEDS = [500, 750, 1000, 1250, 1500]
TABLE5_NOMINAL = [4.54, 7.42, 12.76, 20.14, 30.47]
TABLE5_CALIBRATED = [4.47, 7.32, 12.61, 19.84, 30.14]

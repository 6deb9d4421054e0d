"""The calibration paper's reference numbers, to print beside ours (mm, degrees as in the paper)."""

# Table 1, in identification.PAPER_PARAMETERS order (a, b, h, theta0 per leg; then P0).
TABLE1_NOMINAL = [500, 1000, 50, 0] * 3 + [0, 0, 750]
TABLE1_CALIBRATED = [500.89, 1002.86, 48.69, 0.316, 500.01, 1001.37, 49.96, 0.844,
                     499.96, 1001.28, 48.68, 0.936, 5.31, 0.31, 743.74]
# Section 6.2.1: largest singular value of J_RC (J_RN^-1 - J_RC^-1) over the 300 x 400 mm cylinder.
JACOBIAN_MAX = 0.015
# Table 4: ISO 9283 repeatability, five-point loop 25 times: speed (m/s) -> (range of Xc, Yc, Zc; RP).
TABLE4 = {1.0: ((0.032, 0.025, 0.114), 0.07041), 2.0: ((0.039, 0.034, 0.121), 0.07512)}
# Figures 9 and 10: mean positioning distance accuracy over the five planes (real robot).
DISTANCE_ACCURACY_MEAN = {'nominal': 1.468, 'calibrated': 0.583}
# Table 5 (section 6.2.2): tracking error mean (mm) over 10 tests of 5,000 samples, per maximum ball speed (mm/s).
TABLE5_SPEEDS = [500, 750, 1000, 1250, 1500]
TABLE5_NOMINAL = [4.54, 7.42, 12.76, 20.14, 30.47]
TABLE5_CALIBRATED = [4.47, 7.32, 12.61, 19.84, 30.14]

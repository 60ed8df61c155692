#!/usr/bin/python3
"""mirrorcal's lens models against OpenCV's: cv2.projectPoints for radtan (k1, k2, p1, p2) and
cv2.fisheye.projectPoints for equidistant (k1..k4), on the grid lens_dump prints. Exit 0 when every
pixel agrees to 1e-6 px."""
import subprocess
import sys

import cv2
import numpy as np


def main():
    out = subprocess.run([sys.argv[1]], check=True, capture_output=True, text=True).stdout
    worst = {"radtan": 0.0, "equidistant": 0.0}
    count = {"radtan": 0, "equidistant": 0}
    for line in out.splitlines():
        f = line.split()
        model = f[0]
        fu, fv, cu, cv_, skew, *rest = map(float, f[1:])
        d = np.array(rest[0:4])
        p = np.array([[rest[4:7]]])
        ours = np.array(rest[7:9])
        k = np.array([[fu, skew, cu], [0.0, fv, cv_], [0.0, 0.0, 1.0]])
        zero = np.zeros(3)
        if model == "radtan":
            theirs, _ = cv2.projectPoints(p, zero, zero, k, d)
        elif model == "equidistant":
            # OpenCV's fisheye skew is alpha, with u = fu (x_d + alpha y_d) + cu.
            theirs, _ = cv2.fisheye.projectPoints(p, zero, zero, k, d, alpha=skew / fu)
        else:
            sys.exit("unknown model " + model)
        worst[model] = max(worst[model], float(np.abs(theirs.reshape(2) - ours).max()))
        count[model] += 1
    for model in worst:
        print(f"{model}: {count[model]} points, largest difference from OpenCV "
              f"{worst[model]:.3g} px")
    ok = all(count[m] > 0 and worst[m] < 1e-6 for m in worst)
    sys.exit(0 if ok else 1)


main()

"""Recompute reference.json: OpenCV's own calibration pipeline on the images here.

findChessboardCorners (9 x 6 inner corners) + cornerSubPix (11 x 11 window, as OpenCV's
calibration sample) + calibrateCamera with default flags. Run once, from this folder:
``python make_reference.py``; the tests compare hmlvs.detect_board's corners against it.
"""

import glob
import json

import cv2
import numpy as np

PATTERN = (9, 6)  # inner corners per row, per column


def main() -> None:
    objp = np.zeros((PATTERN[0] * PATTERN[1], 3), np.float32)
    objp[:, :2] = np.mgrid[0:PATTERN[0], 0:PATTERN[1]].T.reshape(-1, 2)
    crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 30, 0.001)
    names, obj, img = [], [], []
    for f in sorted(glob.glob("left*.jpg")):
        g = cv2.imread(f, cv2.IMREAD_GRAYSCALE)
        ok, c = cv2.findChessboardCorners(g, PATTERN)
        if not ok:
            continue
        names.append(f)
        obj.append(objp)
        img.append(cv2.cornerSubPix(g, c, (11, 11), (-1, -1), crit))
    rms, k, dist, rvecs, tvecs = cv2.calibrateCamera(obj, img, (640, 480), None, None)
    per_view = []
    for o, i, r, t in zip(obj, img, rvecs, tvecs):
        p, _ = cv2.projectPoints(o, r, t, k, dist)
        e = p.reshape(-1, 2) - i.reshape(-1, 2)
        per_view.append(float(np.sqrt(np.mean(np.sum(e ** 2, axis=1)))))
    doc = {"opencv": cv2.__version__, "images": names, "pattern": list(PATTERN),
           "fx": k[0, 0], "fy": k[1, 1], "cx": k[0, 2], "cy": k[1, 2],
           "dist": dist.ravel().tolist(), "rms": rms, "per_view_rms": per_view}
    with open("reference.json", "w") as fh:
        json.dump({k: (float(v) if isinstance(v, np.floating) else v) for k, v in doc.items()},
                  fh, indent=1)


if __name__ == "__main__":
    main()

#!/usr/bin/python3
"""The recordings' image reader and PNG writer against OpenCV's PNG codec (libpng): every PNG
OpenCV writes (grey, BGR, BGRA; compression levels 0-9, which take libpng's filters) reads as
OpenCV reads it (colour as its luma, within 1 of cv2.cvtColor's; 16-bit ones by their upper byte,
as OpenCV's grey), and OpenCV reads what the writer writes, pixel for pixel. Exit 0 when all hold."""
import os
import subprocess
import sys
import tempfile

import cv2
import numpy as np


def read_pgm(path):
    with open(path, "rb") as f:
        data = f.read()
    magic, w, h, maxval, rest = data.split(maxsplit=4)
    assert magic == b"P5" and maxval == b"255"
    return np.frombuffer(rest, dtype=np.uint8).reshape(int(h), int(w))


def main():
    tool = sys.argv[1]
    rng = np.random.default_rng(17)
    failures = []
    checked = 0
    with tempfile.TemporaryDirectory() as tmp:
        # A scene like the camera's: smooth background, bright spots, noise; and pure noise.
        y, x = np.mgrid[0:480, 0:640]
        scene = 20 + 20 * x / 640 + 150 * np.exp(-((x - 300) ** 2 + (y - 200) ** 2) / 3.0)
        scene = np.clip(scene + rng.normal(0, 2, scene.shape), 0, 255).astype(np.uint8)
        noise = rng.integers(0, 256, (37, 53), dtype=np.uint8)
        colour = rng.integers(0, 256, (31, 45, 3), dtype=np.uint8)
        alpha = rng.integers(0, 256, (31, 45, 4), dtype=np.uint8)
        def decode_as(path, theirs, tol):
            """Our reader's image of path against OpenCV's, within tol grey levels."""
            out = path + ".pgm"
            r = subprocess.run([tool, "decode", path, out], capture_output=True, text=True)
            if r.returncode != 0:
                failures.append(f"{path}: {r.stderr.strip()}")
                return
            ours = read_pgm(out).astype(int)
            if ours.shape != theirs.shape or np.abs(ours - theirs.astype(int)).max() > tol:
                failures.append(f"{path}: pixels differ from OpenCV's")

        for name, img in [("scene", scene), ("noise", noise), ("bgr", colour), ("bgra", alpha)]:
            for level in range(10):
                path = os.path.join(tmp, f"{name}-{level}.png")
                cv2.imwrite(path, img, [cv2.IMWRITE_PNG_COMPRESSION, level])
                checked += 1
                if img.ndim == 2:
                    decode_as(path, cv2.imread(path, cv2.IMREAD_UNCHANGED), 0)
                else:
                    bgr = cv2.imread(path, cv2.IMREAD_COLOR)
                    decode_as(path, cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY), 1)
        # 16-bit, grey and colour: read as OpenCV reduces them to 8 bits (the upper byte).
        wide = noise.astype(np.uint16) * 256 + 3
        for name, deep in [("deep", wide), ("deep-bgr", np.dstack([wide, wide[::-1], wide[:, ::-1]]))]:
            path = os.path.join(tmp, name + ".png")
            cv2.imwrite(path, deep)
            checked += 1
            decode_as(path, cv2.imread(path, cv2.IMREAD_GRAYSCALE), 0 if deep.ndim == 2 else 1)
        # Our writer, read by OpenCV.
        for name, img in [("scene", scene), ("noise", noise)]:
            pgm = os.path.join(tmp, f"{name}.pgm")
            cv2.imwrite(pgm, img)
            png = os.path.join(tmp, f"{name}-ours.png")
            r = subprocess.run([tool, "encode", pgm, png], capture_output=True, text=True)
            checked += 1
            back = cv2.imread(png, cv2.IMREAD_UNCHANGED)
            if r.returncode != 0 or back is None or back.dtype != np.uint8 or \
                    back.shape != img.shape or not np.array_equal(back, img):
                failures.append(f"{png}: OpenCV does not read back what was written {r.stderr}")
            else:
                print(f"{name}: {os.path.getsize(png)} bytes as our PNG, "
                      f"{img.size} pixels")
    for f in failures:
        print("FAIL", f)
    print(f"{checked - len(failures)} of {checked} checks against OpenCV {cv2.__version__} hold")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())

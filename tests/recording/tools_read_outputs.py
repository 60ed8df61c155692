#!/usr/bin/python3
"""The files mirrorcal writes for other tools, read by the parsers those tools use (Debian's
python3-yaml and python3-opencv) the way each tool reads them: camchain-imucam.yaml as Kalibr's
ConfigReader (CameraChainParameters, PyYAML) and as OpenVINS's YamlParser (OpenCV's FileStorage,
T_imu_cam or else T_cam_imu inverted). Each transform, camera and time offset read is checked
against mirrorcal-result.yaml. Exit 0 when all agree. Usage: tools_read_outputs.py MIRRORCAL"""
import os
import subprocess
import sys
import tempfile

import cv2
import numpy as np
import yaml

MIRRORCAL = sys.argv[1]
failures = []


def check(ok, what):
    if not ok:
        failures.append(what)
        print("FAIL: " + what)


def close(a, b, tol, what):
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    check(a.shape == b.shape and np.abs(a - b).max() <= tol, f"{what}: {a} against {b}")


def mirrorcal(*args):
    subprocess.run([MIRRORCAL, *args], check=True, capture_output=True, text=True)


class Result:
    """What mirrorcal-result.yaml says, as the numbers every other file must carry."""

    def __init__(self, folder):
        with open(os.path.join(folder, "mirrorcal-result.yaml")) as f:
            y = yaml.safe_load(f)
        w, x, yy, z = y["q_b_c_wxyz"]
        rot = np.array([[1 - 2 * (yy * yy + z * z), 2 * (x * yy - w * z), 2 * (x * z + w * yy)],
                        [2 * (x * yy + w * z), 1 - 2 * (x * x + z * z), 2 * (yy * z - w * x)],
                        [2 * (x * z - w * yy), 2 * (yy * z + w * x), 1 - 2 * (x * x + yy * yy)]])
        self.t_imu_cam = np.eye(4)
        self.t_imu_cam[:3, :3] = rot
        self.t_imu_cam[:3, 3] = y["p_b_c"]
        self.intrinsics = y["intrinsics"]
        self.skew = y["skew"]
        self.lens = y["distortion_model"]
        self.coeffs = y["distortion_coeffs"]
        self.resolution = y["resolution"]
        self.timeshift = y["timeshift_cam_imu"]
        self.rostopic = y["rostopic"]


def kalibr_lens(result):
    return "radtan" if result.lens == "none" else result.lens


def read_like_kalibr(path, result):
    """CameraChainParameters: yaml.safe_load, every top-level key a camera, each field checked as
    ConfigReader checks it."""
    with open(path) as f:
        data = yaml.safe_load(f)
    check(list(data) == ["cam0"], f"{path}: Kalibr counts {len(data)} cameras")
    cam = data["cam0"]
    for key in ["camera_model", "intrinsics", "distortion_model", "distortion_coeffs",
                "resolution", "rostopic", "T_cam_imu", "timeshift_cam_imu", "cam_overlaps"]:
        check(key in cam, f"{path}: Kalibr: Field '{key}' missing")
    check(isinstance(cam["rostopic"], str), f"{path}: rostopic has to be a string")
    check(cam["camera_model"] == "pinhole", f"{path}: camera_model")
    k = cam["intrinsics"]
    check(len(k) == 4 and all(isinstance(v, float) and v >= 0 for v in k),
          f"{path}: invalid intrinsics for pinhole {k}")
    check({"radtan": 4, "equidistant": 4, "none": 0}.get(cam["distortion_model"])
          == len(cam["distortion_coeffs"]), f"{path}: distortion model and coefficients")
    res = cam["resolution"]
    check(len(res) == 2 and all(isinstance(v, int) for v in res), f"{path}: invalid resolution")
    check(isinstance(cam["timeshift_cam_imu"], float), f"{path}: invalid timeshift cam-imu")
    check(all(c < len(data) for c in cam["cam_overlaps"]), f"{path}: cam_overlaps out of range")
    t_cam_imu = np.array(cam["T_cam_imu"], dtype=float)
    check(t_cam_imu.shape == (4, 4), f"{path}: T_cam_imu is not 4x4")
    close(t_cam_imu @ result.t_imu_cam, np.eye(4), 1e-9, f"{path}: Kalibr's T_cam_imu")
    close(k, result.intrinsics, 1e-6, f"{path}: Kalibr's intrinsics")
    check(cam["distortion_model"] == kalibr_lens(result), f"{path}: Kalibr's distortion_model")
    close(cam["distortion_coeffs"], result.coeffs, 1e-9, f"{path}: Kalibr's distortion_coeffs")
    check(res == result.resolution, f"{path}: Kalibr's resolution {res}")
    check(cam["rostopic"] == result.rostopic, f"{path}: Kalibr's rostopic {cam['rostopic']}")
    close(cam["timeshift_cam_imu"], result.timeshift, 1e-9, f"{path}: Kalibr's timeshift")


def seq(node):
    return [node.at(i).real() for i in range(node.size())]


def read_like_openvins(path, result):
    """ov_core::YamlParser: cv::FileStorage, keys found by iterating the node, T_imu_cam read as a
    nested sequence (or T_cam_imu, inverted), vectors read element by element."""
    fs = cv2.FileStorage(path, cv2.FILE_STORAGE_READ)
    check(fs.isOpened(), f"{path}: OpenCV cannot open it")
    check("cam0" in fs.root().keys(), f"{path}: OpenVINS finds no cam0")
    cam = fs.getNode("cam0")
    keys = cam.keys()
    name = "T_imu_cam" if "T_imu_cam" in keys else "T_cam_imu"
    node = cam.getNode(name)
    t = np.array([[node.at(r).at(c).real() for c in range(4)] for r in range(4)])
    if name == "T_cam_imu":
        t = np.linalg.inv(t)
    close(t, result.t_imu_cam, 1e-9, f"{path}: OpenVINS's T_imu_cam (from {name})")
    close(seq(cam.getNode("intrinsics")), result.intrinsics, 1e-6, f"{path}: OpenVINS intrinsics")
    close(seq(cam.getNode("distortion_coeffs")), result.coeffs, 1e-9,
          f"{path}: OpenVINS's distortion_coeffs")
    check(cam.getNode("distortion_model").string() == kalibr_lens(result),
          f"{path}: OpenVINS's distortion_model")
    check([int(v) for v in seq(cam.getNode("resolution"))] == result.resolution,
          f"{path}: OpenVINS's resolution")
    close(cam.getNode("timeshift_cam_imu").real(), result.timeshift, 1e-9,
          f"{path}: OpenVINS's timeshift_cam_imu")
    check(cam.getNode("rostopic").string() == result.rostopic, f"{path}: OpenVINS's rostopic")


def check_files(folder, result):
    read_like_kalibr(os.path.join(folder, "camchain-imucam.yaml"), result)
    read_like_openvins(os.path.join(folder, "camchain-imucam.yaml"), result)


def check_the_parsers_are_strict(d):
    """The failures the files avoid are real with these parsers: OpenCV refuses a file without a
    %YAML directive and rows as deep as their key; PyYAML refuses OpenCV's "%YAML:1.0"."""
    body = "cam0:\n  T_cam_imu:\n  - [1, 0, 0, 0]\n  - [0, 1, 0, 0]\n"
    path = os.path.join(d, "strict.yaml")
    for text in [body, "%YAML 1.0\n---\n" + body]:
        with open(path, "w") as f:
            f.write(text)
        try:
            cv2.FileStorage(path, cv2.FILE_STORAGE_READ)
            check(False, "OpenCV read " + repr(text))
        except (cv2.error, SystemError):  # the binding wraps OpenCV's error in a SystemError
            pass
    with open(path, "w") as f:
        f.write("%YAML:1.0\n---\ncam0:\n  rostopic: /cam0/image_raw\n")
    try:
        with open(path) as f:
            yaml.safe_load(f)
        check(False, "PyYAML read %YAML:1.0")
    except yaml.YAMLError:
        pass


def main():
    with tempfile.TemporaryDirectory(prefix="mirrorcal-tools-") as d:
        check_the_parsers_are_strict(d)
        # A recording whose camchain.yaml names its own topic, with EuRoC cam0's lens and a 12 ms
        # time offset: calibrate carries the topic into the files.
        rec, cal = os.path.join(d, "rec"), os.path.join(d, "cal")
        mirrorcal("record", "--seed", "7", "--distortion", "radtan", "--timeshift", "0.012",
                  "--out", rec)
        camchain = os.path.join(rec, "camchain.yaml")
        with open(camchain) as f:
            text = f.read()
        with open(camchain, "w") as f:
            f.write(text.replace("rostopic: /cam0/image_raw", "rostopic: /rig/front/image_raw"))
        mirrorcal("calibrate", rec, "--out", cal)
        result = Result(cal)
        check(result.rostopic == "/rig/front/image_raw", f"result's rostopic {result.rostopic}")
        check_files(cal, result)
        # A fisheye, estimating the intrinsics (skew too), with the default topic.
        fish = os.path.join(d, "fish")
        mirrorcal("sim", "--seed", "7", "--distortion", "equidistant", "--intrinsics",
                  "--no-plots", "--out", fish)
        result = Result(fish)
        check(result.rostopic == "/cam0/image_raw", f"default rostopic {result.rostopic}")
        check(result.lens == "equidistant", f"fisheye lens {result.lens}")
        check_files(fish, result)
    print("every file read as its tool reads it, and agreed with mirrorcal-result.yaml"
          if not failures else f"{len(failures)} failures")
    sys.exit(1 if failures else 0)


main()

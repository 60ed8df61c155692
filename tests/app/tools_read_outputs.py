#!/usr/bin/python3
"""The files mirrorcal writes for other tools, read by the parsers those tools use (Debian's
python3-yaml and python3-opencv) the way each tool reads them:
  - camchain-imucam.yaml as Kalibr's ConfigReader (CameraChainParameters, PyYAML) and as OpenVINS's
    YamlParser (OpenCV's FileStorage, T_imu_cam or else T_cam_imu inverted);
  - `export --format openvins` as OpenVINS, `vins-fusion` as VINS-Fusion and camodocal (FileStorage,
    body_T_cam0 an opencv-matrix), `ros-camera-info` as a ROS camera_info YAML (PyYAML);
  - kalibr_imu_chain.yaml (the IMU's intrinsics) as OpenVINS reads it (FileStorage).
Each transform, camera and time offset read is checked against mirrorcal-result.yaml. Exit 0 when
all agree. Usage: tools_read_outputs.py MIRRORCAL"""
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


def read_like_vins_fusion(path, result):
    """VINS-Fusion's readParameters and camodocal's camera readers, through cv::FileStorage."""
    fs = cv2.FileStorage(path, cv2.FILE_STORAGE_READ)
    check(fs.isOpened(), f"{path}: OpenCV cannot open it")
    close(fs.getNode("body_T_cam0").mat(), result.t_imu_cam, 1e-9, f"{path}: body_T_cam0")
    close(fs.getNode("td").real(), result.timeshift, 1e-9, f"{path}: td")
    check(int(fs.getNode("num_of_cam").real()) == 1, f"{path}: num_of_cam")
    check(fs.getNode("image0_topic").string() == result.rostopic, f"{path}: image0_topic")
    check([int(fs.getNode("image_width").real()), int(fs.getNode("image_height").real())]
          == result.resolution, f"{path}: image_width, image_height")
    # VINS-Fusion reads cam0_calib relative to the config's folder.
    camera_path = os.path.join(os.path.dirname(path), fs.getNode("cam0_calib").string())
    cam = cv2.FileStorage(camera_path, cv2.FILE_STORAGE_READ)
    check(cam.isOpened(), f"{camera_path}: OpenCV cannot open it")
    model = cam.getNode("model_type").string()
    fu, fv, cu, cv_ = result.intrinsics
    if result.lens == "equidistant":
        check(model == "KANNALA_BRANDT", f"{camera_path}: model_type {model}")
        p = cam.getNode("projection_parameters")
        close([p.getNode(k).real() for k in ["mu", "mv", "u0", "v0"]], [fu, fv, cu, cv_], 1e-6,
              f"{camera_path}: projection_parameters")
        close([p.getNode(k).real() for k in ["k2", "k3", "k4", "k5"]], result.coeffs, 1e-9,
              f"{camera_path}: Kannala-Brandt k2..k5")
    else:
        check(model == "PINHOLE", f"{camera_path}: model_type {model}")
        p = cam.getNode("projection_parameters")
        close([p.getNode(k).real() for k in ["fx", "fy", "cx", "cy"]], [fu, fv, cu, cv_], 1e-6,
              f"{camera_path}: projection_parameters")
        d = cam.getNode("distortion_parameters")
        close([d.getNode(k).real() for k in ["k1", "k2", "p1", "p2"]], result.coeffs, 1e-9,
              f"{camera_path}: distortion_parameters")
    check([int(cam.getNode("image_width").real()), int(cam.getNode("image_height").real())]
          == result.resolution, f"{camera_path}: image size")


def read_like_ros(path, result):
    """A ROS camera_info YAML (camera_calibration_parsers' keys), read with PyYAML."""
    with open(path) as f:
        y = yaml.safe_load(f)

    def matrix(key, rows, cols):
        m = y[key]
        check(m["rows"] == rows and m["cols"] == cols and len(m["data"]) == rows * cols,
              f"{path}: {key} is not {rows}x{cols}")
        return np.array(m["data"], dtype=float).reshape(rows, cols)

    fu, fv, cu, cv_ = result.intrinsics
    k = np.array([[fu, result.skew, cu], [0, fv, cv_], [0, 0, 1]])
    check([y["image_width"], y["image_height"]] == result.resolution, f"{path}: image size")
    check(isinstance(y["camera_name"], str), f"{path}: camera_name")
    close(matrix("camera_matrix", 3, 3), k, 1e-6, f"{path}: camera_matrix")
    close(matrix("rectification_matrix", 3, 3), np.eye(3), 0, f"{path}: rectification_matrix")
    close(matrix("projection_matrix", 3, 4), np.hstack([k, np.zeros((3, 1))]), 1e-6,
          f"{path}: projection_matrix")
    if result.lens == "equidistant":
        check(y["distortion_model"] == "equidistant", f"{path}: distortion_model")
        close(matrix("distortion_coefficients", 1, 4)[0], result.coeffs, 1e-9, f"{path}: D")
    else:
        check(y["distortion_model"] == "plumb_bob", f"{path}: distortion_model")
        close(matrix("distortion_coefficients", 1, 5)[0], result.coeffs + [0.0], 1e-9,
              f"{path}: D (k1 k2 p1 p2 k3)")


def check_exports(folder, result):
    read_like_kalibr(os.path.join(folder, "camchain-imucam.yaml"), result)
    read_like_openvins(os.path.join(folder, "camchain-imucam.yaml"), result)
    out = os.path.join(folder, "exports")
    os.makedirs(out)
    for fmt, reader in [("openvins", read_like_openvins), ("vins-fusion", read_like_vins_fusion),
                        ("ros-camera-info", read_like_ros)]:
        path = os.path.join(out, fmt + ".yaml")
        mirrorcal("export", "--format", fmt, folder, path)
        reader(path, result)


def read_imu_like_openvins(folder):
    """kalibr_imu_chain.yaml as OpenVINS's VioManagerOptions reads it (cv::FileStorage through its
    YamlParser: imu0's Tw, R_IMUtoGYRO, Ta, R_IMUtoACC, Tg as nested sequences), against the
    sensor mirrorcal-result.yaml's imu section describes (T_g = Tw R_IMUtoGYRO, T_a = Ta, T_s = Tg);
    and that section's Kalibr matrices as PyYAML reads them."""
    path = os.path.join(folder, "kalibr_imu_chain.yaml")
    fs = cv2.FileStorage(path, cv2.FILE_STORAGE_READ)
    check(fs.isOpened(), f"{path}: OpenCV cannot open it")
    imu = fs.getNode("imu0")
    check(not imu.empty(), f"{path}: OpenVINS finds no imu0")

    def mat(key):
        node = imu.getNode(key)
        return np.array([[node.at(r).at(c).real() for c in range(3)] for r in range(3)])

    with open(os.path.join(folder, "mirrorcal-result.yaml")) as f:
        section = yaml.safe_load(f)["imu"]
    tw, r_gyro, ta, tg = mat("Tw"), mat("R_IMUtoGYRO"), mat("Ta"), mat("Tg")
    close(tw @ r_gyro, np.array(section["T_g"]), 1e-9, f"{path}: Tw R_IMUtoGYRO against T_g")
    close(ta, np.array(section["T_a"]), 1e-9, f"{path}: Ta against T_a")
    close(tg, np.array(section["T_s"]), 1e-9, f"{path}: Tg against T_s")
    close(mat("R_IMUtoACC"), np.eye(3), 0, f"{path}: R_IMUtoACC")
    close(r_gyro @ r_gyro.T, np.eye(3), 1e-9, f"{path}: R_IMUtoGYRO a rotation")
    close(np.triu(tw, 1), np.zeros((3, 3)), 0, f"{path}: Tw lower triangular (OpenVINS's kalibr)")
    check(imu.getNode("model").string() == "kalibr", f"{path}: model")
    for key in ["accelerometer_noise_density", "gyroscope_noise_density",
                "accelerometer_random_walk", "gyroscope_random_walk", "update_rate"]:
        check(imu.getNode(key).real() > 0, f"{path}: {key}")
    # OpenVINS's Dw and Da are the inverses; Kalibr's M_gyro C_gyro_i is T_g.
    close(np.linalg.inv(tw) @ tw, np.eye(3), 1e-12, f"{path}: Tw invertible")
    close(np.array(section["M_gyro"]) @ np.array(section["C_gyro_i"]), np.array(section["T_g"]),
          1e-9, "Kalibr's M_gyro C_gyro_i against T_g")
    check(section["model"] == "scale-misalignment", f"imu model {section['model']}")


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
        check_exports(cal, result)
        # A fisheye, estimating the intrinsics (skew too), with the default topic.
        fish = os.path.join(d, "fish")
        mirrorcal("sim", "--seed", "7", "--distortion", "equidistant", "--intrinsics",
                  "--no-plots", "--out", fish)
        result = Result(fish)
        check(result.rostopic == "/cam0/image_raw", f"default rostopic {result.rostopic}")
        check(result.lens == "equidistant", f"fisheye lens {result.lens}")
        check_exports(fish, result)
        # A MEMS IMU's intrinsics estimated: OpenVINS's IMU file beside the result.
        mems = os.path.join(d, "mems")
        mirrorcal("sim", "--scenario", "mems", "--seed", "3", "--imu-model", "scale-misalignment",
                  "--no-plots", "--out", mems)
        read_imu_like_openvins(mems)
        check_exports(mems, Result(mems))
    print("every file read as its tool reads it, and agreed with mirrorcal-result.yaml"
          if not failures else f"{len(failures)} failures")
    sys.exit(1 if failures else 0)


main()

#!/usr/bin/env python3
"""The figures README.md quotes are those of the committed campaigns, to the digits it shows: a
campaign made again moves them, and the README must move with it.

    check_readme_figures.py SOURCE_DIR

Checked: stage 1's and stage 2's average NEES and intervals (docs/campaign/summary.csv and
docs/campaign/stage2/summary.csv), stage 2's intrinsics RMS, and the filter's RMS error over the
batch's per group on the paper's scenario and on the random family (docs/campaign/batch). Each
sentence must be there: a README reworded so that a pattern no longer matches fails too.
"""
import csv
import math
import os
import re
import sys

GROUPS = {
    "p_b_c": ["p_x", "p_y", "p_z"],
    "rotation": ["rot_x", "rot_y", "rot_z"],
    "markers": [f"f{i}_{a}" for i in (1, 2, 3) for a in "xyz"],
    "time offset": ["timeshift_cam_imu"],
}


def unit(name):
    return "deg" if name.startswith("rot") else "ms" if name.startswith("time") else "cm"


def summary(path):
    """The rows of a summary.csv by parameter, and its closing comment's key=value pairs."""
    with open(path) as f:
        lines = f.read().splitlines()
    rows = {r["parameter"]: r for r in csv.DictReader(l for l in lines if not l.startswith("#"))}
    tail = dict(kv.split("=") for l in lines if l.startswith("#") for kv in l[1:].split())
    return rows, tail


def rms(rows, names):
    squares = [float(r[f"err_{n} [{unit(n)}]"]) ** 2 for r in rows for n in names]
    return math.sqrt(sum(squares) / len(squares))


def filter_over_batch(folder):
    """Each group's RMS error, filter (runs.csv) over batch (batch.csv), on the same runs."""
    with open(os.path.join(folder, "runs.csv")) as f:
        runs = list(csv.DictReader(f))
    with open(os.path.join(folder, "batch.csv")) as f:
        batch = list(csv.DictReader(f))
    if [r["seed"] for r in runs] != [r["seed"] for r in batch]:
        sys.exit(f"{folder}: runs.csv and batch.csv are not the same runs")
    return {g: rms(runs, names) / rms(batch, names) for g, names in GROUPS.items()}


class Readme:
    def __init__(self, path):
        with open(path) as f:
            self.text = " ".join(f.read().split())  # a sentence may break across lines
        self.failures = []

    def find(self, pattern, what):
        m = re.search(pattern, self.text)
        if not m:
            self.failures.append(f"README.md no longer says {what} (pattern {pattern!r})")
        return m

    def expect(self, quoted, value, what):
        """quoted (as the README writes it) is value rounded to quoted's decimals."""
        decimals = len(quoted.split(".")[1]) if "." in quoted else 0
        if quoted != f"{value:.{decimals}f}":
            self.failures.append(f"README.md says {what} {quoted}; the campaign has {value:.4f}")


def main():
    root = sys.argv[1]
    readme = Readme(os.path.join(root, "README.md"))
    campaign = os.path.join(root, "docs", "campaign")

    _, tail = summary(os.path.join(campaign, "summary.csv"))
    m = readme.find(r"average NEES ([\d.]+) of 16 states, in its 95 % interval ([\d.]+)\.\.([\d.]+)",
                    "stage 1's NEES")
    if m:
        for quoted, key in zip(m.groups(), ("nees_mean", "nees_95_lo", "nees_95_hi")):
            readme.expect(quoted, float(tail[key]), f"stage 1's {key}")

    rows, tail = summary(os.path.join(campaign, "stage2", "summary.csv"))
    m = readme.find(r"fu ([\d.]+), fv ([\d.]+), cu ([\d.]+), cv ([\d.]+), skew ([\d.]+) px RMS",
                    "stage 2's intrinsics RMS")
    if m:
        for quoted, name in zip(m.groups(), ("fu", "fv", "cu", "cv", "skew")):
            readme.expect(quoted, float(rows[name]["rms_error"]), f"stage 2's {name} RMS")
    m = readme.find(r"NEES ([\d.]+) of 21 states, in ([\d.]+)\.\.([\d.]+)", "stage 2's NEES")
    if m:
        for quoted, key in zip(m.groups(), ("nees_mean", "nees_95_lo", "nees_95_hi")):
            readme.expect(quoted, float(tail[key]), f"stage 2's {key}")

    paper = filter_over_batch(os.path.join(campaign, "batch", "paper"))
    m = readme.find(r"the filter's errors are the batch's \(([\d.]+)-([\d.]+)\) on the paper's",
                    "the paper scenario's filter over batch")
    if m:
        readme.expect(m.group(1), min(paper.values()), "the paper's lowest filter/batch")
        readme.expect(m.group(2), max(paper.values()), "the paper's highest filter/batch")
    family = filter_over_batch(os.path.join(campaign, "batch"))
    m = readme.find(r"p_b_c ([\d.]+), rotation ([\d.]+), markers ([\d.]+) and time offset ([\d.]+) "
                    r"times the batch's", "the random family's filter over batch")
    if m:
        for quoted, group in zip(m.groups(), GROUPS):
            readme.expect(quoted, family[group], f"the random family's {group} filter/batch")

    for f in readme.failures:
        print(f)
    sys.exit(1 if readme.failures else 0)


if __name__ == "__main__":
    main()

#!/usr/bin/env python3
"""Every source file a comment names exists: a comment that points at a file which was renamed or
removed sends its reader nowhere.

    check_comment_files.py SOURCE_DIR

A name counts as a file when it ends in .hpp, .cpp, .py, .md or .cmake. It is found when a
tracked file (git ls-files) or a file CMake generates has that path or that last component.
Names of another project's files (their first folder not one of this repository's) are not
checked, nor are #include lines (the compiler checks those).
"""
import os
import re
import subprocess
import sys

# Written into the build folder by CMake (cmake/MarkerCounts.cmake).
GENERATED = {"marker_counts.hpp"}
NAME = re.compile(r"(?<![\w.-])((?:[\w-]+/)*[\w-]+\.(?:hpp|cpp|py|md|cmake))\b")
COMMENT = re.compile(r"(?://|^\s*#(?!\s*include))(.*)$")


def tracked(root):
    """The repository's files: git's list, or outside a clone every file but the build folders'."""
    out = subprocess.run(["git", "-C", root, "ls-files"], capture_output=True, text=True)
    if out.returncode == 0:
        return out.stdout.split()
    files = []
    for folder, subfolders, names in os.walk(root):
        subfolders[:] = [d for d in subfolders if d not in ("build", ".git")]
        files += [os.path.relpath(os.path.join(folder, n), root) for n in names]
    return files


def comments(path):
    with open(path, errors="replace") as f:
        for number, line in enumerate(f, 1):
            m = COMMENT.search(line)
            if m:
                yield number, m.group(1)


def main(root):
    files = tracked(root)
    paths = set(files)
    names = {os.path.basename(f) for f in files} | GENERATED
    folders = {f.split("/")[0] for f in files if "/" in f} | {
        part for f in files for part in f.split("/")[:-1]}
    sources = [f for f in files if f.endswith((".hpp", ".cpp", ".py", ".cmake", "CMakeLists.txt"))
               or f.startswith(("toolchain/", ".ci/"))]
    missing = []
    for source in sources:
        for number, text in comments(os.path.join(root, source)):
            for name in NAME.findall(text):
                if "/" in name and name.split("/")[0] not in folders:
                    continue  # another project's file
                if os.path.basename(name) in GENERATED:
                    continue
                if name in paths or any(p.endswith("/" + name) for p in paths):
                    continue
                if "/" not in name and name in names:
                    continue
                missing.append(f"{source}:{number}: names {name}, which does not exist")
    for line in missing:
        print(line)
    if missing:
        sys.exit(f"check_comment_files: {len(missing)} comment(s) name a missing file")
    print(f"check_comment_files: every file named in the comments of {len(sources)} sources exists")


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else ".")

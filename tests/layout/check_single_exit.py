#!/usr/bin/env python3
"""The program has one exit: main (firmware/app/main.cpp) returns the status its command returned.
A call to exit or quick_exit anywhere else would end the program without unwinding, leaving files
unflushed and temporary folders behind (issue 38).

    check_single_exit.py SOURCE_DIR

Scans the C++ sources under firmware/, estimator/, hal/, io/, sim/ and drivers/ for calls of exit, std::exit,
quick_exit and std::quick_exit, comments and string literals left out. _exit (a forked child's) and
abort are not counted. Lists each call found outside main.cpp and exits with 1 if there is one.
"""
import os
import re
import sys

FOLDERS = ("firmware", "estimator", "hal", "io", "sim", "drivers")
ALLOWED = {"firmware/app/main.cpp"}
EXTENSIONS = (".cpp", ".hpp", ".cc", ".h", ".ipp")
# exit( or quick_exit(, alone or qualified (std::exit); not _exit, atexit or a member's a.exit().
CALL = re.compile(r"(?<![\w.>])(?:quick_)?exit\s*\(")


def is_digit_separator(text, i):
    """Whether the quote at text[i] separates digits (1'000'000) rather than opening a literal."""
    j = i
    while j > 0 and (text[j - 1].isalnum() or text[j - 1] in "'."):
        j -= 1
    return j < i and text[j].isdigit()


def code_only(text):
    """text with comments and string and character literals blanked (newlines kept)."""
    out = []
    i, n = 0, len(text)
    while i < n:
        c = text[i]
        if text.startswith("//", i):
            end = text.find("\n", i)
            i = n if end < 0 else end
        elif text.startswith("/*", i):
            end = text.find("*/", i + 2)
            end = n if end < 0 else end + 2
            out.append("\n" * text.count("\n", i, end))
            i = end
        elif c == '"' and i > 0 and text[i - 1] == "R":  # a raw string: R"delim( ... )delim"
            open_paren = text.find("(", i)
            close = ")" + text[i + 1:open_paren] + '"'
            end = text.find(close, open_paren) if open_paren >= 0 else -1
            end = n if end < 0 else end + len(close)
            out.append("\n" * text.count("\n", i, end))
            i = end
        elif c == '"' or (c == "'" and not is_digit_separator(text, i)):
            j = i + 1
            while j < n and text[j] != c and text[j] != "\n":
                j += 2 if text[j] == "\\" else 1
            i = j + 1 if j < n and text[j] == c else j  # an unclosed one ends at its line
        else:
            out.append(c)
            i += 1
    return "".join(out)


def sources(root):
    for folder in FOLDERS:
        for path, subfolders, names in os.walk(os.path.join(root, folder)):
            subfolders.sort()
            for name in sorted(names):
                if name.endswith(EXTENSIONS):
                    yield os.path.relpath(os.path.join(path, name), root)


def main(root):
    calls = []
    for source in sources(root):
        if source.replace(os.sep, "/") in ALLOWED:
            continue
        with open(os.path.join(root, source), errors="replace") as f:
            text = f.read()
        lines = text.splitlines()
        code = code_only(text)
        for m in CALL.finditer(code):
            number = code.count("\n", 0, m.start()) + 1
            calls.append(f"{source}:{number}: {lines[number - 1].strip()}")
    if calls:
        print("exit called outside main (firmware/app/main.cpp): return the status to main instead")
        print("\n".join(calls))
        return 1
    return 0


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit("usage: check_single_exit.py SOURCE_DIR")
    sys.exit(main(sys.argv[1]))

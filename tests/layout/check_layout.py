#!/usr/bin/env python3
"""The layout's rule, checked: what each part's code may include of ours. The rule is the table in
docs/design.md ("Layout"), read from there: one row per folder, its last column the parts it may
include. Every C++ file under a part's folder is checked, and so is every header of ours it
reaches through its includes (a header of an allowed part that includes a forbidden one breaks
the rule too). The board's program (firmware/app without its host-only files, which the table's
row names) reaches nothing of evaluation or sim. Lists each break; exits 1 if there is any.

Each part has one name: folder firmware/loop/ is part `loop`, include path mirrorcal/loop/."""
import os
import re
import sys

INCLUDE = re.compile(r'^\s*#\s*include\s*"(mirrorcal/([a-z_]+)/[A-Za-z0-9_./]+)"', re.M)
LOCAL = re.compile(r'^\s*#\s*include\s*"([a-z_]+\.hpp)"', re.M)
ROW = re.compile(r'^\| `([a-z_/]+)/` \| (.*) \| ([^|]*) \|$', re.M)
HOST_ONLY_NOTE = re.compile(r'Its host-only files \(([^)]*)\)')
# Parts the board's program may not reach (host only).
HOST_PARTS = {'evaluation', 'sim'}


def read_table(root):
    """{folder: (part, allowed parts)} and the app's host-only files, from docs/design.md."""
    text = open(os.path.join(root, 'docs', 'design.md'), encoding='utf-8').read()
    section = text[text.index('\n## Layout\n'):]
    section = section[:section.index('\n## ', 1)]
    rules, host_only = {}, set()
    for folder, what, may in ROW.findall(section):
        if folder in ('tests', 'toolchain'):
            continue
        part = folder.rsplit('/', 1)[-1]
        allowed = {p.strip() for p in may.split(',') if p.strip() not in ('', '-')}
        rules[folder] = (part, allowed | {part})
        note = HOST_ONLY_NOTE.search(what)
        if note:
            for name in re.findall(r'`([^`]+)`', note.group(1)):
                host_only |= {name.replace('.*', ext) for ext in ('.hpp', '.cpp')}
    if not rules:
        sys.exit('layout: no table found in docs/design.md, "Layout"')
    return rules, host_only


def header_paths(root, rules):
    """Where each part's public headers live: mirrorcal/<part>/x.hpp -> path."""
    found = {}
    for folder in rules:
        inc = os.path.join(root, folder, 'include')
        for d, _, files in os.walk(inc):
            for name in files:
                path = os.path.join(d, name)
                found[os.path.relpath(path, inc)] = os.path.relpath(path, root)
    return found


def folder_of(path, rules):
    for f in sorted(rules, key=len, reverse=True):
        if path.startswith(f + '/'):
            return f
    return None


def main(root):
    rules, host_only = read_table(root)
    headers = header_paths(root, rules)
    parts = {part for part, _ in rules.values()}
    cache = {}

    def reached(path):
        """Every part whose header path reaches, with the chain of headers that leads there."""
        if path in cache:
            return cache[path]
        cache[path] = {}
        text = open(os.path.join(root, path), encoding='utf-8').read()
        out = {}
        for include, part in INCLUDE.findall(text):
            out.setdefault(part, [include])
            target = headers.get(include)
            if target:  # generated headers (marker_counts.hpp) live in the build folder
                for p, chain in reached(target).items():
                    out.setdefault(p, [include] + chain)
        for local in LOCAL.findall(text):
            beside = os.path.join(os.path.dirname(path), local)
            if os.path.exists(os.path.join(root, beside)):
                for p, chain in reached(beside).items():
                    out.setdefault(p, [local] + chain)
        cache[path] = out
        return out

    broken = []
    for folder, (part, allowed) in rules.items():
        for d, _, files in os.walk(os.path.join(root, folder)):
            for name in files:
                if not name.endswith(('.cpp', '.hpp')):
                    continue
                path = os.path.relpath(os.path.join(d, name), root)
                text = open(os.path.join(root, path), encoding='utf-8').read()
                for local in LOCAL.findall(text):
                    if not os.path.exists(os.path.join(root, os.path.dirname(path), local)):
                        broken.append(f'{path}: includes "{local}", which is not beside it')
                board = part == 'app' and name not in host_only
                for p, chain in sorted(reached(path).items()):
                    via = ' via ' + ' -> '.join(chain) if len(chain) > 1 else ''
                    if p not in parts:
                        broken.append(f'{path}: reaches mirrorcal/{p}/{via}, of no part in the table')
                    elif p not in allowed and not (part == 'app' and p in HOST_PARTS and not board):
                        broken.append(f'{path}: reaches mirrorcal/{p}/{via} ({part} may not)')
                    elif board and p in HOST_PARTS:
                        broken.append(f'{path}: reaches mirrorcal/{p}/{via} (the board\'s program '
                                      'has no ' + p + ')')
    for b in broken:
        print(b)
    print(f'layout: {len(broken)} includes break the rule' if broken
          else f'layout: every include of {len(rules)} parts keeps the rule')
    return 1 if broken else 0


if __name__ == '__main__':
    sys.exit(main(sys.argv[1]))

#!/usr/bin/env python3
"""The layout's rule, checked: what each folder's code may include of ours (docs/design.md,
"Layout"). Reads every C++ file under the source tree given and lists each include that breaks the
rule; exits 1 if there is any.

A folder's code may include its own headers and those of the parts below it:
  estimator  <- hal  <- loop, detection  <- calibration  <- evaluation  <- app
  hal        <- drivers, sim_host
and the board's program (firmware/app without its host-only files) nothing of evaluation."""
import os
import re
import sys

# mirrorcal/<part>/ headers each folder may include.
ALLOWED = {
    'estimator': {'estimator'},
    'hal': {'hal', 'estimator'},
    'firmware/loop': {'firmware', 'hal', 'estimator'},
    'firmware/detection': {'detection', 'hal', 'estimator'},
    'firmware/calibration': {'calibration', 'firmware', 'detection', 'hal', 'estimator', 'sim_host'},
    'firmware/evaluation': {'evaluation', 'calibration', 'firmware', 'detection', 'hal', 'estimator',
                            'sim_host'},
    'firmware/app': {'evaluation', 'calibration', 'firmware', 'detection', 'drivers', 'hal',
                     'estimator', 'sim_host'},
    'drivers': {'drivers', 'hal', 'estimator'},
    'sim_host': {'sim_host', 'hal', 'estimator'},
}
# The program's files that only the host's build compiles (firmware/app/CMakeLists.txt).
HOST_ONLY_APP = {'cmd_batch.cpp', 'cmd_sim.cpp', 'cmd_montecarlo.cpp', 'sim_options.hpp', 'sim_options.cpp',
                 'host_tools.cpp'}
INCLUDE = re.compile(r'^\s*#\s*include\s*"mirrorcal/([a-z_]+)/', re.M)
LOCAL = re.compile(r'^\s*#\s*include\s*"([a-z_]+\.hpp)"', re.M)


def folder_of(path):
    for f in sorted(ALLOWED, key=len, reverse=True):
        if path == f or path.startswith(f + '/'):
            return f
    return None


def main(root):
    broken = []
    for d, _, files in os.walk(root):
        for name in files:
            if not name.endswith(('.cpp', '.hpp')):
                continue
            path = os.path.relpath(os.path.join(d, name), root)
            folder = folder_of(path)
            if folder is None:  # tests, tools: may use everything
                continue
            text = open(os.path.join(root, path), encoding='utf-8').read()
            for part in INCLUDE.findall(text):
                if part not in ALLOWED[folder]:
                    broken.append(f'{path}: includes mirrorcal/{part}/ ({folder} may not)')
                elif (folder == 'firmware/app' and part == 'evaluation'
                      and name not in HOST_ONLY_APP):
                    broken.append(f'{path}: includes mirrorcal/evaluation/ (the board\'s program '
                                  'links no evaluation)')
            # A quoted include without a folder is a private header beside the file.
            for local in LOCAL.findall(text):
                if not os.path.exists(os.path.join(root, os.path.dirname(path), local)):
                    broken.append(f'{path}: includes "{local}", which is not beside it')
                elif (folder == 'firmware/app' and local in HOST_ONLY_APP
                      and name not in HOST_ONLY_APP):
                    broken.append(f'{path}: includes the host-only "{local}"')
    for b in broken:
        print(b)
    print(f'layout: {len(broken)} includes break the rule' if broken else 'layout: every include keeps the rule')
    return 1 if broken else 0


if __name__ == '__main__':
    sys.exit(main(sys.argv[1]))

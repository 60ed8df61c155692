#!/usr/bin/python3
"""report.html in a real browser at 1200 px: nothing clipped, every warning on screen.

Calibrates a simulated rig whose report warns (mirrorcal sim), then opens its
report.html in Debian's Chromium, headless, inside a page of this test's that measures it after
layout: the page must not scroll sideways, no element may clip its content (overflow hidden,
auto or scroll with content wider than the element) or reach past the window's width, and each
WARNING line of the report's text must lie within the window. Exits 0, or 1 naming what failed.

usage: report_in_browser.py MIRRORCAL [CHROMIUM]
"""
import json
import os
import pathlib
import re
import shutil
import subprocess
import sys
import tempfile

WIDTH = 1200

CHECK_PAGE = """<!DOCTYPE html>
<html><body style="margin:0">
<iframe id="report" src="REPORT" style="width:%dpx;height:900px;border:0"></iframe>
<pre id="result">RESULT pending</pre>
<script>
document.getElementById('report').addEventListener('load', () => {
  const doc = document.getElementById('report').contentDocument;
  const view = doc.defaultView;
  const width = doc.documentElement.clientWidth;
  const problems = [];
  if (doc.documentElement.scrollWidth > width + 1)
    problems.push('the page scrolls sideways: ' + doc.documentElement.scrollWidth + ' px in ' + width);
  for (const el of doc.querySelectorAll('body *')) {
    const overflow = view.getComputedStyle(el).overflowX;
    if (['auto', 'scroll', 'hidden'].includes(overflow) && el.scrollWidth > el.clientWidth + 1)
      problems.push(el.tagName + ' clips its content: ' + el.scrollWidth + ' px in ' + el.clientWidth);
    const right = el.getBoundingClientRect().right;
    if (right > width + 1) problems.push(el.tagName + ' reaches ' + Math.round(right) + ' px');
  }
  // Each WARNING line of the text, measured as laid out (wrapped lines give several boxes).
  let warnings = 0;
  for (const pre of doc.querySelectorAll('pre')) {
    const node = pre.firstChild;
    if (!node) continue;
    const text = node.textContent;
    for (const m of text.matchAll(/^ *WARNING[^\\n]*/gm)) {
      ++warnings;
      const range = doc.createRange();
      range.setStart(node, m.index);
      range.setEnd(node, m.index + m[0].length);
      for (const box of range.getClientRects())
        if (box.right > width + 1 || box.left < -1)
          problems.push('a WARNING line reaches ' + Math.round(box.right) + ' px: ' + m[0].slice(0, 60));
    }
  }
  document.getElementById('result').textContent =
      'RESULT ' + JSON.stringify({width: width, warnings: warnings, problems: problems});
});
</script>
</body></html>
""" % WIDTH


def main():
    if len(sys.argv) < 2:
        sys.exit(__doc__)
    mirrorcal = sys.argv[1]
    chromium = sys.argv[2] if len(sys.argv) > 2 else shutil.which("chromium")
    if chromium and chromium.endswith("NOTFOUND"):  # CMake's find_program found none
        chromium = None
    if not chromium:
        sys.exit("report_in_browser: no chromium (Debian's package chromium; toolchain/setup-host)")
    with tempfile.TemporaryDirectory() as work:
        out = os.path.join(work, "sim")
        # A random rig whose two passes lock onto a wrong solution (ReportFiles' "bad" run): its
        # report says so in long WARNING lines.
        run = subprocess.run([mirrorcal, "sim", "--passes", "2", "--scenario", "random", "--seed",
                              "14543870473635789003", "--out", out],
                             capture_output=True, text=True)
        if run.returncode not in (0, 3):
            sys.exit("mirrorcal sim failed (%d):\n%s" % (run.returncode, run.stderr))
        report = pathlib.Path(out, "report.html")
        text = pathlib.Path(out, "report.txt").read_text()
        expected = len(re.findall(r"^ *WARNING", text, re.M))
        if expected == 0:
            sys.exit("report_in_browser: the run's report has no WARNING line to look for:\n" + text)
        check = pathlib.Path(work, "check.html")
        check.write_text(CHECK_PAGE.replace("REPORT", report.as_uri()))
        dom = subprocess.run(
            [chromium, "--headless", "--no-sandbox", "--disable-gpu", "--hide-scrollbars",
             "--allow-file-access-from-files", "--window-size=%d,900" % WIDTH,
             "--virtual-time-budget=30000", "--dump-dom", check.as_uri()],
            capture_output=True, text=True, timeout=300)
        found = re.search(r"RESULT (\{.*\})", dom.stdout)
        if not found:
            sys.exit("report_in_browser: the check page did not run (chromium %d):\n%s\n%s" %
                     (dom.returncode, dom.stdout[-2000:], dom.stderr[-2000:]))
        result = json.loads(found.group(1).replace("&quot;", '"'))
        print("report.html at %d px: %d WARNING lines, problems: %s" %
              (result["width"], result["warnings"], result["problems"] or "none"))
        if result["warnings"] != expected:
            sys.exit("report_in_browser: report.txt has %d WARNING lines, the page %d" %
                     (expected, result["warnings"]))
        if result["problems"]:
            sys.exit(1)


if __name__ == "__main__":
    main()

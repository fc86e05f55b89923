"""Open an ``oos run`` report in headless Chromium (Debian's ``chromium``), with no network.

A copy of the page gets a probe script (before ``</head>``, so after the page's own CSP) that
records every error (script errors, resources that fail to load, CSP violations, console.error
and console.warn) and, once the page has loaded, writes into the DOM: each image's natural
size, each headline's ``data-value`` and shown text, each section's position and the page
height. ``chromium --dump-dom`` returns that DOM; the probe's JSON is read back from it.
Chromium's own log of console messages (``--enable-logging=stderr``) is read as a second
witness. Screenshots use ``--screenshot``; a section's screenshot is cropped (Pillow) from a
full-height one at the section's offset.
"""

from __future__ import annotations

import html
import json
import os
import re
import shutil
import subprocess
from pathlib import Path

import pytest

#: Where Debian's package installs the browser.
CHROMIUM = "/usr/bin/chromium"
#: Width of the browser window [px].
WIDTH = 1400
#: Tallest full-page screenshot taken [px].
MAX_HEIGHT = 30000

PROBE = """<script>
(function () {
  var errors = [];
  window.__probeErrors = errors;
  window.addEventListener('error', function (e) {
    var t = e.target;
    errors.push(t && t !== window && (t.src || t.href)
      ? 'failed to load ' + (t.alt || '') + ' ' + String(t.src || t.href).slice(0, 60)
      : 'error: ' + e.message);
  }, true);
  window.addEventListener('unhandledrejection', function (e) {
    errors.push('unhandled rejection: ' + e.reason);
  });
  document.addEventListener('securitypolicyviolation', function (e) {
    errors.push('CSP violation: ' + e.violatedDirective + ' ' + String(e.blockedURI).slice(0, 80));
  });
  ['error', 'warn'].forEach(function (level) {
    var original = console[level];
    console[level] = function () {
      errors.push('console.' + level + ': ' + Array.prototype.join.call(arguments, ' '));
      original.apply(console, arguments);
    };
  });
  window.addEventListener('load', function () {
    var result = {
      errors: errors,
      images: Array.prototype.map.call(document.images, function (img) {
        return {alt: img.alt, complete: img.complete,
                width: img.naturalWidth, height: img.naturalHeight};
      }),
      headlines: Array.prototype.map.call(
        document.querySelectorAll('[data-headline]'), function (el) {
          return {key: el.dataset.headline, value: el.dataset.value, text: el.textContent};
        }),
      sections: Array.prototype.map.call(document.querySelectorAll('section'), function (s) {
        return {id: s.id, top: s.offsetTop, height: s.offsetHeight,
                notRun: s.querySelectorAll('.notrun').length};
      }),
      resources: performance.getEntriesByType('resource').map(function (r) { return r.name; }),
      pageHeight: document.documentElement.scrollHeight
    };
    var pre = document.createElement('pre');
    pre.id = 'report-probe';
    pre.textContent = JSON.stringify(result);
    document.body.appendChild(pre);
  });
})();
</script>"""


def chromium() -> str:
    """Path of the browser; skips (a failure in CI, see ``conftest.py``) when not installed."""
    path = shutil.which("chromium") or (CHROMIUM if os.access(CHROMIUM, os.X_OK) else None)
    if path is None:
        pytest.skip("chromium not installed (make venv installs it: apt-get install -y chromium)")
    return path


def _run(arguments: list[str], user_data: Path, timeout: float = 120.0):
    command = [
        chromium(),
        "--headless",
        "--disable-gpu",
        "--no-sandbox",
        "--no-first-run",
        "--hide-scrollbars",
        "--disable-extensions",
        "--host-resolver-rules=MAP * ~NOTFOUND",  # no network: any host lookup fails
        f"--user-data-dir={user_data}",
        *arguments,
    ]
    return subprocess.run(command, capture_output=True, text=True, timeout=timeout, check=False)


def probe(page: Path, work: Path) -> dict:
    """Open a probed copy of ``page`` and return what the probe recorded, plus
    ``console_log``: the console messages Chromium logged itself."""
    work.mkdir(parents=True, exist_ok=True)
    text = Path(page).read_text(encoding="utf-8")
    assert "</head>" in text, "the report has no </head>"
    probed = work / "probed.html"
    probed.write_text(text.replace("</head>", PROBE + "</head>", 1), encoding="utf-8")
    result = _run(
        [
            "--enable-logging=stderr",
            "--v=0",
            "--virtual-time-budget=15000",
            f"--window-size={WIDTH},1000",
            "--dump-dom",
            probed.as_uri(),
        ],
        work / "profile-probe",
    )
    match = re.search(r'<pre id="report-probe">(.*?)</pre>', result.stdout, re.S)
    assert match, (
        f"the probe did not run (chromium status {result.returncode}): {result.stderr[-2000:]}"
    )
    data = json.loads(html.unescape(match.group(1)))
    data["console_log"] = [line for line in result.stderr.splitlines() if ":CONSOLE" in line]
    return data


def screenshot(page: Path, path: Path, work: Path, height: int = 1400) -> Path:
    """PNG of the top ``height`` pixels of ``page`` at :data:`WIDTH`."""
    path.parent.mkdir(parents=True, exist_ok=True)
    result = _run(
        [f"--window-size={WIDTH},{height}", f"--screenshot={path}", Path(page).as_uri()],
        work / "profile-shot",
    )
    assert path.is_file(), f"no screenshot (chromium status {result.returncode})"
    return path


def section_screenshots(
    page: Path,
    sections: dict,
    names: dict[str, str],
    folder: Path,
    work: Path,
    height: int = 1400,
) -> dict[str, Path]:
    """Screenshots of sections: ``names`` maps a section id to a file name in ``folder``;
    ``sections`` is the probe's section list (offsets [px])."""
    from PIL import Image

    offsets = {s["id"]: s["top"] for s in sections}
    bottom = max(offsets[n] for n in names) + height
    if bottom > MAX_HEIGHT:
        raise ValueError(f"sections end at {bottom} px, beyond {MAX_HEIGHT} px")
    full = screenshot(page, work / "full.png", work, height=bottom)
    shots = {}
    with Image.open(full) as image:
        for section, name in names.items():
            top = offsets[section]
            box = (0, top, image.width, min(top + height, image.height))
            shots[section] = folder / name
            folder.mkdir(parents=True, exist_ok=True)
            image.crop(box).save(shots[section])
    return shots

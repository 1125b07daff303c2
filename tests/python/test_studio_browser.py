"""`moirecast studio` in a real browser: Debian's chromium, headless,
driven over the DevTools protocol by tests/node/studio.mjs (playwright-core,
installed by scripts/test-all.sh). The first frame arrives, the tilt slider
changes it, afov = 200 is refused at its field naming `lens.afov`, the 3D
view orbits, "Write device files" writes device.stl; a screenshot is saved
as target/studio-screenshot.png."""
import os
import subprocess

import pytest
from conftest import BIN, ROOT, tool

RUNNER = ROOT / "tests" / "node" / "studio.mjs"
HOSTILE = ROOT / "tests" / "node" / "studio-hostile.mjs"


def browser_tools():
    """node, with chromium and playwright-core; under CI=true a missing one fails."""
    node = tool("node")
    tool("chromium")
    if not (ROOT / "tests" / "node" / "node_modules" / "playwright-core").exists():
        msg = "playwright-core is not installed: run `npm ci --prefix tests/node`"
        if os.environ.get("CI") == "true":
            pytest.fail(msg)
        pytest.skip(msg)
    return node


def run_in_chromium(script, *args):
    """Runs a tests/node script that drives Debian's chromium; it passes
    when it exits 0 and printed no FAIL."""
    run = subprocess.run(
        [browser_tools(), str(script), str(BIN), *map(str, args)],
        capture_output=True,
        text=True,
        timeout=600,
    )
    print(run.stdout)
    assert run.returncode == 0, f"{run.stdout}\n{run.stderr}"
    assert "FAIL" not in run.stdout


def test_the_studio_refuses_hostile_pages_and_file_names(tmp_path):
    """A PNG named like markup lists as text under a CSP that forbids inline
    script; another site's page cannot write, save, edit or frame it."""
    run_in_chromium(HOSTILE, tmp_path)


def test_the_studio_works_in_chromium(tmp_path):
    screenshot = ROOT / "target" / "studio-screenshot.png"
    run_in_chromium(RUNNER, tmp_path, screenshot)
    assert screenshot.stat().st_size > 10_000

"""`moirecast studio` under a short HTTP fuzz run (scripts/studio-fuzz.py):
random routes, methods, queries, headers and bodies, random spec TOML
among them. No crash, no request left unanswered, RSS under 1 GB. The
closing note's 100,000-request run is the same script."""
import json
import subprocess
import sys

from conftest import BIN, ROOT


def test_the_studio_survives_random_requests():
    run = subprocess.run(
        [sys.executable, str(ROOT / "scripts" / "studio-fuzz.py"), str(BIN), "3000", "7"],
        capture_output=True,
        text=True,
        timeout=900,
    )
    assert run.returncode == 0, run.stdout + run.stderr
    counts = json.loads(run.stdout.strip().splitlines()[-1])
    assert counts["crashes"] == 0 and counts["hangs"] == 0, counts
    assert counts["statuses"].get("200", 0) > 0, counts

"""An output folder holds exactly one run (docs/decisions.md, "Output
folders"): `device` and `mold` runs killed at random moments never leave a
mixed set, and nothing they leave survives the next run. A short round of
scripts/kill-loop.py; the closing note's 200-round loop is the same script."""
import json
import subprocess
import sys

from conftest import BIN, ROOT


def test_runs_killed_at_random_never_leave_a_mixed_folder():
    run = subprocess.run(
        [sys.executable, str(ROOT / "scripts" / "kill-loop.py"), str(BIN),
         str(ROOT / "molds" / "plane-rings.toml"), "16", "5"],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert run.returncode == 0, run.stderr
    counts = json.loads(run.stdout.strip().splitlines()[-1])
    assert counts["runs"] == 16 and counts["killed"] >= 4, counts

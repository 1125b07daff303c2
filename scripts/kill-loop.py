#!/usr/bin/env python3
"""Kills `moirecast device` and `moirecast mold` runs at random moments and
checks that the output folder always holds exactly one run, never a mix,
and that nothing a killed run left survives the next one.

    python3 scripts/kill-loop.py MOIRECAST_BIN SPEC RUNS [SEED]

Each round starts `device` or `mold` on SPEC into the same folder (with
`[view] compensate` flipped every other round, so consecutive runs differ),
kills it with SIGKILL after a random time within the run's usual length
(some rounds run to the end), then checks the folder: absent, or every file
its manifest lists present and no other, report.json's SHA-256s matching
the files, and one spec's run (device or mold, one `compensate`). After the
next finished run nothing stray may be left beside it. Prints the counts;
exits non-zero on the first violation. Only the standard library."""
import hashlib
import json
import pathlib
import random
import shutil
import signal
import subprocess
import sys
import tempfile
import time

MANIFEST = ".moirecast-run"


def check_folder(out: pathlib.Path) -> str:
    """'absent' or the run's kind; raises AssertionError on a mix."""
    if not out.exists():
        return "absent"
    listed = (out / MANIFEST).read_text().split()
    present = sorted(
        str(p.relative_to(out)) for p in out.rglob("*") if p.is_file() and p.name != MANIFEST
    )
    assert sorted(listed) == present, f"manifest {listed} against files {present}"
    report = json.loads((out / "report.json").read_text())
    for name, digest in report["sha256"].items():
        actual = hashlib.sha256((out / name).read_bytes()).hexdigest()
        assert actual == digest, f"{name}: {actual} against report {digest}"
    expected = set(report["sha256"]) | {"report.json"}
    assert set(present) == expected, f"files {present} against report {sorted(expected)}"
    kind = "mold" if "mold-top.stl" in present else "device"
    compensated = report["view"]["compensated"]
    return f"{kind}, compensate={compensated}"


def strays(out: pathlib.Path) -> list:
    prefix = f".{out.name}.moirecast-"
    return sorted(p.name for p in out.parent.iterdir() if p.name.startswith(prefix)) + sorted(
        p.name for p in out.glob(".*.tmp")
    )


def main():
    binary, spec, runs = sys.argv[1], pathlib.Path(sys.argv[2]).resolve(), int(sys.argv[3])
    rng = random.Random(int(sys.argv[4]) if len(sys.argv) > 4 else 1)
    work = pathlib.Path(tempfile.mkdtemp(prefix="moirecast-kill-"))
    base = spec.read_text()
    specs = []
    for compensate in ("true", "false"):
        path = work / f"spec-{compensate}.toml"
        path.write_text(f"{base}\n[view]\ncompensate = {compensate}\n" if "[view]" not in base else base)
        specs.append(path)
    for profiles in (spec.parent / "profiles",):
        if profiles.exists():
            (work / "profiles").symlink_to(profiles)
    out = work / "out"
    usual = {}
    counts = {"killed": 0, "finished": 0, "absent after a kill": 0, "old run after a kill": 0, "new run after a kill": 0}
    previous = None
    for i in range(runs):
        command = rng.choice(["device", "mold"])
        spec_path = specs[i % 2]
        args = [binary, command, str(spec_path), "-o", str(out), "-q"]
        started = time.monotonic()
        proc = subprocess.Popen(args, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        limit = usual.get(command)
        kill_at = None if limit is None or rng.random() < 0.15 else rng.uniform(0.0, 1.1 * limit)
        try:
            proc.wait(timeout=kill_at)
            killed = False
        except subprocess.TimeoutExpired:
            proc.send_signal(signal.SIGKILL)
            proc.wait()
            killed = True
        elapsed = time.monotonic() - started
        if not killed:
            assert proc.returncode == 0, proc.stderr.read().decode()
            usual[command] = elapsed
            assert not strays(out), f"round {i}: left beside a finished run: {strays(out)}"
        state = check_folder(out)
        if killed:
            counts["killed"] += 1
            now = f"{command}, compensate={spec_path.name.endswith('true.toml')}"
            key = "absent after a kill" if state == "absent" else (
                "new run after a kill" if state == now and state != previous else "old run after a kill")
            counts[key] += 1
        else:
            counts["finished"] += 1
        previous = state if state != "absent" else previous
    # a last finished run clears whatever the kills left
    subprocess.run([binary, "device", str(specs[0]), "-o", str(out), "-q"], check=True)
    assert not strays(out), strays(out)
    check_folder(out)
    shutil.rmtree(work)
    print(json.dumps({"runs": runs, **counts}))


if __name__ == "__main__":
    main()

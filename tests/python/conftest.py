"""Shared fixtures: the moirecast binary and the shipped specs, built once."""
import functools
import importlib
import json
import os
import pathlib
import subprocess
import tomllib

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]
# the test command's build (profile `checked`), or a release build
BIN = pathlib.Path(
    os.environ.get("MOIRECAST_BIN")
    or next(
        (p for p in (ROOT / "target" / d / "moirecast" for d in ("checked", "release")) if p.exists()),
        ROOT / "target" / "checked" / "moirecast",
    )
)
ALL_SPECS = sorted((ROOT / "molds").glob("*.toml"))


def is_printed(spec):
    """A printed (multi-material) design: two bodies, no B-rep, no mold."""
    return tomllib.loads(spec.read_text()).get("base", {}).get("kind") == "printed"


# Cast (dual-lens) devices: device.stl, device.step and a mold each.
SPECS = [s for s in ALL_SPECS if not is_printed(s)]
# Printed devices: device-clear.stl, device-black.stl and device.3mf.
PRINTED_SPECS = [s for s in ALL_SPECS if is_printed(s)]


def oracle(name):
    """Imports an oracle library. Under CI=true a missing one fails; elsewhere it skips."""
    try:
        return importlib.import_module(name)
    except ImportError as e:  # pragma: no cover - depends on the machine
        if os.environ.get("CI") == "true":
            pytest.fail(f"oracle `{name}` is not installed under CI: {e}")
        pytest.skip(f"oracle `{name}` is not installed: {e}")


def tool(name):
    """The path of an executable oracle. Under CI=true a missing one fails; elsewhere it skips."""
    import shutil

    path = shutil.which(name)
    if path is None:
        if os.environ.get("CI") == "true":
            pytest.fail(f"tool `{name}` is not installed under CI")
        pytest.skip(f"tool `{name}` is not installed")
    return path


def build(spec, out):
    """Runs `moirecast device` and returns (stl path, report)."""
    if not BIN.exists():
        pytest.fail(f"moirecast binary not found at {BIN}; run ./scripts/test-all.sh")
    args = [str(BIN), "device"] + ([str(spec)] if spec else []) + ["-o", str(out), "--quiet"]
    r = subprocess.run(args, capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    return out / "device.stl", json.loads((out / "report.json").read_text())


def shared_dir(tmp_path_factory):
    """A folder every test process of this run shares: under pytest-xdist
    each worker's base temp is <run>/popen-gwN, and the fixtures live in <run>."""
    base = tmp_path_factory.getbasetemp()
    root = base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base
    shared = root / "moirecast-fixtures"
    shared.mkdir(exist_ok=True)
    return shared


def run_once(shared, command, spec):
    """`moirecast COMMAND SPEC -o DIR` once per test run, whichever worker
    asks first (the others wait on its lock): (output dir, report)."""
    import fcntl
    import shutil

    key = f"{command}-{spec.stem if spec else 'default'}"
    out, done = shared / key, shared / f"{key}.done"
    with open(shared / f"{key}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if not done.exists():
            if not BIN.exists():
                pytest.fail(f"moirecast binary not found at {BIN}; run ./scripts/test-all.sh")
            shutil.rmtree(out, ignore_errors=True)
            args = [str(BIN), command] + ([str(spec)] if spec else []) + ["-o", str(out), "--quiet"]
            r = subprocess.run(args, capture_output=True, text=True)
            assert r.returncode == 0, r.stderr
            done.write_text("")
    return out, json.loads((out / "report.json").read_text())


@pytest.fixture(scope="session")
def built(tmp_path_factory):
    """Every shipped spec's device, plus the embedded default design, built
    once per run: a function from spec (or None) to (stl path, report)."""
    shared = shared_dir(tmp_path_factory)

    def get(spec):
        out, report = run_once(shared, "device", spec)
        return out / "device.stl", report

    return get


def runs_once(tmp_path_factory, command):
    """`moirecast COMMAND SPEC -o DIR`, each spec run once per test run:
    a function from spec to (output dir, report)."""
    shared = shared_dir(tmp_path_factory)
    return lambda spec: run_once(shared, command, spec)


@functools.lru_cache(maxsize=16)
def manifold(path):
    """An STL as a manifold3d solid, welded first; its status must be NoError.
    Loaded once per process (solids are immutable)."""
    import numpy as np

    m3d = oracle("manifold3d")
    trimesh = oracle("trimesh")
    raw = trimesh.load(str(path), process=False)
    mesh = m3d.Mesh(
        vert_properties=np.asarray(raw.vertices, dtype=np.float32),
        tri_verts=np.asarray(raw.faces, dtype=np.uint32),
    )
    mesh.merge()  # STL repeats vertices per facet: weld before loading
    solid = m3d.Manifold(mesh)
    assert solid.status() == m3d.Error.NoError, (path.name, solid.status())
    return solid

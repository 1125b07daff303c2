"""Shared fixtures: the moirecast binary and the shipped specs, built once."""
import importlib
import json
import os
import pathlib
import subprocess
import tomllib

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]
BIN = pathlib.Path(os.environ.get("MOIRECAST_BIN", ROOT / "target" / "release" / "moirecast"))
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
        pytest.fail(f"moirecast binary not found at {BIN}; build it with `cargo build --release`")
    args = [str(BIN), "device"] + ([str(spec)] if spec else []) + ["-o", str(out), "--quiet"]
    r = subprocess.run(args, capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    return out / "device.stl", json.loads((out / "report.json").read_text())


@pytest.fixture(scope="session")
def built(tmp_path_factory):
    """Every shipped spec, plus the embedded default design, built once."""
    cache = {}

    def get(spec):
        key = spec.name if spec else "default"
        if key not in cache:
            cache[key] = build(spec, tmp_path_factory.mktemp(key.replace(".toml", "")))
        return cache[key]

    return get


def runs_once(tmp_path_factory, command):
    """`moirecast COMMAND SPEC -o DIR`, each spec run once per session:
    a function from spec to (output dir, report)."""
    cache = {}

    def get(spec):
        if spec.name not in cache:
            if not BIN.exists():
                pytest.fail(f"moirecast binary not found at {BIN}; build it with `cargo build --release`")
            out = tmp_path_factory.mktemp(spec.stem)
            r = subprocess.run([str(BIN), command, str(spec), "-o", str(out), "--quiet"], capture_output=True, text=True)
            assert r.returncode == 0, r.stderr
            cache[spec.name] = (out, json.loads((out / "report.json").read_text()))
        return cache[spec.name]

    return get


def manifold(path):
    """An STL as a manifold3d solid, welded first; its status must be NoError."""
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

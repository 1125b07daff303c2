"""Every shipped spec's device.stl, checked by tools that share no code with
moirecast: manifold3d (status, genus, shells) and trimesh (watertight,
winding-consistent, is_volume). Volumes must agree with report.json."""
import numpy as np
import pytest

from conftest import SPECS, build, oracle

CASES = SPECS + [None]  # None: the embedded default design
IDS = [s.stem for s in SPECS] + ["default"]


def load_arrays(stl):
    trimesh = oracle("trimesh")
    raw = trimesh.load(str(stl), process=False)
    return np.asarray(raw.vertices, dtype=np.float32), np.asarray(raw.faces, dtype=np.uint32)


@pytest.mark.parametrize("spec", CASES, ids=IDS)
def test_manifold3d_accepts_the_device(spec, built):
    m3d = oracle("manifold3d")
    stl, report = built(spec)
    verts, faces = load_arrays(stl)
    mesh = m3d.Mesh(vert_properties=verts, tri_verts=faces)
    mesh.merge()  # STL repeats vertices per facet: weld before loading
    solid = m3d.Manifold(mesh)
    assert solid.status() == m3d.Error.NoError, solid.status()
    assert solid.genus() == 0
    assert len(solid.decompose()) == 1, "one shell"
    assert solid.num_tri() == report["files"]["device.stl"]["triangles"]
    expected = report["files"]["device.stl"]["volume_mm3"]
    assert solid.volume() == pytest.approx(expected, rel=1e-6)


@pytest.mark.parametrize("spec", CASES, ids=IDS)
def test_trimesh_finds_a_watertight_volume(spec, built):
    trimesh = oracle("trimesh")
    stl, report = built(spec)
    mesh = trimesh.load(str(stl), process=True)  # merges coincident vertices
    assert mesh.is_watertight
    assert mesh.is_winding_consistent
    assert mesh.is_volume
    assert len(mesh.faces) == report["files"]["device.stl"]["triangles"]
    assert mesh.volume == pytest.approx(report["files"]["device.stl"]["volume_mm3"], rel=1e-6)
    lo, hi = mesh.bounds
    assert np.allclose(lo, report["files"]["device.stl"]["bbox_min"], atol=1e-5)
    assert np.allclose(hi, report["files"]["device.stl"]["bbox_max"], atol=1e-5)


@pytest.mark.parametrize("spec", CASES, ids=IDS)
def test_every_check_passed_and_lenses_match_the_design(spec, built):
    _, report = built(spec)
    failed = [c for c in report["checks"] if not c["passed"]]
    assert not failed, failed
    afov = report["design"]["afov_deg"]
    assert report["lenses"]["afov_deg"]["min"] == pytest.approx(afov, abs=1e-6)
    assert report["lenses"]["afov_deg"]["max"] == pytest.approx(afov, abs=1e-6)
    assert report["mesh"]["triangles"] < report["mesh"]["uniform_triangles"]


def test_the_default_design_is_the_reference(built):
    _, default = built(None)
    assert "saddle-horse" in default["spec"]
    assert default["derived"]["N"] == 120


def test_a_shipped_spec_is_byte_deterministic(tmp_path):
    spec = next(s for s in SPECS if s.stem == "plane-rings")
    a, _ = build(spec, tmp_path / "a")
    b, _ = build(spec, tmp_path / "b")
    assert a.read_bytes() == b.read_bytes()
    assert (tmp_path / "a" / "report.json").read_bytes() == (tmp_path / "b" / "report.json").read_bytes()


def test_full_checks_measure_every_vertex(tmp_path):
    """`--full-checks` measures every vertex and lens triangle; all pass."""
    import json
    import subprocess

    from conftest import BIN

    spec = next(s for s in SPECS if s.stem == "plane-rings")
    r = subprocess.run([str(BIN), "device", str(spec), "-o", str(tmp_path), "--quiet", "--full-checks"], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    report = json.loads((tmp_path / "report.json").read_text())
    checks = {c["name"]: c for c in report["checks"]}
    assert all(c["passed"] for c in checks.values()), [c for c in checks.values() if not c["passed"]]
    assert checks["vertex-on-surface"]["detail"].startswith("every vertex")
    assert "every lens triangle" in checks["surface-to-mesh"]["detail"]
    assert checks["surface-to-mesh"]["value"] <= report["design"]["tolerance_mm"]

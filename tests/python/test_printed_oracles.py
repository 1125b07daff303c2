"""Printed (multi-material) devices (METHOD §5.2), checked by tools that
share no code with moirecast: manifold3d and trimesh on the two STLs, and
the 3MF Consortium's lib3mf on device.3mf."""
import numpy as np
import pytest

from conftest import PRINTED_SPECS, manifold, oracle, runs_once

IDS = [s.stem for s in PRINTED_SPECS]
BODIES = ["device-clear.stl", "device-black.stl"]


@pytest.fixture(scope="session")
def printed(tmp_path_factory):
    """Each printed spec built once: (output dir, report)."""
    return runs_once(tmp_path_factory, "device")


def test_a_printed_example_ships():
    assert "saddle-camera-printed" in IDS


@pytest.mark.parametrize("spec", PRINTED_SPECS, ids=IDS)
def test_both_bodies_are_valid_solids(spec, printed):
    trimesh = oracle("trimesh")
    out, report = printed(spec)
    p = report["printed"]
    for name in BODIES:
        solid = manifold(out / name)
        assert solid.volume() > 0
        assert solid.num_tri() == report["files"][name]["triangles"]
        assert solid.volume() == pytest.approx(report["files"][name]["volume_mm3"], rel=1e-6)
        mesh = trimesh.load(str(out / name), process=True)
        assert mesh.is_watertight, name
        assert mesh.is_winding_consistent, name
        assert mesh.is_volume, name
    clear, black = (manifold(out / n) for n in BODIES)
    # the clear body is one shell with a tunnel per band that runs wall to wall
    assert len(clear.decompose()) == 1
    assert clear.genus() == p["clear_genus"]
    # the black layer is one closed band per period, each a ball
    bands = black.decompose()
    assert len(bands) == p["bands"]
    assert all(b.genus() == 0 for b in bands)


@pytest.mark.parametrize("spec", PRINTED_SPECS, ids=IDS)
def test_the_bodies_touch_without_overlap_and_fill_the_device(spec, printed):
    out, report = printed(spec)
    clear, black = (manifold(out / n) for n in BODIES)
    device = report["printed"]["device_volume_mm3"]
    overlap = (clear ^ black).volume()
    assert overlap <= 1e-6 * device, overlap
    union = clear + black
    assert union.volume() == pytest.approx(device, rel=1e-6)
    # together: one solid without holes (no gap between the bodies)
    assert len(union.decompose()) == 1
    assert union.genus() == 0


@pytest.mark.parametrize("spec", PRINTED_SPECS, ids=IDS)
def test_the_duty_cycle_is_kept(spec, printed):
    """By volume: black volume / band-layer volume, the layer being the
    outline's rectangle times t_b (layers are vertical). Along lines: the
    black body's xy shadow cut by thin strips y = const, over the strip's
    whole periods (from its first band start to its last)."""
    m3d = oracle("manifold3d")
    out, report = printed(spec)
    duty = report["design"]["base_duty"]
    t_b = report["design"]["base_band_thickness_mm"]
    black = manifold(out / "device-black.stl")
    (x0, y0, _), (x1, y1, _) = (report["files"]["device-clear.stl"][k] for k in ["bbox_min", "bbox_max"])
    layer = (x1 - x0) * (y1 - y0) * t_b
    assert black.volume() / layer == pytest.approx(duty, rel=0.01)
    shadow = black.project()  # the bands seen from above: xy regions
    assert shadow.area() * t_b == pytest.approx(black.volume(), rel=1e-6)
    width, fractions = 1e-3, []
    for y in np.linspace(y0, y1, 11)[1:-1]:
        strip = m3d.CrossSection.square((x1 - x0 + 2, width)).translate((x0 - 1, y - width / 2))
        cut = shadow ^ strip
        spans = sorted((b[0], b[2]) for b in (piece.bounds() for piece in cut.decompose()))
        starts = [a for a, _ in spans if a > x0 + 1e-4]
        lo, hi = starts[0], starts[-1]
        inside = sum(max(0.0, min(b, hi) - max(a, lo)) for a, b in spans)
        fractions.append(inside / (hi - lo))
        assert inside / (hi - lo) == pytest.approx(duty, rel=0.01), y
    assert np.mean(fractions) == pytest.approx(report["printed"]["duty"]["along_lines"], abs=2e-3)


def read_3mf(path):
    lib3mf = oracle("lib3mf")
    wrapper = lib3mf.get_wrapper()
    model = wrapper.CreateModel()
    reader = model.QueryReader("3mf")
    reader.ReadFromFile(str(path))
    objects = {}
    it = model.GetMeshObjects()
    while it.MoveNext():
        o = it.GetCurrentMeshObject()
        resource, prop, has = o.GetObjectLevelProperty()
        assert has, o.GetName()
        group = model.GetBaseMaterialGroupByID(resource)
        colour = group.GetDisplayColor(prop)
        verts = np.array([v.Coordinates[0:3] for v in o.GetVertices()], dtype=np.float64)
        tris = np.array([t.Indices[0:3] for t in o.GetTriangleIndices()], dtype=np.int64)
        objects[o.GetName()] = dict(
            material=group.GetName(prop),
            colour=(colour.Red, colour.Green, colour.Blue, colour.Alpha),
            manifold=o.IsManifoldAndOriented(),
            verts=verts,
            tris=tris,
        )
    items = model.GetBuildItems()
    n_items = 0
    while items.MoveNext():
        n_items += 1
    return objects, n_items, reader.GetWarningCount()


def volume(verts, tris):
    a, b, c = (verts[tris[:, i]] for i in range(3))
    return np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0


@pytest.mark.parametrize("spec", PRINTED_SPECS, ids=IDS)
def test_lib3mf_reads_two_objects_with_their_materials(spec, printed):
    out, report = printed(spec)
    objects, items, warnings = read_3mf(out / "device.3mf")
    assert warnings == 0
    assert sorted(objects) == ["black", "clear"]
    assert items == 2, "both objects in one build"
    assert objects["clear"]["material"] == "clear"
    assert objects["black"]["material"] == "black"
    assert objects["black"]["colour"][:3] == (16, 16, 16)
    assert objects["clear"]["colour"][3] < 255, "clear is translucent"
    for name, stl in [("clear", "device-clear.stl"), ("black", "device-black.stl")]:
        o = objects[name]
        assert o["manifold"], name
        assert len(o["tris"]) == report["files"][stl]["triangles"]
        # the same f32 vertices as the STL: the same volume
        assert volume(o["verts"], o["tris"]) == pytest.approx(report["files"][stl]["volume_mm3"], rel=1e-6)


@pytest.mark.parametrize("spec", PRINTED_SPECS, ids=IDS)
def test_opencascade_reads_the_bodies_step_files(spec, printed):
    """device-clear.step is one valid solid, device-black.step one valid
    solid per band, with the faces report.json counts; each file's volume
    is its STL's to within the STL's surface area × tolerance (the STL's
    triangles are chords of the exact faces, within the tolerance)."""
    from test_step_oracles import read_step

    trimesh = oracle("trimesh")
    out, report = printed(spec)
    brep = report["printed"]["brep"]
    tol = report["design"]["tolerance_mm"]
    expected = {
        "device-clear": (1, brep["clear_faces"]),
        "device-black": (report["printed"]["bands"], brep["black_faces"]),
    }
    for name, (solids, faces) in expected.items():
        step = read_step(out / f"{name}.step")
        assert step["solids"] == solids, name
        assert step["faces"] == faces, name
        assert step["valid"], f"BRepCheck_Analyzer finds {name}.step invalid"
        mesh = trimesh.load(str(out / f"{name}.stl"), process=False)
        v_stl = report["files"][f"{name}.stl"]["volume_mm3"]
        assert abs(step["volume"] - v_stl) <= mesh.area * tol, (name, step["volume"], v_stl)


@pytest.mark.parametrize("spec", PRINTED_SPECS, ids=IDS)
@pytest.mark.parametrize("deflection", [0.05, 0.01])
def test_brepmesh_closes_both_bodies_steps(spec, deflection, printed):
    """Each body's STEP file, meshed by OpenCascade's BRepMesh (as FreeCAD
    and PrusaSlicer do), is closed, in as many pieces as its STL (the
    clear body one, the black layer one per band), of its STL's volume."""
    from test_step_oracles import brepmesh_matches_the_stl

    out, report = printed(spec)
    brepmesh_matches_the_stl(out / "device-clear.step", out / "device-clear.stl", deflection)
    bands = report["printed"]["bands"]
    brepmesh_matches_the_stl(out / "device-black.step", out / "device-black.stl", deflection, pieces=bands)

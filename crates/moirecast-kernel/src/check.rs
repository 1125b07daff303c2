//! Named checks of METHOD §7.1, each carrying its evidence: what was
//! measured, the limit, and where the worst case is.

use crate::checks::Bound;
use crate::mesh::Mesh;
use glam::DVec3;
use rayon::prelude::*;

/// The outcome of one check.
#[derive(Clone, Debug, PartialEq)]
pub struct CheckResult {
    pub name: &'static str,
    /// The measured value, in `unit`.
    pub value: f64,
    /// The limit the value is compared against (see `passed`).
    pub limit: f64,
    pub unit: &'static str,
    pub passed: bool,
    /// Where the worst case is, or what was counted.
    pub detail: String,
}

impl CheckResult {
    /// `value` held against `limit` by `bound`. The name must be in the
    /// registry ([`crate::checks`]) with this unit and bound: checked in
    /// debug builds, where every test runs.
    pub fn bounded(
        name: &'static str,
        value: f64,
        bound: Bound,
        limit: f64,
        unit: &'static str,
        detail: String,
    ) -> Self {
        debug_assert!(
            crate::checks::check_doc(name).is_some_and(|d| d.unit == unit && d.bound == bound),
            "check `{name}` ({unit}, {}) is not in the registry",
            bound.words()
        );
        CheckResult {
            name,
            value,
            limit,
            unit,
            passed: bound.passes(value, limit),
            detail,
        }
    }

    /// Passed when value ≤ limit.
    pub fn at_most(
        name: &'static str,
        value: f64,
        limit: f64,
        unit: &'static str,
        detail: String,
    ) -> Self {
        Self::bounded(name, value, Bound::AtMost, limit, unit, detail)
    }

    /// Passed when value ≥ limit.
    pub fn at_least(
        name: &'static str,
        value: f64,
        limit: f64,
        unit: &'static str,
        detail: String,
    ) -> Self {
        Self::bounded(name, value, Bound::AtLeast, limit, unit, detail)
    }
}

/// Smallest triangle altitude (mm) that is not a degenerate triangle: 10 nm,
/// about five f32 steps at 30 mm, so no triangle can flip when written as
/// STL; far below any tolerance.
pub const MIN_ALTITUDE_MM: f64 = 1e-5;

/// The solid checks every mesh must pass before it is written
/// (METHOD §7.1): finite, closed and oriented, one shell of genus 0,
/// positive volume, no degenerate triangles.
pub fn solid_checks(mesh: &Mesh) -> Vec<CheckResult> {
    solid_checks_of_genus(mesh, 0)
}

/// What a solid must be beyond closed and oriented.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SolidSpec {
    /// Through-holes: 0 for a device; sprue, vents and bolts for a mold half.
    /// Summed over the shells.
    pub genus: u32,
    /// Connected shells: 1 for every part; more for a set of construction
    /// solids (the key bumps, say).
    pub shells: u32,
    /// Smallest triangle altitude (mm). Our own meshes keep
    /// [`MIN_ALTITUDE_MM`]; boolean results may hold thinner slivers where
    /// faces cross at a shallow angle, and are held to
    /// [`MIN_BOOLEAN_ALTITUDE_MM`] plus the f32 check below.
    pub min_altitude: f64,
    /// Every triangle keeps its orientation when its vertices are rounded
    /// to f32 (as STL stores them).
    pub f32_safe: bool,
}

/// Smallest altitude (mm) of a triangle out of a boolean: not degenerate in f64.
pub const MIN_BOOLEAN_ALTITUDE_MM: f64 = 1e-9;

impl SolidSpec {
    pub const DEVICE: SolidSpec = SolidSpec {
        genus: 0,
        shells: 1,
        min_altitude: MIN_ALTITUDE_MM,
        f32_safe: false,
    };
    /// A mold half with `genus` through-holes.
    pub fn boolean_result(genus: u32) -> SolidSpec {
        Self::boolean_results(genus, 1)
    }
    /// `shells` solids out of booleans, with `genus` holes among them.
    pub fn boolean_results(genus: u32, shells: u32) -> SolidSpec {
        SolidSpec {
            genus,
            shells,
            min_altitude: MIN_BOOLEAN_ALTITUDE_MM,
            f32_safe: true,
        }
    }
}

/// [`solid_checks`] for a solid with `genus` through-holes (a mold half with
/// its sprue, vents and bolt holes).
pub fn solid_checks_of_genus(mesh: &Mesh, genus: u32) -> Vec<CheckResult> {
    solid_checks_for(
        mesh,
        SolidSpec {
            genus,
            ..SolidSpec::DEVICE
        },
    )
}

/// The solid checks against `spec`.
pub fn solid_checks_for(mesh: &Mesh, spec: SolidSpec) -> Vec<CheckResult> {
    solid_checks_and_volume(mesh, spec).0
}

/// [`solid_checks_for`] and the volume its `positive-volume` check measured.
fn solid_checks_and_volume(mesh: &Mesh, spec: SolidSpec) -> (Vec<CheckResult>, f64) {
    let genus = spec.genus;
    let mut out = Vec::new();
    let bad_coords = mesh.positions.iter().filter(|p| !p.is_finite()).count();
    out.push(CheckResult::at_most(
        "finite-coordinates",
        bad_coords as f64,
        0.0,
        "vertices",
        format!("{} vertices", mesh.positions.len()),
    ));
    // the measurements are independent; the two serial ones (the edge
    // index and the union-find) run beside the parallel ones
    let (unmatched, ((shells, vertices), (volume, (min_alt, worst), f32_faults))) = rayon::join(
        || unmatched_edges(mesh),
        || {
            rayon::join(
                || shells_and_used_vertices(mesh),
                || {
                    let ((volume, altitude), f32_faults) = rayon::join(
                        || rayon::join(|| mesh.volume(), || smallest_altitude(mesh)),
                        || spec.f32_safe.then(|| f32_rounding_faults(mesh)),
                    );
                    (volume, altitude, f32_faults)
                },
            )
        },
    );
    let directed = 3 * mesh.triangles.len();
    let undirected = directed / 2;
    out.push(CheckResult::at_most(
        "closed-oriented",
        unmatched as f64,
        0.0,
        "edges",
        format!("{directed} directed edges; {unmatched} not matched by exactly one opposite edge"),
    ));
    // One shell, genus 0: connected, and V − E + F = 2.
    let euler = vertices as i64 - undirected as i64 + mesh.triangles.len() as i64;
    out.push(CheckResult::bounded(
        "shells",
        shells as f64,
        Bound::Exactly,
        spec.shells as f64,
        "shells",
        format!(
            "{shells} connected shells, {} unused vertices",
            mesh.positions.len() - vertices
        ),
    ));
    // Summed over the shells: χ = Σ (2 − 2 g_i).
    let measured_genus = (2 * shells as i64 - euler) as f64 / 2.0;
    out.push(CheckResult::bounded(
        "genus",
        measured_genus,
        Bound::Exactly,
        genus as f64,
        "holes",
        format!("Euler characteristic {euler}"),
    ));

    out.push(CheckResult::bounded(
        "positive-volume",
        volume,
        Bound::Above,
        0.0,
        "mm³",
        String::new(),
    ));

    let at = mesh
        .triangles
        .get(worst)
        .map(|t| mesh.positions[t[0] as usize])
        .unwrap_or_default();
    if let Some((flipped, merged)) = f32_faults {
        out.push(CheckResult::at_most(
            "f32-safe-triangles",
            flipped as f64,
            0.0,
            "triangles",
            "triangles that collapse or flip when rounded to f32 (STL)".into(),
        ));
        out.push(CheckResult::at_most(
            "f32-distinct-vertices",
            merged as f64,
            0.0,
            "vertices",
            "vertices that round to the same f32 point as another vertex".into(),
        ));
    }
    out.push(CheckResult::at_least(
        "no-degenerate-triangles",
        min_alt,
        spec.min_altitude,
        "mm",
        format!(
            "smallest altitude, at triangle {worst} near ({:.3}, {:.3}, {:.3})",
            at.x, at.y, at.z
        ),
    ));
    (out, volume)
}

/// Directed edges of `mesh` not matched by exactly one opposite edge (with
/// no twin of their own): 0 for a closed, consistently oriented mesh.
/// Outgoing edges per vertex in CSR form make this O(E).
fn unmatched_edges(mesh: &Mesh) -> usize {
    let nv = mesh.positions.len();
    let mut start = vec![0u32; nv + 1];
    for t in &mesh.triangles {
        for &a in t {
            start[a as usize + 1] += 1;
        }
    }
    for v in 0..nv {
        start[v + 1] += start[v];
    }
    let mut fill = start.clone();
    let mut out_edges = vec![0u32; 3 * mesh.triangles.len()];
    for t in &mesh.triangles {
        for e in 0..3 {
            let a = t[e] as usize;
            out_edges[fill[a] as usize] = t[(e + 1) % 3];
            fill[a] += 1;
        }
    }
    let out_of = |a: u32| &out_edges[start[a as usize] as usize..start[a as usize + 1] as usize];
    (0..nv as u32)
        .into_par_iter()
        .map(|a| {
            out_of(a)
                .iter()
                .filter(|&&b| {
                    out_of(a).iter().filter(|&&x| x == b).count() != 1
                        || out_of(b).iter().filter(|&&x| x == a).count() != 1
                })
                .count()
        })
        .sum()
}

/// Connected shells of `mesh` (by shared vertices) and the vertices that
/// some triangle uses.
fn shells_and_used_vertices(mesh: &Mesh) -> (usize, usize) {
    let mut parent: Vec<u32> = (0..mesh.positions.len() as u32).collect();
    fn find(p: &mut [u32], mut x: u32) -> u32 {
        while p[x as usize] != x {
            p[x as usize] = p[p[x as usize] as usize];
            x = p[x as usize];
        }
        x
    }
    for t in &mesh.triangles {
        for e in 1..3 {
            let (a, b) = (find(&mut parent, t[0]), find(&mut parent, t[e]));
            if a != b {
                parent[a as usize] = b;
            }
        }
    }
    let mut used = vec![false; mesh.positions.len()];
    for t in &mesh.triangles {
        for &v in t {
            used[v as usize] = true;
        }
    }
    let vertices = used.iter().filter(|&&u| u).count();
    let shells = (0..mesh.positions.len() as u32)
        .filter(|&v| used[v as usize] && find(&mut parent, v) == v)
        .count();
    (shells, vertices)
}

/// The smallest altitude (mm) of the triangle `[a, b, c]`: twice its area
/// over its longest edge; 0 for a collapsed one.
pub fn triangle_altitude([a, b, c]: [DVec3; 3]) -> f64 {
    let longest = (b - a).length().max((c - b).length()).max((a - c).length());
    if longest > 0.0 {
        (b - a).cross(c - a).length() / longest
    } else {
        0.0
    }
}

/// The smallest altitude of a triangle (mm; 0 for a collapsed one) and the
/// first triangle that has it.
fn smallest_altitude(mesh: &Mesh) -> (f64, usize) {
    mesh.triangles
        .par_iter()
        .enumerate()
        .map(|(i, t)| (triangle_altitude(t.map(|i| mesh.positions[i as usize])), i))
        .reduce(
            || (f64::INFINITY, 0),
            |x, y| {
                if y.0 < x.0 || (y.0 == x.0 && y.1 < x.1) {
                    y
                } else {
                    x
                }
            },
        )
}

/// What rounding `mesh` to f32 (as an STL stores it) breaks: triangles
/// that collapse or flip, and vertices that land on another vertex's f32
/// point (a reader that welds an STL by position, as trimesh and slicers
/// do, would join them).
fn f32_rounding_faults(mesh: &Mesh) -> (usize, usize) {
    let flipped = mesh
        .triangles
        .par_iter()
        .filter(|t| {
            let [a, b, c] = t.map(|i| mesh.positions[i as usize]);
            let [fa, fb, fc] = [a, b, c].map(|p| p.as_vec3().as_dvec3());
            (b - a).cross(c - a).dot((fb - fa).cross(fc - fa)) <= 0.0
        })
        .count();
    // vertices beyond the first at each f32 point: sorted, the equal keys
    // are neighbours (a parallel sort; hashing 300 k points took longer)
    let mut keys: Vec<[u32; 3]> = mesh
        .positions
        .par_iter()
        .map(|p| p.as_vec3().to_array().map(|c| (c + 0.0).to_bits()))
        .collect();
    keys.par_sort_unstable();
    let merged = keys.windows(2).filter(|w| w[0] == w[1]).count();
    (flipped, merged)
}

/// A mesh that passed every solid check. Only [`SolidMesh::validate`] and
/// [`CheckedMesh::solid`] (from the checks it ran itself) make one, so a
/// writer that takes it cannot write an unchecked mesh, and no mesh is
/// checked twice.
#[derive(Clone, Copy, Debug)]
pub struct SolidMesh<'a> {
    mesh: &'a Mesh,
    /// Measured by the `positive-volume` check.
    volume: f64,
}

impl<'a> SolidMesh<'a> {
    /// Runs [`solid_checks`]; the mesh is solid only if all passed.
    pub fn validate(mesh: &'a Mesh) -> (Vec<CheckResult>, Option<SolidMesh<'a>>) {
        Self::validate_for(mesh, SolidSpec::DEVICE)
    }

    /// [`SolidMesh::validate`] against `spec`.
    pub fn validate_for(
        mesh: &'a Mesh,
        spec: SolidSpec,
    ) -> (Vec<CheckResult>, Option<SolidMesh<'a>>) {
        let (checks, volume) = solid_checks_and_volume(mesh, spec);
        let ok = checks.iter().all(|c| c.passed);
        (checks, ok.then_some(SolidMesh { mesh, volume }))
    }

    pub fn mesh(&self) -> &'a Mesh {
        self.mesh
    }

    /// The solid's volume (mm³), as its checks measured it.
    pub fn volume(&self) -> f64 {
        self.volume
    }
}

/// A mesh that owns its solid checks: [`SolidMesh`] for a mesh that must
/// outlive the place it was checked in (a mold's halves are checked as
/// they are cut and written at the end). Only [`CheckedMesh::check`] makes
/// one, and the mesh cannot be changed after.
#[derive(Clone, Debug)]
pub struct CheckedMesh {
    mesh: Mesh,
    checks: Vec<CheckResult>,
    volume: f64,
}

impl CheckedMesh {
    /// Runs [`solid_checks_for`] on `mesh` against `spec`.
    pub fn check(mesh: Mesh, spec: SolidSpec) -> Self {
        let (checks, volume) = solid_checks_and_volume(&mesh, spec);
        CheckedMesh {
            mesh,
            checks,
            volume,
        }
    }

    pub fn mesh(&self) -> &Mesh {
        &self.mesh
    }

    /// The checks, passed or failed.
    pub fn checks(&self) -> &[CheckResult] {
        &self.checks
    }

    /// The mesh as a [`SolidMesh`] if every check passed; not checked again.
    pub fn solid(&self) -> Option<SolidMesh<'_>> {
        self.checks.iter().all(|c| c.passed).then_some(SolidMesh {
            mesh: &self.mesh,
            volume: self.volume,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DVec3;

    fn tetra() -> Mesh {
        Mesh {
            positions: vec![DVec3::ZERO, DVec3::X, DVec3::Y, DVec3::Z],
            triangles: vec![[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]],
        }
    }

    #[test]
    fn tetrahedron_passes() {
        for c in solid_checks(&tetra()) {
            assert!(c.passed, "{c:?}");
        }
        assert!((tetra().volume() - 1.0 / 6.0).abs() < 1e-15);
        let m = tetra();
        let (_, solid) = SolidMesh::validate(&m);
        assert_eq!(solid.unwrap().volume(), m.volume());
    }

    #[test]
    fn flipped_or_open_meshes_fail() {
        let mut m = tetra();
        m.triangles[0] = [0, 1, 2];
        let failed: Vec<_> = solid_checks(&m)
            .into_iter()
            .filter(|c| !c.passed)
            .map(|c| c.name)
            .collect();
        assert!(failed.contains(&"closed-oriented"), "{failed:?}");
        let mut m = tetra();
        m.triangles.pop();
        assert!(solid_checks(&m)
            .iter()
            .any(|c| c.name == "closed-oriented" && !c.passed));
        let mut m = tetra();
        m.positions[3] = DVec3::new(0.5, 0.5, 0.0);
        assert!(solid_checks(&m)
            .iter()
            .any(|c| c.name == "no-degenerate-triangles" && !c.passed));
    }

    /// Vertices distinct in f64 but one point in f32 are counted once per
    /// extra vertex; −0 and +0 are one point.
    #[test]
    fn vertices_that_meet_in_f32_are_counted() {
        let mut m = tetra();
        let distinct = |m: &Mesh| {
            solid_checks_for(m, SolidSpec::boolean_result(0))
                .into_iter()
                .find(|c| c.name == "f32-distinct-vertices")
                .unwrap()
                .value
        };
        assert_eq!(distinct(&m), 0.0);
        m.positions.extend([
            DVec3::X * (1.0 + 1e-12),
            DVec3::new(-0.0, 0.0, 0.0),
            DVec3::Z * (1.0 - 1e-13),
            DVec3::Y * 0.5,
        ]);
        assert_eq!(distinct(&m), 3.0);
    }
}

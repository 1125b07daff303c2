//! The independent second path from the exact model to a mesh:
//! truck-meshalgo tessellates the B-rep, a spatial hash welds it, and the
//! result is compared with the direct mesh (volume and Hausdorff distance).

use crate::error::BrepError;
use glam::DVec3;
use moirecast_kernel::check::CheckResult;
use moirecast_kernel::measure::closest_on_triangle;
use moirecast_kernel::Mesh;
use rayon::prelude::*;
use std::collections::HashMap;
use truck_meshalgo::prelude::{MeshedShape, RobustMeshableShape};
use truck_modeling::Solid;

/// Distance (mm) under which tessellation vertices are the same point.
/// truck-meshalgo puts an edge's polyline points into both faces it
/// bounds, evaluated per face, so they differ by round-off; 1 nm is far
/// above that and far below any tolerance.
pub const WELD_MM: f64 = 1e-6;

/// Tessellates `solid` with truck-meshalgo (`robust_triangulation`, which
/// projects edge points onto each face's surface) at `tolerance` (mm),
/// welds the faces with [`weld`], and drops the triangles welding
/// collapsed. Fails if a face could not be tessellated.
pub fn tessellate(solid: &Solid, tolerance: f64) -> Result<Mesh, BrepError> {
    let meshed = solid.robust_triangulation(tolerance);
    let failed = meshed.boundaries()[0]
        .face_iter()
        .filter(|f| f.surface().is_none())
        .count();
    if failed > 0 {
        return Err(BrepError::Tessellation(format!(
            "{failed} faces could not be tessellated"
        )));
    }
    let poly = meshed.to_polygon();
    let positions: Vec<DVec3> = poly
        .positions()
        .iter()
        .map(|p| DVec3::new(p.x, p.y, p.z))
        .collect();
    let triangles: Vec<[u32; 3]> = poly
        .faces()
        .triangle_iter()
        .map(|t| [t[0].pos as u32, t[1].pos as u32, t[2].pos as u32])
        .collect();
    Ok(weld(
        &Mesh {
            positions,
            triangles,
        },
        WELD_MM,
    ))
}

/// Merges vertices closer than `distance` (the first one seen stays, so the
/// result is deterministic) and drops triangles that lose a corner.
pub fn weld(mesh: &Mesh, distance: f64) -> Mesh {
    let cell = |p: DVec3| (p / distance).floor().as_i64vec3();
    let mut grid: HashMap<glam::I64Vec3, Vec<u32>> = HashMap::new();
    let mut positions: Vec<DVec3> = Vec::new();
    let remap: Vec<u32> = mesh
        .positions
        .iter()
        .map(|&p| {
            let c = cell(p);
            for dx in -1..=1 {
                for dy in -1..=1 {
                    for dz in -1..=1 {
                        if let Some(list) = grid.get(&(c + glam::I64Vec3::new(dx, dy, dz))) {
                            if let Some(&i) = list
                                .iter()
                                .find(|&&i| (positions[i as usize] - p).length() < distance)
                            {
                                return i;
                            }
                        }
                    }
                }
            }
            let i = positions.len() as u32;
            positions.push(p);
            grid.entry(c).or_default().push(i);
            i
        })
        .collect();
    let mut triangles: Vec<[u32; 3]> = mesh
        .triangles
        .iter()
        .map(|t| t.map(|v| remap[v as usize]))
        .filter(|t| t[0] != t[1] && t[1] != t[2] && t[0] != t[2])
        .collect();
    // keep only the vertices triangles use, in order of first use
    let mut renumber = vec![u32::MAX; positions.len()];
    let mut used = Vec::new();
    for t in &mut triangles {
        for v in t.iter_mut() {
            if renumber[*v as usize] == u32::MAX {
                renumber[*v as usize] = used.len() as u32;
                used.push(positions[*v as usize]);
            }
            *v = renumber[*v as usize];
        }
    }
    Mesh {
        positions: used,
        triangles,
    }
}

/// Triangles of a mesh bucketed on a dense uniform grid (compressed rows),
/// for closest-point queries.
pub(crate) struct TriangleGrid<'a> {
    mesh: &'a Mesh,
    lo: DVec3,
    cell: f64,
    dims: [usize; 3],
    /// Triangles of cell c: `items[offsets[c]..offsets[c + 1]]`.
    offsets: Vec<u32>,
    items: Vec<u32>,
}

/// About this many triangles share a cell (they are mostly much smaller).
const TRIANGLES_PER_CELL: f64 = 8.0;
/// Cap on the number of cells of the dense grid.
const MAX_CELLS: f64 = 3.0e7;

impl<'a> TriangleGrid<'a> {
    pub(crate) fn new(mesh: &'a Mesh) -> Self {
        let (lo, hi) = mesh.bounds();
        let size = (hi - lo).max(DVec3::splat(1e-9));
        let cell = (TRIANGLES_PER_CELL * mesh.area() / mesh.triangles.len().max(1) as f64)
            .sqrt()
            .max((size.x * size.y * size.z / MAX_CELLS).cbrt());
        let dims = ((size / cell).floor().as_uvec3() + glam::UVec3::ONE)
            .to_array()
            .map(|d| d as usize);
        let cells_of = |t: &[u32; 3]| {
            let [a, b, c] = t.map(|v| mesh.positions[v as usize]);
            let i0 = ((a.min(b).min(c) - lo) / cell).floor().as_uvec3();
            let i1 = ((a.max(b).max(c) - lo) / cell).floor().as_uvec3();
            (i0, i1)
        };
        let index =
            |x: u32, y: u32, z: u32| (x as usize * dims[1] + y as usize) * dims[2] + z as usize;
        let mut counts = vec![0u32; dims[0] * dims[1] * dims[2] + 1];
        for t in &mesh.triangles {
            let (i0, i1) = cells_of(t);
            for x in i0.x..=i1.x {
                for y in i0.y..=i1.y {
                    for z in i0.z..=i1.z {
                        counts[index(x, y, z) + 1] += 1;
                    }
                }
            }
        }
        for c in 1..counts.len() {
            counts[c] += counts[c - 1];
        }
        let offsets = counts.clone();
        let mut items = vec![0u32; *offsets.last().unwrap() as usize];
        for (ti, t) in mesh.triangles.iter().enumerate() {
            let (i0, i1) = cells_of(t);
            for x in i0.x..=i1.x {
                for y in i0.y..=i1.y {
                    for z in i0.z..=i1.z {
                        let c = index(x, y, z);
                        items[counts[c] as usize] = ti as u32;
                        counts[c] += 1;
                    }
                }
            }
        }
        TriangleGrid {
            mesh,
            lo,
            cell,
            dims,
            offsets,
            items,
        }
    }

    /// Distance from `p` to the mesh: rings of cells outwards, skipping
    /// cells farther than the best distance found so far.
    pub(crate) fn distance(&self, p: DVec3) -> f64 {
        let rel = (p - self.lo) / self.cell;
        let c = rel.floor().as_i64vec3();
        let dims = self.dims.map(|d| d as i64);
        let mut best = f64::INFINITY;
        let max_ring = dims.iter().copied().max().unwrap_or(1) + 1;
        for ring in 0..=max_ring {
            if best <= (ring as f64 - 1.0).max(0.0) * self.cell {
                break;
            }
            for x in -ring..=ring {
                for y in -ring..=ring {
                    for z in -ring..=ring {
                        if x.abs().max(y.abs()).max(z.abs()) != ring {
                            continue;
                        }
                        let q = c + glam::I64Vec3::new(x, y, z);
                        if q.cmplt(glam::I64Vec3::ZERO).any()
                            || q.x >= dims[0]
                            || q.y >= dims[1]
                            || q.z >= dims[2]
                        {
                            continue;
                        }
                        // distance from p to the cell's box
                        let box_lo = q.as_dvec3();
                        let gap = (box_lo - rel)
                            .max(rel - (box_lo + DVec3::ONE))
                            .max(DVec3::ZERO);
                        if gap.length() * self.cell >= best {
                            continue;
                        }
                        let ci = (q.x as usize * self.dims[1] + q.y as usize) * self.dims[2]
                            + q.z as usize;
                        for &t in
                            &self.items[self.offsets[ci] as usize..self.offsets[ci + 1] as usize]
                        {
                            let [a, b, cc] = self.mesh.triangles[t as usize]
                                .map(|v| self.mesh.positions[v as usize]);
                            best = best.min((p - closest_on_triangle(p, a, b, cc)).length());
                        }
                    }
                }
            }
        }
        best
    }
}

/// The largest distance from the vertices and triangle centroids of `from`
/// to the mesh `to`, and where it is.
pub fn one_sided_distance(from: &Mesh, to: &Mesh) -> (f64, DVec3) {
    let centroids = from
        .triangles
        .iter()
        .map(|t| t.map(|v| from.positions[v as usize]))
        .map(|[a, b, c]| (a + b + c) / 3.0);
    let samples: Vec<DVec3> = from.positions.iter().copied().chain(centroids).collect();
    farthest_from(&samples, to)
}

/// The largest distance from the points `samples` to the mesh `to`, and
/// which point it is (the least in x, y, z among equals, so the answer is
/// deterministic).
pub fn farthest_from(samples: &[DVec3], to: &Mesh) -> (f64, DVec3) {
    let grid = TriangleGrid::new(to);
    samples.par_iter().map(|&p| (grid.distance(p), p)).reduce(
        || (0.0, DVec3::ZERO),
        |a, b| {
            if b.0 > a.0 || (b.0 == a.0 && b.1.to_array() < a.1.to_array()) {
                b
            } else {
                a
            }
        },
    )
}

/// How the B-rep's tessellation compares with the direct mesh.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct CrossCheck {
    pub brep_triangles: usize,
    pub brep_volume_mm3: f64,
    pub direct_volume_mm3: f64,
    /// |V_brep − V_direct| / V_direct.
    pub volume_rel_diff: f64,
    /// Symmetric Hausdorff distance (mm) sampled at vertices and centroids.
    pub hausdorff_mm: f64,
    pub hausdorff_at: [f64; 3],
}

/// Compares a B-rep tessellation with the direct mesh.
pub fn compare(brep_mesh: &Mesh, direct: &Mesh) -> CrossCheck {
    let ((ab, pa), (ba, pb)) = rayon::join(
        || one_sided_distance(brep_mesh, direct),
        || one_sided_distance(direct, brep_mesh),
    );
    let (h, at) = if ab >= ba { (ab, pa) } else { (ba, pb) };
    let (vb, vd) = (brep_mesh.volume(), direct.volume());
    CrossCheck {
        brep_triangles: brep_mesh.triangles.len(),
        brep_volume_mm3: vb,
        direct_volume_mm3: vd,
        volume_rel_diff: (vb - vd).abs() / vd.abs(),
        hausdorff_mm: h,
        hausdorff_at: at.to_array(),
    }
}

/// The cross-check's verdicts, with their evidence:
/// - `brep-mesh-solid`: the welded tessellation passes every solid check;
/// - `brep-mesh-hausdorff`: it lies within 2 × tolerance of the direct mesh
///   (each is within the tolerance of the exact surface);
/// - `brep-mesh-volume`: the volumes differ by at most lens area ×
///   tolerance, the most two meshes inscribed in the lenses within the
///   tolerance can differ (their chordal deficits, measured 6.6e-4 of the
///   volume at 2 µm on a 1.7 mm device, are not equal).
pub fn verdicts(
    brep_mesh: &Mesh,
    cross: &CrossCheck,
    tolerance: f64,
    lens_area_mm2: f64,
) -> Vec<CheckResult> {
    let failed: Vec<String> = moirecast_kernel::check::solid_checks(brep_mesh)
        .into_iter()
        .filter(|c| !c.passed)
        .map(|c| format!("{} = {} {} ({})", c.name, c.value, c.unit, c.detail))
        .collect();
    let at = cross.hausdorff_at;
    vec![
        CheckResult::at_most(
            "brep-mesh-solid",
            failed.len() as f64,
            0.0,
            "failed checks",
            if failed.is_empty() {
                format!("{} triangles, every solid check passed", cross.brep_triangles)
            } else {
                failed.join("; ")
            },
        ),
        CheckResult::at_most(
            "brep-mesh-hausdorff",
            cross.hausdorff_mm,
            2.0 * tolerance,
            "mm",
            format!(
                "vertices and centroids of each mesh against the other; worst near ({:.3}, {:.3}, {:.3})",
                at[0], at[1], at[2]
            ),
        ),
        CheckResult::at_most(
            "brep-mesh-volume",
            cross.volume_rel_diff,
            lens_area_mm2 * tolerance / cross.direct_volume_mm3.abs(),
            "relative",
            format!(
                "{:.4} mm³ against the direct mesh's {:.4} mm³; limit: lens area {:.1} mm² × tolerance",
                cross.brep_volume_mm3, cross.direct_volume_mm3, lens_area_mm2
            ),
        ),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;
    use moirecast_kernel::check::SolidMesh;
    use moirecast_kernel::mesher::mesh_device;
    use moirecast_kernel::progress::Silent;
    use moirecast_kernel::{Design, DesignParams, PitchSurface};

    fn cube(offset: DVec3) -> Mesh {
        let positions = (0..8)
            .map(|i| {
                DVec3::new((i & 1) as f64, ((i >> 1) & 1) as f64, ((i >> 2) & 1) as f64) + offset
            })
            .collect();
        let triangles = vec![
            [0, 2, 1],
            [1, 2, 3],
            [4, 5, 6],
            [5, 7, 6],
            [0, 1, 4],
            [1, 5, 4],
            [2, 6, 3],
            [3, 6, 7],
            [0, 4, 2],
            [2, 4, 6],
            [1, 3, 5],
            [3, 7, 5],
        ];
        Mesh {
            positions,
            triangles,
        }
    }

    #[test]
    fn weld_merges_near_points_and_drops_collapsed_triangles() {
        let mut m = cube(DVec3::ZERO);
        // split vertex 7 into a copy 1e-9 away, used by two triangles
        m.positions.push(m.positions[7] + DVec3::splat(1e-9));
        m.triangles[7] = [3, 6, 8];
        m.triangles.push([7, 8, 8]); // collapses
        m.positions.push(DVec3::splat(5.0)); // unused
        let w = weld(&m, WELD_MM);
        assert_eq!(w.positions.len(), 8);
        assert_eq!(w.triangles.len(), 12);
        assert!((w.volume() - 1.0).abs() < 1e-12);
        assert!(SolidMesh::validate(&w).1.is_some());
    }

    #[test]
    fn one_sided_distance_of_a_shifted_cube() {
        let (a, b) = (cube(DVec3::ZERO), cube(DVec3::new(0.0, 0.0, 0.25)));
        let (d, _) = one_sided_distance(&a, &b);
        assert!((d - 0.25).abs() < 1e-12, "{d}");
        let c = compare(&a, &a);
        assert!(c.hausdorff_mm < 1e-15 && c.volume_rel_diff == 0.0, "{c:?}");
    }

    /// A device without trimmed faces (a plane, no base shift: every edge
    /// is an iso-line of its faces) is the case truck-meshalgo tessellates
    /// well: closed after welding, within 2 × tolerance of the direct mesh.
    #[test]
    fn meshalgo_agrees_with_the_direct_mesh_on_an_untrimmed_device() {
        let mut p = DesignParams::with_defaults(PitchSurface::Plane, 10.0, 8.0, 0.5);
        p.base.levels = 0.0;
        let design = Design::new(p).unwrap();
        let dm = mesh_device(&design, &Silent).unwrap();
        let brep = crate::build_brep(&design, &dm).unwrap();
        let tol = design.tolerance.mm();
        let mesh = tessellate(&brep.solid, tol).unwrap();
        let (checks, solid) = SolidMesh::validate(&mesh);
        assert!(
            solid.is_some(),
            "{:?}",
            checks.iter().filter(|c| !c.passed).collect::<Vec<_>>()
        );
        let c = compare(&mesh, &dm.mesh);
        assert!(c.hausdorff_mm <= 2.0 * tol, "{c:?}");
        // Both meshes are inscribed in the lenses; their volumes differ by
        // their chordal deficits, each below lens area × tolerance.
        let lens_area = 2.0 * 10.0 * 8.0 / 30f64.to_radians().cos();
        assert!(
            (c.brep_volume_mm3 - c.direct_volume_mm3).abs() <= lens_area * tol,
            "{c:?}"
        );
    }
}

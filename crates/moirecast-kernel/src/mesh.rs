//! Indexed triangle meshes and their measures.

use glam::DVec3;

/// An indexed triangle mesh. Triangles are counter-clockwise seen from
/// outside (outward normals).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Mesh {
    pub positions: Vec<DVec3>,
    pub triangles: Vec<[u32; 3]>,
}

impl Mesh {
    /// Signed volume by the divergence theorem (mm³), about the bounding-box
    /// centre to keep round-off small.
    pub fn volume(&self) -> f64 {
        use rayon::prelude::*;
        let (lo, hi) = self.bounds();
        let c = 0.5 * (lo + hi);
        // Fixed-size blocks summed in parallel, then in order: the result does
        // not depend on the number of threads.
        let blocks: Vec<f64> = self
            .triangles
            .par_chunks(4096)
            .map(|block| {
                block
                    .iter()
                    .map(|t| {
                        let [a, b, d] = t.map(|i| self.positions[i as usize] - c);
                        a.dot(b.cross(d))
                    })
                    .sum::<f64>()
            })
            .collect();
        blocks.iter().sum::<f64>() / 6.0
    }

    /// Total area (mm²).
    pub fn area(&self) -> f64 {
        self.triangles.iter().map(|t| self.triangle_area(t)).sum()
    }

    pub fn triangle_area(&self, t: &[u32; 3]) -> f64 {
        let [a, b, c] = t.map(|i| self.positions[i as usize]);
        0.5 * (b - a).cross(c - a).length()
    }

    /// Axis-aligned bounding box (min, max).
    pub fn bounds(&self) -> (DVec3, DVec3) {
        self.positions.iter().fold(
            (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
            |(lo, hi), p| (lo.min(*p), hi.max(*p)),
        )
    }
}

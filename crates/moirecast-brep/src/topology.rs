//! The B-rep's topology, read off the mesher's face partition.
//!
//! The mesher tags every triangle with the face it belongs to (a lens or a
//! wall) and shares every crease, trim and wall vertex by index. So the
//! connected pieces of one patch are the B-rep's faces, each piece's
//! boundary loops are its wires, and a loop splits into edges where the
//! piece on the other side changes. A base lens cut in two by a wall gives
//! two faces; the pieces on both sides of an edge see the same run of mesh
//! vertices in opposite directions, which is how edges are shared.

use crate::error::BrepError;
use moirecast_kernel::mesher::Patch;
use moirecast_kernel::Mesh;
use rayon::prelude::*;

/// One face of the B-rep: a connected piece of one patch (by default the
/// device mesher's [`Patch`]; a printed body's faces use their own labels).
#[derive(Debug)]
pub struct Piece<P = Patch> {
    pub patch: P,
    /// One triangle of the piece (for its orientation).
    pub triangle: u32,
    /// Boundary loops, counter-clockwise seen from outside, as runs.
    pub loops: Vec<Vec<Run>>,
}

/// A maximal stretch of a boundary loop along one neighbouring piece.
#[derive(Debug, Clone)]
pub struct Run {
    pub neighbour: usize,
    /// Mesh vertices from the run's start to its end.
    pub vertices: Vec<u32>,
}

impl Run {
    /// A key shared by the two sides of the edge: the smallest mesh edge of
    /// the run as an unordered pair.
    pub fn key(&self) -> (u32, u32) {
        self.vertices
            .windows(2)
            .map(|w| (w[0].min(w[1]), w[0].max(w[1])))
            .min()
            .expect("a run has at least one mesh edge")
    }
}

fn find(parent: &mut [u32], mut x: u32) -> u32 {
    while parent[x as usize] != x {
        let p = parent[x as usize];
        parent[x as usize] = parent[p as usize];
        x = p;
    }
    x
}

/// The faces of a closed mesh's B-rep whose triangles lie on `patches`
/// (one label per triangle), in a deterministic order (by their first
/// triangle).
pub fn pieces<P: Copy + Eq + Send + Sync>(
    mesh: &Mesh,
    patches: &[P],
) -> Result<Vec<Piece<P>>, BrepError> {
    let tris = &mesh.triangles;
    let half = |h: usize| -> (u32, u32) {
        let t = tris[h / 3];
        (t[h % 3], t[(h + 1) % 3])
    };
    // twin[h]: the opposite half-edge, looked up among the half-edges that
    // leave h's end vertex (bucketed by start vertex: linear time).
    let vertices = mesh.positions.len();
    let mut offsets = vec![0u32; vertices + 1];
    for t in tris {
        for &v in t {
            offsets[v as usize + 1] += 1;
        }
    }
    for v in 0..vertices {
        offsets[v + 1] += offsets[v];
    }
    let mut fill = offsets.clone();
    // (end vertex, half-edge) of the half-edges leaving each vertex
    let mut leaving = vec![(0u32, 0u32); tris.len() * 3];
    for h in 0..tris.len() * 3 {
        let (a, b) = half(h);
        leaving[fill[a as usize] as usize] = (b, h as u32);
        fill[a as usize] += 1;
    }
    let twin: Vec<u32> = (0..tris.len() * 3)
        .into_par_iter()
        .map(|h| {
            let (a, b) = half(h);
            let mut found = leaving[offsets[b as usize] as usize..offsets[b as usize + 1] as usize]
                .iter()
                .filter(|&&(end, _)| end == a);
            match (found.next(), found.next()) {
                (Some(&(_, o)), None) => o,
                _ => u32::MAX,
            }
        })
        .collect();
    if let Some(h) = twin.iter().position(|&o| o == u32::MAX) {
        return Err(BrepError::Topology(format!(
            "mesh edge {:?} is not shared by exactly two triangles in opposite directions",
            half(h)
        )));
    }
    // pieces: triangles joined across edges inside one patch
    let mut parent: Vec<u32> = (0..tris.len() as u32).collect();
    for h in 0..tris.len() * 3 {
        let t2 = twin[h] as usize / 3;
        // each edge once, from its lower triangle
        if t2 > h / 3 && patches[h / 3] == patches[t2] {
            let (a, b) = (
                find(&mut parent, (h / 3) as u32),
                find(&mut parent, t2 as u32),
            );
            if a != b {
                parent[a.max(b) as usize] = a.min(b);
            }
        }
    }
    // a root is its piece's first triangle (roots are the smallest index)
    let mut piece_of = vec![0usize; tris.len()];
    let mut first_triangle = Vec::new();
    for t in 0..tris.len() {
        let root = find(&mut parent, t as u32) as usize;
        if root == t {
            piece_of[t] = first_triangle.len();
            first_triangle.push(t as u32);
        } else {
            piece_of[t] = piece_of[root];
        }
    }
    let is_boundary = |h: usize| piece_of[h / 3] != piece_of[twin[h] as usize / 3];
    // next boundary half-edge: turn about the end vertex inside the piece
    let next_of = |h: usize| -> usize {
        let mut e = (h / 3) * 3 + (h % 3 + 1) % 3;
        while !is_boundary(e) {
            let o = twin[e] as usize;
            e = (o / 3) * 3 + (o % 3 + 1) % 3;
        }
        e
    };
    let mut loops_of: Vec<Vec<Vec<Run>>> = vec![Vec::new(); first_triangle.len()];
    let mut seen = vec![false; tris.len() * 3];
    let boundary: Vec<usize> = (0..tris.len() * 3)
        .into_par_iter()
        .filter(|&h| is_boundary(h))
        .collect();
    for h0 in boundary {
        if seen[h0] {
            continue;
        }
        let mut cycle = Vec::new();
        let mut h = h0;
        while !seen[h] {
            seen[h] = true;
            cycle.push(h);
            h = next_of(h);
        }
        if h != h0 {
            return Err(BrepError::Topology(format!(
                "boundary of the piece of triangle {} does not close",
                h0 / 3
            )));
        }
        let neighbour = |h: usize| piece_of[twin[h] as usize / 3];
        let Some(start) = (0..cycle.len()).find(|&i| {
            neighbour(cycle[i]) != neighbour(cycle[(i + cycle.len() - 1) % cycle.len()])
        }) else {
            return Err(BrepError::Topology(format!(
                "a boundary loop of the piece of triangle {} has one neighbour all round (no vertex to start an edge)",
                h0 / 3
            )));
        };
        cycle.rotate_left(start);
        let mut runs: Vec<Run> = Vec::new();
        for &h in &cycle {
            let (a, b) = half(h);
            match runs.last_mut() {
                Some(r) if r.neighbour == neighbour(h) => r.vertices.push(b),
                _ => runs.push(Run {
                    neighbour: neighbour(h),
                    vertices: vec![a, b],
                }),
            }
        }
        loops_of[piece_of[h0 / 3]].push(runs);
    }
    Ok(first_triangle
        .into_iter()
        .zip(loops_of)
        .map(|(t, loops)| Piece {
            patch: patches[t as usize],
            triangle: t,
            loops,
        })
        .collect())
}

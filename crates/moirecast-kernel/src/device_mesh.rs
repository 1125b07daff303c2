//! The device mesh and the provenance of every vertex and triangle: which
//! exact surface a vertex was computed on (and at which parameters), and
//! which face a triangle belongs to. [`crate::mesher`] builds it;
//! [`crate::measure`], [`crate::printed`] and the B-rep read it.

use crate::mesh::Mesh;
use crate::model::LensRef;
use glam::{DVec2, DVec3};
use std::collections::BTreeMap;

/// Where a vertex comes from: its exact surface and parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum VertexOrigin {
    /// On revealer crease `i` (between lenses i−1 and i) at station v.
    RevealerCrease { i: i64, v: f64 },
    /// Inside revealer lens `i` at arc parameter t, station v.
    RevealerLens { i: i64, t: f64, v: f64 },
    /// On base crease `k` at station v.
    BaseCrease { k: i64, v: f64 },
    /// Inside base lens `k` (including where an x-wall cuts it).
    BaseLens { k: i64, t: f64, v: f64 },
}

impl VertexOrigin {
    /// Whether the vertex is on the revealer (the device's top).
    pub fn is_revealer(&self) -> bool {
        matches!(
            self,
            VertexOrigin::RevealerCrease { .. } | VertexOrigin::RevealerLens { .. }
        )
    }

    /// The (t, v) parameters of this vertex on `lens`, if it lies on it.
    pub fn params_on(&self, lens: LensRef) -> Option<DVec2> {
        match (*self, lens) {
            (VertexOrigin::RevealerCrease { i, v }, LensRef::Revealer(l))
            | (VertexOrigin::BaseCrease { k: i, v }, LensRef::Base(l)) => {
                if i == l {
                    Some(DVec2::new(0.0, v))
                } else if i == l + 1 {
                    Some(DVec2::new(1.0, v))
                } else {
                    None
                }
            }
            (VertexOrigin::RevealerLens { i, t, v }, LensRef::Revealer(l))
            | (VertexOrigin::BaseLens { k: i, t, v }, LensRef::Base(l)) => {
                (i == l).then_some(DVec2::new(t, v))
            }
            _ => None,
        }
    }
}

/// A vertical side wall of the device (METHOD §5.3).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Side {
    /// x = outline_x.0
    Left,
    /// x = outline_x.1
    Right,
    /// y = −H/2
    Front,
    /// y = +H/2
    Back,
}

/// The face a triangle belongs to.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Patch {
    Lens(LensRef),
    Wall(Side),
}

/// Counts that describe a device mesh.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct MeshStats {
    pub triangles: usize,
    pub vertices: usize,
    pub revealer_triangles: usize,
    pub base_triangles: usize,
    pub wall_triangles: usize,
    pub revealer_rows: usize,
    pub base_rows: usize,
    /// Rows placed where a base crease crosses an x-wall.
    pub crossing_rows: usize,
    pub revealer_columns: (usize, usize),
    pub base_columns: (usize, usize),
    /// Triangles a uniform grid needs for the same tolerance: the finest
    /// column count on every lens and the finest row spacing everywhere.
    pub uniform_triangles: usize,
    /// What the budget estimated, before any vertex, a mold run of the
    /// design holds at its peak ([`crate::MeshBudget::estimated_bytes`]).
    pub estimated_peak_bytes: f64,
}

/// The device mesh with the provenance of every vertex and triangle.
#[derive(Clone, Debug)]
pub struct DeviceMesh {
    pub mesh: Mesh,
    pub origins: Vec<VertexOrigin>,
    pub patches: Vec<Patch>,
    pub stats: MeshStats,
    /// Revealer row stations (the first and last rows are solved onto y = ±H/2).
    pub revealer_rows: Vec<f64>,
    /// Columns per revealer lens.
    pub revealer_columns: Vec<usize>,
    /// Columns per base lens (lenses entirely outside the outline included).
    pub base_columns: BTreeMap<i64, usize>,
    /// Columns of the revealer lenses before lens i (i = 0..=n): where lens
    /// i starts in a row, and the row's length less one.
    revealer_starts: Vec<usize>,
}

impl DeviceMesh {
    /// A mesh with its vertices and no triangles yet: revealer rows first
    /// (`revealer_rows.len()` rows of one vertex per column and one more),
    /// then the base.
    pub(crate) fn with_vertices(
        positions: Vec<DVec3>,
        origins: Vec<VertexOrigin>,
        revealer_rows: Vec<f64>,
        revealer_columns: Vec<usize>,
        base_columns: BTreeMap<i64, usize>,
    ) -> Self {
        let revealer_starts = std::iter::once(0)
            .chain(revealer_columns.iter().scan(0, |sum, &c| {
                *sum += c;
                Some(*sum)
            }))
            .collect();
        DeviceMesh {
            mesh: Mesh {
                positions,
                triangles: Vec::new(),
            },
            origins,
            patches: Vec::new(),
            stats: MeshStats::default(),
            revealer_rows,
            revealer_columns,
            base_columns,
            revealer_starts,
        }
    }

    /// Index of revealer vertex (row r, lens i, column j ∈ 0..=n_i).
    pub fn revealer_vertex(&self, r: usize, i: usize, j: usize) -> u32 {
        (r * self.revealer_row_len() + self.revealer_starts[i] + j) as u32
    }

    pub(crate) fn revealer_row_len(&self) -> usize {
        self.revealer_starts
            .last()
            .expect("one start per lens and one past")
            + 1
    }
}

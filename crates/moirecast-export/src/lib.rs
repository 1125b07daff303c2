//! Output files: binary STL, 3MF and an all-or-nothing output directory.
//!
//! Nothing is written until every file of a run has been encoded and every
//! check has passed. A run's files then replace its folder whole
//! ([`OutputSet::commit_run`], [`run_folder`]); single files (a saved spec)
//! go to a temporary name and are renamed into place ([`OutputSet::commit`]),
//! so a failed run leaves no partial file behind and readers never see half
//! a file.
//!
//! ```
//! use moirecast_kernel::{check::SolidMesh, mesher::mesh_device, progress::Silent, Design, DesignParams, PitchSurface};
//! use moirecast_export::{stl_bytes, OutputSet};
//!
//! let mut params = DesignParams::with_defaults(PitchSurface::Plane, 2.0, 2.0, 0.5);
//! params.tolerance = 0.01;
//! let device = mesh_device(&Design::new(params).unwrap(), &Silent).unwrap();
//! // only a mesh that passed its solid checks can be encoded
//! let (_checks, solid) = SolidMesh::validate(&device.mesh);
//! let stl = stl_bytes("device.stl", solid.expect("a solid")).unwrap();
//! assert_eq!(stl.len(), 84 + 50 * device.mesh.triangles.len());
//! let mut files = OutputSet::new();
//! files.add("device.stl", stl);
//! let dir = std::env::temp_dir().join("moirecast-export-doc");
//! let written = files.commit(&dir).unwrap();
//! assert_eq!(written, vec![dir.join("device.stl")]);
//! ```

pub mod run_folder;
mod threemf;

pub use threemf::{model_xml, threemf_bytes, threemf_file, Material, Object, ThreemfFile};

use moirecast_kernel::check::SolidMesh;
use std::path::{Path, PathBuf};
use thiserror::Error;

#[derive(Debug, Error)]
pub enum ExportError {
    /// A mesh failed a solid check (METHOD §7.1); nothing was written.
    #[error("refusing to write `{file}`: check `{check}` failed ({detail})")]
    InvalidMesh {
        file: String,
        check: &'static str,
        detail: String,
    },
    /// The output folder holds files no run wrote; nothing was written.
    #[error("`{path}` holds files that no moirecast run wrote ({strangers}): a run replaces its folder whole, so that it holds exactly one run. Fix: write into an empty folder, a new one, or a run's")]
    NotARunFolder { path: PathBuf, strangers: String },
    /// The operating system refused a write or rename.
    #[error("cannot write `{path}`: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
}

/// Validates `mesh` as a solid (METHOD §7.1), or says which check failed.
pub fn validate<'a>(
    file: &str,
    mesh: &'a moirecast_kernel::Mesh,
) -> Result<SolidMesh<'a>, ExportError> {
    let (checks, solid) = SolidMesh::validate(mesh);
    solid.ok_or_else(|| {
        let c = checks
            .into_iter()
            .find(|c| !c.passed)
            .expect("a failed check");
        ExportError::InvalidMesh {
            file: file.to_owned(),
            check: c.name,
            detail: format!("{} {} vs limit {}; {}", c.value, c.unit, c.limit, c.detail),
        }
    })
}

/// Encodes a validated solid as binary STL (f32 coordinates, outward facet
/// normals). Taking a [`SolidMesh`] means an unchecked mesh cannot be written.
///
/// The layout is fixed (an 80-byte header of zeros, the count, then 50
/// bytes per facet: normal, three corners, a zero attribute word, all
/// little-endian), so facets are encoded straight into their place in the
/// file, in parallel. The bytes are stl_io's `write_stl`'s (a test
/// compares them); that writer goes through a `BufWriter` one f32 at a
/// time and took four times as long on the printed reference.
pub fn stl_bytes(file: &str, solid: SolidMesh) -> Result<Vec<u8>, ExportError> {
    use rayon::prelude::*;
    const HEADER: usize = 84;
    const FACET: usize = 50;
    /// Facets per parallel task.
    const CHUNK: usize = 16384;
    let mesh = solid.mesh();
    let count = u32::try_from(mesh.triangles.len()).map_err(|_| ExportError::Io {
        path: file.into(),
        source: std::io::Error::other("over 2³² triangles: a binary STL cannot count them"),
    })?;
    let mut out = vec![0u8; HEADER + FACET * mesh.triangles.len()];
    out[80..HEADER].copy_from_slice(&count.to_le_bytes());
    out[HEADER..]
        .par_chunks_mut(FACET * CHUNK)
        .zip(mesh.triangles.par_chunks(CHUNK))
        .with_max_len(1)
        .for_each(|(bytes, tris)| {
            for (facet, t) in bytes.chunks_exact_mut(FACET).zip(tris) {
                for (slot, f) in facet.chunks_exact_mut(4).zip(stl_facet(mesh, t)) {
                    slot.copy_from_slice(&f.to_le_bytes());
                }
                // the attribute word stays zero
            }
        });
    Ok(out)
}

/// One STL facet's twelve f32s: the outward unit normal, then the corners.
fn stl_facet(mesh: &moirecast_kernel::Mesh, t: &[u32; 3]) -> [f32; 12] {
    let [a, b, c] = t.map(|i| mesh.positions[i as usize]);
    let n = (b - a).cross(c - a).normalize_or_zero();
    [n, a, b, c]
        .map(|p| [p.x as f32, p.y as f32, p.z as f32])
        .as_flattened()
        .try_into()
        .expect("twelve")
}

/// A staged file's bytes: one buffer, or pieces written in order and never
/// joined (a STEP file's tens of MB are written from its parts).
pub trait FileContent: Send + Sync {
    /// The file's size in bytes.
    fn size(&self) -> usize;
    /// The file's bytes in order.
    fn pieces(&self) -> Vec<&[u8]>;
}

impl FileContent for Vec<u8> {
    fn size(&self) -> usize {
        self.len()
    }
    fn pieces(&self) -> Vec<&[u8]> {
        vec![self]
    }
}

/// Files staged for one output directory, written together by [`commit`](Self::commit).
#[derive(Default)]
pub struct OutputSet {
    files: Vec<(String, Box<dyn FileContent>)>,
}

impl OutputSet {
    pub fn new() -> Self {
        Self::default()
    }

    /// Stages `content` as `name` (a file name inside the directory).
    pub fn add(&mut self, name: &str, content: impl FileContent + 'static) {
        self.files.push((name.to_owned(), Box::new(content)));
    }

    /// Names and sizes of the staged files.
    pub fn sizes(&self) -> Vec<(String, usize)> {
        self.files
            .iter()
            .map(|(n, b)| (n.clone(), b.size()))
            .collect()
    }

    /// Replaces the run in `dir` with the staged files, as one swap of
    /// folders ([`run_folder`]): the folder then holds exactly this run,
    /// with a manifest of every file's SHA-256, or, on error, the last run
    /// untouched. A folder of files no run wrote is refused.
    pub fn commit_run(self, dir: &Path) -> Result<Vec<PathBuf>, ExportError> {
        let written = run_folder::commit_run(&self.files, dir)?;
        free_in_background(self.files);
        Ok(written)
    }

    /// The hex SHA-256 of each staged file, by name (in parallel).
    pub fn digests(&self) -> Vec<(String, String)> {
        use rayon::prelude::*;
        self.files
            .par_iter()
            .map(|(n, c)| (n.clone(), run_folder::sha256(c.as_ref())))
            .collect()
    }

    /// Writes every staged file into `dir` (created if missing), beside
    /// what is there (a saved spec): all to temporary names first, then all
    /// renamed. On error, temporaries are removed.
    pub fn commit(self, dir: &Path) -> Result<Vec<PathBuf>, ExportError> {
        std::fs::create_dir_all(dir).map_err(|source| ExportError::Io {
            path: dir.to_owned(),
            source,
        })?;
        let temps: Vec<(PathBuf, PathBuf)> = self
            .files
            .iter()
            .map(|(name, _)| {
                (
                    dir.join(format!(".{name}.{}.tmp", std::process::id())),
                    dir.join(name),
                )
            })
            .collect();
        let cleanup = |temps: &[(PathBuf, PathBuf)]| {
            for (t, _) in temps {
                let _ = std::fs::remove_file(t);
            }
        };
        // the files are written in parallel: copying tens of MB into the
        // page cache is a large part of a run
        use rayon::prelude::*;
        let written: Vec<Result<(), ExportError>> = self
            .files
            .par_iter()
            .zip(&temps)
            .map(|((_, content), (temp, _))| {
                write_pieces(temp, &content.pieces()).map_err(|source| ExportError::Io {
                    path: temp.clone(),
                    source,
                })
            })
            .collect();
        if let Some(error) = written.into_iter().find_map(Result::err) {
            cleanup(&temps);
            return Err(error);
        }
        for (temp, target) in &temps {
            if let Err(source) = std::fs::rename(temp, target) {
                cleanup(&temps);
                return Err(ExportError::Io {
                    path: target.clone(),
                    source,
                });
            }
        }
        free_in_background(self.files);
        Ok(temps.into_iter().map(|(_, t)| t).collect())
    }
}

/// Writes `pieces`, in order, as the file `path`: a few vectored writes of
/// up to 1024 pieces each.
pub(crate) fn write_pieces(path: &Path, pieces: &[&[u8]]) -> std::io::Result<()> {
    use std::io::{IoSlice, Write};
    const BATCH: usize = 1024;
    let mut file = std::fs::File::create(path)?;
    let mut slices: Vec<IoSlice> = pieces
        .iter()
        .filter(|p| !p.is_empty())
        .map(|p| IoSlice::new(p))
        .collect();
    let mut rest = &mut slices[..];
    while !rest.is_empty() {
        let batch = rest.len().min(BATCH);
        let written = file.write_vectored(&rest[..batch])?;
        if written == 0 {
            return Err(std::io::ErrorKind::WriteZero.into());
        }
        IoSlice::advance_slices(&mut rest, written);
    }
    Ok(())
}

/// Frees `value` on a short-lived thread of its own. A run's meshes, B-rep
/// and file buffers (hundreds of MB) take tens of milliseconds to free;
/// once their files are written, nothing needs to wait for that. (If no
/// thread can be started, `value` is freed here.)
pub fn free_in_background<T: Send + 'static>(value: T) {
    let _ = std::thread::Builder::new()
        .name("free".into())
        .spawn(move || drop(value));
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DVec3;
    use moirecast_kernel::Mesh;

    #[test]
    fn stl_round_trips_through_stl_io() {
        let m = Mesh {
            positions: vec![DVec3::ZERO, DVec3::X, DVec3::Y, DVec3::Z],
            triangles: vec![[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]],
        };
        let bytes = stl_bytes("t.stl", validate("t.stl", &m).unwrap()).unwrap();
        assert_eq!(bytes.len(), 84 + 4 * 50);
        let back = stl_io::read_stl(&mut std::io::Cursor::new(bytes)).unwrap();
        assert_eq!(back.faces.len(), 4);
        assert_eq!(back.vertices.len(), 4);
    }

    #[test]
    fn an_open_mesh_is_refused() {
        let m = Mesh {
            positions: vec![DVec3::ZERO, DVec3::X, DVec3::Y],
            triangles: vec![[0, 1, 2]],
        };
        assert!(matches!(
            validate("open.stl", &m),
            Err(ExportError::InvalidMesh {
                check: "closed-oriented",
                ..
            })
        ));
    }

    #[test]
    fn commit_writes_everything_or_nothing() {
        let dir =
            std::env::temp_dir().join(format!("moirecast-export-test-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let mut set = OutputSet::new();
        set.add("a.txt", b"a".to_vec());
        set.add("b.txt", b"b".to_vec());
        set.commit(&dir).unwrap();
        assert_eq!(std::fs::read(dir.join("b.txt")).unwrap(), b"b");
        let leftovers = std::fs::read_dir(&dir)
            .unwrap()
            .filter(|e| {
                e.as_ref()
                    .unwrap()
                    .file_name()
                    .to_string_lossy()
                    .ends_with(".tmp")
            })
            .count();
        assert_eq!(leftovers, 0);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// A file staged in pieces is written whole, in order, past the
    /// batches of vectored writes (empty pieces included).
    #[test]
    fn a_file_in_pieces_is_written_whole() {
        struct Pieces(Vec<Vec<u8>>);
        impl FileContent for Pieces {
            fn size(&self) -> usize {
                self.0.iter().map(Vec::len).sum()
            }
            fn pieces(&self) -> Vec<&[u8]> {
                self.0.iter().map(Vec::as_slice).collect()
            }
        }
        let pieces: Vec<Vec<u8>> = (0..5000u32)
            .map(|i| i.to_string().into_bytes().repeat((i % 3) as usize))
            .collect();
        let whole = pieces.concat();
        let dir =
            std::env::temp_dir().join(format!("moirecast-pieces-test-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let mut set = OutputSet::new();
        set.add("p.txt", Pieces(pieces));
        assert_eq!(set.sizes(), vec![("p.txt".to_string(), whole.len())]);
        set.commit(&dir).unwrap();
        assert!(std::fs::read(dir.join("p.txt")).unwrap() == whole);
        std::fs::remove_dir_all(&dir).unwrap();
    }
}

#[cfg(test)]
mod direct_stl {
    use super::*;
    use moirecast_kernel::*;

    /// The direct, parallel encoding is byte-identical to stl_io's writer
    /// over all triangles (a device of more than one parallel chunk).
    #[test]
    fn direct_stl_equals_stl_io_write() {
        let mut params = DesignParams::with_defaults(PitchSurface::Plane, 20.0, 20.0, 0.5);
        params.profile = Profile::Rings { wavelength: 4.0 };
        params.tolerance = 0.001;
        let design = Design::new(params).unwrap();
        let dm = mesher::mesh_device(&design, &progress::Silent).unwrap();
        assert!(
            dm.mesh.triangles.len() > 65536,
            "{} triangles: one chunk only",
            dm.mesh.triangles.len()
        );
        let direct = stl_bytes("d.stl", validate("d.stl", &dm.mesh).unwrap()).unwrap();
        let m = &dm.mesh;
        let all = m.triangles.iter().map(|t| {
            let [a, b, c] = t.map(|i| m.positions[i as usize]);
            let n = (b - a).cross(c - a).normalize_or_zero();
            let v = |p: glam::DVec3| stl_io::Vertex::new([p.x as f32, p.y as f32, p.z as f32]);
            stl_io::Triangle {
                normal: stl_io::Normal::new([n.x as f32, n.y as f32, n.z as f32]),
                vertices: [v(a), v(b), v(c)],
            }
        });
        let mut reference = Vec::new();
        stl_io::write_stl(&mut reference, all).unwrap();
        assert!(direct == reference, "direct encoding differs from stl_io's");
    }
}

/// `assembly.scad`: imports the device and both mold halves with colours.
/// `exploded` (mm) pulls the halves apart; `mode = "check"` renders the
/// pairwise intersections of the three parts, which are empty when the
/// mold is right ("checking solids in OpenSCAD"); `rebuild-top` and
/// `rebuild-bottom` rebuild each half in OpenSCAD from the block, the
/// device and the construction solids, to compare with ours.
pub fn assembly_scad(title: &str, block_min: [f64; 3], block_size: [f64; 3]) -> String {
    let v = |a: [f64; 3]| format!("[{:?}, {:?}, {:?}]", a[0], a[1], a[2]);
    let (block_min, block_size) = (v(block_min), v(block_size));
    format!(
        r#"// {title}
// Open in OpenSCAD. Customizer: `exploded` pulls the halves apart;
// mode = "check" renders the pairwise intersections of the parts: an empty
// result means no part overlaps another. mode = "rebuild-top" (or
// "rebuild-bottom") rebuilds a half from the block, device.stl and the
// construction-*.stl solids.
exploded = 0;        // [0:1:80]
mode = "assembly";   // ["assembly", "check", "top", "bottom", "device", "rebuild-top", "rebuild-bottom"]

block_min = {block_min};
block_size = {block_size};
module block() {{ translate(block_min) cube(block_size); }}
module construction(name) {{ import(str("construction-", name, ".stl"), convexity = 10); }}

module top() {{ import("mold-top.stl", convexity = 10); }}
module bottom() {{ import("mold-bottom.stl", convexity = 10); }}
module device() {{ import("device.stl", convexity = 10); }}

if (mode == "check") {{
    intersection() {{ top(); bottom(); }}
    intersection() {{ top(); device(); }}
    intersection() {{ bottom(); device(); }}
}} else if (mode == "top") {{
    top();
}} else if (mode == "bottom") {{
    bottom();
}} else if (mode == "device") {{
    device();
}} else if (mode == "rebuild-top") {{
    difference() {{
        intersection() {{ block(); construction("above"); }}
        device();
        construction("channels");
        construction("key-sockets");
    }}
}} else if (mode == "rebuild-bottom") {{
    difference() {{
        union() {{ intersection() {{ block(); construction("below"); }} construction("key-bumps"); }}
        device();
        construction("channels");
    }}
}} else {{
    color([0.90, 0.55, 0.20, 0.55]) translate([0, 0, exploded]) top();
    color([0.25, 0.45, 0.80, 0.55]) translate([0, 0, -exploded]) bottom();
    color([0.92, 0.92, 0.97, 0.90]) device();
}}
"#
    )
}

//! STEP (ISO 10303-21) text of a B-rep, written by truck-stepio with a
//! clean, deterministic header, and read back by truck-stepio.
//!
//! truck-stepio lays the file out (every entity's index) and writes it
//! serially; nearly all of the text is the control points of the surfaces
//! and curves. So the layout pass writes a marker in place of each of them
//! and records its index, and their text, truck-stepio's own, is then
//! written in parallel and spliced in: the same bytes, on every core.

use crate::error::BrepError;
use rayon::prelude::*;
use std::cell::RefCell;
use std::fmt::{self, Formatter, Write};
use truck_modeling::{Curve, Point3, Solid, Surface};
use truck_stepio::out::{
    DisplayByStep, StepCurve, StepDisplay, StepLength, StepModels, StepSurface,
};
use truck_topology::compress::{CompressedEdge, CompressedFace, CompressedShell, CompressedSolid};

/// The timestamp written into every header: outputs are deterministic, so
/// the file carries no clock reading (ISO 8601, as STEP asks).
pub const STEP_TIMESTAMP: &str = "2000-01-01T00:00:00";

/// What truck-stepio names the schema (AP214's automotive design context).
const FILE_SCHEMA: &str = "FILE_SCHEMA(('ISO-10303-042'));";

/// Stands in the layout text for one curve's or surface's entities; STEP
/// text is printable ASCII, so it never occurs there.
const MARKER: char = '\u{1}';

/// The STEP text of `solid`, as file `file_name`.
///
/// truck-stepio 0.3 wraps the author and organization lists in a second
/// pair of parentheses (`(('x'))`), which OpenCascade reports as an error,
/// and stamps the current time; the header is therefore written here.
pub fn step_text(solid: &Solid, file_name: &str, description: &str) -> String {
    step_text_of(std::slice::from_ref(solid), file_name, description)
}

/// The STEP text of several `solids` in one file (each its own solid), as
/// file `file_name`, with the same header as [`step_text`].
pub fn step_text_of(solids: &[Solid], file_name: &str, description: &str) -> String {
    let compressed: Vec<_> = solids.iter().map(|s| s.compress()).collect();
    let queue = RefCell::new(Vec::new());
    let deferred: Vec<_> = compressed.iter().map(|s| defer(s, &queue)).collect();
    let layout = deferred.iter().collect::<StepModels<_, _, _>>().to_string();
    let queue = queue.take();
    let texts: Vec<String> = queue
        .par_iter()
        .map(|&(idx, geometry)| match geometry {
            Geometry::Curve(c) => StepDisplay::new(c, idx).to_string(),
            Geometry::Surface(s) => StepDisplay::new(s, idx).to_string(),
        })
        .collect();
    let header = header(file_name, description);
    const FOOTER: &str = "ENDSEC;\nEND-ISO-10303-21;\n";
    let size =
        header.len() + layout.len() + texts.iter().map(String::len).sum::<usize>() + FOOTER.len();
    let mut out = String::with_capacity(size);
    out.push_str(&header);
    let mut pieces = layout.split(MARKER);
    out.push_str(pieces.next().expect("split yields at least one piece"));
    let mut texts = texts.iter();
    for piece in pieces {
        out.push_str(texts.next().expect("one text per marker"));
        out.push_str(piece);
    }
    assert!(texts.next().is_none(), "one marker per text");
    out.push_str(FOOTER);
    out
}

/// The header written here, through `DATA;`.
fn header(file_name: &str, description: &str) -> String {
    let escape = |s: &str| s.replace('\'', "''");
    format!(
        "ISO-10303-21;\nHEADER;\nFILE_DESCRIPTION(('{}'), '2;1');\nFILE_NAME('{}', '{}', ('moirecast'), ('moirecast'), 'truck-stepio 0.3', 'moirecast {}', '');\n{FILE_SCHEMA}\nENDSEC;\nDATA;\n",
        escape(description),
        escape(file_name),
        STEP_TIMESTAMP,
        env!("CARGO_PKG_VERSION"),
    )
}

/// A curve or surface of the solid.
#[derive(Clone, Copy)]
enum Geometry<'a> {
    Curve(&'a Curve),
    Surface(&'a Surface),
}

/// Curves and surfaces met by the layout pass, with their entity index, in
/// the order their text belongs in the file.
type Queue<'a> = RefCell<Vec<(usize, Geometry<'a>)>>;

/// A curve or surface in the layout pass: as long as its text (so indices
/// come out right), written as [`MARKER`].
struct Deferred<'a> {
    geometry: Geometry<'a>,
    queue: &'a Queue<'a>,
}

impl StepLength for Deferred<'_> {
    fn step_length(&self) -> usize {
        match self.geometry {
            Geometry::Curve(c) => c.step_length(),
            Geometry::Surface(s) => s.step_length(),
        }
    }
}

impl StepCurve for Deferred<'_> {
    fn same_sense(&self) -> bool {
        match self.geometry {
            Geometry::Curve(c) => StepCurve::same_sense(c),
            Geometry::Surface(s) => StepSurface::same_sense(s),
        }
    }
}

impl StepSurface for Deferred<'_> {
    fn same_sense(&self) -> bool {
        StepCurve::same_sense(self)
    }
}

impl DisplayByStep for Deferred<'_> {
    fn fmt(&self, idx: usize, f: &mut Formatter<'_>) -> fmt::Result {
        self.queue.borrow_mut().push((idx, self.geometry));
        f.write_char(MARKER)
    }
}

/// `solid` with its curves and surfaces deferred.
fn defer<'a>(
    solid: &'a CompressedSolid<Point3, Curve, Surface>,
    queue: &'a Queue<'a>,
) -> CompressedSolid<Point3, Deferred<'a>, Deferred<'a>> {
    let deferred = |geometry| Deferred { geometry, queue };
    CompressedSolid {
        boundaries: solid
            .boundaries
            .iter()
            .map(|shell| CompressedShell {
                vertices: shell.vertices.clone(),
                edges: shell
                    .edges
                    .iter()
                    .map(|e| CompressedEdge {
                        vertices: e.vertices,
                        curve: deferred(Geometry::Curve(&e.curve)),
                    })
                    .collect(),
                faces: shell
                    .faces
                    .iter()
                    .map(|f| CompressedFace {
                        boundaries: f.boundaries.clone(),
                        orientation: f.orientation,
                        surface: deferred(Geometry::Surface(&f.surface)),
                    })
                    .collect(),
            })
            .collect(),
    }
}

/// Reads STEP text back with truck-stepio and returns the face count of
/// each shell in it.
pub fn read_back_faces(text: &str) -> Result<Vec<usize>, BrepError> {
    use truck_stepio::r#in::Table;
    let table = Table::from_step(text)
        .ok_or_else(|| BrepError::StepRoundTrip("truck-stepio could not parse the text".into()))?;
    let mut shells: Vec<_> = table.shell.iter().collect();
    shells.sort_by_key(|(id, _)| **id);
    shells
        .into_iter()
        .map(|(id, holder)| {
            table
                .to_compressed_shell(holder)
                .map(|s| s.faces.len())
                .map_err(|e| BrepError::StepRoundTrip(format!("shell #{id}: {e}")))
        })
        .collect()
}

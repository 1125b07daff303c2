//! STEP (ISO 10303-21) text of a B-rep, written by truck-stepio with a
//! clean, deterministic header, and read back by truck-stepio.
//!
//! truck-stepio lays the file out (every entity's index) and writes it
//! serially; nearly all of the text is the control points of the surfaces
//! and curves. So the layout pass writes a marker in place of each of them
//! and records its index, and their text, truck-stepio's own, is then
//! written in parallel, on every core; the file stays in those pieces
//! ([`StepText`]), which a writer writes in order. The B-spline kinds
//! (all but a few planes) are written here in truck-stepio's form with
//! zmij's floats in place of `core::fmt`'s (most of the text is numbers):
//! the same text, but where a 17-digit tie rounds to even (the same
//! number; see `Writer::float`).

use crate::error::BrepError;
use rayon::prelude::*;
use std::cell::RefCell;
use std::fmt::{self, Formatter, Write};
use truck_modeling::Homogeneous;
use truck_modeling::{
    BSplineCurve, Curve, KnotVec, NurbsCurve, NurbsSurface, Point3, Solid, Surface, Vector4,
};
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
    step_file_of(solids, file_name, description).to_text()
}

/// The STEP file of `solids`, in pieces: [`step_text_of`] without joining
/// its tens of MB into one string (a writer writes the pieces in order).
pub fn step_file_of(solids: &[Solid], file_name: &str, description: &str) -> StepText {
    let compressed: Vec<_> = solids.iter().map(|s| s.compress()).collect();
    let queue = RefCell::new(Vec::new());
    let deferred: Vec<_> = compressed.iter().map(|s| defer(s, &queue)).collect();
    let layout = deferred.iter().collect::<StepModels<_, _, _>>().to_string();
    let queue = queue.take();
    let geometries: Vec<String> = queue
        .par_iter()
        // small tasks, so that a thread that frees up late still finds some
        .with_max_len(16)
        .map(|&(idx, geometry)| geometry_text(geometry, idx))
        .collect();
    assert_eq!(
        layout.matches(MARKER).count(),
        geometries.len(),
        "one marker per curve or surface"
    );
    let header = header(file_name, description);
    let len = header.len()
        + layout.len()
        + geometries.iter().map(String::len).sum::<usize>()
        + FOOTER.len()
        - geometries.len() * MARKER.len_utf8();
    StepText {
        header,
        layout,
        geometries,
        len,
    }
}

/// What ends every STEP file.
const FOOTER: &str = "ENDSEC;\nEND-ISO-10303-21;\n";

/// A STEP file held in pieces: its header, truck-stepio's layout with a
/// marker for each curve and surface, their texts, and the footer.
pub struct StepText {
    header: String,
    layout: String,
    geometries: Vec<String>,
    len: usize,
}

impl StepText {
    /// The file's length in bytes.
    pub fn len(&self) -> usize {
        self.len
    }

    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// The file's text in order, in pieces (some may be empty).
    pub fn pieces(&self) -> impl Iterator<Item = &str> {
        let mut layout = self.layout.split(MARKER);
        let first = layout.next().expect("split yields at least one piece");
        std::iter::once(self.header.as_str())
            .chain(std::iter::once(first))
            .chain(
                self.geometries
                    .iter()
                    .zip(layout)
                    .flat_map(|(g, l)| [g.as_str(), l]),
            )
            .chain(std::iter::once(FOOTER))
    }

    /// The whole text as one string.
    pub fn to_text(&self) -> String {
        let mut out = String::with_capacity(self.len);
        self.pieces().for_each(|p| out.push_str(p));
        out
    }
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

/// The text of one curve or surface whose first entity is `idx`:
/// truck-stepio's, with the same numbers.
fn geometry_text(geometry: Geometry, idx: usize) -> String {
    // room for every control point's line and the entity's lists, so the
    // text is not copied as it grows
    let points = match geometry {
        Geometry::Surface(Surface::NurbsSurface(s)) => {
            s.control_points().iter().map(Vec::len).sum()
        }
        Geometry::Curve(Curve::BSplineCurve(c)) => c.control_points().len(),
        Geometry::Curve(Curve::NurbsCurve(c)) => c.control_points().len(),
        _ => 0,
    };
    let mut w = Writer {
        text: String::with_capacity(512 + 128 * points),
        ..Writer::default()
    };
    match geometry {
        Geometry::Surface(Surface::NurbsSurface(s)) => w.nurbs_surface(s, idx),
        Geometry::Curve(Curve::BSplineCurve(c)) => w.bspline_curve(c, idx),
        Geometry::Curve(Curve::NurbsCurve(c)) => w.nurbs_curve(c, idx),
        Geometry::Curve(c) => return StepDisplay::new(c, idx).to_string(),
        Geometry::Surface(s) => return StepDisplay::new(s, idx).to_string(),
    }
    w.text
}

/// truck-stepio's text around a B-spline curve's degree, point list and
/// knots (see [`Writer::curve_head`]).
const BSPLINE_CURVE: [&str; 3] = [
    " = B_SPLINE_CURVE_WITH_KNOTS('', ",
    ", .UNSPECIFIED., .U., .U., ",
    ", .UNSPECIFIED.);\n",
];
/// The same for a rational curve, up to its weights.
const NURBS_CURVE: [&str; 3] = [
    " = (\n    BOUNDED_CURVE()\n    B_SPLINE_CURVE(",
    ", .UNSPECIFIED., .U., .U.)\n    B_SPLINE_CURVE_WITH_KNOTS(",
    ", .UNSPECIFIED.)\n    CURVE()\n    GEOMETRIC_REPRESENTATION_ITEM()\n    RATIONAL_B_SPLINE_CURVE(",
];

/// STEP text in truck-stepio's layout, with fast floats.
#[derive(Default)]
struct Writer {
    text: String,
    floats: zmij::Buffer,
    integers: itoa::Buffer,
}

impl Writer {
    fn str(&mut self, s: &str) {
        self.text.push_str(s);
    }

    fn index(&mut self, idx: usize) {
        self.text.push('#');
        self.usize(idx);
    }

    fn usize(&mut self, n: usize) {
        self.text.push_str(self.integers.format(n));
    }

    /// truck-stepio's `FloatDisplay`: `{:.10E}` below 0.01, else `{:?}`,
    /// the shortest digits that read back as `x`. zmij writes the same
    /// between 0.01 and 1e15 but where two such strings of 17 digits are
    /// equally near `x`: it rounds that tie to even, `core::fmt` up (both
    /// read back as `x`; property tests).
    fn float(&mut self, x: f64) {
        let a = x.abs();
        if a < 1e-2 && x != 0.0 {
            write!(self.text, "{x:.10E}").expect("writing to a String");
        } else if (1e-2..1e15).contains(&a) {
            self.text.push_str(self.floats.format_finite(x));
        } else {
            write!(self.text, "{x:?}").expect("writing to a String");
        }
    }

    /// `(a, b, …)` of `items`, each written by `each`.
    fn list<T>(&mut self, items: impl IntoIterator<Item = T>, mut each: impl FnMut(&mut Self, T)) {
        self.text.push('(');
        for (i, x) in items.into_iter().enumerate() {
            if i != 0 {
                self.text.push_str(", ");
            }
            each(self, x);
        }
        self.text.push(')');
    }

    fn floats(&mut self, xs: impl IntoIterator<Item = f64>) {
        self.list(xs, Self::float);
    }

    fn usizes(&mut self, ns: &[usize]) {
        self.list(ns.iter().copied(), Self::usize);
    }

    /// `(#first, …, #first + count − 1)`
    fn indices(&mut self, first: usize, count: usize) {
        self.list(first..first + count, Self::index);
    }

    fn point(&mut self, p: Point3, idx: usize) {
        self.index(idx);
        self.str(" = CARTESIAN_POINT('', ");
        self.floats([p.x, p.y, p.z]);
        self.str(");\n");
    }

    fn knots(&mut self, knots: &KnotVec) {
        let (single, multi) = knots.to_single_multi();
        self.usizes(&multi);
        self.str(", ");
        self.floats(single);
    }

    /// `#idx = …` of a curve of `degree` over control points idx + 1 …
    /// idx + n: `open`, the degree, the point list, `middle`, the knots,
    /// `close`.
    fn curve_head(
        &mut self,
        idx: usize,
        (degree, n, knots): (usize, usize, &KnotVec),
        [open, middle, close]: [&str; 3],
    ) {
        self.index(idx);
        self.str(open);
        self.usize(degree);
        self.str(", ");
        self.indices(idx + 1, n);
        self.str(middle);
        self.knots(knots);
        self.str(close);
    }

    /// The control points' entities, numbered from `first`.
    fn points(&mut self, points: impl Iterator<Item = Point3>, first: usize) {
        for (i, p) in points.enumerate() {
            self.point(p, first + i);
        }
    }

    fn bspline_curve(&mut self, c: &BSplineCurve<Point3>, idx: usize) {
        let shape = (c.degree(), c.control_points().len(), c.knot_vec());
        self.curve_head(idx, shape, BSPLINE_CURVE);
        self.points(c.control_points().iter().copied(), idx + 1);
    }

    fn nurbs_curve(&mut self, c: &NurbsCurve<Vector4>, idx: usize) {
        let shape = (c.degree(), c.control_points().len(), c.knot_vec());
        self.curve_head(idx, shape, NURBS_CURVE);
        self.floats(c.control_points().iter().map(|v| v.weight()));
        self.str(")\n    REPRESENTATION_ITEM('')\n);\n");
        self.points(c.control_points().iter().map(|v| v.to_point()), idx + 1);
    }

    fn nurbs_surface(&mut self, s: &NurbsSurface<Vector4>, idx: usize) {
        let rows = s.control_points();
        self.index(idx);
        self.str(" = (\n    BOUNDED_SURFACE()\n    B_SPLINE_SURFACE(");
        self.usize(s.udegree());
        self.str(", ");
        self.usize(s.vdegree());
        self.str(", ");
        let mut first = idx + 1;
        self.list(rows, |w, row| {
            w.indices(first, row.len());
            first += row.len();
        });
        self.str(", .UNSPECIFIED., .U., .U., .U.)\n    B_SPLINE_SURFACE_WITH_KNOTS(");
        let (uknots, umulti) = s.uknot_vec().to_single_multi();
        let (vknots, vmulti) = s.vknot_vec().to_single_multi();
        self.usizes(&umulti);
        self.str(", ");
        self.usizes(&vmulti);
        self.str(", ");
        self.floats(uknots);
        self.str(", ");
        self.floats(vknots);
        self.str(
            ", .UNSPECIFIED.)\n    GEOMETRIC_REPRESENTATION_ITEM()\n    RATIONAL_B_SPLINE_SURFACE(",
        );
        self.list(rows, |w, row| w.floats(row.iter().map(|v| v.weight())));
        self.str(")\n    REPRESENTATION_ITEM('')\n    SURFACE()\n);\n");
        self.points(rows.iter().flatten().map(|v| v.to_point()), idx + 1);
    }
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

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn written(x: f64) -> String {
        let mut w = Writer::default();
        w.float(x);
        w.text
    }

    /// truck-stepio's `FloatDisplay`, spelled out.
    fn truck_stepio(x: f64) -> String {
        if x.abs() < 1e-2 && x != 0.0 {
            format!("{x:.10E}")
        } else {
            format!("{x:?}")
        }
    }

    #[test]
    fn floats_at_the_edges_read_as_truck_stepio_writes_them() {
        for x in [
            0.0,
            -0.0,
            1.0,
            -1.0,
            0.01,
            -0.01,
            0.009999999999999998,
            1e15,
            9.999999999999998e14,
            1e16,
            123456789.0,
            0.1,
            0.3,
            2.0 / 3.0,
            f64::MAX,
            f64::MIN_POSITIVE,
        ] {
            assert_eq!(written(x), truck_stepio(x), "{x:e}");
        }
    }

    proptest! {
        #![proptest_config(moirecast_kernel::strategies::config(4096))]
        #[test]
        fn any_float_reads_back_with_as_many_digits_as_truck_stepio_writes(
            x in prop_oneof![
                (-3.0..16.0f64, any::<bool>()).prop_map(|(e, neg)| if neg { -(10f64.powf(e)) } else { 10f64.powf(e) }),
                any::<f64>().prop_filter("finite", |x| x.is_finite()),
                (-1e6..1e6f64),
            ]
        ) {
            let (ours, theirs) = (written(x), truck_stepio(x));
            if !(1e-2..1e15).contains(&x.abs()) {
                // core::fmt's own text (truck-stepio keeps 10 digits below 0.01)
                prop_assert_eq!(ours, theirs);
                return Ok(());
            }
            prop_assert_eq!(ours.parse::<f64>().unwrap(), x);
            prop_assert_eq!(ours.len(), theirs.len());
            if ours != theirs {
                // a tie, rounded to even: the last digits differ by one
                prop_assert_eq!(&ours[..ours.len() - 1], &theirs[..theirs.len() - 1]);
            }
        }
    }
}

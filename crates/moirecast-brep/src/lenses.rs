//! One NURBS surface per lens (METHOD §2, §5.1), or per band span of a
//! printed base (METHOD §5.2).
//!
//! **Across** a lens (parameter t ∈ [0, 1]) every station's section is the
//! exact arc as a rational quadratic: ends P0 and P1 with weight 1, and the
//! tangents' intersection M + (w/2)·tan β·m with weight cos β. Across a band
//! span of s (between two band edges) it is m quadratic pieces (C⁰ at
//! double knots j/m), each through its ends and its exact middle point; s is
//! no conic, so m doubles until the pieces lie within a quarter of the fit
//! of s at the first stations (one piece for most spans; wide bands on a
//! bending surface need more), and the surface is measured against s like
//! every other approximation here.
//! **Along** a lens (parameter v, the station) the homogeneous control points
//! are interpolated by clamped C² cubics through shared stations, so at every
//! station the section *is* the exact arc, and neighbouring lenses share
//! their crease curve bit for bit (the crease is computed once).
//!
//! **Guarantee.** Stations are refined until, at the middle of every span and
//! for every lens, the surface lies within `fit` of the exact arc of that
//! station; a second, independent sample then measures the worst distance.

use crate::ends::WallEnds;
use crate::error::BrepError;
use crate::spline::{clamped_knots, interpolate};
use glam::DVec3;
use moirecast_kernel::lens::LensArc;
use moirecast_kernel::model::BaseSection;
use moirecast_kernel::profile::Profile;
use moirecast_kernel::{BaseKind, Design};
use rayon::prelude::*;
use std::collections::BTreeMap;
use truck_modeling::{BSplineSurface, KnotVec, NurbsSurface, Vector4};

/// Homogeneous control points of one section: [P0, w·Pm, P1] for an arc;
/// [P0, M0, P1, M1, …, Pm] for a band span of m quadratic pieces.
type Section = Vec<[f64; 4]>;

/// Most quadratic pieces across one band span.
const MAX_PIECES: usize = 64;

/// Widest first spacing of the stations (mm); refinement halves spans.
const FIRST_SPACING_MM: f64 = 2.0;
/// Bisection rounds before giving up (a span of 2 mm / 2¹⁴ ≈ 0.1 µm).
const MAX_ROUNDS: usize = 14;
/// Rounds that halve only the spans beyond the fit; the k-th later round
/// halves those beyond [`LATE_ROUND_SHARE`]^k of it too (0.8, 0.64, 0.51, …).
const PATIENT_ROUNDS: usize = 6;
const LATE_ROUND_SHARE: f64 = 0.8;
/// Across-lens parameters at which spans are tested while refining.
const REFINE_T: [f64; 5] = [0.1, 0.25, 0.5, 0.75, 0.9];
/// Span fractions and across-lens parameters of the final, independent sample.
const VERIFY_S: [f64; 2] = [1.0 / 3.0, 2.0 / 3.0];
const VERIFY_T: [f64; 4] = [0.05, 0.35, 0.6, 0.95];
/// How far over the fit the independent sample of a band span may lie
/// before the span gets more pieces across: to half the tolerance.
const VERIFY_SLACK: f64 = 0.5 / FIT_SHARE;
/// Times a band span family's refinement goes on from the samples the
/// independent check found beyond [`VERIFY_SLACK`].
const MAX_RESTARTS: usize = 8;

fn section(arc: &LensArc) -> Section {
    let w = arc.half_angle.cos();
    let mid = 0.5 * (arc.p0 + arc.p1) + 0.5 * arc.width() * arc.half_angle.tan() * arc.bulge;
    vec![
        [arc.p0.x, arc.p0.y, arc.p0.z, 1.0],
        [w * mid.x, w * mid.y, w * mid.z, w],
        [arc.p1.x, arc.p1.y, arc.p1.z, 1.0],
    ]
}

/// The exact section of one lens, or of one band span, at one station.
#[derive(Clone, Copy, Debug)]
pub enum ExactSection<'a> {
    /// A lens: its circular arc.
    Arc(LensArc),
    /// A printed base's span of s between two band edges.
    Span(BaseSection<'a>),
}

impl ExactSection<'_> {
    /// Homogeneous control points across: the exact arc, or for a span
    /// `pieces` quadratics, each through its ends and its middle point.
    fn section(&self, pieces: usize) -> Section {
        match self {
            ExactSection::Arc(arc) => section(arc),
            ExactSection::Span(span) => {
                // the span at every piece's ends and middle, each once
                let halves = 2 * pieces;
                let p: Vec<DVec3> = (0..=halves)
                    .map(|i| span.point(i as f64 / halves as f64))
                    .collect();
                (0..=halves)
                    .map(|i| {
                        // even rows are the pieces' ends, odd rows their
                        // middle control points
                        let c = if i % 2 == 0 {
                            p[i]
                        } else {
                            2.0 * p[i] - 0.5 * (p[i - 1] + p[i + 1])
                        };
                        [c.x, c.y, c.z, 1.0]
                    })
                    .collect()
            }
        }
    }

    /// Distance (mm) from `q`, a surface's point at across-parameter `t`, to
    /// the exact section: to the arc; for a span, to its point at the same
    /// t (an upper bound of the distance to the span, and at t = 0 and 1
    /// the error of the band's edge).
    fn distance(&self, t: f64, q: DVec3) -> f64 {
        match self {
            ExactSection::Arc(arc) => distance_to_arc(arc, q),
            ExactSection::Span(span) => (q - span.point(t)).length(),
        }
    }
}

/// Distance (mm) from `q` to the exact arc: to its circle within the arc's
/// angular span, to the nearer end outside it.
pub fn distance_to_arc(arc: &LensArc, q: glam::DVec3) -> f64 {
    let c = arc.centre();
    let normal = arc.chord_dir.cross(arc.bulge);
    let d = q - c;
    let off_plane = d.dot(normal);
    let (x, y) = (d.dot(arc.chord_dir), d.dot(arc.bulge));
    let angle = x.atan2(y);
    if angle.abs() <= arc.half_angle {
        let radial = (x * x + y * y).sqrt() - arc.radius;
        (off_plane * off_plane + radial * radial).sqrt()
    } else {
        (q - arc.p0).length().min((q - arc.p1).length())
    }
}

/// The stations' first spacing: [`FIRST_SPACING_MM`], or a procedural
/// profile's detail where that is finer (rings a few periods across bend the
/// base creases within a fraction of a millimetre; stations mid-test only
/// their midpoints, so stations sparser than the detail alias and never
/// converge). A sampled image's detail is its grid's, far finer than its
/// blur lets it bend: refinement finds its stations.
fn first_spacing(design: &Design) -> f64 {
    let detail = match design.params.profile {
        Profile::Sampled(_) => None,
        ref procedural => procedural.detail_mm(),
    };
    detail.map_or(FIRST_SPACING_MM, |d| d.min(FIRST_SPACING_MM))
}

pub use crate::array::Array;

/// Share of the mesh tolerance a lens surface may deviate from the exact
/// lens: the rest is left for tessellating the B-rep (the cross-check).
pub const FIT_SHARE: f64 = 0.1;

/// The lens surfaces of one array over shared stations.
pub struct LensFamily {
    pub array: Array,
    pub stations: Vec<f64>,
    /// Lens index → its surface (t ∈ [0, 1], v ∈ [first, last station]).
    pub surfaces: BTreeMap<i64, NurbsSurface<Vector4>>,
    /// Worst distance (mm) of the independent sample, and where.
    pub deviation: Deviation,
    /// The stations at which the surfaces end in a wall, where they do
    /// ([`crate::ends`]).
    pub ends: WallEnds,
}

/// A distance (mm) from the exact lenses, and where: lens, t, v.
pub type Deviation = (f64, i64, f64, f64);

/// A refined family, and the stations of the independent samples that lie
/// beyond [`VERIFY_SLACK`] times the fit.
struct Refined {
    family: LensFamily,
    misses: Vec<f64>,
}

impl LensFamily {
    /// Surfaces for `lenses` of `array` over `v_range`, each within `fit`
    /// (mm) of the exact lenses at every tested point.
    pub fn build(
        design: &Design,
        array: Array,
        lenses: &[i64],
        v_range: (f64, f64),
        fit: f64,
    ) -> Result<LensFamily, BrepError> {
        let (lo, hi) = v_range;
        let spans = ((hi - lo) / first_spacing(design)).ceil().max(2.0) as usize;
        let stations: Vec<f64> = (0..=spans)
            .map(|j| {
                if j == spans {
                    hi
                } else {
                    lo + (hi - lo) * j as f64 / spans as f64
                }
            })
            .collect();
        let exact = ExactSections { design, array };
        let mut pieces = exact.pieces_across(lenses, &stations, fit)?;
        let mut stations = stations;
        let mut restarts = 0;
        loop {
            match Self::refined(&exact, lenses, stations.clone(), pieces, fit) {
                Err(BrepError::SurfaceFit { .. }) if exact.has_spans() && pieces < MAX_PIECES => {
                    // between the first stations the spans bend more
                    pieces *= 2;
                }
                // The independent sample found a face moving between
                // stations where the refinement's midpoints did not: a
                // band span's edges (found-74146f9018634401: 0.21 µm at a
                // third of a 1.9 mm span against a 0.018 µm fit, the
                // creases following a gray image's blurred edge), or a
                // base lens's edge (found-fae34bbfc624b3e3: 1.8 µm at
                // t = 0.05 against a 0.094 µm fit, a shape profile's
                // 0.07 mm blur). Those samples become stations, and the
                // refinement goes on from there.
                Ok(Refined { family, misses }) if !misses.is_empty() && restarts < MAX_RESTARTS => {
                    stations = family.stations;
                    stations.extend(misses);
                    stations.sort_by(f64::total_cmp);
                    restarts += 1;
                }
                done => return done.map(|r| r.family),
            }
        }
    }

    /// Refines `stations` until the surfaces of `pieces` quadratics across
    /// lie within `fit` of the exact sections.
    fn refined(
        exact: &ExactSections,
        lenses: &[i64],
        mut stations: Vec<f64>,
        pieces: usize,
        fit: f64,
    ) -> Result<Refined, BrepError> {
        let array = exact.array;
        let mut sections = exact.at(lenses, &stations, pieces)?;
        for round in 0..MAX_ROUNDS {
            // Late rounds also halve spans just inside the fit: under a
            // periodic profile every span can sit a hair from it, and
            // each halving tips a neighbour over (found-f750fafefad97272:
            // rings, one new failing span a round, 1.03 fits each). The
            // share sinks every late round, because at a fixed share the
            // tipping goes on below it: found-ba11a4fed42c5c5d (rings on
            // a 109 mm lens) tipped two spans a round at 0.8 to 0.97 fits,
            // 1.57 mm a round, and ran out of rounds halfway along.
            let limit = if round < PATIENT_ROUNDS {
                fit
            } else {
                LATE_ROUND_SHARE.powi((round + 1 - PATIENT_ROUNDS) as i32) * fit
            };
            let surfaces = surfaces_of(lenses, &stations, &sections, pieces);
            let mids: Vec<f64> = stations.windows(2).map(|w| 0.5 * (w[0] + w[1])).collect();
            let arcs = exact.arcs_at(lenses, &mids)?;
            let knots = clamped_knots(&stations);
            // each span's worst distance at its middle, over all lenses
            let worst: Vec<f64> = (0..mids.len())
                .into_par_iter()
                .map(|s| {
                    let along = Along::at(&knots, mids[s]);
                    let mut worst = 0.0_f64;
                    for (l, k) in lenses.iter().enumerate() {
                        let section = along.section(&surfaces[k]);
                        for &t in &REFINE_T {
                            worst = worst.max(arcs[l][s].distance(t, section.point(t)));
                        }
                    }
                    worst
                })
                .collect();
            if worst.iter().all(|&d| d <= fit) {
                let (deviation, misses) =
                    verify(exact, lenses, &stations, &surfaces, VERIFY_SLACK * fit)?;
                return Ok(Refined {
                    family: LensFamily {
                        array,
                        stations,
                        surfaces,
                        deviation,
                        ends: WallEnds::default(),
                    },
                    misses,
                });
            }
            let failing: Vec<bool> = worst.iter().map(|&d| d > limit).collect();
            let mut refined = Vec::with_capacity(stations.len() * 2);
            for (s, w) in stations.windows(2).enumerate() {
                refined.push(w[0]);
                if failing[s] {
                    refined.push(mids[s]);
                }
            }
            refined.push(*stations.last().expect("two or more stations"));
            // the new stations are the failing mids, whose exact sections are at hand
            let new: Vec<f64> = (0..mids.len())
                .filter(|&s| failing[s])
                .map(|s| mids[s])
                .collect();
            let new_sections: Vec<Vec<Section>> = arcs
                .iter()
                .map(|per_mid| {
                    (0..mids.len())
                        .filter(|&s| failing[s])
                        .map(|s| per_mid[s].section(pieces))
                        .collect()
                })
                .collect();
            sections = merge_sections(&stations, &sections, &new, &new_sections, &refined);
            stations = refined;
        }
        Err(BrepError::SurfaceFit {
            array,
            stations: stations.len(),
            fit_mm: fit,
        })
    }
}

/// The worst deviation of several families, each named (`"revealer
/// lens"`), and where it is, in words.
pub fn worst_deviation(families: &[(&LensFamily, &str)]) -> (f64, String) {
    families
        .iter()
        .map(|(f, name)| {
            let (d, k, t, v) = f.deviation;
            (d, format!("{name} {k} at t = {t:.2}, v = {v:.3} mm"))
        })
        .fold((0.0, String::new()), |a, b| if b.0 > a.0 { b } else { a })
}

/// The cubic basis along the lenses at one station v, which every lens of a
/// family shares (their stations, hence knots, are the same): a lens's
/// section there costs four control points per row, not a basis per point.
struct Along {
    /// The first control point with a nonzero weight.
    first: usize,
    weights: [f64; 4],
}

impl Along {
    fn at(knots: &KnotVec, v: f64) -> Along {
        let basis = knots
            .try_bspline_basis_functions(3, v)
            .expect("v lies within the stations");
        let first = basis
            .iter()
            .position(|&b| b != 0.0)
            .unwrap_or(0)
            .min(basis.len().saturating_sub(4));
        let mut weights = [0.0; 4];
        for (w, b) in weights.iter_mut().zip(&basis[first..]) {
            *w = *b;
        }
        debug_assert!(basis
            .iter()
            .enumerate()
            .all(|(i, &b)| b == 0.0 || (first..first + 4).contains(&i)));
        Along { first, weights }
    }

    /// The homogeneous section of `surface` at this station.
    fn section(&self, surface: &NurbsSurface<Vector4>) -> Across {
        let rows = surface.control_points();
        Across(
            rows.iter()
                .map(|row| {
                    self.weights
                        .iter()
                        .zip(&row[self.first..])
                        .fold(Vector4::new(0.0, 0.0, 0.0, 0.0), |acc, (w, c)| {
                            acc + *c * *w
                        })
                })
                .collect(),
        )
    }
}

/// A lens surface's section across at one station: rational quadratic
/// pieces [P0, M0, P1, …] over equal parts of t.
struct Across(Vec<Vector4>);

impl Across {
    fn point(&self, t: f64) -> DVec3 {
        let pieces = (self.0.len() - 1) / 2;
        let scaled = t * pieces as f64;
        let j = (scaled.floor().max(0.0) as usize).min(pieces - 1);
        let (t, c) = (scaled - j as f64, &self.0[2 * j..]);
        let s = 1.0 - t;
        let h = c[0] * (s * s) + c[1] * (2.0 * s * t) + c[2] * (t * t);
        DVec3::new(h.x / h.w, h.y / h.w, h.z / h.w)
    }
}

/// The exact sections of one array, with base creases computed once per
/// station and shared by the two lenses that meet there.
struct ExactSections<'a> {
    design: &'a Design,
    array: Array,
}

impl ExactSections<'_> {
    /// arcs[lens position][station]
    fn arcs_at<'d>(
        &'d self,
        lenses: &[i64],
        stations: &[f64],
    ) -> Result<Vec<Vec<ExactSection<'d>>>, BrepError> {
        let d = self.design;
        let per_station: Vec<Vec<ExactSection>> = stations
            .par_iter()
            .map(|&v| -> Result<Vec<ExactSection>, BrepError> {
                match self.array {
                    Array::Revealer => Ok(lenses
                        .iter()
                        .map(|&i| ExactSection::Arc(d.revealer_arc(i, v)))
                        .collect()),
                    Array::Base => {
                        let mut creases = BTreeMap::new();
                        let mut near = None;
                        for &k in lenses {
                            for c in [k, k + 1] {
                                if let std::collections::btree_map::Entry::Vacant(e) =
                                    creases.entry(c)
                                {
                                    let u = d.base_crease_u_near(c, v, near)?;
                                    let step = d.crease_phase(c + 1) - d.crease_phase(c);
                                    near = Some(u + step * d.params.period);
                                    e.insert(u);
                                }
                            }
                        }
                        Ok(lenses
                            .iter()
                            .map(|&k| {
                                match d.base_section_between(creases[&k], creases[&(k + 1)], v) {
                                    BaseSection::Lens(arc) => ExactSection::Arc(arc),
                                    band => ExactSection::Span(band),
                                }
                            })
                            .collect())
                    }
                }
            })
            .collect::<Result<_, _>>()?;
        Ok((0..lenses.len())
            .map(|l| per_station.iter().map(|s| s[l]).collect())
            .collect())
    }

    /// sections[lens position][station]
    fn at(
        &self,
        lenses: &[i64],
        stations: &[f64],
        pieces: usize,
    ) -> Result<Vec<Vec<Section>>, BrepError> {
        Ok(self
            .arcs_at(lenses, stations)?
            .iter()
            .map(|arcs| arcs.iter().map(|a| a.section(pieces)).collect())
            .collect())
    }

    /// Whether this array's sections are band spans (a printed base).
    fn has_spans(&self) -> bool {
        self.array == Array::Base && !matches!(self.design.params.base.kind, BaseKind::DualLens)
    }

    /// Quadratic pieces across each band span: the fewest (a power of two)
    /// that lie within a quarter of `fit` of every span at `stations`, at
    /// the quarters of every piece. One for lens arcs, which are exact.
    fn pieces_across(
        &self,
        lenses: &[i64],
        stations: &[f64],
        fit: f64,
    ) -> Result<usize, BrepError> {
        if !self.has_spans() {
            return Ok(1);
        }
        let spans = self.arcs_at(lenses, stations)?;
        let within = |pieces: usize| {
            spans.par_iter().flatten().all(|span| {
                let across = Across(span.section(pieces).into_iter().map(homogeneous).collect());
                (0..4 * pieces).all(|q| {
                    let t = (q as f64 + 0.5) / (4 * pieces) as f64;
                    span.distance(t, across.point(t)) <= fit / 4.0
                })
            })
        };
        let mut pieces = 1;
        while pieces < MAX_PIECES && !within(pieces) {
            pieces *= 2;
        }
        Ok(pieces)
    }
}

fn merge_sections(
    old_stations: &[f64],
    old: &[Vec<Section>],
    new_stations: &[f64],
    new: &[Vec<Section>],
    merged: &[f64],
) -> Vec<Vec<Section>> {
    (0..old.len())
        .map(|l| {
            let (mut i, mut j) = (0, 0);
            merged
                .iter()
                .map(|&v| {
                    if i < old_stations.len() && old_stations[i] == v {
                        i += 1;
                        old[l][i - 1].clone()
                    } else {
                        debug_assert_eq!(new_stations[j], v);
                        j += 1;
                        new[l][j - 1].clone()
                    }
                })
                .collect()
        })
        .collect()
}

fn surfaces_of(
    lenses: &[i64],
    stations: &[f64],
    sections: &[Vec<Section>],
    pieces: usize,
) -> BTreeMap<i64, NurbsSurface<Vector4>> {
    let knots = (across_knots(pieces), clamped_knots(stations));
    lenses
        .par_iter()
        .enumerate()
        .map(|(l, &k)| {
            let rows: Vec<Vec<Vector4>> = (0..2 * pieces + 1)
                .map(|row| {
                    let data: Vec<[f64; 4]> = sections[l].iter().map(|s| s[row]).collect();
                    interpolate(stations, &data)
                        .into_iter()
                        .map(homogeneous)
                        .collect()
                })
                .collect();
            (
                k,
                NurbsSurface::new(BSplineSurface::new(knots.clone(), rows)),
            )
        })
        .collect()
}

/// A homogeneous control point as truck holds it.
fn homogeneous(c: [f64; 4]) -> Vector4 {
    Vector4::new(c[0], c[1], c[2], c[3])
}

/// Quadratic knots across `pieces` equal parts of [0, 1], each inner knot
/// doubled (the pieces meet with C⁰ at P_j): Bézier knots for one piece.
fn across_knots(pieces: usize) -> KnotVec {
    if pieces == 1 {
        return KnotVec::bezier_knot(2);
    }
    let mut knots = vec![0.0; 3];
    for j in 1..pieces {
        let k = j as f64 / pieces as f64;
        knots.extend([k, k]);
    }
    knots.extend([1.0; 3]);
    KnotVec::from(knots)
}

/// The worst distance of an independent sample (other span fractions and
/// other t than refinement used) from the exact arcs, and the stations of
/// the samples farther than `limit`.
fn verify(
    exact: &ExactSections,
    lenses: &[i64],
    stations: &[f64],
    surfaces: &BTreeMap<i64, NurbsSurface<Vector4>>,
    limit: f64,
) -> Result<(Deviation, Vec<f64>), BrepError> {
    let sample_v: Vec<f64> = stations
        .windows(2)
        .flat_map(|w| VERIFY_S.map(|s| w[0] + s * (w[1] - w[0])))
        .collect();
    let arcs = exact.arcs_at(lenses, &sample_v)?;
    let knots = clamped_knots(stations);
    let along: Vec<Along> = sample_v.iter().map(|&v| Along::at(&knots, v)).collect();
    let worst = lenses
        .par_iter()
        .enumerate()
        .map(|(l, &k)| {
            let mut worst = (0.0f64, k, 0.0, 0.0);
            let mut missed = vec![false; sample_v.len()];
            for (s, &v) in sample_v.iter().enumerate() {
                let section = along[s].section(&surfaces[&k]);
                for t in VERIFY_T {
                    let d = arcs[l][s].distance(t, section.point(t));
                    missed[s] |= d > limit;
                    if d > worst.0 {
                        worst = (d, k, t, v);
                    }
                }
            }
            (worst, missed)
        })
        .reduce(
            || ((0.0, i64::MIN, 0.0, 0.0), vec![false; sample_v.len()]),
            |(a, missed_a), (b, missed_b)| {
                let missed = missed_a
                    .iter()
                    .zip(&missed_b)
                    .map(|(x, y)| *x || *y)
                    .collect();
                if b.0 > a.0 || (b.0 == a.0 && b.1 < a.1) {
                    (b, missed)
                } else {
                    (a, missed)
                }
            },
        );
    let (worst, missed) = worst;
    let misses = sample_v
        .iter()
        .zip(missed)
        .filter(|(_, m)| *m)
        .map(|(&v, _)| v)
        .collect();
    Ok((worst, misses))
}

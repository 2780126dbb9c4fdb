//! Curve-guided vector field with greedy curve orientation (Xu et al., "Feature-Aligned Shape
//! Texturing", §4): a smooth tangent field that follows un-oriented feature curves.
//!
//! * §4.1 preprocessing (joining close-by segments, breaking at sharp turns) is in
//!   [`super::curve_grouping`].
//! * §4.2 field: three scalar solves (x, y, z) of (L + P) x = P b, L = D − W the cotangent
//!   Laplacian ([`crate::geom::laplacian::cotan_weights`], whose weights are clamped to a small
//!   positive floor on obtuse triangles, see there), P diagonal with α (paper: 10⁸) at
//!   constrained vertices, b the signed unit tangent of the curve. The result is projected to
//!   the vertex tangent planes and normalized (the paper projects "as in [Praun et al. 2000]").
//! * §4.1 greedy orientation: the longest curve gets +1 (or, when the user fixed some curves'
//!   directions, those curves get theirs, the paper's remedy for symmetric spokes made per
//!   curve; see [`feature_field_with`]); then repeatedly every un-oriented
//!   curve c is scored by eq. (1), g(c, u) = max{Σ (π−θ_p)/(π+θ_p), Σ θ_p/(2π−θ_p)}, against
//!   the current field u; the best one is oriented (+1 if the first sum wins, −1 if the
//!   second) and the field re-solved, until all curves are oriented. `Arbitrary` gives each
//!   curve a seeded random sign and solves once (the comparison of the paper's Figs. 3 and 6).
//!
//! Updating the field between greedy steps (§4.2 "Implementation"): the paper updates a
//! supernodal Cholesky factor with a low-rank modification (Davis & Hager 2006, CHOLMOD). Here
//! adding a curve only raises diagonal entries of L + P, so the sparsity pattern never
//! changes: the fill-reducing ordering and symbolic factorization are computed once
//! ([`crate::linalg::SpdPattern`]) and every step redoes only the numeric factorization,
//! which gives exactly the system a fresh factorization would solve. The Woodbury identity was
//! the alternative for a step that adds k constraints: it needs k solves with the current
//! factor plus a k×k dense system, and a curve on a 400k-triangle mesh has hundreds of
//! vertices, so k solves (each ~4·nnz(L) flops) cost more than one numeric factorization;
//! measured below.
//!
//! Measured (ignored test `timing_on_a_400k_triangle_torus`, release, faer sequential, on a
//! shared 2-core machine; two runs, the first under load from other jobs): twice-subdivided
//! torus, 409,600 triangles / 204,800 vertices, 30 curves with 5,726 vertices. Laplacian
//! assembly with the symbolic analysis 0.25–0.48 s; first numeric factorization 0.28–0.56 s
//! (goal < 3 s for both: met); each greedy step 0.34–0.68 s mean (goal < 0.1 s: missed), of which the numeric
//! refactorization is 0.28–0.42 s and the three-column solve 0.06–0.09 s. A fresh
//! factorization (`SpdSolver`) takes 0.42–0.71 s, so keeping the symbolic analysis saves about
//! a third per step; Woodbury for the mean curve (190 vertices) needs a 190-column solve,
//! 1.7–2.7 s, so it loses by 4–6× and is not used. Whole greedy run: 10.5–21 s for 30 curves
//! (paper: "under one minute" for 400K triangles, ~1 s per step, with CHOLMOD's supernodal
//! update). Singularities there: greedy 0, arbitrary signs 24.8–26 (mean of 10 seeds).
//!
//! Choices where the paper is silent:
//! * Tangent at a curve vertex: central difference of its two path neighbours (one-sided at
//!   open ends), normalized, times the curve's sign. A vertex on several oriented curves
//!   (curves meeting at a break vertex or crossing) is constrained to the normalized sum of
//!   their signed tangents; if they cancel (opposite directions) it is constrained to zero, a
//!   genuine conflict the field cannot satisfy either way.
//! * Mesh components without any constrained vertex: L alone is singular there, so those
//!   vertices get a tiny diagonal regularization (10⁻⁸ × the mean diagonal of L), whose
//!   solution there is zero; in the final field they get a fallback: the global x axis
//!   projected to the tangent plane (y where x is nearly normal). During greedy steps they
//!   stay zero, so curves in a component no oriented curve has reached yet score θ = π/2 at
//!   every vertex (n/3, sign +1). Components that do have constraints are not regularized, so
//!   their field is exactly the paper's.
//! * Where the projected field is shorter than 10⁻⁹ it is left zero and counted
//!   (`FeatureField::zero_vectors`).
//! * In g(c, u), θ_p is the angle between the curve tangent and u(p), both projected to the
//!   tangent plane at p; where either is ~zero, θ_p = π/2 (both terms 1/3: no preference). A
//!   tie between the two sums picks +1; a tie between curves picks the lower index.
//! * Arbitrary signs: bit 0 of `counter_hash(orientation_seed, stream, curve index)`.
//!
//! faer runs sequentially (as in [`crate::linalg::SpdSolver`]), and the only rayon use is
//! per-vertex / per-curve / per-triangle maps, so results are identical for any thread count.

use super::curve_grouping::group_and_break;
use crate::check::{ParamError, check_range};
use crate::extract::crease_lines::{Polyline, polyline_length};
use crate::geom::Mesh;
use crate::geom::laplacian::cotan_weights;
use crate::linalg::{SolveError, SpdFactor, SpdPattern};
use glam::{DVec3, Vec3};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;
use std::time::Instant;
use texsyn_core::algorithm::Failure;
use texsyn_core::math::PureMath;

/// The `feature_field` node's algorithm and version (part of its key; bump on any change of output).
pub const NODE: texsyn_core::algorithm::Algorithm =
    texsyn_core::algorithm::Algorithm::new("feature_field", 2);

/// Stream of `counter_hash` for arbitrary curve signs.
const SIGN_STREAM: u64 = 0x5167_0001;

/// Curve indices with their signs, in the order they were oriented.
type Signed = Vec<(usize, i8)>;

/// How curve signs are chosen.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Orientation {
    /// The paper's incremental algorithm (§4.1).
    Greedy,
    /// A seeded random sign per curve, solved once (for comparison, Figs. 3 and 6).
    Arbitrary,
    /// Every curve along its vertex order as given, solved once: as if every curve were
    /// fixed (`extract.curves[i].fixed`, see [`feature_field_with`]). For an edited
    /// `lines.obj` (written oriented as the field follows each curve) given back as the curves
    /// file. A curve joined from pieces (`join_distance`) follows most of its edges.
    Given,
}

/// Parameters of [`feature_field`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct FeatureFieldParams {
    /// How curve orientations are chosen: "greedy" (the paper), "arbitrary" (seeded random
    /// signs, for comparison) or "given" (each curve's own vertex order). Default: greedy.
    pub orientation: Orientation,
    /// Seed of the arbitrary signs; unused by greedy. Default: 1.
    pub orientation_seed: u64,
    /// Penalty weight α of the curve constraints (eq. 2), 1..=1e12. Default: 1e8, the paper's
    /// value; larger makes the field follow the curves more exactly, smaller lets it deviate
    /// to be smoother.
    pub alpha: f64,
    /// Largest gap between two curve ends that are joined into one curve, as a fraction of
    /// the bounding box's diagonal, 0..=1 (0: join only curves ending at the same vertex).
    /// Default: 0.02, a few edges on typical meshes: crease lines broken by noise are joined,
    /// separate features rarely.
    pub join_distance: f32,
    /// Largest turn, in degrees (1..=180), along a curve and across a joined gap: curves are
    /// broken where they turn more, and ends are joined only when their directions agree
    /// within it. Default: 60: a cube's 90° corners break, a staircase of mesh edges along a
    /// smooth feature does not (turns are measured over 3 edges).
    pub break_angle: f32,
    /// A rotation of the texture against the field, in degrees (-180..=180): every vector is
    /// turned by it about its vertex normal (counter-clockwise seen from outside), so the
    /// exemplar's line runs at this angle to the curves. Default: 0. Left out of the node's
    /// key at 0.
    #[serde(skip_serializing_if = "is_zero")]
    pub rotation: f32,
}

/// Whether a key-omittable parameter is at its default 0.
pub(crate) fn is_zero(x: &f32) -> bool {
    *x == 0.0
}

impl Default for FeatureFieldParams {
    fn default() -> Self {
        FeatureFieldParams {
            orientation: Orientation::Greedy,
            orientation_seed: 1,
            alpha: 1e8,
            join_distance: 0.02,
            break_angle: 60.0,
            rotation: 0.0,
        }
    }
}

impl FeatureFieldParams {
    pub fn validate(&self) -> Result<(), ParamError> {
        check_range("field.alpha", self.alpha, 1.0, 1e12)?;
        check_range("field.join_distance", self.join_distance, 0.0, 1.0)?;
        check_range("field.break_angle", self.break_angle, 1.0, 180.0)?;
        check_range("field.rotation", self.rotation, -180.0, 180.0)
    }
}

/// Each of `vectors` turned by `degrees` about its vertex's unit normal (Rodrigues, for a
/// tangent vector: `v cos θ + (n × v) sin θ`), renormalized; zero vectors stay zero.
pub fn rotate_about_normals(vectors: &mut [Vec3], normals: &[Vec3], degrees: f32) {
    let (sin, cos) = degrees.to_radians().sin_cos_pure();
    for (v, n) in vectors.iter_mut().zip(normals) {
        if *v != Vec3::ZERO {
            let t = *v - *n * n.dot(*v);
            *v = (t * cos + n.cross(t) * sin).normalize_or(*v);
        }
    }
}

/// The curve-guided field.
#[derive(Clone, Debug, PartialEq)]
pub struct FeatureField {
    /// One unit tangent per vertex (zero where the field vanished).
    pub vectors: Vec<Vec3>,
    /// The curves after preprocessing, in the order they were oriented, each with its sign
    /// (+1: along its vertex order).
    pub curves: Vec<(Polyline, i8)>,
    /// Per curve: it holds a curve the user fixed, so its sign is theirs.
    pub fixed: Vec<bool>,
    /// Triangles holding a singularity ([`count_singularities`]).
    pub singularities: u32,
    /// Vertices where the projected field vanished (left zero).
    pub zero_vectors: u32,
}

/// Wall-clock times; not part of the result (times are not deterministic).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct FieldTimings {
    /// Assembling the cotangent Laplacian and the components, and the symbolic analysis
    /// (ordering, elimination tree).
    pub setup_secs: f64,
    /// The first numeric factorization.
    pub factorization_secs: f64,
    /// Each later greedy step: numeric refactorization, three-column solve, projection and
    /// scoring of the remaining curves.
    pub step_secs: Vec<f64>,
}

#[derive(Debug, thiserror::Error)]
pub enum FeatureFieldError {
    #[error(
        "no feature curves to align to: none is left after preprocessing (each needs two \
         vertices); extract more feature lines (e.g. lower extract.crease.angle, extract.crest.threshold or the min_length of either)"
    )]
    NoCurves,
    #[error("feature curve {curve} names vertex {vertex}, but the mesh has {count} vertices")]
    BadVertex {
        curve: usize,
        vertex: u32,
        count: usize,
    },
    #[error("the feature field could not be solved ({0}); try a smaller field.alpha")]
    Solve(#[from] SolveError),
    #[error(transparent)]
    Params(#[from] ParamError),
}

/// §4.1 preprocessing with the thresholds of `p` (see [`super::curve_grouping`]); `fixed` as
/// in [`feature_field_with`]. Each curve comes with the sign its fixed pieces keep, if any.
pub fn preprocess_curves(
    mesh: &Mesh,
    curves: &[Polyline],
    fixed: &[bool],
    p: &FeatureFieldParams,
) -> Vec<(Polyline, Option<i8>)> {
    let (lo, hi) = mesh.bounds();
    group_and_break(
        mesh,
        curves,
        fixed,
        p.join_distance * (hi - lo).length(),
        p.break_angle,
    )
}

/// The field of `curves` (see the module doc), with timings; no curve fixed.
pub fn feature_field(
    mesh: &Mesh,
    curves: &[Polyline],
    p: &FeatureFieldParams,
) -> Result<(FeatureField, FieldTimings), FeatureFieldError> {
    feature_field_with(mesh, curves, &[], p, &|_| {})
}

/// [`feature_field`] with some curves fixed (`fixed[i]` for `curves[i]`; a shorter slice
/// leaves the rest free), reporting the fraction done to `progress`: the setup, then each
/// greedy step (one per curve, each a refactorization and solve of about the same cost).
///
/// A fixed curve keeps its own vertex order: the paper's remedy for §4.1's limitation
/// ("for symmetric configurations such as spokes … the user can specify the orientation of
/// one curve") made per curve. The greedy step then starts from the fixed curves, all
/// oriented at once, instead of from the longest curve, and orients the rest around them;
/// arbitrary signs leave fixed curves as they are; `Given` fixes every curve. After §4.1's
/// joining and breaking, a piece follows the fixed curves it runs along ([`fixed_signs`]).
pub fn feature_field_with(
    mesh: &Mesh,
    curves: &[Polyline],
    fixed: &[bool],
    p: &FeatureFieldParams,
    progress: &(dyn Fn(f32) + Sync),
) -> Result<(FeatureField, FieldTimings), FeatureFieldError> {
    p.validate()?;
    check_vertices(mesh, curves)?;
    let fixed: Vec<bool> = match p.orientation {
        Orientation::Given => vec![true; curves.len()],
        _ => (0..curves.len())
            .map(|i| fixed.get(i).copied().unwrap_or(false))
            .collect(),
    };
    let (curves, kept): (Vec<Polyline>, Vec<Option<i8>>) =
        preprocess_curves(mesh, curves, &fixed, p)
            .into_iter()
            .unzip();
    if curves.is_empty() {
        return Err(FeatureFieldError::NoCurves);
    }
    let mut timings = FieldTimings::default();
    let t = Instant::now();
    let sys = FieldSystem::new(mesh, p.alpha)?;
    timings.setup_secs = t.elapsed().as_secs_f64();
    progress(0.05);

    let (order, raw) = match p.orientation {
        Orientation::Arbitrary | Orientation::Given => {
            let signed: Vec<(usize, i8)> = (0..curves.len())
                .map(|c| {
                    let h = crate::random::counter_hash(p.orientation_seed, SIGN_STREAM, c as u64);
                    let arbitrary = if h & 1 == 0 { 1 } else { -1 };
                    (c, kept[c].unwrap_or(arbitrary))
                })
                .collect();
            let t = Instant::now();
            let mut upd = sys.updater();
            upd.add(&curves, &signed)?;
            timings.factorization_secs = t.elapsed().as_secs_f64();
            let raw = upd.field(&curves)?;
            (signed, raw)
        }
        Orientation::Greedy => greedy(&sys, &curves, &kept, &mut timings, progress)?,
    };
    progress(1.0);
    let mut vectors = raw;
    sys.apply_fallback(
        &mut vectors,
        &constrained_mask(mesh.vertex_count(), &curves, &order),
    );
    let zero_vectors = vectors.iter().filter(|v| **v == Vec3::ZERO).count() as u32;
    let singularities = count_singularities(mesh, &vectors);
    let fixed = match p.orientation {
        // Every curve keeps its direction there, but none was marked fixed.
        Orientation::Given => vec![false; order.len()],
        _ => order.iter().map(|&(c, _)| kept[c].is_some()).collect(),
    };
    let curves = order
        .into_iter()
        .map(|(c, s)| (curves[c].clone(), s))
        .collect();
    Ok((
        FeatureField {
            vectors,
            curves,
            fixed,
            singularities,
            zero_vectors,
        },
        timings,
    ))
}

fn check_vertices(mesh: &Mesh, curves: &[Polyline]) -> Result<(), FeatureFieldError> {
    let count = mesh.vertex_count();
    for (i, c) in curves.iter().enumerate() {
        if let Some(&v) = c.vertices.iter().find(|&&v| v as usize >= count) {
            return Err(FeatureFieldError::BadVertex {
                curve: i,
                vertex: v,
                count,
            });
        }
    }
    Ok(())
}

/// §4.1's greedy orientation, starting from the curves whose sign is `kept` (all at once),
/// or from the longest curve (+1) when none is.
fn greedy(
    sys: &FieldSystem,
    curves: &[Polyline],
    kept: &[Option<i8>],
    timings: &mut FieldTimings,
    progress: &(dyn Fn(f32) + Sync),
) -> Result<(Signed, Vec<Vec3>), FeatureFieldError> {
    let mesh = sys.mesh;
    let mut order: Signed = (0..curves.len())
        .filter_map(|c| kept[c].map(|s| (c, s)))
        .collect();
    if order.is_empty() {
        let lengths: Vec<f32> = curves.iter().map(|c| polyline_length(mesh, c)).collect();
        let mut first = 0;
        for c in 1..curves.len() {
            if lengths[c] > lengths[first] {
                first = c;
            }
        }
        order.push((first, 1));
    }
    let mut oriented = vec![false; curves.len()];
    for &(c, _) in &order {
        oriented[c] = true;
    }
    let t = Instant::now();
    let mut upd = sys.updater();
    upd.add(curves, &order)?;
    timings.factorization_secs = t.elapsed().as_secs_f64();
    let mut field = upd.field(curves)?;
    while order.len() < curves.len() {
        let t = Instant::now();
        let rest: Vec<usize> = (0..curves.len()).filter(|&c| !oriented[c]).collect();
        let scores: Vec<(f64, i8)> = rest
            .par_iter()
            .map(|&c| consistency_score(mesh, &curves[c], &field))
            .collect();
        let mut best = 0;
        for k in 1..rest.len() {
            if scores[k].0 > scores[best].0 {
                best = k;
            }
        }
        let pick = (rest[best], scores[best].1);
        oriented[pick.0] = true;
        order.push(pick);
        upd.add(curves, &[pick])?;
        field = upd.field(curves)?;
        timings.step_secs.push(t.elapsed().as_secs_f64());
        progress(0.05 + 0.95 * order.len() as f32 / curves.len() as f32);
    }
    Ok((order, field))
}

/// One fresh solve of the field of already oriented curves (fallback applied), for
/// comparisons and tests.
pub fn solve_field(
    mesh: &Mesh,
    curves: &[(Polyline, i8)],
    alpha: f64,
) -> Result<Vec<Vec3>, FeatureFieldError> {
    check_vertices(
        mesh,
        &curves.iter().map(|c| c.0.clone()).collect::<Vec<_>>(),
    )?;
    let plain: Vec<Polyline> = curves.iter().map(|c| c.0.clone()).collect();
    let signed: Vec<(usize, i8)> = curves.iter().enumerate().map(|(i, c)| (i, c.1)).collect();
    let sys = FieldSystem::new(mesh, alpha)?;
    let mut upd = sys.updater();
    upd.add(&plain, &signed)?;
    let mut v = upd.field(&plain)?;
    sys.apply_fallback(
        &mut v,
        &constrained_mask(mesh.vertex_count(), &plain, &signed),
    );
    Ok(v)
}

fn constrained_mask(n: usize, curves: &[Polyline], signed: &[(usize, i8)]) -> Vec<bool> {
    let mut m = vec![false; n];
    for &(c, _) in signed {
        for &v in &curves[c].vertices {
            m[v as usize] = true;
        }
    }
    m
}

/// Unit tangent of `c` at its k-th vertex (along the vertex order; see the module doc).
fn curve_tangent(mesh: &Mesh, c: &Polyline, k: usize) -> DVec3 {
    let m = c.vertices.len();
    let p = |i: usize| mesh.positions[c.vertices[i] as usize].as_dvec3();
    let (a, b) = if c.closed && m > 2 {
        ((k + m - 1) % m, (k + 1) % m)
    } else {
        (k.saturating_sub(1), (k + 1).min(m - 1))
    };
    (p(b) - p(a)).normalize_or_zero()
}

/// The cotangent Laplacian with its symbolic factorization, and the mesh's components.
pub struct FieldSystem<'a> {
    mesh: &'a Mesh,
    alpha: f64,
    pattern: SpdPattern,
    component: Vec<u32>,
    components: usize,
    regularization: f64,
    /// The L triplets, kept so tests can build the same system for a fresh solver.
    triplets: Vec<(usize, usize, f64)>,
}

impl<'a> FieldSystem<'a> {
    pub fn new(mesh: &'a Mesh, alpha: f64) -> Result<Self, SolveError> {
        let n = mesh.vertex_count();
        let w = cotan_weights(mesh);
        let mut diag = vec![0.0f64; n];
        let mut triplets = Vec::with_capacity(w.len() + n);
        for &(i, j, x) in &w {
            triplets.push((j as usize, i as usize, -x));
            diag[i as usize] += x;
            diag[j as usize] += x;
        }
        triplets.extend(diag.iter().enumerate().map(|(i, &d)| (i, i, d)));
        let nonzero: Vec<f64> = diag.iter().copied().filter(|&d| d > 0.0).collect();
        let mean = if nonzero.is_empty() {
            1.0
        } else {
            nonzero.iter().sum::<f64>() / nonzero.len() as f64
        };
        // Components by union-find over triangle edges.
        let mut parent: Vec<u32> = (0..n as u32).collect();
        fn find(parent: &mut [u32], mut v: u32) -> u32 {
            while parent[v as usize] != v {
                parent[v as usize] = parent[parent[v as usize] as usize];
                v = parent[v as usize];
            }
            v
        }
        for t in &mesh.triangles {
            for k in 1..3 {
                let (a, b) = (find(&mut parent, t[0]), find(&mut parent, t[k]));
                if a != b {
                    parent[a.max(b) as usize] = a.min(b);
                }
            }
        }
        let mut label = vec![u32::MAX; n];
        let mut component = vec![0u32; n];
        let mut components = 0;
        for v in 0..n {
            let r = find(&mut parent, v as u32) as usize;
            if label[r] == u32::MAX {
                label[r] = components as u32;
                components += 1;
            }
            component[v] = label[r];
        }
        let pattern = SpdPattern::new(n, &triplets)?;
        Ok(FieldSystem {
            mesh,
            alpha,
            pattern,
            component,
            components,
            regularization: 1e-8 * mean,
            triplets,
        })
    }

    /// Lower-triangle triplets of L (for building the same system elsewhere).
    pub fn laplacian_triplets(&self) -> &[(usize, usize, f64)] {
        &self.triplets
    }

    pub fn updater(&self) -> Updater<'_, 'a> {
        Updater {
            sys: self,
            signed: Vec::new(),
            factor: None,
        }
    }

    /// The diagonal added to L for the constraint set `mask`: α at constrained vertices, the
    /// regularization in components without any.
    fn extra_diagonal(&self, mask: &[bool]) -> Vec<f64> {
        let mut has = vec![false; self.components];
        for (v, &m) in mask.iter().enumerate() {
            if m {
                has[self.component[v] as usize] = true;
            }
        }
        (0..mask.len())
            .map(|v| {
                if mask[v] {
                    self.alpha
                } else if !has[self.component[v] as usize] {
                    self.regularization
                } else {
                    0.0
                }
            })
            .collect()
    }

    /// Fills vertices of components without constraints with the projected global axis.
    fn apply_fallback(&self, field: &mut [Vec3], mask: &[bool]) {
        let mut has = vec![false; self.components];
        for (v, &m) in mask.iter().enumerate() {
            if m {
                has[self.component[v] as usize] = true;
            }
        }
        let normals = self.mesh.vertex_normals();
        for v in 0..field.len() {
            if has[self.component[v] as usize] {
                continue;
            }
            let n = normals[v];
            let x = Vec3::X - n * n.dot(Vec3::X);
            field[v] = if x.length() > 0.1 {
                x.normalize()
            } else {
                (Vec3::Y - n * n.dot(Vec3::Y)).normalize_or_zero()
            };
        }
    }
}

/// The factorization of L + P for a growing set of oriented curves.
pub struct Updater<'s, 'a> {
    sys: &'s FieldSystem<'a>,
    signed: Vec<(usize, i8)>,
    factor: Option<SpdFactor>,
}

impl Updater<'_, '_> {
    /// Adds oriented curves (indices into `curves`) and updates the factorization: a numeric
    /// refactorization with the symbolic analysis kept (see the module doc).
    pub fn add(&mut self, curves: &[Polyline], signed: &[(usize, i8)]) -> Result<(), SolveError> {
        self.signed.extend_from_slice(signed);
        let mask = constrained_mask(self.sys.mesh.vertex_count(), curves, &self.signed);
        self.factor = Some(
            self.sys
                .pattern
                .factorize(&self.sys.extra_diagonal(&mask))?,
        );
        Ok(())
    }

    /// The constraint vectors b (zero where unconstrained).
    fn constraints(&self, curves: &[Polyline]) -> Vec<DVec3> {
        let mesh = self.sys.mesh;
        let mut b = vec![DVec3::ZERO; mesh.vertex_count()];
        // Summed in the order curves were added: a fixed order.
        for &(c, s) in &self.signed {
            for k in 0..curves[c].vertices.len() {
                b[curves[c].vertices[k] as usize] += curve_tangent(mesh, &curves[c], k) * s as f64;
            }
        }
        for x in &mut b {
            *x = x.normalize_or_zero();
        }
        b
    }

    /// Raw solution of (L + P) x = P b, three columns (x, y, z), column-major.
    pub fn solve_raw(&self, curves: &[Polyline]) -> Vec<f64> {
        let n = self.sys.mesh.vertex_count();
        let b = self.constraints(curves);
        let mut rhs = vec![0.0f64; 3 * n];
        for v in 0..n {
            for c in 0..3 {
                rhs[c * n + v] = self.sys.alpha * b[v][c];
            }
        }
        self.factor
            .as_ref()
            .expect("add() before solving")
            .solve(&mut rhs, 3);
        rhs
    }

    /// The solution projected to the tangent planes and normalized; zero in components
    /// without constraints and where the projection vanished.
    pub fn field(&self, curves: &[Polyline]) -> Result<Vec<Vec3>, SolveError> {
        let n = self.sys.mesh.vertex_count();
        let x = self.solve_raw(curves);
        let normals = self.sys.mesh.vertex_normals();
        Ok((0..n)
            .into_par_iter()
            .map(|v| {
                let u = DVec3::new(x[v], x[n + v], x[2 * n + v]);
                let nv = normals[v].as_dvec3();
                let t = u - nv * nv.dot(u);
                let len = t.length();
                if len.is_finite() && len > 1e-9 {
                    (t / len).as_vec3()
                } else {
                    Vec3::ZERO
                }
            })
            .collect())
    }
}

/// Eq. (1): g(c, u) and the sign it picks (+1: the curve's vertex order agrees with u).
pub fn consistency_score(mesh: &Mesh, curve: &Polyline, field: &[Vec3]) -> (f64, i8) {
    let normals = mesh.vertex_normals();
    let (mut agree, mut oppose) = (0.0f64, 0.0f64);
    for k in 0..curve.vertices.len() {
        let v = curve.vertices[k] as usize;
        let n = normals[v].as_dvec3();
        let t = curve_tangent(mesh, curve, k);
        let u = field[v].as_dvec3();
        let (t, u) = (t - n * n.dot(t), u - n * n.dot(u));
        let theta = if t.length() < 1e-6 || u.length() < 1e-6 {
            PI / 2.0
        } else {
            t.normalize()
                .dot(u.normalize())
                .clamp(-1.0, 1.0)
                .acos_pure()
        };
        agree += (PI - theta) / (PI + theta);
        oppose += theta / (2.0 * PI - theta);
    }
    if agree >= oppose {
        (agree, 1)
    } else {
        (oppose, -1)
    }
}

/// Index of the field around triangle f (see [`count_singularities`]); None if a corner
/// vector is zero or the triangle is degenerate.
fn triangle_index(mesh: &Mesh, field: &[Vec3], f: usize) -> Option<i32> {
    let n = mesh
        .face_normal_unnormalized(f)
        .as_dvec3()
        .normalize_or_zero();
    if n == DVec3::ZERO {
        return None;
    }
    let t = mesh.triangles[f];
    let mut w = [DVec3::ZERO; 3];
    for k in 0..3 {
        let u = field[t[k] as usize].as_dvec3();
        w[k] = u - n * n.dot(u);
        if w[k].length() < 1e-9 {
            return None;
        }
    }
    let mut sum = 0.0;
    for k in 0..3 {
        let (a, b) = (w[k], w[(k + 1) % 3]);
        sum += n.dot(a.cross(b)).atan2_pure(a.dot(b));
    }
    Some((sum / (2.0 * PI)).round() as i32)
}

/// Triangles holding a singularity: the corner vectors, projected into the triangle's plane,
/// turn by ±2π (not 0) going once around the corners. Triangles with a zero corner vector are
/// skipped, so a singularity sitting exactly on a vertex (field zero there) is not counted.
pub fn count_singularities(mesh: &Mesh, field: &[Vec3]) -> u32 {
    singularity_indices(mesh, field).0
}

/// (number of singular triangles, sum of their indices).
pub fn singularity_indices(mesh: &Mesh, field: &[Vec3]) -> (u32, i32) {
    let idx: Vec<i32> = (0..mesh.face_count())
        .into_par_iter()
        .map(|f| triangle_index(mesh, field, f).unwrap_or(0))
        .collect();
    (
        idx.iter().filter(|&&i| i != 0).count() as u32,
        idx.iter().sum(),
    )
}

/// The field of §4 with what the run reports about it: singularities of the greedy
/// orientation and of one arbitrary orientation of the same curves (Fig. 3, Fig. 6).
pub struct OrientedField {
    pub field: FeatureField,
    pub arbitrary_singularities: u32,
}

/// The field node: the field of §4, and for the log and the report the paper's comparison
/// (Fig. 3, Fig. 6), the singularities of the same curves arbitrarily oriented.
/// `fixed[i]`: `curves[i]` keeps its direction (see [`feature_field_with`]).
pub fn node(
    mesh: &Mesh,
    curves: &[Polyline],
    fixed: &[bool],
    p: &FeatureFieldParams,
    progress: &(dyn Fn(f32) + Sync),
) -> Result<OrientedField, Failure> {
    // The arbitrary orientation's solve (for the report's comparison) is one factorization:
    // about as long as a greedy step, so a small share at the end.
    let share = |f: f32| progress(0.95 * f);
    let (mut field, t) =
        feature_field_with(mesh, curves, fixed, p, &share).map_err(Failure::input)?;
    if p.rotation != 0.0 {
        rotate_about_normals(&mut field.vectors, mesh.vertex_normals(), p.rotation);
    }
    let mut steps = t.step_secs.clone();
    steps.sort_by(f64::total_cmp);
    let median = steps.get(steps.len() / 2).copied().unwrap_or(0.0);
    let other = match p.orientation {
        Orientation::Arbitrary => field.singularities,
        Orientation::Greedy | Orientation::Given => {
            let arbitrary = FeatureFieldParams {
                orientation: Orientation::Arbitrary,
                ..p.clone()
            };
            // The same curves (fixed ones kept as drawn, joined alike), signs seeded.
            let (f, _) = feature_field_with(mesh, curves, fixed, &arbitrary, &|_| {})
                .map_err(Failure::input)?;
            f.singularities
        }
    };
    tracing::info!(
        "field: {} curves oriented ({:?}); setup (Laplacian, symbolic analysis) {:.2} s, first factorization {:.2} s, {} steps, median {:.3} s; \
         {} singular triangles ({} with arbitrary orientation)",
        field.curves.len(),
        p.orientation,
        t.setup_secs,
        t.factorization_secs,
        t.step_secs.len(),
        median,
        field.singularities,
        other
    );
    Ok(OrientedField {
        field,
        arbitrary_singularities: other,
    })
}

/// The input mesh's field on the refined mesh: each new vertex the mean of its parents',
/// then projected to its tangent plane and normalized (zero stays zero).
pub fn carry_field(
    refined: &crate::geom::edge_refine::Refined,
    vectors: &[Vec3],
) -> Result<Vec<Vec3>, Failure> {
    if vectors.len() != refined.input_vertices as usize {
        return Err(Failure::internal("the field and the mesh disagree"));
    }
    let carried = refined.carry(vectors, |a, b| (a + b) * 0.5);
    let normals = refined.mesh.vertex_normals();
    Ok(carried
        .iter()
        .zip(normals)
        .map(|(v, n)| (*v - *n * v.dot(*n)).normalize_or_zero())
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::field::curve_grouping::shortest_path;
    use crate::geom::primitives::{grid, torus};
    use crate::linalg::SpdSolver;
    use crate::testing::assert_validation;

    /// A vertex path through the vertices nearest to `pts`, joined by shortest edge paths.
    fn trace(mesh: &Mesh, pts: &[Vec3], closed: bool) -> Polyline {
        let nearest = |q: Vec3| {
            (0..mesh.vertex_count())
                .min_by(|&a, &b| {
                    mesh.positions[a]
                        .distance_squared(q)
                        .total_cmp(&mesh.positions[b].distance_squared(q))
                })
                .unwrap() as u32
        };
        let mut ids: Vec<u32> = pts.iter().map(|&q| nearest(q)).collect();
        ids.dedup();
        if closed {
            ids.push(ids[0]);
        }
        let mut out = vec![ids[0]];
        for w in ids.windows(2) {
            let p = shortest_path(mesh, w[0], w[1], f64::INFINITY).unwrap();
            out.extend(p.into_iter().skip(1));
        }
        if closed {
            out.pop();
        }
        Polyline {
            vertices: out,
            closed,
        }
    }

    fn unit_grid(n: usize) -> Mesh {
        grid(n, 1.0 / (n - 1) as f32)
    }

    fn polyline(pts: impl Fn(f32) -> Vec3, samples: usize) -> Vec<Vec3> {
        (0..=samples)
            .map(|k| pts(k as f32 / samples as f32))
            .collect()
    }

    /// Tangent computed independently of the module: central difference along the path.
    fn tangent(mesh: &Mesh, c: &Polyline, k: usize) -> Vec3 {
        let m = c.vertices.len();
        let (a, b) = if c.closed {
            ((k + m - 1) % m, (k + 1) % m)
        } else {
            (k.saturating_sub(1), (k + 1).min(m - 1))
        };
        (mesh.positions[c.vertices[b] as usize] - mesh.positions[c.vertices[a] as usize])
            .normalize()
    }

    fn assert_follows(mesh: &Mesh, f: &FeatureField, max_deg: f32) {
        let mut uses = vec![0; mesh.vertex_count()];
        for (c, _) in &f.curves {
            for &v in &c.vertices {
                uses[v as usize] += 1;
            }
        }
        let normals = mesh.vertex_normals();
        let mut checked = 0;
        for (c, s) in &f.curves {
            for k in 0..c.vertices.len() {
                let v = c.vertices[k] as usize;
                if uses[v] != 1 {
                    continue;
                }
                let n = normals[v];
                let t = tangent(mesh, c, k) * *s as f32;
                let t = (t - n * n.dot(t)).normalize();
                let angle = f.vectors[v]
                    .dot(t)
                    .clamp(-1.0, 1.0)
                    .acos_pure()
                    .to_degrees();
                assert!(
                    angle < max_deg,
                    "vertex {v}: field is {angle}° off the curve"
                );
                checked += 1;
            }
        }
        assert!(checked > 50, "only {checked} vertices checked");
    }

    #[test]
    fn field_follows_each_oriented_curve_on_a_plane_and_a_torus() {
        let mesh = unit_grid(41);
        let curves = vec![
            trace(
                &mesh,
                &polyline(|t| Vec3::new(0.1 + 0.8 * t, 0.2, 0.0), 4),
                false,
            ),
            trace(
                &mesh,
                &polyline(
                    |t| {
                        let a = t * std::f32::consts::PI;
                        Vec3::new(0.5 + 0.25 * a.cos_pure(), 0.5 + 0.25 * a.sin_pure(), 0.0)
                    },
                    24,
                ),
                false,
            ),
            trace(
                &mesh,
                &polyline(|t| Vec3::new(0.1 + 0.8 * t, 0.95 - 0.1 * t, 0.0), 4),
                false,
            ),
        ];
        let (f, _) = feature_field(&mesh, &curves, &FeatureFieldParams::default()).unwrap();
        assert_eq!(f.curves.len(), 3);
        assert_follows(&mesh, &f, 5.0);

        let mesh = torus(64, 32, 0.6);
        let longitude = |j: u32| Polyline {
            vertices: (0..64).map(|i| i * 32 + j).collect(),
            closed: true,
        };
        let meridian_arc = Polyline {
            vertices: (3..9).map(|j| 5 * 32 + j).collect(),
            closed: false,
        };
        let curves = vec![longitude(0), longitude(12), longitude(20), meridian_arc];
        let (f, _) = feature_field(&mesh, &curves, &FeatureFieldParams::default()).unwrap();
        assert_eq!(f.curves.len(), 4);
        assert_follows(&mesh, &f, 5.0);
        assert_eq!(f.zero_vectors, 0);
    }

    /// Staggered wavy segments on a plane: all parallel, so one common direction gives a
    /// field without singularities, while opposite neighbours force the field to turn round.
    fn wavy_rows(mesh: &Mesh) -> Vec<Polyline> {
        let mut curves = Vec::new();
        for row in 0..6 {
            for half in 0..2 {
                let y = 0.12 + 0.15 * row as f32;
                let x0 = 0.05 + 0.5 * half as f32 + 0.03 * (row % 2) as f32;
                let phase = (row * 2 + half) as f32;
                curves.push(trace(
                    mesh,
                    &polyline(
                        |t| Vec3::new(x0 + 0.38 * t, y + 0.025 * (6.0 * t + phase).sin_pure(), 0.0),
                        12,
                    ),
                    false,
                ));
            }
        }
        curves
    }

    /// Staggered arcs of longitudes on a torus, 4 tube-steps apart, each covering 2/3 of the
    /// way round: neighbours overlap, so opposite signs must turn the field round between them.
    fn torus_arcs(mesh_n: u32, mesh_m: u32) -> Vec<Polyline> {
        (0..8u32)
            .map(|k| {
                let j = k * mesh_m / 8;
                let start = (k * 7 * mesh_n / 24) % mesh_n;
                Polyline {
                    vertices: (0..mesh_n * 2 / 3)
                        .map(|i| ((start + i) % mesh_n) * mesh_m + j)
                        .collect(),
                    closed: false,
                }
            })
            .collect()
    }

    fn mean_arbitrary(mesh: &Mesh, curves: &[Polyline]) -> f64 {
        let total: u32 = (1..=10)
            .map(|seed| {
                let p = FeatureFieldParams {
                    orientation: Orientation::Arbitrary,
                    orientation_seed: seed,
                    ..FeatureFieldParams::default()
                };
                feature_field(mesh, curves, &p).unwrap().0.singularities
            })
            .sum();
        total as f64 / 10.0
    }

    #[test]
    fn given_orientation_keeps_each_curve_s_own_direction() {
        // Two parallel rows, the second drawn right to left: greedy makes them agree, "given"
        // keeps what was drawn.
        let mesh = unit_grid(31);
        let row = |y: f32, left_to_right: bool| {
            let pts = polyline(|t| Vec3::new(0.1 + 0.8 * t, y, 0.0), 4);
            let pts: Vec<Vec3> = if left_to_right {
                pts
            } else {
                pts.into_iter().rev().collect()
            };
            trace(&mesh, &pts, false)
        };
        let curves = vec![row(0.3, true), row(0.7, false)];
        // Per curve of a result: the field at its middle vertex against its vertex order.
        let follows_order = |f: &FeatureField| -> Vec<f32> {
            f.curves
                .iter()
                .map(|(c, _)| {
                    let (a, b) = (c.vertices[0], *c.vertices.last().unwrap());
                    let d = (mesh.positions[b as usize] - mesh.positions[a as usize]).normalize();
                    f.vectors[c.vertices[c.vertices.len() / 2] as usize].dot(d)
                })
                .collect()
        };
        let greedy = feature_field(&mesh, &curves, &FeatureFieldParams::default())
            .unwrap()
            .0;
        let g = follows_order(&greedy);
        assert!(
            g.iter().any(|&x| x < -0.9),
            "greedy turns one row round: {g:?}"
        );
        let given = FeatureFieldParams {
            orientation: Orientation::Given,
            ..Default::default()
        };
        let f = feature_field(&mesh, &curves, &given).unwrap().0;
        assert!(f.curves.iter().all(|(_, s)| *s == 1));
        let o = follows_order(&f);
        assert!(o.iter().all(|&x| x > 0.9), "given: {o:?}");
    }

    #[test]
    fn a_fixed_curve_keeps_its_direction_and_greedy_orients_the_rest_around_it() {
        // Three rows, the longest and the top one drawn left to right, the middle one right
        // to left. Greedy alone starts from the longest (+x everywhere); with the middle row
        // fixed, every row must follow it (−x everywhere).
        let mesh = unit_grid(31);
        let row = |y: f32, from: f32, to: f32| {
            let pts = polyline(|t| Vec3::new(from + (to - from) * t, y, 0.0), 4);
            trace(&mesh, &pts, false)
        };
        let curves = vec![row(0.2, 0.1, 0.9), row(0.5, 0.7, 0.3), row(0.8, 0.3, 0.7)];
        let x_at_middles = |f: &FeatureField| -> Vec<f32> {
            curves
                .iter()
                .map(|c| f.vectors[c.vertices[c.vertices.len() / 2] as usize].x)
                .collect()
        };
        let p = FeatureFieldParams::default();
        let free = feature_field(&mesh, &curves, &p).unwrap().0;
        let x = x_at_middles(&free);
        assert!(x.iter().all(|&x| x > 0.9), "greedy alone: {x:?}");
        let fixed = [false, true, false];
        let f = feature_field_with(&mesh, &curves, &fixed, &p, &|_| {})
            .unwrap()
            .0;
        let x = x_at_middles(&f);
        assert!(x.iter().all(|&x| x < -0.9), "middle row fixed: {x:?}");
        // The fixed row is oriented first, along its own order.
        assert_eq!(f.curves[0].1, 1);
        assert_eq!(f.curves[0].0.vertices, curves[1].vertices);
        // Arbitrary signs leave a fixed curve as drawn too, whatever the seed.
        for seed in 0..8 {
            let a = FeatureFieldParams {
                orientation: Orientation::Arbitrary,
                orientation_seed: seed,
                ..Default::default()
            };
            let f = feature_field_with(&mesh, &curves, &fixed, &a, &|_| {})
                .unwrap()
                .0;
            assert_eq!(f.curves[1].1, 1, "seed {seed}");
        }
    }

    #[test]
    fn fixed_spokes_drawn_outward_stay_apart_and_keep_their_directions() {
        // Two collinear spokes drawn outward from one centre: free, §4.1 joins them into one
        // line (one direction through the centre); fixed, they stay two curves and the field
        // points away from the centre on both sides.
        let mesh = unit_grid(31);
        let spoke = |to: f32| {
            let pts = polyline(|t| Vec3::new(0.5 + (to - 0.5) * t, 0.5, 0.0), 4);
            trace(&mesh, &pts, false)
        };
        let curves = vec![spoke(0.1), spoke(0.9)];
        let p = FeatureFieldParams::default();
        let free = feature_field(&mesh, &curves, &p).unwrap().0;
        assert_eq!(free.curves.len(), 1, "free spokes are joined");
        let f = feature_field_with(&mesh, &curves, &[true, true], &p, &|_| {})
            .unwrap()
            .0;
        assert_eq!(f.curves.len(), 2, "fixed spokes stay apart");
        let x_at = |x: f32| {
            let v = (0..mesh.vertex_count())
                .min_by(|&a, &b| {
                    let d = |v: usize| mesh.positions[v].distance(Vec3::new(x, 0.5, 0.0));
                    d(a).total_cmp(&d(b))
                })
                .unwrap();
            f.vectors[v].x
        };
        assert!(
            x_at(0.25) < -0.9 && x_at(0.75) > 0.9,
            "{} {}",
            x_at(0.25),
            x_at(0.75)
        );
    }

    #[test]
    fn a_rotation_turns_the_node_s_field_about_the_normals() {
        let mesh = unit_grid(21);
        let curves = vec![trace(
            &mesh,
            &polyline(|t| Vec3::new(0.1 + 0.8 * t, 0.3 + 0.2 * t, 0.0), 4),
            false,
        )];
        let plain = node(&mesh, &curves, &[], &FeatureFieldParams::default(), &|_| {}).unwrap();
        let turned = FeatureFieldParams {
            rotation: 90.0,
            ..Default::default()
        };
        let rotated = node(&mesh, &curves, &[], &turned, &|_| {}).unwrap();
        let n = mesh.vertex_normals()[0];
        let mut compared = 0;
        for (a, b) in plain.field.vectors.iter().zip(&rotated.field.vectors) {
            if *a == Vec3::ZERO {
                assert_eq!(*b, Vec3::ZERO);
                continue;
            }
            // A quarter turn counter-clockwise seen from the normal's side: n × a.
            assert!((*b - n.cross(*a)).length() < 1e-5, "{a} turned to {b}");
            compared += 1;
        }
        assert!(compared > 400, "{compared}");
        let mut v = vec![Vec3::X, Vec3::ZERO];
        rotate_about_normals(&mut v, &[Vec3::Z, Vec3::Z], -30.0);
        let (s, c) = (0.5f32, 0.75f32.sqrt());
        assert!((v[0] - Vec3::new(c, -s, 0.0)).length() < 1e-6, "{}", v[0]);
        assert_eq!(v[1], Vec3::ZERO);
        let bad = FeatureFieldParams {
            rotation: 200.0,
            ..Default::default()
        };
        assert!(
            bad.validate()
                .unwrap_err()
                .to_string()
                .contains("field.rotation")
        );
    }

    #[test]
    fn greedy_orientation_has_fewer_singularities_than_arbitrary_signs() {
        let mesh = unit_grid(61);
        let curves = wavy_rows(&mesh);
        let (g, _) = feature_field(&mesh, &curves, &FeatureFieldParams::default()).unwrap();
        assert_eq!(g.curves.len(), 12);
        let arb = mean_arbitrary(&mesh, &curves);
        eprintln!("plane: greedy {} arbitrary mean {arb}", g.singularities);
        assert!(arb >= 2.0, "arbitrary signs gave only {arb} singularities");
        assert!((g.singularities as f64) < arb);

        let mesh = torus(96, 32, 0.7);
        let curves = torus_arcs(96, 32);
        let (g, _) = feature_field(&mesh, &curves, &FeatureFieldParams::default()).unwrap();
        let arb = mean_arbitrary(&mesh, &curves);
        eprintln!("torus: greedy {} arbitrary mean {arb}", g.singularities);
        assert!(arb >= 2.0, "arbitrary signs gave only {arb} singularities");
        assert!((g.singularities as f64) < arb);
    }

    #[test]
    fn updated_factorization_solves_the_same_system_as_a_fresh_one() {
        let mesh = torus(48, 24, 0.6);
        let curves = torus_arcs(48, 24);
        let sys = FieldSystem::new(&mesh, 1e8).unwrap();
        let mut upd = sys.updater();
        let n = mesh.vertex_count();
        for step in 0..curves.len() {
            let sign = if step % 2 == 0 { 1 } else { -1 };
            upd.add(&curves, &[(step, sign)]).unwrap();
            if step < 2 {
                continue;
            }
            let x = upd.solve_raw(&curves);
            let mask = constrained_mask(n, &curves, &upd.signed);
            let extra = sys.extra_diagonal(&mask);
            let mut t = sys.laplacian_triplets().to_vec();
            t.extend(extra.iter().enumerate().map(|(i, &d)| (i, i, d)));
            let fresh = SpdSolver::new(n, &t).unwrap();
            let b = upd.constraints(&curves);
            let mut rhs = vec![0.0; 3 * n];
            for v in 0..n {
                for k in 0..3 {
                    rhs[k * n + v] = 1e8 * b[v][k];
                }
            }
            // The refactorized solution solves the current system (residual check, independent
            // of any factorization) ...
            let mut ax = vec![0.0; 3 * n];
            for &(i, j, a) in &t {
                for k in 0..3 {
                    ax[k * n + i] += a * x[k * n + j];
                    if i != j {
                        ax[k * n + j] += a * x[k * n + i];
                    }
                }
            }
            let scale = rhs.iter().fold(0.0f64, |m, r| m.max(r.abs()));
            let res = ax
                .iter()
                .zip(&rhs)
                .fold(0.0f64, |m, (a, r)| m.max((a - r).abs()));
            assert!(res < 1e-8 * scale, "step {step}: residual {res} vs {scale}");
            // ... and agrees with a fresh factorization.
            let mut y = rhs.clone();
            fresh.solve(&mut y, 3);
            let ymax = y.iter().fold(0.0f64, |m, r| m.max(r.abs()));
            let diff = x
                .iter()
                .zip(&y)
                .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
            assert!(diff < 1e-8 * ymax, "step {step}: {diff} vs {ymax}");
        }
        // And the greedy result equals a fresh solve of its final orientation.
        let (f, _) = feature_field(&mesh, &curves, &FeatureFieldParams::default()).unwrap();
        let fresh = solve_field(&mesh, &f.curves, 1e8).unwrap();
        for v in 0..n {
            assert!(f.vectors[v].distance(fresh[v]) < 1e-5);
        }
    }

    #[test]
    fn consistency_score_matches_equation_1() {
        let mesh = unit_grid(21);
        let row = Polyline {
            vertices: (2..19).map(|x| 10 * 21 + x).collect(),
            closed: false,
        };
        let n = row.vertices.len() as f64;
        let constant = |v: Vec3| vec![v; mesh.vertex_count()];
        let (g, s) = consistency_score(&mesh, &row, &constant(Vec3::X));
        assert!((g - n).abs() < 1e-6 && s == 1, "{g} {s}");
        let (g, s) = consistency_score(&mesh, &row, &constant(-Vec3::X));
        assert!((g - n).abs() < 1e-6 && s == -1, "{g} {s}");
        let reversed = Polyline {
            vertices: row.vertices.iter().rev().copied().collect(),
            closed: false,
        };
        let (g, s) = consistency_score(&mesh, &reversed, &constant(Vec3::X));
        assert!((g - n).abs() < 1e-6 && s == -1, "{g} {s}");
        // Perpendicular: θ = π/2, both terms 1/3.
        let (g, _) = consistency_score(&mesh, &row, &constant(Vec3::Y));
        assert!((g - n / 3.0).abs() < 1e-6, "{g}");
        // 45°: (3π/4)/(5π/4) = 0.6 per vertex beats (π/4)/(7π/4) = 1/7.
        let (g, s) =
            consistency_score(&mesh, &row, &constant(Vec3::new(1.0, 1.0, 0.0).normalize()));
        assert!((g - 0.6 * n).abs() < 1e-5 && s == 1, "{g} {s}");
        // 135°: the second sum, (3π/4)/(5π/4) = 0.6, with sign −1.
        let (g, s) = consistency_score(
            &mesh,
            &row,
            &constant(Vec3::new(-1.0, 1.0, 0.0).normalize()),
        );
        assert!((g - 0.6 * n).abs() < 1e-5 && s == -1, "{g} {s}");
    }

    #[test]
    fn preprocessing_joins_gaps_breaks_corners_and_keeps_far_segments_apart() {
        let mesh = unit_grid(41);
        let row = |y: u32, xs: std::ops::Range<u32>| Polyline {
            vertices: xs.map(|x| y * 41 + x).collect(),
            closed: false,
        };
        let p = FeatureFieldParams {
            join_distance: 0.06,
            ..FeatureFieldParams::default()
        };
        // Gap of three edges (0.075 = 0.053 of the diagonal): joined, through the row.
        let pieces = |curves: &[Polyline]| -> Vec<Polyline> {
            let out = preprocess_curves(&mesh, curves, &[], &p);
            assert!(out.iter().all(|(_, s)| s.is_none()), "nothing was fixed");
            out.into_iter().map(|(c, _)| c).collect()
        };
        let out = pieces(&[row(20, 2..11), row(20, 13..26)]);
        assert_eq!(out.len(), 1, "{out:?}");
        let mut v = out[0].vertices.clone();
        if v[0] > v[1] {
            v.reverse();
        }
        assert_eq!(v, row(20, 2..26).vertices);
        // Far apart (16 edges): not joined.
        let out = pieces(&[row(20, 2..11), row(20, 27..36)]);
        assert_eq!(out.len(), 2);
        // Close but perpendicular ends: not joined.
        let column = Polyline {
            vertices: (22..35).map(|y| y * 41 + 12).collect(),
            closed: false,
        };
        let out = pieces(&[row(20, 2..11), column]);
        assert_eq!(out.len(), 2);
        // An L: broken at the corner, which both pieces keep.
        let corner = 5 * 41 + 20;
        let mut l = row(5, 5..21).vertices;
        l.extend((6..21).map(|y| y * 41 + 20));
        let out = pieces(&[Polyline {
            vertices: l,
            closed: false,
        }]);
        assert_eq!(out.len(), 2, "{out:?}");
        assert_eq!(*out[0].vertices.last().unwrap(), corner);
        assert_eq!(out[1].vertices[0], corner);
        assert_eq!(out[0].vertices.len() + out[1].vertices.len(), 32);
        // A smooth arc traced through mesh edges (a staircase) is not broken.
        let arc = trace(
            &mesh,
            &polyline(
                |t| {
                    let a = t * 2.0;
                    Vec3::new(0.5 + 0.35 * a.cos_pure(), 0.5 + 0.35 * a.sin_pure(), 0.0)
                },
                30,
            ),
            false,
        );
        assert_eq!(pieces(&[arc]).len(), 1);
    }

    #[test]
    fn singularities_of_a_vortex_a_saddle_and_a_constant_field() {
        let mesh = unit_grid(41);
        // The centroid of a triangle near the middle: not on a vertex or an edge.
        let t = mesh.triangles[2 * (20 * 40 + 20)];
        let c = (mesh.positions[t[0] as usize]
            + mesh.positions[t[1] as usize]
            + mesh.positions[t[2] as usize])
            / 3.0;
        let vortex: Vec<Vec3> = mesh
            .positions
            .iter()
            .map(|&p| Vec3::Z.cross(p - c))
            .collect();
        assert_eq!(singularity_indices(&mesh, &vortex), (1, 1));
        assert_eq!(count_singularities(&mesh, &vortex), 1);
        let saddle: Vec<Vec3> = mesh
            .positions
            .iter()
            .map(|&p| Vec3::new(p.x - c.x, c.y - p.y, 0.0))
            .collect();
        assert_eq!(singularity_indices(&mesh, &saddle), (1, -1));
        assert_eq!(
            count_singularities(&mesh, &vec![Vec3::X; mesh.vertex_count()]),
            0
        );
    }

    #[test]
    fn results_are_identical_with_one_and_two_threads() {
        let mesh = torus(48, 24, 0.6);
        let curves = torus_arcs(48, 24);
        let run = |k: usize| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(k)
                .build()
                .unwrap()
                .install(|| {
                    feature_field(&mesh, &curves, &FeatureFieldParams::default())
                        .unwrap()
                        .0
                })
        };
        let (a, b) = (run(1), run(2));
        assert_eq!(a.curves, b.curves);
        assert_eq!(a.singularities, b.singularities);
        let bits = |f: &FeatureField| -> Vec<[u32; 3]> {
            f.vectors
                .iter()
                .map(|v| v.to_array().map(f32::to_bits))
                .collect()
        };
        assert_eq!(bits(&a), bits(&b));
    }

    #[test]
    fn parameters_are_checked_and_read_from_toml() {
        assert_validation!(FeatureFieldParams {
            alpha: 0.0 => "field.alpha must be in 1..=1000000000000, got 0",
            join_distance: -0.1 => "field.join_distance must be in 0..=1, got -0.1",
            break_angle: 0.5 => "field.break_angle must be in 1..=180, got 0.5",
        });
        let p: FeatureFieldParams =
            toml::from_str("orientation = \"arbitrary\"\norientation_seed = 7").unwrap();
        assert_eq!(p.orientation, Orientation::Arbitrary);
        assert_eq!(p.orientation_seed, 7);
        assert!(toml::from_str::<FeatureFieldParams>("orientation = \"random\"").is_err());
    }

    #[test]
    fn no_curves_and_bad_vertices_are_errors() {
        let mesh = unit_grid(5);
        let e = feature_field(&mesh, &[], &FeatureFieldParams::default()).unwrap_err();
        assert!(matches!(e, FeatureFieldError::NoCurves));
        assert!(e.to_string().contains("no feature curves to align to"));
        let bad = Polyline {
            vertices: vec![0, 99],
            closed: false,
        };
        let e = feature_field(&mesh, &[bad], &FeatureFieldParams::default()).unwrap_err();
        assert!(matches!(e, FeatureFieldError::BadVertex { vertex: 99, .. }));
    }

    #[test]
    fn a_component_without_curves_gets_the_fallback_field() {
        // Two grids side by side; curves only on the first.
        let a = unit_grid(11);
        let mut pos = a.positions.clone();
        let mut tris = a.triangles.clone();
        let off = pos.len() as u32;
        pos.extend(a.positions.iter().map(|p| *p + Vec3::new(2.0, 0.0, 0.0)));
        tris.extend(a.triangles.iter().map(|t| t.map(|v| v + off)));
        let mesh = Mesh::new(pos, tris);
        let diag = Polyline {
            vertices: (1..10).map(|k| k * 11 + k).collect(),
            closed: false,
        };
        let (f, _) = feature_field(&mesh, &[diag], &FeatureFieldParams::default()).unwrap();
        for v in off as usize..mesh.vertex_count() {
            assert!(f.vectors[v].distance(Vec3::X) < 1e-6);
        }
        let d = Vec3::new(1.0, 1.0, 0.0).normalize();
        for v in 0..off as usize {
            assert!(f.vectors[v].dot(d) > 0.999, "{v}: {}", f.vectors[v]);
        }
    }

    /// Run with `cargo test --release -p texsyn-stages --lib feature_field -- --ignored
    /// --nocapture`.
    #[test]
    #[ignore]
    fn timing_on_a_400k_triangle_torus() {
        use crate::geom::subdivide::subdivide;
        let base = torus(160, 80, 0.6);
        let mesh = subdivide(&subdivide(&base));
        // Subdivision keeps the base vertices' ids; trace curves through them.
        let mut curves = Vec::new();
        // 18 staggered longitude arcs, 12 meridian arcs: 30 curves.
        for k in 0..18u32 {
            let j = (k * 80 / 18 + 1) % 80;
            let start = (k * 37) % 160;
            let len = 40 + (k * 13) % 60;
            let pts: Vec<Vec3> = (0..=len)
                .step_by(4)
                .map(|i| base.positions[(((start + i) % 160) * 80 + j) as usize])
                .collect();
            curves.push(trace_fast(&mesh, &pts));
        }
        for k in 0..12u32 {
            let i = (k * 160 / 12 + 7) % 160;
            let j0 = (k * 29) % 80;
            let pts: Vec<Vec3> = (0..=20)
                .step_by(4)
                .map(|j| base.positions[(i * 80 + (j0 + j) % 80) as usize])
                .collect();
            curves.push(trace_fast(&mesh, &pts));
        }
        eprintln!(
            "mesh: {} triangles, {} vertices, {} curves ({} curve vertices)",
            mesh.face_count(),
            mesh.vertex_count(),
            curves.len(),
            curves.iter().map(|c| c.vertices.len()).sum::<usize>()
        );
        let t = Instant::now();
        let (g, times) = feature_field(&mesh, &curves, &FeatureFieldParams::default()).unwrap();
        let total = t.elapsed().as_secs_f64();
        let mean_step = times.step_secs.iter().sum::<f64>() / times.step_secs.len() as f64;
        let max_step = times.step_secs.iter().fold(0.0f64, |m, &s| m.max(s));
        eprintln!(
            "greedy: setup {:.3}s, first numeric factorization {:.3}s, {} steps: \
             mean {:.3}s max {:.3}s, total {:.2}s; {} curves after preprocessing",
            times.setup_secs,
            times.factorization_secs,
            times.step_secs.len(),
            mean_step,
            max_step,
            total,
            g.curves.len()
        );
        // The fresh alternative per step, for comparison: a whole SpdSolver factorization.
        let sys = FieldSystem::new(&mesh, 1e8).unwrap();
        let mask = constrained_mask(mesh.vertex_count(), &[g.curves[0].0.clone()], &[(0, 1)]);
        let mut t_ = sys.laplacian_triplets().to_vec();
        t_.extend(
            sys.extra_diagonal(&mask)
                .iter()
                .enumerate()
                .map(|(i, &d)| (i, i, d)),
        );
        let t = Instant::now();
        let s = SpdSolver::new(mesh.vertex_count(), &t_).unwrap();
        let fresh_secs = t.elapsed().as_secs_f64();
        let mut rhs = vec![1.0; 3 * mesh.vertex_count()];
        let t = Instant::now();
        s.solve(&mut rhs, 3);
        let solve_secs = t.elapsed().as_secs_f64();
        let t = Instant::now();
        let _ = sys.pattern.factorize(&sys.extra_diagonal(&mask)).unwrap();
        let numeric_secs = t.elapsed().as_secs_f64();
        // Woodbury's cost for one curve of k vertices: k single-column solves.
        let k = g.curves.iter().map(|c| c.0.vertices.len()).sum::<usize>() / g.curves.len();
        let mut rhs = vec![1.0; k * mesh.vertex_count()];
        let t = Instant::now();
        s.solve(&mut rhs, k);
        let woodbury_solves = t.elapsed().as_secs_f64();
        eprintln!(
            "fresh SpdSolver factorization {fresh_secs:.3}s, numeric refactorization only \
             {numeric_secs:.3}s, 3-column solve {solve_secs:.3}s, {k}-column solve (Woodbury, \
             mean curve) {woodbury_solves:.3}s"
        );
        let arb = mean_arbitrary(&mesh, &curves);
        eprintln!(
            "singularities: greedy {}, arbitrary mean of 10 {arb}",
            g.singularities
        );
    }

    /// `trace` with a nearest-vertex search restricted to the base mesh's vertex ids (kept by
    /// subdivision), which are the first ones.
    fn trace_fast(mesh: &Mesh, pts: &[Vec3]) -> Polyline {
        let base = 160 * 80;
        let nearest = |q: Vec3| {
            (0..base)
                .min_by(|&a, &b| {
                    mesh.positions[a]
                        .distance_squared(q)
                        .total_cmp(&mesh.positions[b].distance_squared(q))
                })
                .unwrap() as u32
        };
        let mut ids: Vec<u32> = pts.iter().map(|&q| nearest(q)).collect();
        ids.dedup();
        let mut out = vec![ids[0]];
        for w in ids.windows(2) {
            out.extend(
                shortest_path(mesh, w[0], w[1], f64::INFINITY)
                    .unwrap()
                    .into_iter()
                    .skip(1),
            );
        }
        Polyline {
            vertices: out,
            closed: false,
        }
    }
}

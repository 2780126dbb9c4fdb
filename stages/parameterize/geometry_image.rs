//! Geometry images for geometric texture synthesis: Lai, Hu, Gu & Martin, "Geometric Texture
//! Synthesis and Transfer via Geometry Images" (SPM 2005), §3 (cut the model to a disk, map it
//! to a square, sample a regular grid) with the parameterization requirement of §4.2.2 (the
//! cut-nodes lie on the grid of the coarsest synthesis level, so the boundary-fixing pyramid
//! keeps mated boundary samples matched at every level), after Gu, Gortler & Hoppe,
//! "Geometry Images" (SIGGRAPH 2002).
//!
//! Steps:
//! 1. Cut ([`crate::geom::cut_graph`]): tree-cotree with Erickson–Whittlesey's greedy dual
//!    tree, boundary loops joined by shortest paths, closed spheres cut along a path between
//!    two far-apart vertices (at least two edges); a mesh without area is refused; the cut is
//!    then straightened path by path, and optional cuts to extremities are added (and,
//!    with `stretch_cuts`, cuts to the most anisotropic vertices, each kept only if the
//!    rebuilt map is better; below). Cutting splits every cut vertex into wedges; the disk boundary
//!    alternates between the two sides of *cut paths* (paths of the cut graph between
//!    *cut-nodes*: cut-graph vertices of degree ≠ 2 and vertices where the cut meets the mesh
//!    boundary) and runs of the mesh's own boundary.
//! 2. Boundary: cut-nodes go to perimeter positions that are multiples of the coarse spacing
//!    2^(coarse_levels − 1); each cut path gets the same whole number of coarse units on both
//!    of its sides, proportional to its length (at least one unit; largest remainder so the
//!    total is the perimeter 4(size − 1)); boundary vertices inside a path are placed by arc
//!    length. The whole layout is then turned along the perimeter by whole coarse units so
//!    that the tips of cut paths that end inside the surface sit as far from the square's
//!    corners as possible (a tip at a corner folds its one grid cell onto itself; no turn when
//!    the cut has no tip). A boundary vertex is inserted at any corner of the square that
//!    falls inside a boundary edge, so the disk covers the whole square.
//! 3. Interior: every chord (an interior edge with both ends on the boundary) is split at its
//!    midpoint so no triangle lies flat on a side of the square; then the mean value
//!    convex-combination map (Floater 2003) with the boundary fixed, and stretch reduction by
//!    iterative reweighting (Yoshizawa et al. 2004). The boundary is convex and the weights
//!    positive, so the map is a bijection (Floater 2003).
//! 4. Sampling: boundary samples are computed once per cut path by arc length along its 3D
//!    polyline and copied to both sides, so mated samples are bit-identical (positions and
//!    normals); `mate_rep` groups them. Interior samples interpolate positions and the
//!    input's area-weighted vertex normals barycentrically in the parameter-domain triangle
//!    that contains them (the one they are most inside, ties to the lower index).
//!
//! Departures from the papers, and why:
//! - Gu et al. 2002 find the initial cut by contracting triangles and pruning, and add cuts
//!   at the points of worst stretch of a Floater parameterization, re-parameterizing each
//!   time; Lai et al. use a contraction like Gu's or Zhu et al. 2003's skeleton seams. Here
//!   the cut is Erickson–Whittlesey's greedy tree-cotree (the shortest system of loops through
//!   a root, several roots tried), which needs no iteration; extremity cuts are shortest
//!   paths from the cut to the geodesically farthest vertex, one at a time (default off).
//! - Stretch-driven cuts (`stretch_cuts`) are Gu et al.'s iteration with shape, not area, as
//!   the stretch: Lai et al. §3 ask for a map that avoids undersampling *and* is close to
//!   conformal, "a compromise", and Yoshizawa's reweighting below evens out the area at the
//!   price of shape (the cow's mean anisotropy σ₁/σ₂ is 7.3; its relief came out as streaks
//!   along the legs). Each round cuts a shortest path from the cut to the vertex whose
//!   triangles are most anisotropic (parameter-area-weighted mean of ln σ₁/σ₂) and rebuilds the
//!   whole map; the cut is kept when the mean anisotropy falls, no more triangles flip and
//!   the L² stretch stays within [`STRETCH_CUT_AREA_BOUND`] of the uncut map's (so thin parts
//!   keep their samples); a refused vertex is not tried again, and a candidate whose
//!   rebuild fails (no room on the perimeter, an unsolvable map) is refused too. Gu et al.
//!   stop at the first cut that does not help; here a fixed number of candidates is tried,
//!   because on the cow a refused candidate was often followed by a kept one.
//! - Our addition: the tree-cotree cut is straightened (each cut path replaced by the
//!   shortest path between its cut-nodes that keeps the cut a disk, running along the rest of
//!   the cut for free). Shortest-path trees leave branches running side by side one or two
//!   triangles apart; the thin strips between them have long boundaries far apart on the
//!   square and were crushed to nothing (refined_elephant: L² stretch 10^33 before, 186 after
//!   straightening; elephant cut length 3.5 → 2.0).
//! - Gu et al. minimize the geometric stretch of Sander et al. 2001 with a nonlinear
//!   optimization and Lai et al. mention Sander et al. 2003; here stretch is reduced with
//!   Yoshizawa et al.'s reweighted linear solves, which keep the map a convex combination
//!   (never flipped) and cost one sparse LU solve each. We keep iterating from an iterate that
//!   got worse (it often improves again) and keep the best map, ranking maps by flipped
//!   triangles first (extremely compressed regions can collapse numerically) and stretch next.
//! - Gu et al. place boundary vertices so every cut path's two sides have equal parametric
//!   length, with cut-nodes on grid points; here the cut-nodes also land on the coarse grid
//!   of §4.2.2 and the square's corners are ordinary perimeter positions.
//! - Boundary samples are taken from the 3D polyline by arc length (not from the interior
//!   interpolation): the same values on both sides of a cut by construction. The tip of a cut
//!   path that ends inside the surface (a cut-node of degree 1, e.g. each end of a sphere's
//!   cut or of an extremity cut) is a single boundary sample with no mate.
//! - Corner insertion and chord splitting are ours: they make the disk cover the square and
//!   keep every triangle non-degenerate in the plane.

use crate::check::{ParamError, check_range};
use crate::geom::Mesh;
use crate::geom::cut_graph::{CutError, cut_graph, cut_to_disk};
use crate::geom::geometry_image::GeometryImage;
use crate::geom::half_edge::{HalfEdgeMesh, NONE, TopologyError};
use crate::geom::mean_value::{
    ConvexCombinationSolver, MeanValueError, mean_value_weights, reduce_stretch,
};
use glam::{DVec2, DVec3, Vec2, Vec3};
use std::cmp::Reverse;
use std::collections::HashMap;
use texsyn_core::algorithm::Failure;
use texsyn_core::math::PureMath;

/// The `geometry_image` node's algorithm and version (part of its key; bump on any change of output).
pub const NODE: texsyn_core::algorithm::Algorithm =
    texsyn_core::algorithm::Algorithm::new("geometry_image", 2);

/// Parameters of [`build_geometry_image`].
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct GeometryImageParams {
    /// Samples per side of the square grid: 2^k + 1 with 2 ≤ k ≤ 12 (5 to 4097).
    /// Default: 257 (the paper's resolution).
    pub size: u32,
    /// Extra cuts from the cut graph to the vertices geodesically farthest from it, added one
    /// at a time; they let protrusions open up and lower stretch. Range 0 to 256. Default: 0.
    pub extremity_cuts: u32,
    /// Stretch-driven cuts (Gu et al. 2002's iterative cut augmentation, with anisotropy as the
    /// stretch): after the map is built, a shortest path from the cut to the vertex whose
    /// triangles the map distorts most in shape is added to the cut and the map rebuilt; the
    /// cut is kept if that lowers the map's mean anisotropy (see the module doc for the exact
    /// rule), and the next candidate is the worst vertex not tried yet. This many candidates
    /// are tried. Range 0 to 64. Default: 0 (each candidate is a whole rebuild:
    /// refined_elephant's 44k vertices took 7.6–9.2× as long with 8, for a small gain
    /// there). The shipped configs set 8: relief_cow keeps 3 of them, mean anisotropy
    /// 7.3 → 4.2, the surface metric's median stretch 2.43 → 1.83.
    #[serde(skip_serializing_if = "is_zero")]
    pub stretch_cuts: u32,
    /// Stretch-reduction iterations after the mean value map (0 keeps the plain mean value
    /// map; the best iterate is kept). Each costs one sparse LU solve. Range 0 to 100.
    /// Default: 8 (the cow's stretch is 15 after 3, 2.4 after 10).
    pub stretch_iterations: u32,
    /// Levels of the synthesis pyramid: cut-nodes are placed on the grid of the coarsest
    /// level, spacing 2^(coarse_levels − 1) samples (§4.2.2, boundary-fixing pyramid).
    /// Range 1 to k where size = 2^k + 1. Default: 3 (the paper's three-level pyramid).
    /// The geometry-image method sets it to the synthesis's levels (`analyse_exemplar.levels`);
    /// a config that gives it is refused.
    #[serde(deserialize_with = "set_by_levels")]
    pub coarse_levels: u32,
}

impl Default for GeometryImageParams {
    fn default() -> Self {
        GeometryImageParams {
            size: 257,
            extremity_cuts: 0,
            stretch_cuts: 0,
            stretch_iterations: 8,
            coarse_levels: 3,
        }
    }
}

impl GeometryImageParams {
    /// Checks every field's range; the message names the field, the range and the value.
    pub fn validate(&self) -> Result<(), ParamError> {
        let k = size_exponent(self.size).ok_or_else(|| {
            ParamError::invalid(
                "size",
                format!(
                    "must be 2^k + 1 with 2 <= k <= 12 (5, 9, 17, 33, 65, 129, 257, 513, 1025, \
                     2049 or 4097), got {}",
                    self.size
                ),
            )
        })?;
        if self.coarse_levels < 1 || self.coarse_levels > k {
            return Err(ParamError::invalid(
                "coarse_levels",
                format!(
                    "must be in 1..={k} for size {} (the coarsest grid needs at least 3 samples \
                     per side), got {}",
                    self.size, self.coarse_levels
                ),
            ));
        }
        check_range("extremity_cuts", self.extremity_cuts, 0, 256)?;
        check_range("stretch_cuts", self.stretch_cuts, 0, 64)?;
        check_range("stretch_iterations", self.stretch_iterations, 0, 100)
    }
}

fn is_zero(x: &u32) -> bool {
    *x == 0
}

/// k with size = 2^k + 1, 2 ≤ k ≤ 12.
fn size_exponent(size: u32) -> Option<u32> {
    let m = size.checked_sub(1)?;
    (m.is_power_of_two() && (4..=4096).contains(&m)).then(|| m.trailing_zeros())
}

#[derive(Debug, thiserror::Error)]
pub enum GeometryImageError {
    #[error("invalid geometry image parameters: {0}")]
    Params(#[from] ParamError),
    #[error("the mesh is not a surface a geometry image can be made of: {0}")]
    Topology(#[from] TopologyError),
    #[error("cutting the mesh to a disk failed: {0}")]
    Cut(#[from] CutError),
    #[error(
        "the mesh has no area: all of its {triangles} triangles are degenerate (their corners \
         coincide or lie on one line), so there is no surface to map to the square"
    )]
    NoArea { triangles: usize },
    #[error(
        "size {size} is too small for this cut: its perimeter has {available} coarse units of \
         {spacing} samples (coarse_levels = {coarse_levels}), but the cut's {paths} paths and \
         boundary runs need {needed}; size {suggested} would work (or lower coarse_levels)"
    )]
    PerimeterTooShort {
        size: u32,
        coarse_levels: u32,
        spacing: u32,
        available: usize,
        paths: usize,
        needed: usize,
        suggested: u32,
    },
    #[error("parameterizing the disk failed: {0}")]
    Map(#[from] MeanValueError),
    #[error("internal error in the geometry image (a bug, please report): {0}")]
    Internal(String),
}

/// The geometry image and everything it was made from.
#[derive(Debug, Clone)]
pub struct GeometryImageBuild {
    pub image: GeometryImage,
    /// The disk: the input cut open (wedge vertices along the cut), with vertices inserted at
    /// the square's corners and at chord midpoints. Triangle order: the input's triangles
    /// first (some shrunk by splits), then the pieces added by splits. No colours.
    pub disk: Mesh,
    /// Parameter position of each disk vertex in grid units: u = column j, v = row i, both in
    /// [0, size − 1]. Triangles are counter-clockwise.
    pub disk_uv: Vec<Vec2>,
    /// Per disk vertex, the input vertex it is a copy of; `u32::MAX` for inserted vertices
    /// (corner and chord splits), which lie on the input surface but not at a vertex.
    pub original_vertex: Vec<u32>,
    /// Total length of the cut (sum of the cut edges' lengths).
    pub cut_length: f32,
    /// The cut edges as input vertex pairs (smaller first), sorted.
    pub cut_edges: Vec<[u32; 2]>,
    /// The cut-nodes (input vertices), ascending.
    pub cut_nodes: Vec<u32>,
    pub genus: u32,
    pub boundary_loops: u32,
    /// Global L² stretch (Sander et al. 2001, 1 = isometric up to scale; over the triangles
    /// that are not flipped) of the mean value map and of the final map.
    pub initial_stretch: f32,
    pub stretch: f32,
    /// The stretch-reduction iteration whose map was kept (0: the mean value map).
    pub stretch_iterations_used: u32,
    /// Parameter-domain triangles with non-positive signed area (0 for a bijective map).
    pub flipped_triangles: usize,
    /// The vertices the kept stretch-driven cuts run to, in the order they were added.
    pub stretch_cuts: Vec<u32>,
    /// The map's mean anisotropy: the exponential of the parameter-area-weighted mean of
    /// `ln(σ₁ / σ₂)` (1 for a conformal map; over the triangles that are not flipped).
    pub anisotropy: f32,
}

/// One run of the disk boundary between consecutive cut-nodes.
struct Run {
    /// Boundary positions `start..start + count` (edges `k → k + 1`).
    start: usize,
    count: usize,
    length: f64,
    /// The run on the other side of the same cut path, or `NONE` for the mesh boundary.
    mate: u32,
    /// Allocated grid steps and first perimeter position.
    steps: u64,
    t0: u64,
}

/// Builds the geometry image of `mesh` (see the module doc). `progress` receives fractions
/// from 0 to 1. Deterministic: the same output for any number of threads.
pub fn build_geometry_image(
    mesh: &Mesh,
    p: &GeometryImageParams,
    progress: &dyn Fn(f32),
) -> Result<GeometryImageBuild, GeometryImageError> {
    p.validate()?;
    let builds = p.stretch_cuts as f32 + 1.0;
    let mut targets = Vec::new();
    let mut best = build_for_cut(mesh, p, &targets, &|f| progress(f / builds))?;
    let mut best_shape = map_shape_distortion(&best);
    let (uncut_anisotropy, uncut_stretch) = (best_shape.anisotropy, best.stretch);
    // Stretch-driven cuts (Gu et al. 2002's cut augmentation), greedy: a cut to the worst
    // vertex not tried yet is kept when it lowers the shape distortion without flipping more
    // triangles or letting the area distortion grow past STRETCH_CUT_AREA_BOUND times the
    // uncut map's. A candidate whose rebuild fails (no room on the perimeter for its path, or
    // a map that cannot be solved) is refused like one that does not help: the option must
    // never cost the user the map they had.
    let mut tried = Vec::new();
    for k in 0..p.stretch_cuts {
        let Some(&x) = best_shape.ranking.iter().find(|v| !tried.contains(*v)) else {
            break;
        };
        tried.push(x);
        targets.push(x);
        let sub = |f: f32| progress((k as f32 + 1.0 + f) / builds);
        let next = match build_for_cut(mesh, p, &targets, &sub) {
            Ok(b) => Some(b),
            // Expected near the end of a long search: no warning.
            Err(GeometryImageError::PerimeterTooShort { .. }) => {
                tracing::info!(vertex = x, "stretch cut refused: no room on the perimeter");
                None
            }
            Err(e) => {
                let e = e.to_string();
                tracing::warn!(vertex = x, "stretch cut refused, its rebuild failed: {e}");
                None
            }
        };
        match next {
            Some(next)
                if next.stretch <= STRETCH_CUT_AREA_BOUND * uncut_stretch
                    && next.flipped_triangles <= best.flipped_triangles =>
            {
                let next_shape = map_shape_distortion(&next);
                if next_shape.anisotropy < best_shape.anisotropy {
                    best = next;
                    best_shape = next_shape;
                } else {
                    targets.pop();
                }
            }
            _ => {
                targets.pop();
            }
        }
    }
    if p.stretch_cuts > 0 {
        tracing::info!(
            kept = targets.len(),
            tried = tried.len(),
            anisotropy_before = uncut_anisotropy.exp_pure(),
            anisotropy_after = best_shape.anisotropy.exp_pure(),
            l2_stretch_before = uncut_stretch,
            l2_stretch_after = best.stretch,
            "stretch-driven cuts"
        );
    }
    best.anisotropy = best_shape.anisotropy.exp_pure() as f32;
    progress(1.0);
    Ok(best)
}

/// How much a stretch-driven cut may raise the map's L² stretch (area distortion) over the
/// uncut map's. Unbounded, the cow's cuts took its mean anisotropy from 7.3 to 2.3 but its L²
/// stretch from 2.3 to 5.3, and the relief mesh lost its tail and hooves to the coarser
/// sampling there; at 1.25 they stay, and the anisotropy still falls to 4.2.
pub const STRETCH_CUT_AREA_BOUND: f32 = 1.25;

/// A map's distortion of shape (see [`map_shape_distortion`]).
struct ShapeDistortion {
    /// The parameter-area-weighted mean of `ln(σ₁ / σ₂)` over the disk's triangles.
    anisotropy: f64,
    /// The input vertices off the disk's boundary (not on the cut or the mesh's boundary),
    /// by the mean `ln(σ₁ / σ₂)` of their triangles, largest first (ties: smaller index).
    ranking: Vec<u32>,
}

/// The map's shape distortion: the parameter-area-weighted mean of `ln(σ₁ / σ₂)` over the
/// disk's triangles (σ the singular values of the map from the triangle to the plane; 0 for
/// a conformal map), and the input vertices ranked by the same mean over their triangles,
/// leaving out those on the disk's boundary, which a cut cannot reach further. Weighting by
/// parameter area counts what the grid's samples see. Flipped and degenerate triangles are
/// left out (the caller compares flip counts separately).
fn map_shape_distortion(b: &GeometryImageBuild) -> ShapeDistortion {
    let nv = b
        .original_vertex
        .iter()
        .filter(|&&v| v != u32::MAX)
        .max()
        .map_or(0, |&v| v as usize + 1);
    // The disk's boundary vertices are copies of input vertices on the cut or the mesh's
    // boundary.
    let mut excluded = vec![false; nv];
    for dv in b.disk.boundary_vertices() {
        let v = b.original_vertex[dv as usize];
        if v != u32::MAX {
            excluded[v as usize] = true;
        }
    }
    let mut per_vertex = vec![(0.0f64, 0.0f64); nv];
    let (mut sum, mut weight) = (0.0f64, 0.0f64);
    for t in &b.disk.triangles {
        let q = t.map(|v| b.disk.positions[v as usize].as_dvec3());
        let p = t.map(|v| b.disk_uv[v as usize].as_dvec2());
        let Some(log_ratio) = log_singular_ratio(q, p) else {
            continue;
        };
        let area = 0.5 * (p[1] - p[0]).perp_dot(p[2] - p[0]);
        sum += area * log_ratio;
        weight += area;
        for &dv in t {
            let v = b.original_vertex[dv as usize];
            if v != u32::MAX {
                let e = &mut per_vertex[v as usize];
                e.0 += area * log_ratio;
                e.1 += area;
            }
        }
    }
    let mut ranked: Vec<(u32, f64)> = (0..nv)
        .filter(|&v| !excluded[v] && per_vertex[v].1 > 0.0)
        .map(|v| (v as u32, per_vertex[v].0 / per_vertex[v].1))
        .collect();
    ranked.sort_by(|a, b| b.1.total_cmp(&a.1).then(a.0.cmp(&b.0)));
    ShapeDistortion {
        anisotropy: if weight > 0.0 { sum / weight } else { 0.0 },
        ranking: ranked.into_iter().map(|(v, _)| v).collect(),
    }
}

/// `ln(σ₁ / σ₂)` of the affine map from the 3D triangle `q` to the plane triangle `p`, or
/// `None` when either is degenerate or the map flips it.
fn log_singular_ratio(q: [DVec3; 3], p: [DVec2; 3]) -> Option<f64> {
    let (e1, e2) = (q[1] - q[0], q[2] - q[0]);
    let l1 = e1.length();
    let n = e1.cross(e2);
    if l1 <= 0.0 || n.length() <= 0.0 {
        return None;
    }
    let x = e1 / l1;
    let y = n.normalize().cross(x);
    // The triangle in its own plane: (l1, 0) and (e2·x, e2·y), with e2·y > 0.
    let (a, bx, by) = (l1, e2.dot(x), e2.dot(y));
    let (f1, f2) = (p[1] - p[0], p[2] - p[0]);
    if f1.perp_dot(f2) <= 0.0 {
        return None;
    }
    // J maps (1, 0) ↦ f1 / a and (0, 1) ↦ (f2 − bx · f1 / a) / by.
    let ju = f1 / a;
    let jv = (f2 - ju * bx) / by;
    let (e, f, g) = (ju.length_squared(), ju.dot(jv), jv.length_squared());
    let det = ju.perp_dot(jv);
    // σ₁² and σ₂² are the eigenvalues of JᵀJ = [[e, f], [f, g]].
    let half_trace = 0.5 * (e + g);
    let root = (0.25 * (e - g) * (e - g) + f * f).sqrt();
    // σ₁² σ₂² = det², which gives σ₂² without cancellation.
    let s1 = half_trace + root;
    let s2 = det * det / s1;
    if s2 <= 0.0 || !s2.is_finite() {
        return None;
    }
    Some(0.5 * (s1 / s2).ln_pure())
}

/// The geometry image for the cut that `cut_graph` makes with the given extra targets.
fn build_for_cut(
    mesh: &Mesh,
    p: &GeometryImageParams,
    targets: &[u32],
    progress: &dyn Fn(f32),
) -> Result<GeometryImageBuild, GeometryImageError> {
    progress(0.0);
    let n = p.size as usize;
    let side = (n - 1) as u64;
    let perimeter = 4 * side;
    let spacing = 1u64 << (p.coarse_levels - 1);

    // 1. Cut to a disk.
    let he = HalfEdgeMesh::new(mesh)?;
    let zero_area = (0..mesh.face_count())
        .filter(|&f| {
            let t = mesh.triangles[f].map(|v| mesh.positions[v as usize].as_dvec3());
            (t[1] - t[0]).cross(t[2] - t[0]) == DVec3::ZERO
        })
        .count();
    if zero_area == mesh.face_count() {
        return Err(GeometryImageError::NoArea {
            triangles: zero_area,
        });
    }
    if zero_area > 0 {
        tracing::warn!(
            "the mesh has {zero_area} triangles of zero area (corners that coincide or lie \
             on one line)"
        );
    }
    let cut = cut_graph(&he, &mesh.positions, p.extremity_cuts, targets)?;
    let dc = cut_to_disk(mesh, &he, &cut.is_cut)?;
    progress(0.15);
    let cut_degree = cut.degrees(&he);
    let is_node = |v: u32| {
        let d = cut_degree[v as usize];
        d != 0 && (d != 2 || he.is_boundary_vertex(v))
    };
    let bnd_vertex: Vec<u32> = dc.boundary.iter().map(|&h| dc.he.origin(h)).collect();
    let nb = bnd_vertex.len();
    let orig = |dv: u32| dc.original_vertex[dv as usize];
    let mut node_positions: Vec<usize> =
        (0..nb).filter(|&k| is_node(orig(bnd_vertex[k]))).collect();
    if node_positions.is_empty() {
        // An uncut disk: its boundary is one run from an arbitrary (the first) vertex.
        node_positions.push(0);
    }
    // Rotate the boundary so that it starts at a node.
    let shift = node_positions[0];
    let bv: Vec<u32> = (0..nb).map(|k| bnd_vertex[(k + shift) % nb]).collect();
    let mate: Vec<u32> = (0..nb)
        .map(|k| {
            let m = dc.mate[(k + shift) % nb];
            if m == NONE {
                NONE
            } else {
                ((m as usize + nb - shift) % nb) as u32
            }
        })
        .collect();
    let node_positions: Vec<usize> = node_positions.iter().map(|&k| k - shift).collect();
    let pos3 = |dv: u32| dc.disk.positions[dv as usize].as_dvec3();
    let edge_len = |k: usize| (pos3(bv[(k + 1) % nb]) - pos3(bv[k])).length();

    // 2. Runs between nodes and their mates.
    let mut runs: Vec<Run> = Vec::new();
    let mut run_of_position = vec![0u32; nb];
    for (r, &start) in node_positions.iter().enumerate() {
        let end = node_positions.get(r + 1).copied().unwrap_or(nb);
        for k in start..end {
            run_of_position[k] = r as u32;
        }
        runs.push(Run {
            start,
            count: end - start,
            length: (start..end).map(edge_len).sum(),
            mate: NONE,
            steps: 0,
            t0: 0,
        });
    }
    for r in 0..runs.len() {
        let (start, count) = (runs[r].start, runs[r].count);
        let first_mate = mate[start];
        let kinds_differ =
            (start..start + count).any(|k| (mate[k] == NONE) != (first_mate == NONE));
        if kinds_differ {
            return Err(GeometryImageError::Internal(format!(
                "boundary run {r} mixes cut and mesh-boundary edges"
            )));
        }
        if first_mate == NONE {
            continue;
        }
        let m = run_of_position[first_mate as usize] as usize;
        let (ms, mc) = (runs[m].start, runs[m].count);
        let consistent = m != r
            && mc == count
            && (0..count).all(|i| mate[start + i] as usize == ms + count - 1 - i);
        if !consistent {
            return Err(GeometryImageError::Internal(format!(
                "the two sides of the cut path at boundary run {r} do not match"
            )));
        }
        runs[r].mate = m as u32;
    }

    // 3. Steps per run: whole coarse units, the same on both sides of a cut path.
    let units = perimeter / spacing;
    // Items: cut paths (counted twice on the perimeter) and mesh-boundary runs.
    let items: Vec<(usize, u64)> = (0..runs.len())
        .filter(|&r| runs[r].mate == NONE || (runs[r].mate as usize) > r)
        .map(|r| (r, if runs[r].mate == NONE { 1 } else { 2 }))
        .collect();
    let needed: u64 = items.iter().map(|&(_, m)| m).sum();
    if needed > units {
        let k_min = (needed.next_power_of_two().trailing_zeros() + p.coarse_levels).max(3) - 3;
        let k_min = k_min.max(p.coarse_levels).max(2);
        return Err(GeometryImageError::PerimeterTooShort {
            size: p.size,
            coarse_levels: p.coarse_levels,
            spacing: spacing as u32,
            available: units as usize,
            paths: items.len(),
            needed: needed as usize,
            suggested: (1u32 << k_min) + 1,
        });
    }
    let alloc = allocate_units(
        &items
            .iter()
            .map(|&(r, m)| (runs[r].length, m))
            .collect::<Vec<_>>(),
        units,
    )
    .ok_or_else(|| GeometryImageError::Internal("unit allocation failed".into()))?;
    for (&(r, _), &u) in items.iter().zip(&alloc) {
        runs[r].steps = u * spacing;
        if runs[r].mate != NONE {
            let m = runs[r].mate as usize;
            runs[m].steps = u * spacing;
        }
    }
    // The tip of a cut path that ends inside the surface (a cut-node of degree 1) is a fold:
    // the perimeter turns back on itself there, so the half-plane around a tip on a side maps
    // to the whole disk around it on the surface. At a corner only a quarter-plane would, and
    // the corner's one grid cell would fold onto itself (no triangle of the output can hold
    // the tip). The whole layout is turned along the perimeter, by whole coarse units, to
    // keep the tips as far from the corners as possible (no turn when there are no tips).
    let tip = |k: usize| {
        let v = orig(bv[k]);
        cut_degree[v as usize] == 1 && !he.is_boundary_vertex(v)
    };
    let mut offsets_t: Vec<u64> = Vec::new();
    let mut t = 0u64;
    for run in &runs {
        if tip(run.start) {
            offsets_t.push(t);
        }
        t += run.steps;
    }
    let corner_distance = |x: u64| {
        let x = x % side;
        x.min(side - x)
    };
    let turn = (0..side / spacing)
        .map(|u| u * spacing)
        .max_by_key(|&o| {
            let worst = offsets_t
                .iter()
                .map(|&t| corner_distance(t + o))
                .min()
                .unwrap_or(0);
            (worst, Reverse(o))
        })
        .unwrap_or(0);
    let mut t = turn;
    for run in &mut runs {
        run.t0 = t;
        t += run.steps;
    }
    if t != turn + perimeter {
        return Err(GeometryImageError::Internal(format!(
            "perimeter steps {t} != {perimeter}"
        )));
    }

    // Perimeter parameter of every boundary position (arc length inside each run).
    let mut tpos = vec![0.0f64; nb];
    for run in &runs {
        let mut arc = 0.0;
        for i in 0..run.count {
            let k = run.start + i;
            let frac = if run.length > 0.0 {
                arc / run.length
            } else {
                i as f64 / run.count as f64
            };
            tpos[k] = run.t0 as f64 + run.steps as f64 * frac;
            arc += edge_len(k);
        }
    }

    // 4. Boundary samples: per cut path once, copied to its other side.
    let normals_in = mesh.vertex_normals();
    let n_of = |dv: u32| normals_in[orig(dv) as usize];
    let mut positions = vec![Vec3::ZERO; n * n];
    let mut normals = vec![Vec3::ZERO; n * n];
    let grid_index = |t: u64| -> usize {
        let t = t % perimeter;
        let (s, f) = ((t / side) as usize, (t % side) as usize);
        let (u, v) = match s {
            0 => (f, 0),
            1 => (n - 1, f),
            2 => (n - 1 - f, n - 1),
            _ => (0, n - 1 - f),
        };
        v * n + u
    };
    let mut uf: Vec<u32> = (0..(n * n) as u32).collect();
    for (r, run) in runs.iter().enumerate() {
        if run.mate != NONE && (run.mate as usize) < r {
            continue;
        }
        let samples = sample_polyline(
            &(run.start..=run.start + run.count)
                .map(|k| bv[k % nb])
                .collect::<Vec<_>>(),
            &dc.disk.positions,
            &|dv| n_of(dv),
            run.steps,
        );
        for (m, &(pp, nn)) in samples.iter().enumerate() {
            let g = grid_index(run.t0 + m as u64);
            positions[g] = pp;
            normals[g] = nn;
            if run.mate != NONE {
                let other = &runs[run.mate as usize];
                let g2 = grid_index(other.t0 + run.steps - m as u64);
                positions[g2] = pp;
                normals[g2] = nn;
                union(&mut uf, g as u32, g2 as u32);
            }
        }
    }
    progress(0.25);

    // 5. The disk with corner and chord splits, boundary fixed on the square.
    let mut disk = Editable {
        positions: dc.disk.positions.clone(),
        normals: (0..dc.disk.vertex_count() as u32).map(n_of).collect(),
        original: dc.original_vertex.clone(),
        triangles: dc.disk.triangles.clone(),
    };
    let mut ring: Vec<(u32, f64)> = (0..nb).map(|k| (bv[k], tpos[k])).collect();
    let mut directed = disk.directed_edges();
    // Perimeter parameters run from `turn` (the first node) to `turn + perimeter`.
    let first_corner = turn.div_ceil(side) * side;
    for c in 0..4u64 {
        let tc = (first_corner + c * side) as f64;
        let k = ring.partition_point(|&(_, t)| t <= tc) - 1;
        if ring[k].1 == tc {
            continue;
        }
        let (t_next, k_next) = if k + 1 < ring.len() {
            (ring[k + 1].1, k + 1)
        } else {
            ((turn + perimeter) as f64, 0)
        };
        const SNAP: f64 = 1e-3;
        if tc - ring[k].1 < SNAP {
            ring[k].1 = tc;
        } else if t_next - tc < SNAP && k_next != 0 {
            ring[k_next].1 = tc;
        } else {
            let alpha = (tc - ring[k].1) / (t_next - ring[k].1);
            let m = disk.split_edge(ring[k].0, ring[k_next].0, alpha, &mut directed)?;
            ring.insert(k + 1, (m, tc));
        }
    }
    let mut on_boundary = vec![false; disk.positions.len()];
    for &(v, _) in &ring {
        on_boundary[v as usize] = true;
    }
    let mut chords: Vec<(u32, u32)> = directed
        .keys()
        .filter(|&&(a, b)| {
            a < b
                && on_boundary[a as usize]
                && on_boundary[b as usize]
                && directed.contains_key(&(b, a))
        })
        .copied()
        .collect();
    chords.sort_unstable();
    for (a, b) in chords {
        disk.split_edge(a, b, 0.5, &mut directed)?;
    }
    let disk_mesh = Mesh::new(disk.positions.clone(), disk.triangles.clone());
    let square = |t: f64| -> DVec2 {
        let s = side as f64;
        let t = t.rem_euclid(perimeter as f64);
        let (q, f) = ((t / s).floor(), t - (t / s).floor() * s);
        match q as i64 {
            0 => DVec2::new(f, 0.0),
            1 => DVec2::new(s, f),
            2 => DVec2::new(s - f, s),
            _ => DVec2::new(0.0, s - f),
        }
    };
    let fixed: Vec<(u32, DVec2)> = ring.iter().map(|&(v, t)| (v, square(t))).collect();
    progress(0.35);

    // 6. Mean value map, then stretch reduction.
    let mut solver = ConvexCombinationSolver::new(&disk_mesh, &fixed)?;
    let weights = mean_value_weights(&disk_mesh);
    let uv0 = solver.solve(&disk_mesh, &weights)?;
    progress(0.55);
    let reduced = reduce_stretch(&disk_mesh, &mut solver, weights, uv0, p.stretch_iterations)?;
    let uv = reduced.uv;
    progress(0.85);
    let flipped_triangles = disk_mesh
        .triangles
        .iter()
        .filter(|t| {
            let q = t.map(|v| uv[v as usize]);
            (q[1] - q[0]).perp_dot(q[2] - q[0]) <= 0.0
        })
        .count();
    if flipped_triangles > 0 {
        tracing::warn!(
            flipped_triangles,
            "geometry image parameterization has flipped triangles"
        );
    }

    // 7. Interior samples: the most-inside triangle per grid point (ties: lower index).
    let mut best = vec![(f64::NEG_INFINITY, NONE, DVec3::ZERO); n * n];
    for (f, t) in disk_mesh.triangles.iter().enumerate() {
        let q = t.map(|v| uv[v as usize]);
        let lo = q[0].min(q[1]).min(q[2]);
        let hi = q[0].max(q[1]).max(q[2]);
        let det = (q[1] - q[0]).perp_dot(q[2] - q[0]);
        if det.abs() <= 0.0 || !det.is_finite() {
            continue;
        }
        let i0 = ((lo.y - 1e-9).ceil() as i64).max(1);
        let i1 = ((hi.y + 1e-9).floor() as i64).min(n as i64 - 2);
        let j0 = ((lo.x - 1e-9).ceil() as i64).max(1);
        let j1 = ((hi.x + 1e-9).floor() as i64).min(n as i64 - 2);
        for i in i0..=i1 {
            for j in j0..=j1 {
                let (i, j) = (i as usize, j as usize);
                let x = DVec2::new(j as f64, i as f64);
                let b1 = (x - q[0]).perp_dot(q[2] - q[0]) / det;
                let b2 = (q[1] - q[0]).perp_dot(x - q[0]) / det;
                let b0 = 1.0 - b1 - b2;
                let score = b0.min(b1).min(b2);
                let slot = &mut best[i * n + j];
                if score > slot.0 {
                    *slot = (score, f as u32, DVec3::new(b0, b1, b2));
                }
            }
        }
    }
    for i in 1..n - 1 {
        for j in 1..n - 1 {
            let (score, f, b) = best[i * n + j];
            if f == NONE {
                return Err(GeometryImageError::Internal(format!(
                    "grid point ({i}, {j}) is covered by no parameter-domain triangle"
                )));
            }
            // Outside every triangle only by rounding: clamp into the nearest one.
            let b = if score < 0.0 {
                let c = b.max(DVec3::ZERO);
                c / (c.x + c.y + c.z)
            } else {
                b
            };
            let t = disk_mesh.triangles[f as usize];
            let pp = disk.positions[t[0] as usize].as_dvec3() * b.x
                + disk.positions[t[1] as usize].as_dvec3() * b.y
                + disk.positions[t[2] as usize].as_dvec3() * b.z;
            let nn = disk.normals[t[0] as usize].as_dvec3() * b.x
                + disk.normals[t[1] as usize].as_dvec3() * b.y
                + disk.normals[t[2] as usize].as_dvec3() * b.z;
            positions[i * n + j] = pp.as_vec3();
            normals[i * n + j] = nn.normalize_or_zero().as_vec3();
        }
    }

    // 8. Mate groups: representative = smallest index; copy its values bit for bit.
    let mut mate_rep = vec![0u32; n * n];
    for g in 0..n * n {
        mate_rep[g] = find(&mut uf, g as u32);
    }
    for g in 0..n * n {
        let r = mate_rep[g] as usize;
        if r != g {
            positions[g] = positions[r];
            normals[g] = normals[r];
        }
    }
    progress(1.0);

    let mut cut_edges: Vec<[u32; 2]> = cut
        .edges
        .iter()
        .map(|&e| {
            let (a, b) = he.edge_vertices(e);
            [a.min(b), a.max(b)]
        })
        .collect();
    cut_edges.sort_unstable();
    let cut_nodes: Vec<u32> = (0..mesh.vertex_count() as u32)
        .filter(|&v| is_node(v))
        .collect();
    Ok(GeometryImageBuild {
        image: GeometryImage {
            n: p.size,
            positions,
            normals,
            mate_rep,
        },
        disk_uv: uv.iter().map(|q| q.as_vec2()).collect(),
        disk: disk_mesh,
        original_vertex: disk.original,
        cut_length: cut.length as f32,
        cut_edges,
        cut_nodes,
        genus: cut.genus as u32,
        boundary_loops: cut.boundary_loops as u32,
        initial_stretch: reduced.before.stretch as f32,
        stretch: reduced.after.stretch as f32,
        stretch_iterations_used: reduced.iterations,
        flipped_triangles,
        stretch_cuts: targets.to_vec(),
        anisotropy: f32::NAN,
    })
}

/// Whole units per item, at least one each, proportional to `(length, multiplicity)`
/// (an item uses `multiplicity` units per unit it gets), summing to exactly `total`: the
/// floors of the ideal shares (at least 1), then single units to the largest remainders
/// (or from the smallest, when the minimum of one unit overshot). `None` if impossible.
fn allocate_units(items: &[(f64, u64)], total: u64) -> Option<Vec<u64>> {
    let weight: f64 = items.iter().map(|&(l, m)| l * m as f64).sum();
    let ideal: Vec<f64> = items
        .iter()
        .map(|&(l, _)| {
            if weight > 0.0 {
                total as f64 * l / weight
            } else {
                total as f64 / items.iter().map(|&(_, m)| m as f64).sum::<f64>()
            }
        })
        .collect();
    let mut u: Vec<u64> = ideal.iter().map(|&x| (x.floor() as u64).max(1)).collect();
    let mut used: u64 = u.iter().zip(items).map(|(&x, &(_, m))| x * m).sum();
    while used > total {
        // Take from the most over-served item that can spare a unit.
        let i = (0..items.len()).filter(|&i| u[i] > 1).max_by(|&a, &b| {
            (u[a] as f64 - ideal[a])
                .total_cmp(&(u[b] as f64 - ideal[b]))
                .then(b.cmp(&a))
        })?;
        u[i] -= 1;
        used -= items[i].1;
    }
    while used < total {
        let room = total - used;
        let i = (0..items.len())
            .filter(|&i| items[i].1 <= room)
            .max_by(|&a, &b| {
                (ideal[a] - u[a] as f64)
                    .total_cmp(&(ideal[b] - u[b] as f64))
                    .then(b.cmp(&a))
            })?;
        u[i] += 1;
        used += items[i].1;
    }
    Some(u)
}

/// `steps + 1` samples (position, unit normal) evenly spaced by arc length along the polyline
/// through `vertices` (3D positions from `positions`), normals interpolated linearly and
/// renormalized. The first and last samples are exactly the end vertices.
fn sample_polyline(
    vertices: &[u32],
    positions: &[Vec3],
    normal: &dyn Fn(u32) -> Vec3,
    steps: u64,
) -> Vec<(Vec3, Vec3)> {
    let p = |i: usize| positions[vertices[i] as usize].as_dvec3();
    let mut cum = vec![0.0f64; vertices.len()];
    for i in 1..vertices.len() {
        cum[i] = cum[i - 1] + (p(i) - p(i - 1)).length();
    }
    let total = *cum.last().unwrap();
    let last = vertices.len() - 1;
    let mut out = Vec::with_capacity(steps as usize + 1);
    let mut seg = 0usize;
    for m in 0..=steps {
        if m == 0 || m == steps {
            let i = if m == 0 { 0 } else { last };
            out.push((positions[vertices[i] as usize], normal(vertices[i])));
            continue;
        }
        let (pos, nor) = if total > 0.0 {
            let s = total * m as f64 / steps as f64;
            while seg + 1 < last && cum[seg + 1] < s {
                seg += 1;
            }
            let l = cum[seg + 1] - cum[seg];
            let a = if l > 0.0 {
                ((s - cum[seg]) / l).clamp(0.0, 1.0)
            } else {
                0.0
            };
            let pp = p(seg).lerp(p(seg + 1), a);
            let nn = normal(vertices[seg])
                .as_dvec3()
                .lerp(normal(vertices[seg + 1]).as_dvec3(), a);
            (pp, nn)
        } else {
            let x = m as f64 / steps as f64 * last as f64;
            let i = (x.floor() as usize).min(last - 1);
            let a = x - i as f64;
            (
                p(i).lerp(p(i + 1), a),
                normal(vertices[i])
                    .as_dvec3()
                    .lerp(normal(vertices[i + 1]).as_dvec3(), a),
            )
        };
        out.push((pos.as_vec3(), nor.normalize_or_zero().as_vec3()));
    }
    out
}

fn find(uf: &mut [u32], mut x: u32) -> u32 {
    while uf[x as usize] != x {
        let p = uf[uf[x as usize] as usize];
        uf[x as usize] = p;
        x = p;
    }
    x
}

/// Joins two sets, keeping the smaller index as the root (so roots are group minima).
fn union(uf: &mut [u32], a: u32, b: u32) {
    let (ra, rb) = (find(uf, a), find(uf, b));
    if ra != rb {
        let (lo, hi) = (ra.min(rb), ra.max(rb));
        uf[hi as usize] = lo;
    }
}

/// The disk while vertices are inserted.
struct Editable {
    positions: Vec<Vec3>,
    normals: Vec<Vec3>,
    original: Vec<u32>,
    triangles: Vec<[u32; 3]>,
}

impl Editable {
    /// Directed edge (a, b) → (triangle, corner of a).
    fn directed_edges(&self) -> HashMap<(u32, u32), (u32, u8)> {
        let mut map = HashMap::with_capacity(self.triangles.len() * 3);
        for (f, t) in self.triangles.iter().enumerate() {
            for k in 0..3 {
                map.insert((t[k], t[(k + 1) % 3]), (f as u32, k as u8));
            }
        }
        map
    }

    /// Inserts a vertex on edge (a, b) at fraction `alpha` from a, splitting the one or two
    /// triangles on it; keeps `directed` up to date. Returns the new vertex.
    fn split_edge(
        &mut self,
        a: u32,
        b: u32,
        alpha: f64,
        directed: &mut HashMap<(u32, u32), (u32, u8)>,
    ) -> Result<u32, GeometryImageError> {
        let m = self.positions.len() as u32;
        let (pa, pb) = (
            self.positions[a as usize].as_dvec3(),
            self.positions[b as usize].as_dvec3(),
        );
        self.positions.push(pa.lerp(pb, alpha).as_vec3());
        let (na, nb) = (
            self.normals[a as usize].as_dvec3(),
            self.normals[b as usize].as_dvec3(),
        );
        self.normals
            .push(na.lerp(nb, alpha).normalize_or_zero().as_vec3());
        self.original.push(u32::MAX);
        let mut found = false;
        for (x, y) in [(a, b), (b, a)] {
            let Some((f, _)) = directed.remove(&(x, y)) else {
                continue;
            };
            found = true;
            let t = self.triangles[f as usize];
            let k = (0..3).find(|&k| t[k] == x && t[(k + 1) % 3] == y).unwrap();
            let c = t[(k + 2) % 3];
            // (x, y, c) → (x, m, c) in place and (m, y, c) appended.
            let g = self.triangles.len() as u32;
            self.triangles[f as usize] = [x, m, c];
            self.triangles.push([m, y, c]);
            directed.insert((x, m), (f, 0));
            directed.insert((m, c), (f, 1));
            directed.insert((c, x), (f, 2));
            directed.insert((m, y), (g, 0));
            directed.insert((y, c), (g, 1));
            directed.insert((c, m), (g, 2));
        }
        if !found {
            return Err(GeometryImageError::Internal(format!(
                "edge ({a}, {b}) to split is not in the disk"
            )));
        }
        Ok(m)
    }
}

impl GeometryImageParams {
    /// These parameters with cut-nodes on the grid of synthesis level `levels − 1`: valid
    /// parameters of their own (checked with one level) whose size must also fit `levels`.
    pub fn with_levels(&self, levels: u32) -> Result<GeometryImageParams, ParamError> {
        GeometryImageParams {
            coarse_levels: 1,
            ..self.clone()
        }
        .validate()?;
        let p = GeometryImageParams {
            coarse_levels: levels,
            ..self.clone()
        };
        if p.validate().is_err() {
            let message = format!(
                "{levels} levels need parameterize.size >= {} (2^levels + 1, so that the \
                 coarsest synthesis grid, where the cut-nodes sit (§4.2.2), has 3 samples per \
                 side), got size {}",
                (1u32 << levels) + 1,
                self.size
            );
            return Err(ParamError::invalid("analyse_exemplar.levels", message));
        }
        Ok(p)
    }
}

/// The parameterize node: the geometry image of the mesh.
pub fn node(
    mesh: &Mesh,
    p: &GeometryImageParams,
    progress: &dyn Fn(f32),
) -> Result<GeometryImage, Failure> {
    Ok(build_geometry_image(mesh, p, progress)
        .map_err(Failure::input)?
        .image)
}

/// `coarse_levels` is no key of a config's `[parameterize]`: the cut-nodes sit on the grid of
/// the coarsest synthesis level (§4.2.2), so it follows `analyse_exemplar.levels`.
fn set_by_levels<'de, D: serde::Deserializer<'de>>(_: D) -> Result<u32, D::Error> {
    Err(serde::de::Error::custom(
        "is not a setting: the cut-nodes sit on the grid of the coarsest synthesis level \
         (§4.2.2), so it follows analyse_exemplar.levels; remove it and set \
         analyse_exemplar.levels instead",
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn log_singular_ratio_is_zero_for_similarities_and_ln_k_for_a_stretch_by_k() {
        // A 3D triangle in a tilted plane, and its own coordinates in that plane.
        let (x, y) = (
            DVec3::new(1.0, 1.0, 0.0).normalize(),
            DVec3::new(-1.0, 1.0, 2.0).normalize(),
        );
        let flat = [DVec2::ZERO, DVec2::new(2.0, 0.0), DVec2::new(0.5, 1.5)];
        let q = flat.map(|f| DVec3::new(3.0, -1.0, 2.0) + x * f.x + y * f.y);
        let turn = |v: DVec2, a: f64| {
            DVec2::new(
                a.cos_pure() * v.x - a.sin_pure() * v.y,
                a.sin_pure() * v.x + a.cos_pure() * v.y,
            )
        };
        // Turned, scaled and moved: conformal.
        let similar = flat.map(|f| DVec2::new(7.0, 3.0) + 2.5 * turn(f, 0.7));
        assert!(log_singular_ratio(q, similar).unwrap().abs() < 1e-12);
        // Stretched by 3 along a direction at 0.4 rad, then turned: σ₁/σ₂ = 3.
        let stretched = flat.map(|f| {
            let along = turn(f, -0.4);
            turn(DVec2::new(3.0 * along.x, along.y), 1.1)
        });
        let r = log_singular_ratio(q, stretched).unwrap();
        assert!((r - 3f64.ln_pure()).abs() < 1e-12, "{r}");
        // Mirrored (flipped in the plane) or flattened: no value.
        let mirrored = flat.map(|f| DVec2::new(f.x, -f.y));
        assert_eq!(log_singular_ratio(q, mirrored), None);
        let line = [DVec2::ZERO, DVec2::X, DVec2::new(2.0, 0.0)];
        assert_eq!(log_singular_ratio(q, line), None);
    }

    #[test]
    fn allocation_is_proportional_at_least_one_and_exact() {
        // Two cut paths (counted twice) and one boundary run.
        let u = allocate_units(&[(3.0, 2), (1.0, 2), (2.0, 1)], 64).unwrap();
        assert_eq!(u[0] * 2 + u[1] * 2 + u[2], 64);
        // Ideal shares: 64·3/10 = 19.2, 6.4, 12.8.
        assert_eq!(u, vec![19, 6, 14]);
        // A tiny path still gets one unit.
        let u = allocate_units(&[(1000.0, 2), (0.001, 2)], 8).unwrap();
        assert_eq!(u, vec![3, 1]);
        // Impossible: an odd total with only doubled items.
        assert!(allocate_units(&[(1.0, 2)], 5).is_none());
    }

    #[test]
    fn polyline_samples_are_even_in_arc_length_and_end_on_the_vertices() {
        let pos = vec![Vec3::ZERO, Vec3::X, Vec3::new(1.0, 3.0, 0.0)];
        let s = sample_polyline(&[0, 1, 2], &pos, &|_| Vec3::Z, 8);
        assert_eq!(s.len(), 9);
        assert_eq!(s[0].0, pos[0]);
        assert_eq!(s[8].0, pos[2]);
        // Total length 4: sample m is at arc length m/2.
        assert!((s[1].0 - Vec3::new(0.5, 0.0, 0.0)).length() < 1e-6);
        assert!((s[4].0 - Vec3::new(1.0, 1.0, 0.0)).length() < 1e-6);
        assert!(s.iter().all(|x| x.1 == Vec3::Z));
    }

    #[test]
    fn params_validate_names_the_field() {
        let ok = GeometryImageParams::default();
        assert!(ok.validate().is_ok());
        let bad = GeometryImageParams {
            size: 100,
            ..ok.clone()
        };
        assert_eq!(
            bad.validate().unwrap_err().to_string(),
            "size must be 2^k + 1 with 2 <= k <= 12 (5, 9, 17, 33, 65, 129, 257, 513, 1025, 2049 \
             or 4097), got 100"
        );
        let bad = GeometryImageParams {
            coarse_levels: 9,
            ..ok.clone()
        };
        assert!(
            bad.validate()
                .unwrap_err()
                .to_string()
                .contains("coarse_levels")
        );
        let bad = GeometryImageParams {
            size: 65,
            coarse_levels: 7,
            ..ok.clone()
        };
        assert_eq!(
            bad.validate().unwrap_err().to_string(),
            "coarse_levels must be in 1..=6 for size 65 (the coarsest grid needs at least 3 \
             samples per side), got 7"
        );
        let parsed: GeometryImageParams = toml::from_str("size = 65").unwrap();
        assert_eq!(parsed.size, 65);
        assert_eq!(parsed.coarse_levels, 3);
        assert!(toml::from_str::<GeometryImageParams>("sise = 65").is_err());
    }
}

//! Crest lines (ridges and valleys) of smooth meshes: the salient curves of feature-aligned
//! texturing (Xu et al., "Feature-Aligned Shape Texturing", §6: "we adopt the algorithm and
//! available implementation of Yoshizawa et al. [2005]"). texsyn finds them itself, after
//! Yoshizawa, Belyaev & Seidel, "Fast and robust detection of crest lines on meshes" (SPM
//! 2005), whose ridge tracing is that of Ohtake, Belyaev & Seidel, "Ridge-valley lines on
//! meshes via implicit surface fitting" (SIGGRAPH 2004).
//!
//! 1. Principal curvatures k_max ≥ k_min and directions t_max, t_min per vertex, from a
//!    least-squares fit of a height function z = ax² + bxy + cy² + dx + ey over the vertex's
//!    `rings`-ring in the tangent frame of its area-weighted normal. The linear terms absorb
//!    the normal's error; the shape operator is taken with them (first and second
//!    fundamental forms of the fitted graph at the vertex), not as if the plane were exact.
//!    Curvature is positive where the surface bends away from its normal (convex: a sphere
//!    with outward normals has k = 1/R), so ridges are where k_max is large and positive.
//! 2. Extremality coefficients e_max = ∇k_max · t_max and e_min = ∇k_min · t_min: the
//!    gradient of the piecewise-linear k per triangle, averaged over a vertex's triangles
//!    weighted by area, dotted with the vertex's own direction (Yoshizawa §3).
//! 3. Ridge points: on an edge whose ends both have k_max > |k_min|, after flipping one end's
//!    t_max (and e_max) when t_max · t_max' < 0, e_max changes sign; the point is where the
//!    linear interpolation of e_max vanishes. It is kept when it is a maximum: Yoshizawa's
//!    derivative-sign condition, that k_max grows from both ends toward the zero, i.e.
//!    e_max(v1)·(t_max(v1)·(v2 − v1)) − e_max(v2)·(t_max(v2)·(v2 − v1)) > 0. Valleys are the
//!    same with k_min < −|k_max|, e_min, t_min and a minimum (< 0).
//! 4. A triangle with two crossed edges joins their points by a segment; one with three
//!    joins each to its centroid (Ohtake §3), a junction. Segments are traced into polylines
//!    that run from an end or junction to the next; what remains are loops.
//! 5. Filters: a line's strength is ∫|k| ds along it (k = k_max on ridges, k_min on
//!    valleys, interpolated along each segment; Yoshizawa's and Ohtake's filter). Lines
//!    shorter than `min_length` × the bounding-box diagonal, or weaker than `threshold` × the
//!    strongest line of their kind (ridge or valley), are dropped.
//!
//! Departures and values the papers leave open:
//! - The fit is a quadratic over a topological k-ring (default 2), not Yoshizawa's cubic
//!   fit or Ohtake's implicit MPU fit: a quadratic is exact for the curvature of spheres and
//!   cylinders and the 2-ring is what Yoshizawa's neighbourhood amounts to on a regular mesh.
//!   A vertex whose ring holds fewer than six other vertices (boundary corners) takes one
//!   more ring, up to six. Nothing is smoothed: the ring fit already averages over about 18
//!   vertices, and smoothing e would move the zeros.
//! - Crossings of e use a half-open sign test (e ≥ 0 against e < 0), so a ridge passing
//!   exactly through a vertex, where e = 0, is still found on the edge beyond it.
//! - Relative thresholds are per kind, so ridges do not hide valleys that are merely
//!   weaker, and `kind = "ridges"` keeps exactly the ridges of `kind = "both"`.
//! - An absolute floor is added ([`CrestParams::min_sharpness`]): a relative threshold alone
//!   cannot tell a shape with crests from one with none, since on a noisy sphere or plane the
//!   strongest noise line sets the scale and survives. The floor is on ∫(|k| − |k_other|) ds
//!   (k_other the other principal curvature at the same point), which is dimensionless (about
//!   a crest's length over its cross-section's radius of curvature), unchanged by scaling the
//!   mesh, and near zero where the surface is umbilic (spheres, planes), where the crest
//!   direction is noise.
//! - Points on edges are snapped to vertex paths ([`crest_polylines`], via
//!   [`super::vertex_paths`]) for the curve orientation and field, which work on vertices;
//!   back-and-forth steps (a b a) the snapping makes along lines that zig-zag across an edge
//!   are removed.

use super::crease_lines::Polyline;
use super::vertex_paths::Snapper;
use crate::check::{ParamError, check_range};
use crate::geom::Mesh;
use glam::Vec3;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use texsyn_core::math::PureMath;

/// Which crest lines to find.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum CrestKind {
    /// Maxima of the larger principal curvature across the line (convex crests).
    Ridges,
    /// Minima of the smaller principal curvature (concave creases, grooves).
    Valleys,
    Both,
}

/// Parameters of [`crest_lines`] and [`crest_polylines`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CrestParams {
    /// Ridges, valleys or both: "ridges" | "valleys" | "both". Default "both".
    pub kind: CrestKind,
    /// Strength filter: lines whose strength (∫|k| ds) is below this fraction of the
    /// strongest line of their kind are dropped, 0..=1. Default 0.1: Ohtake et al. and
    /// Yoshizawa et al. leave the threshold to the user; 0.1 keeps lines down to a tenth of
    /// the strongest (a crest a tenth as long, or as sharp) and drops the many short weak
    /// lines the noise of a scanned mesh makes: of the ridges longer than `min_length`, it
    /// keeps 36 of 49 on elephant.off, 46 of 90 on man.off, 28 of 90 on
    /// refined_elephant.off.
    pub threshold: f32,
    /// Shortest line kept, fraction of bounding-box diagonal, 0..=1. Default 0.05.
    pub min_length: f32,
    /// Rings of the fitting neighbourhood (1..=4). Default 2.
    pub rings: u32,
    /// Absolute floor: lines with ∫(|k| − |k_other|) ds below this are dropped, where k is
    /// the line's principal curvature and k_other the other one (dimensionless: about the
    /// crest's length over its cross-section's radius of curvature), 0..=1000. It removes
    /// the lines of shapes without crests (spheres, planes, noise), which a relative
    /// threshold cannot. Default 1: a crest at least as long as it is round across.
    pub min_sharpness: f32,
}

impl Default for CrestParams {
    fn default() -> Self {
        CrestParams {
            kind: CrestKind::Both,
            threshold: 0.1,
            min_length: 0.05,
            rings: 2,
            min_sharpness: 1.0,
        }
    }
}

impl CrestParams {
    pub fn validate(&self) -> Result<(), ParamError> {
        check_range("extract.crest.threshold", self.threshold, 0.0, 1.0)?;
        check_range("extract.crest.min_length", self.min_length, 0.0, 1.0)?;
        check_range("extract.crest.rings", self.rings, 1, 4)?;
        check_range(
            "extract.crest.min_sharpness",
            self.min_sharpness,
            0.0,
            1000.0,
        )
    }
}

/// Principal curvatures and directions at a vertex. k > 0 where the surface bends away from
/// its normal (convex). t_max and t_min are unit tangents, orthogonal, each defined up to
/// sign; zero curvature and arbitrary directions where no fit was possible.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Curvature {
    pub k_max: f32,
    pub k_min: f32,
    pub t_max: Vec3,
    pub t_min: Vec3,
}

/// A crest line as traced: points on mesh edges (and triangle centroids at junctions).
#[derive(Clone, Debug, PartialEq)]
pub struct CrestLine {
    pub points: Vec<Vec3>,
    /// A loop; its last point joins the first (not repeated).
    pub closed: bool,
    /// A ridge (else a valley).
    pub ridge: bool,
    /// ∫|k| ds along the line.
    pub strength: f32,
}

/// Per-vertex principal curvatures from the quadratic fit over `rings` rings (see the
/// module doc). `rings` is clamped to 1..=4.
pub fn principal_curvatures(mesh: &Mesh, rings: u32) -> Vec<Curvature> {
    let rings = rings.clamp(1, 4) as usize;
    let normals = mesh.vertex_normals();
    let adj = mesh.adjacency();
    (0..mesh.positions.len())
        .into_par_iter()
        .map(|v| fit_vertex(mesh, normals, adj, v, rings))
        .collect()
}

fn flat(n: Vec3) -> Curvature {
    let (t_max, t_min) = if n == Vec3::ZERO {
        (Vec3::X, Vec3::Y)
    } else {
        n.any_orthonormal_pair()
    };
    Curvature {
        k_max: 0.0,
        k_min: 0.0,
        t_max,
        t_min,
    }
}

/// The vertices within `rings` rings of `v` (excluding `v`), with more rings (up to six)
/// while fewer than six were found.
fn neighbourhood(adj: &crate::geom::VertexAdjacency, v: usize, rings: usize) -> Vec<u32> {
    let mut all: Vec<u32> = vec![v as u32];
    let mut ring: Vec<u32> = vec![v as u32];
    let mut r = 0;
    while r < rings || (all.len() < 7 && r < 6) {
        let mut next: Vec<u32> = ring
            .iter()
            .flat_map(|&u| adj.neighbors(u as usize).iter().copied())
            .collect();
        next.sort_unstable();
        next.dedup();
        next.retain(|x| all.binary_search(x).is_err());
        if next.is_empty() {
            break;
        }
        all.extend_from_slice(&next);
        all.sort_unstable();
        ring = next;
        r += 1;
    }
    all.retain(|&x| x != v as u32);
    all
}

/// Solves the symmetric system `a x = b` (n ≤ 5) by Gaussian elimination with partial
/// pivoting; None when a pivot is negligible against the matrix's scale.
fn solve<const N: usize>(mut a: [[f64; N]; N], mut b: [f64; N]) -> Option<[f64; N]> {
    let scale = (0..N).map(|i| a[i][i].abs()).fold(0.0, f64::max);
    if scale <= 0.0 {
        return None;
    }
    for c in 0..N {
        let p = (c..N)
            .max_by(|&i, &j| a[i][c].abs().total_cmp(&a[j][c].abs()))
            .expect("non-empty");
        if a[p][c].abs() < 1e-10 * scale {
            return None;
        }
        a.swap(c, p);
        b.swap(c, p);
        for r in c + 1..N {
            let f = a[r][c] / a[c][c];
            for k in c..N {
                a[r][k] -= f * a[c][k];
            }
            b[r] -= f * b[c];
        }
    }
    let mut x = [0.0; N];
    for c in (0..N).rev() {
        let s: f64 = (c + 1..N).map(|k| a[c][k] * x[k]).sum();
        x[c] = (b[c] - s) / a[c][c];
    }
    Some(x)
}

fn fit_vertex(
    mesh: &Mesh,
    normals: &[Vec3],
    adj: &crate::geom::VertexAdjacency,
    v: usize,
    rings: usize,
) -> Curvature {
    let n = normals[v];
    if n == Vec3::ZERO {
        return flat(n);
    }
    let (u, w) = n.any_orthonormal_pair();
    let nbrs = neighbourhood(adj, v, rings);
    if nbrs.len() < 3 {
        return flat(n);
    }
    let p = mesh.positions[v];
    // Fit in units of the neighbourhood's size, so the normal equations are well scaled.
    let h = nbrs
        .iter()
        .map(|&q| (mesh.positions[q as usize] - p).length() as f64)
        .sum::<f64>()
        / nbrs.len() as f64;
    if h <= 0.0 || !h.is_finite() {
        return flat(n);
    }
    let local: Vec<[f64; 3]> = nbrs
        .iter()
        .map(|&q| {
            let d = mesh.positions[q as usize] - p;
            [
                d.dot(u) as f64 / h,
                d.dot(w) as f64 / h,
                d.dot(n) as f64 / h,
            ]
        })
        .collect();
    // z = a x² + b xy + c y² + d x + e y; without the linear terms when there are too few
    // points for five unknowns.
    let coeffs = if local.len() >= 5 {
        let mut m = [[0.0; 5]; 5];
        let mut r = [0.0; 5];
        for &[x, y, z] in &local {
            let row = [x * x, x * y, y * y, x, y];
            for i in 0..5 {
                for j in 0..5 {
                    m[i][j] += row[i] * row[j];
                }
                r[i] += row[i] * z;
            }
        }
        solve(m, r)
    } else {
        None
    };
    let [a, b, c, d, e] = match coeffs {
        Some(x) => x,
        None => {
            let mut m = [[0.0; 3]; 3];
            let mut r = [0.0; 3];
            for &[x, y, z] in &local {
                let row = [x * x, x * y, y * y];
                for i in 0..3 {
                    for j in 0..3 {
                        m[i][j] += row[i] * row[j];
                    }
                    r[i] += row[i] * z;
                }
            }
            match solve(m, r) {
                Some([a, b, c]) => [a, b, c, 0.0, 0.0],
                None => return flat(n),
            }
        }
    };
    let (hx, hy, hxx, hxy, hyy) = (d, e, 2.0 * a, b, 2.0 * c);
    let w2 = 1.0 + hx * hx + hy * hy;
    let wl = w2.sqrt();
    // Shape operator −I⁻¹·II of the graph (sign: convex positive), in the basis
    // r_x = (1, 0, hx), r_y = (0, 1, hy); scaled coordinates, so divided by h.
    let (i11, i12, i22) = ((1.0 + hy * hy) / w2, -hx * hy / w2, (1.0 + hx * hx) / w2);
    let (l, m_, nn) = (hxx / wl, hxy / wl, hyy / wl);
    let s11 = -(i11 * l + i12 * m_) / h;
    let s12 = -(i11 * m_ + i12 * nn) / h;
    let s21 = -(i12 * l + i22 * m_) / h;
    let s22 = -(i12 * m_ + i22 * nn) / h;
    let half_tr = 0.5 * (s11 + s22);
    let det = s11 * s22 - s12 * s21;
    let root = (half_tr * half_tr - det).max(0.0).sqrt();
    let (k1, k2) = (half_tr + root, half_tr - root);
    let ev_a = (s12, k1 - s11);
    let ev_b = (k1 - s22, s21);
    let (al, be) = if ev_a.0.hypot_pure(ev_a.1) >= ev_b.0.hypot_pure(ev_b.1) {
        ev_a
    } else {
        ev_b
    };
    let (al, be) = if al.hypot_pure(be) < 1e-12 * (1.0 + k1.abs()) {
        (1.0, 0.0)
    } else {
        (al, be)
    };
    let (u64_, w64, n64) = (u.as_dvec3(), w.as_dvec3(), n.as_dvec3());
    let t_max = (al * (u64_ + hx * n64) + be * (w64 + hy * n64)).normalize();
    let n_fit = (n64 - hx * u64_ - hy * w64) / wl;
    let t_min = n_fit.cross(t_max).normalize();
    if !(t_max.is_finite() && t_min.is_finite() && k1.is_finite() && k2.is_finite()) {
        return flat(n);
    }
    Curvature {
        k_max: k1 as f32,
        k_min: k2 as f32,
        t_max: t_max.as_vec3(),
        t_min: t_min.as_vec3(),
    }
}

/// Per vertex, the area-weighted mean over its triangles of the per-triangle gradient of
/// the piecewise-linear function `f`, for two functions at once.
fn vertex_gradients(mesh: &Mesh, f: &[[f32; 2]]) -> Vec<[Vec3; 2]> {
    let face_terms: Vec<([Vec3; 2], f32)> = mesh
        .triangles
        .par_iter()
        .map(|t| {
            let p = t.map(|v| mesh.positions[v as usize]);
            let nrm = (p[1] - p[0]).cross(p[2] - p[0]);
            let two_a = nrm.length();
            if two_a <= 0.0 || !two_a.is_finite() {
                return ([Vec3::ZERO; 2], 0.0);
            }
            let nh = nrm / two_a;
            // ∇f·A = ½ Σ f_i (n × e_i), e_i the edge opposite corner i, counter-clockwise.
            let e = [p[2] - p[1], p[0] - p[2], p[1] - p[0]];
            let g = |c: usize| {
                (0..3)
                    .map(|i| f[t[i] as usize][c] * nh.cross(e[i]))
                    .fold(Vec3::ZERO, |s, x| s + x)
                    * 0.5
            };
            ([g(0), g(1)], 0.5 * two_a)
        })
        .collect();
    let nv = mesh.positions.len();
    let faces = mesh.vertex_faces();
    (0..nv)
        .into_par_iter()
        .map(|v| {
            let mut g = [Vec3::ZERO; 2];
            let mut area = 0.0f32;
            for &fi in faces.row(v) {
                let (fg, a) = face_terms[fi as usize];
                g[0] += fg[0];
                g[1] += fg[1];
                area += a;
            }
            if area > 0.0 {
                [g[0] / area, g[1] / area]
            } else {
                [Vec3::ZERO; 2]
            }
        })
        .collect()
}

/// A crest point on an edge (or at a junction).
#[derive(Clone, Copy)]
struct Node {
    p: Vec3,
    /// |k| of the line's curvature, and |k| − |k_other|.
    k: f32,
    excess: f32,
}

/// Per-vertex quantities of one kind of crest (ridge: k_max, t_max, e_max, and the
/// condition k_max > |k_min|).
struct Field<'a> {
    ridge: bool,
    curv: &'a [Curvature],
    e: Vec<f32>,
}

impl Field<'_> {
    fn eligible(&self, v: usize) -> bool {
        let c = &self.curv[v];
        if self.ridge {
            c.k_max > c.k_min.abs()
        } else {
            c.k_min < -c.k_max.abs()
        }
    }

    fn k_t(&self, v: usize) -> (f32, f32, Vec3) {
        let c = &self.curv[v];
        if self.ridge {
            (c.k_max, c.k_min, c.t_max)
        } else {
            (c.k_min, c.k_max, c.t_min)
        }
    }

    /// The crest point on edge (a, b), if there is one.
    fn crossing(&self, mesh: &Mesh, a: usize, b: usize) -> Option<Node> {
        if !(self.eligible(a) && self.eligible(b)) {
            return None;
        }
        let (k1, o1, t1) = self.k_t(a);
        let (k2, o2, mut t2) = self.k_t(b);
        let e1 = self.e[a];
        let mut e2 = self.e[b];
        if t1.dot(t2) < 0.0 {
            t2 = -t2;
            e2 = -e2;
        }
        if (e1 >= 0.0) == (e2 >= 0.0) || e1 == e2 {
            return None;
        }
        let (p1, p2) = (mesh.positions[a], mesh.positions[b]);
        let d = p2 - p1;
        // k grows toward the zero from both ends for a maximum; shrinks for a minimum.
        let growth = e1 * t1.dot(d) - e2 * t2.dot(d);
        if (self.ridge && growth <= 0.0) || (!self.ridge && growth >= 0.0) {
            return None;
        }
        let s = e1 / (e1 - e2);
        let k = k1 + s * (k2 - k1);
        let o = o1 + s * (o2 - o1);
        Some(Node {
            p: p1 + s * d,
            k: k.abs(),
            excess: k.abs() - o.abs(),
        })
    }
}

/// Crest lines as traced (points on edges), deterministic order: by decreasing strength,
/// ties in tracing order.
pub fn crest_lines(mesh: &Mesh, p: &CrestParams) -> Vec<CrestLine> {
    if mesh.triangles.is_empty() {
        return Vec::new();
    }
    let curv = principal_curvatures(mesh, p.rings);
    let kvals: Vec<[f32; 2]> = curv.iter().map(|c| [c.k_max, c.k_min]).collect();
    let grads = vertex_gradients(mesh, &kvals);
    let (lo, hi) = mesh.bounds();
    let diag = (hi - lo).length();
    let mut out = Vec::new();
    for ridge in [true, false] {
        let wanted = match p.kind {
            CrestKind::Both => true,
            CrestKind::Ridges => ridge,
            CrestKind::Valleys => !ridge,
        };
        if !wanted {
            continue;
        }
        let e = curv
            .iter()
            .zip(&grads)
            .map(|(c, g)| {
                if ridge {
                    g[0].dot(c.t_max)
                } else {
                    g[1].dot(c.t_min)
                }
            })
            .collect();
        let field = Field {
            ridge,
            curv: &curv,
            e,
        };
        let mut lines = trace(mesh, &field);
        let max_strength = lines.iter().map(|l| l.0.strength).fold(0.0, f32::max);
        lines.retain(|(l, length, excess)| {
            *length >= p.min_length * diag
                && l.strength >= p.threshold * max_strength
                && *excess >= p.min_sharpness
        });
        out.extend(lines.into_iter().map(|l| l.0));
    }
    // Stable: equal strengths keep ridges before valleys and tracing order.
    out.sort_by(|a, b| b.strength.total_cmp(&a.strength));
    out
}

/// Crossing points of one kind, joined within triangles and traced into lines, each with
/// its length and ∫(|k| − |k_other|) ds.
fn trace(mesh: &Mesh, field: &Field) -> Vec<(CrestLine, f32, f32)> {
    let adj = mesh.adjacency();
    let nv = mesh.positions.len();
    // One crossing per undirected edge, indexed by the half-edge (low -> high).
    let per_vertex: Vec<Vec<(u32, Node)>> = (0..nv)
        .into_par_iter()
        .map(|a| {
            let start = adj.offsets[a];
            adj.neighbors(a)
                .iter()
                .enumerate()
                .filter(|&(_, &b)| b as usize > a)
                .filter_map(|(i, &b)| {
                    field
                        .crossing(mesh, a, b as usize)
                        .map(|n| (start + i as u32, n))
                })
                .collect()
        })
        .collect();
    let mut nodes: BTreeMap<u32, Node> = per_vertex.into_iter().flatten().collect();
    let n_he = adj.neighbors.len() as u32;
    let edge_node = |a: u32, b: u32| {
        let (lo, hi) = (a.min(b), a.max(b));
        adj.half_edge(lo as usize, hi).map(|i| i as u32)
    };
    let mut graph: BTreeMap<u32, Vec<u32>> = BTreeMap::new();
    let link = |g: &mut BTreeMap<u32, Vec<u32>>, a: u32, b: u32| {
        g.entry(a).or_default().push(b);
        g.entry(b).or_default().push(a);
    };
    for (f, t) in mesh.triangles.iter().enumerate() {
        let crossed: Vec<u32> = (0..3)
            .filter_map(|k| edge_node(t[k], t[(k + 1) % 3]))
            .filter(|id| nodes.contains_key(id))
            .collect();
        match crossed.len() {
            2 => link(&mut graph, crossed[0], crossed[1]),
            3 => {
                let c = n_he + f as u32;
                let ns = crossed.iter().map(|id| nodes[id]).collect::<Vec<_>>();
                nodes.insert(
                    c,
                    Node {
                        p: (ns[0].p + ns[1].p + ns[2].p) / 3.0,
                        k: (ns[0].k + ns[1].k + ns[2].k) / 3.0,
                        excess: (ns[0].excess + ns[1].excess + ns[2].excess) / 3.0,
                    },
                );
                for &id in &crossed {
                    link(&mut graph, c, id);
                }
            }
            _ => {}
        }
    }
    let paths = crate::geom::chains::trace_chains(&graph);
    paths
        .into_iter()
        .map(|(ids, closed)| {
            let pts: Vec<Node> = ids.iter().map(|id| nodes[id]).collect();
            let mut length = 0.0f32;
            let mut strength = 0.0f32;
            let mut excess = 0.0f32;
            let segs = pts.len() - 1 + usize::from(closed && pts.len() > 2);
            for i in 0..segs {
                let (a, b) = (pts[i], pts[(i + 1) % pts.len()]);
                let ds = a.p.distance(b.p);
                length += ds;
                strength += 0.5 * (a.k + b.k) * ds;
                excess += 0.5 * (a.excess + b.excess) * ds;
            }
            let line = CrestLine {
                points: pts.iter().map(|n| n.p).collect(),
                closed: closed && pts.len() > 2,
                ridge: field.ridge,
                strength,
            };
            (line, length, excess)
        })
        .collect()
}

/// The same lines snapped to vertex paths (see vertex_paths.rs), ready for the field: in
/// the order of [`crest_lines`], with back-and-forth steps removed; lines that shrink to a
/// single vertex are dropped.
pub fn crest_polylines(mesh: &Mesh, p: &CrestParams) -> Vec<(Polyline, bool /*ridge*/)> {
    let lines = crest_lines(mesh, p);
    let Ok(mut snapper) = Snapper::new(mesh) else {
        return Vec::new();
    };
    lines
        .iter()
        .filter_map(|l| {
            // Points of a traced line lie on one connected piece, so snapping cannot fail;
            // a line that did would be dropped rather than stop the run.
            let snapped = snapper.snap(&l.points, l.closed, None).ok()?;
            let poly = without_spikes(snapped);
            (poly.vertices.len() >= 2).then_some((poly, l.ridge))
        })
        .collect()
}

/// Removes a → b → a steps (the path goes back where it came from), also across the seam
/// of a loop.
fn without_spikes(l: Polyline) -> Polyline {
    let mut v: Vec<u32> = Vec::with_capacity(l.vertices.len());
    for &x in &l.vertices {
        if v.len() >= 2 && v[v.len() - 2] == x {
            v.pop();
        } else if v.last() != Some(&x) {
            v.push(x);
        }
    }
    let mut closed = l.closed;
    if closed {
        loop {
            let n = v.len();
            if n >= 2 && v[0] == v[n - 1] {
                v.pop();
            } else if n >= 3 && v[n - 1] == v[1] {
                // … b | a b …: the seam goes a → b → a.
                v.remove(0);
                v.pop();
            } else if n >= 3 && v[n - 2] == v[0] {
                // … a b | a …: the seam goes a → b → a.
                v.pop();
            } else {
                break;
            }
        }
        closed = v.len() >= 3;
    }
    Polyline {
        vertices: v,
        closed,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geom::primitives::{grid, octahedron};
    use crate::geom::subdivide::subdivide;
    use crate::random::counter_unit;
    use crate::testing::assert_validation;
    use std::f32::consts::TAU;

    fn sphere(levels: u32, r: f32) -> Mesh {
        let mut m = octahedron();
        for _ in 0..levels {
            m = subdivide(&m);
        }
        let pos = m.positions.iter().map(|p| p.normalize() * r).collect();
        Mesh::new(pos, m.triangles.clone())
    }

    /// An open cylinder of radius r along z, n around and `rows` rows of height h.
    fn cylinder(r: f32, n: u32, rows: u32, h: f32) -> Mesh {
        let mut pos = Vec::new();
        for j in 0..=rows {
            for i in 0..n {
                // Alternate rows are offset by half a step, for near-equilateral triangles.
                let a = (i as f32 + 0.5 * (j % 2) as f32) / n as f32 * TAU;
                pos.push(Vec3::new(r * a.cos_pure(), r * a.sin_pure(), j as f32 * h));
            }
        }
        let mut tris = Vec::new();
        for j in 0..rows {
            for i in 0..n {
                let (a, b) = (j * n + i, j * n + (i + 1) % n);
                let (c, d) = (a + n, b + n);
                // Outward normals: counter-clockwise seen from outside.
                tris.push([a, b, c]);
                tris.push([b, d, c]);
            }
        }
        Mesh::new(pos, tris)
    }

    #[test]
    fn validation_names_the_key() {
        assert_validation!(CrestParams {
            threshold: 1.5 => "extract.crest.threshold must be in 0..=1, got 1.5",
            min_length: -0.1 => "extract.crest.min_length must be in 0..=1, got -0.1",
            rings: 0 => "extract.crest.rings must be in 1..=4, got 0",
            min_sharpness: -1.0 => "extract.crest.min_sharpness must be in 0..=1000, got -1",
        });
        let p: CrestParams = toml::from_str("kind = \"ridges\"\nrings = 3").unwrap();
        assert_eq!(p.kind, CrestKind::Ridges);
        assert_eq!(p.rings, 3);
        assert!(toml::from_str::<CrestParams>("kind = \"crests\"").is_err());
        assert!(toml::from_str::<CrestParams>("thresold = 0.2").is_err());
    }

    #[test]
    fn a_sphere_has_both_curvatures_one_over_its_radius() {
        let r = 2.5;
        let m = sphere(4, r);
        // A quadratic fit overestimates a sphere's curvature by about r²/(2R²) at distance r,
        // so three rings (r ≈ 0.3 R here) are allowed more.
        for (rings, tol) in [(1, 0.03), (2, 0.03), (3, 0.06)] {
            let c = principal_curvatures(&m, rings);
            for (v, c) in c.iter().enumerate() {
                assert!(
                    (c.k_max * r - 1.0).abs() < tol && (c.k_min * r - 1.0).abs() < tol,
                    "rings {rings}, vertex {v}: {c:?}"
                );
                let n = m.positions[v].normalize();
                assert!(c.t_max.dot(n).abs() < 0.05 && c.t_min.dot(n).abs() < 0.05);
                assert!(c.t_max.dot(c.t_min).abs() < 1e-4);
            }
        }
        // Inward normals flip the sign.
        let inv = Mesh::new(
            m.positions.clone(),
            m.triangles.iter().map(|t| [t[0], t[2], t[1]]).collect(),
        );
        let c = principal_curvatures(&inv, 2);
        assert!(c.iter().all(|c| (c.k_max * r + 1.0).abs() < 0.03));
    }

    #[test]
    fn a_cylinder_curves_across_and_not_along_its_axis() {
        let r = 0.7;
        let m = cylinder(r, 48, 40, 0.08);
        let c = principal_curvatures(&m, 2);
        // Away from the open ends.
        let mut checked = 0;
        for (v, c) in c.iter().enumerate() {
            let z = m.positions[v].z;
            if !(0.4..=2.8).contains(&z) {
                continue;
            }
            checked += 1;
            assert!((c.k_max * r - 1.0).abs() < 0.03, "vertex {v}: {c:?}");
            assert!(c.k_min.abs() * r < 0.03, "vertex {v}: {c:?}");
            assert!(c.t_min.z.abs() > 0.99, "t_min not along the axis: {c:?}");
            assert!(c.t_max.z.abs() < 0.1, "{c:?}");
        }
        assert!(checked > 1000);
    }

    /// A plane z = A·sin(2πx/λ) on a grid of `n`×`n` vertices `h` apart, x from x0.
    fn sine_plane(n: usize, h: f32, amp: f32, lambda: f32, x0: f32) -> Mesh {
        let g = grid(n, h);
        let pos = g
            .positions
            .iter()
            .map(|p| {
                let x = p.x + x0;
                Vec3::new(x, p.y, amp * (TAU * x / lambda).sin_pure())
            })
            .collect();
        Mesh::new(pos, g.triangles.clone())
    }

    /// Distance in x from `x` to the nearest of the lines x = offset + kλ.
    fn off_line(x: f32, offset: f32, lambda: f32) -> f32 {
        let d = (x - offset).rem_euclid(lambda);
        d.min(lambda - d)
    }

    #[test]
    fn a_sine_ridged_plane_has_ridges_on_its_crests_and_valleys_in_its_troughs() {
        let (n, h, lambda) = (91, 0.02, 0.45);
        // x from 0 to 1.8 = 4λ: four crests (x = 0.1125 + kλ) and four troughs (from
        // x = 0.3375), each at least λ/4 from the edge; they do not fall on vertex columns.
        let m = sine_plane(n, h, 0.05, lambda, 0.0);
        let y_len = (n - 1) as f32 * h;
        let lines = crest_lines(&m, &CrestParams::default());
        let ridges: Vec<_> = lines.iter().filter(|l| l.ridge).collect();
        let valleys: Vec<_> = lines.iter().filter(|l| !l.ridge).collect();
        for (set, offset, what) in [
            (&ridges, lambda / 4.0, "ridge"),
            (&valleys, 0.75 * lambda, "valley"),
        ] {
            // Every point near a line of its kind.
            for l in set.iter() {
                for p in &l.points {
                    assert!(
                        off_line(p.x, offset, lambda) < 0.05 * lambda,
                        "{what} point {p} is off the lines x = {offset} + k·{lambda}"
                    );
                }
            }
            // Each of the four lines covered over most of its length (in y).
            for k in 0..4 {
                let x = offset + k as f32 * lambda;
                let mut ys: Vec<f32> = set
                    .iter()
                    .flat_map(|l| l.points.iter())
                    .filter(|p| (p.x - x).abs() < 0.05 * lambda)
                    .map(|p| p.y)
                    .collect();
                ys.sort_by(f32::total_cmp);
                let mut covered = 0.0;
                for w in ys.windows(2) {
                    if w[1] - w[0] < 2.0 * h {
                        covered += w[1] - w[0];
                    }
                }
                assert!(
                    covered > 0.9 * y_len,
                    "{what} at x = {x}: covered {covered} of {y_len}"
                );
            }
        }
        assert!(
            ridges.len() >= 4 && ridges.len() <= 8,
            "{} ridges",
            ridges.len()
        );
        assert!(
            valleys.len() >= 4 && valleys.len() <= 8,
            "{} valleys",
            valleys.len()
        );
        // Crests are convex: ridge strength ≈ A(2π/λ)² × the length.
        let k = 0.05 * (TAU / lambda).powi(2);
        for l in &ridges {
            let len: f32 = l.points.windows(2).map(|w| w[0].distance(w[1])).sum();
            assert!((l.strength / (k * len) - 1.0).abs() < 0.1, "{}", l.strength);
        }
        // Only ridges when asked for; the same ridges.
        let only = crest_lines(
            &m,
            &CrestParams {
                kind: CrestKind::Ridges,
                ..Default::default()
            },
        );
        assert!(only.iter().all(|l| l.ridge));
        assert_eq!(only.len(), ridges.len());
        let only_v = crest_lines(
            &m,
            &CrestParams {
                kind: CrestKind::Valleys,
                ..Default::default()
            },
        );
        assert!(only_v.iter().all(|l| !l.ridge) && only_v.len() == valleys.len());
        // Snapped: vertex paths along the crests, within an edge of them.
        let polys = crest_polylines(&m, &CrestParams::default());
        assert_eq!(polys.len(), lines.len());
        for (pl, ridge) in &polys {
            let offset = if *ridge { lambda / 4.0 } else { 0.75 * lambda };
            for w in pl.vertices.windows(2) {
                assert!(m.adjacency().neighbors(w[0] as usize).contains(&w[1]));
            }
            for &v in &pl.vertices {
                assert!(off_line(m.positions[v as usize].x, offset, lambda) <= 1.01 * h);
            }
        }
    }

    fn noisy(m: &Mesh, amount: f32, seed: u64) -> Mesh {
        let normals = m.vertex_normals();
        let pos = m
            .positions
            .iter()
            .enumerate()
            .map(|(i, p)| *p + normals[i] * amount * (2.0 * counter_unit(seed, 0, i as u64) - 1.0))
            .collect();
        Mesh::new(pos, m.triangles.clone())
    }

    #[test]
    fn shapes_without_crests_give_no_lines() {
        let plane = grid(60, 0.02);
        assert!(crest_lines(&plane, &CrestParams::default()).is_empty());
        // Noise of a twentieth of an edge on a plane, of 0.3 % of the radius on a sphere.
        let bumpy = noisy(&plane, 0.001, 7);
        let unfiltered = CrestParams {
            threshold: 0.0,
            min_length: 0.0,
            min_sharpness: 0.0,
            ..Default::default()
        };
        assert!(
            !crest_lines(&bumpy, &unfiltered).is_empty(),
            "noise makes lines"
        );
        let kept = crest_lines(&bumpy, &CrestParams::default());
        assert!(kept.is_empty(), "{} lines on a noisy plane", kept.len());
        let ball = noisy(&sphere(4, 1.0), 0.003, 3);
        assert!(!crest_lines(&ball, &unfiltered).is_empty());
        // The relative threshold alone keeps the strongest noise lines: the absolute floor
        // is what removes them.
        let relative_only = CrestParams {
            min_sharpness: 0.0,
            ..Default::default()
        };
        assert!(!crest_lines(&ball, &relative_only).is_empty());
        let kept = crest_lines(&ball, &CrestParams::default());
        assert!(kept.is_empty(), "{} lines on a noisy sphere", kept.len());
    }

    #[test]
    fn filters_drop_weak_and_short_lines() {
        // Two separate sine planes side by side: the right one's ridges are a fifth as strong
        // (a fifth of the amplitude, same wavelength and length).
        let (n, h, lambda) = (81, 0.02, 0.4);
        let strong = sine_plane(n, h, 0.05, lambda, -0.03);
        let weak = sine_plane(n, h, 0.01, lambda, -0.03);
        let mut pos = strong.positions.clone();
        let off = pos.len() as u32;
        pos.extend(weak.positions.iter().map(|p| *p + Vec3::new(2.0, 0.0, 0.0)));
        let mut tris = strong.triangles.clone();
        tris.extend(weak.triangles.iter().map(|t| t.map(|v| v + off)));
        let m = Mesh::new(pos, tris);
        let sides = |threshold: f32, min_length: f32| {
            crest_lines(
                &m,
                &CrestParams {
                    kind: CrestKind::Ridges,
                    threshold,
                    min_length,
                    min_sharpness: 0.0,
                    ..Default::default()
                },
            )
            .iter()
            .map(|l| l.points.iter().map(|p| p.x).sum::<f32>() / l.points.len() as f32 > 1.9)
            .collect::<Vec<bool>>()
        };
        let all = sides(0.1, 0.05);
        assert_eq!(all.iter().filter(|&&right| right).count(), 4, "{all:?}");
        assert_eq!(all.len(), 8, "{all:?}");
        let strong_only = sides(0.4, 0.05);
        assert_eq!(strong_only, vec![false; 4]);
        // Lines are 1.6 long, the diagonal 3.9: none is kept at half of it.
        assert!(sides(0.0, 0.5).is_empty());
        // The absolute floor: the weak ridges' ∫(k_max − |k_min|) ds is 1.6 × 0.01 × (2π/λ)²
        // ≈ 3.9, the strong ones' 19.7.
        let floor = crest_lines(
            &m,
            &CrestParams {
                kind: CrestKind::Ridges,
                threshold: 0.0,
                min_sharpness: 10.0,
                ..Default::default()
            },
        );
        assert_eq!(floor.len(), 4);
        assert!(floor.iter().all(|l| l.points[0].x < 1.9));
    }

    #[test]
    fn output_is_deterministic_across_thread_counts() {
        let m = noisy(&sine_plane(61, 0.02, 0.05, 0.4, 0.0), 0.002, 11);
        let run = |threads: usize| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap()
                .install(|| {
                    let p = CrestParams::default();
                    (crest_lines(&m, &p), crest_polylines(&m, &p))
                })
        };
        let (a, b, c) = (run(1), run(2), run(2));
        assert!(!a.0.is_empty());
        assert_eq!(a, b);
        assert_eq!(b, c);
        for (x, y) in a.0.iter().zip(&b.0) {
            assert_eq!(x.strength.to_bits(), y.strength.to_bits());
        }
    }

    #[test]
    fn spikes_are_removed_also_across_the_seam() {
        let l = without_spikes(Polyline {
            vertices: vec![1, 2, 3, 2, 4, 5, 4, 4, 6],
            closed: false,
        });
        assert_eq!(l.vertices, vec![1, 2, 4, 6]);
        let l = without_spikes(Polyline {
            vertices: vec![9, 1, 2, 3, 1],
            closed: true,
        });
        assert_eq!(l.vertices, vec![1, 2, 3]);
        assert!(l.closed);
        let l = without_spikes(Polyline {
            vertices: vec![1, 2, 1],
            closed: true,
        });
        assert!(!l.closed && l.vertices.len() < 3);
    }
}

#[cfg(test)]
mod meshes {
    use super::*;

    /// Crest lines of the shared test meshes, when ../shared/data is there (not for CI):
    /// counts and times, run with `--release -- --ignored --nocapture`.
    #[test]
    #[ignore]
    fn crest_lines_of_shared_meshes() {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/data/meshes");
        for name in [
            "mushroom.off",
            "elephant.off",
            "man.off",
            "refined_elephant.off",
        ] {
            let m = crate::geom::io::read_mesh(&dir.join(name)).unwrap();
            let t = std::time::Instant::now();
            let lines = crest_lines(&m, &CrestParams::default());
            let t_lines = t.elapsed();
            let t = std::time::Instant::now();
            let polys = crest_polylines(&m, &CrestParams::default());
            let t_polys = t.elapsed();
            let ridges = lines.iter().filter(|l| l.ridge).count();
            eprintln!(
                "{name}: {} vertices, {} triangles: {} lines ({ridges} ridges, {} valleys) in \
                 {t_lines:.2?}; crest_polylines {} in {t_polys:.2?}",
                m.positions.len(),
                m.triangles.len(),
                lines.len(),
                lines.len() - ridges,
                polys.len(),
            );
            assert!(!lines.is_empty());
        }
        // A mesh of 140k triangles: man subdivided once.
        let m = crate::geom::subdivide::subdivide(
            &crate::geom::io::read_mesh(&dir.join("man.off")).unwrap(),
        );
        let t = std::time::Instant::now();
        let polys = crest_polylines(&m, &CrestParams::default());
        eprintln!(
            "man subdivided: {} triangles: {} polylines in {:.2?}",
            m.triangles.len(),
            polys.len(),
            t.elapsed()
        );
    }
}

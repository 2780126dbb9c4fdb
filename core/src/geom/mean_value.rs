//! Mean value coordinates (Floater, "Mean value coordinates", CAGD 2003) and convex-combination
//! maps of disk-like meshes to the plane, with optional stretch reduction by iterative
//! reweighting (Yoshizawa, Belyaev & Seidel, "A fast and simple stretch-minimizing mesh
//! parameterization", SMI 2004).
//!
//! A convex-combination map fixes some vertices (usually the boundary, on a convex polygon)
//! and places every other vertex at a convex combination of its neighbours: with positive
//! weights, a boundary on a convex polygon and no edge between two fixed vertices on one
//! straight side, the map is a bijection with no flipped triangle (Tutte, Floater). Mean value
//! weights are positive for any triangle shape and reproduce planar meshes exactly (linear
//! precision); they are not symmetric, so the linear system is solved with a sparse LU.
//!
//! Weights live on the directed edges of [`Mesh::adjacency`]: the weight of `v → w` is at the
//! adjacency index of `w` in `v`'s neighbour list (`adj.half_edge(v, w)`).

use super::Mesh;
use crate::linalg::LuPattern;
use faer::sparse::{SparseColMat, Triplet};
use glam::{DVec2, DVec3, Vec2};

#[derive(Debug, thiserror::Error)]
pub enum MeanValueError {
    #[error("fixed vertex {vertex} is out of range: the mesh has {count} vertices")]
    FixedOutOfRange { vertex: u32, count: usize },
    #[error("vertex {vertex} is fixed twice")]
    FixedTwice { vertex: u32 },
    #[error("fixed vertex {vertex} has a non-finite position {position:?}")]
    FixedNotFinite { vertex: u32, position: Vec2 },
    #[error(
        "vertex {vertex} is free but no fixed vertex is connected to it: every connected \
         component needs at least one fixed vertex"
    )]
    Unconstrained { vertex: u32 },
    #[error("expected {expected} weights (one per adjacency entry), got {got}")]
    WeightCount { expected: usize, got: usize },
    #[error("sparse LU of the convex-combination system failed: {0}")]
    Solve(String),
    #[error("the solution is not finite at vertex {vertex}")]
    NotFinite { vertex: u32 },
}

/// Mean value weights w(v → w) = (tan(α/2) + tan(β/2)) / |x_w − x_v|, where α and β are the
/// angles at v of the (one or two) triangles holding edge vw. One positive, unnormalized
/// weight per entry of `mesh.adjacency().neighbors`.
///
/// Degenerate geometry is made harmless rather than rejected: a zero-length edge gets the
/// largest weight of its row, and every weight is at least 1e-8 of its row's largest, so all
/// weights stay positive and finite (positivity is what makes the map a bijection).
pub fn mean_value_weights(mesh: &Mesh) -> Vec<f64> {
    let adj = mesh.adjacency();
    let mut w = vec![0.0f64; adj.neighbors.len()];
    let p = |v: u32| mesh.positions[v as usize].as_dvec3();
    for t in &mesh.triangles {
        if t[0] == t[1] || t[1] == t[2] || t[0] == t[2] {
            continue;
        }
        for k in 0..3 {
            let (v, a, b) = (t[k], t[(k + 1) % 3], t[(k + 2) % 3]);
            let (ea, eb) = (p(a) - p(v), p(b) - p(v));
            let (la, lb) = (ea.length(), eb.length());
            let half_tan = half_angle_tangent(ea, eb, la, lb);
            let ia = adj
                .half_edge(v as usize, a)
                .expect("triangle edge in adjacency");
            let ib = adj
                .half_edge(v as usize, b)
                .expect("triangle edge in adjacency");
            // A zero-length edge gets +inf here and is replaced by the row maximum below.
            w[ia] += if la > 0.0 {
                half_tan / la
            } else {
                f64::INFINITY
            };
            w[ib] += if lb > 0.0 {
                half_tan / lb
            } else {
                f64::INFINITY
            };
        }
    }
    for v in 0..adj.vertex_count() {
        let row = &mut w[adj.offsets[v] as usize..adj.offsets[v + 1] as usize];
        sanitize_row(row);
    }
    w
}

/// tan(θ/2) for the angle θ between `a` and `b` (lengths `la`, `lb`), as
/// |a × b| / (|a||b| + a·b), which is accurate for small angles. Large (up to +inf) near θ = π.
fn half_angle_tangent(a: DVec3, b: DVec3, la: f64, lb: f64) -> f64 {
    let s = a.cross(b).length();
    let c = la * lb + a.dot(b);
    if c > 0.0 {
        s / c
    } else if s > 0.0 || la * lb > 0.0 {
        f64::INFINITY
    } else {
        0.0
    }
}

/// Makes a row of weights finite and strictly positive: non-finite entries become the
/// largest finite entry (or 1), and everything is floored at 1e-8 of the largest.
fn sanitize_row(row: &mut [f64]) {
    let max_finite = row
        .iter()
        .copied()
        .filter(|x| x.is_finite())
        .fold(0.0f64, f64::max);
    let top = if max_finite > 0.0 { max_finite } else { 1.0 };
    for x in row.iter_mut() {
        if !x.is_finite() {
            *x = top;
        }
        *x = x.max(top * 1e-8);
    }
}

/// The convex-combination map of `mesh` with mean value weights: `fixed` vertices are placed
/// where given, every other vertex referenced by a triangle solves
/// Σ_w λ(v → w)(x_v − x_w) = 0 with the normalized weights λ. Unreferenced vertices get
/// (0, 0). Every connected component needs a fixed vertex.
///
/// For a bijective map, fix the whole boundary of a disk on a convex polygon with no edge
/// joining two fixed vertices on the same straight side.
pub fn convex_combination_map(
    mesh: &Mesh,
    fixed: &[(u32, Vec2)],
) -> Result<Vec<Vec2>, MeanValueError> {
    let fixed64: Vec<(u32, DVec2)> = fixed.iter().map(|&(v, p)| (v, p.as_dvec2())).collect();
    let mut solver = ConvexCombinationSolver::new(mesh, &fixed64)?;
    let uv = solver.solve(mesh, &mean_value_weights(mesh))?;
    Ok(uv.iter().map(|p| p.as_vec2()).collect())
}

/// Solves convex-combination systems for one mesh and one set of fixed vertices with
/// changing weights; the symbolic LU factorization (ordering and fill pattern) is computed
/// once and reused by every solve.
pub struct ConvexCombinationSolver {
    /// Per vertex: its unknown index, or `FIXED` / `UNUSED`.
    slot: Vec<u32>,
    /// Per vertex: the fixed position (meaningful only for fixed vertices).
    fixed_pos: Vec<DVec2>,
    /// The free vertices in unknown order.
    free: Vec<u32>,
    symbolic: Option<LuPattern>,
}

const FIXED: u32 = u32::MAX;
const UNUSED: u32 = u32::MAX - 1;

impl ConvexCombinationSolver {
    /// Checks the fixed set (in range, no duplicates, every component constrained) and numbers
    /// the free vertices.
    pub fn new(mesh: &Mesh, fixed: &[(u32, DVec2)]) -> Result<Self, MeanValueError> {
        let n = mesh.vertex_count();
        let mut slot = vec![UNUSED; n];
        for t in &mesh.triangles {
            for &v in t {
                slot[v as usize] = 0;
            }
        }
        let mut fixed_pos = vec![DVec2::ZERO; n];
        for &(v, p) in fixed {
            if v as usize >= n {
                return Err(MeanValueError::FixedOutOfRange {
                    vertex: v,
                    count: n,
                });
            }
            if slot[v as usize] == FIXED {
                return Err(MeanValueError::FixedTwice { vertex: v });
            }
            if !p.is_finite() {
                return Err(MeanValueError::FixedNotFinite {
                    vertex: v,
                    position: p.as_vec2(),
                });
            }
            slot[v as usize] = FIXED;
            fixed_pos[v as usize] = p;
        }
        // Every free vertex must be connected to a fixed one.
        let adj = mesh.adjacency();
        let mut reached = vec![false; n];
        let mut stack: Vec<u32> = fixed.iter().map(|f| f.0).collect();
        for &v in &stack {
            reached[v as usize] = true;
        }
        while let Some(v) = stack.pop() {
            for &w in adj.neighbors(v as usize) {
                if !reached[w as usize] {
                    reached[w as usize] = true;
                    stack.push(w);
                }
            }
        }
        let mut free = Vec::new();
        for v in 0..n {
            if slot[v] == 0 {
                if !reached[v] {
                    return Err(MeanValueError::Unconstrained { vertex: v as u32 });
                }
                slot[v] = free.len() as u32;
                free.push(v as u32);
            }
        }
        Ok(ConvexCombinationSolver {
            slot,
            fixed_pos,
            free,
            symbolic: None,
        })
    }

    /// Number of free vertices (unknowns).
    pub fn free_count(&self) -> usize {
        self.free.len()
    }

    /// Solves for the free vertices with the given positive weights (one per adjacency entry,
    /// see the module doc; each row is normalized here). Returns a position for every vertex:
    /// fixed ones as given, unreferenced ones (0, 0).
    pub fn solve(&mut self, mesh: &Mesh, weights: &[f64]) -> Result<Vec<DVec2>, MeanValueError> {
        let adj = mesh.adjacency();
        if weights.len() != adj.neighbors.len() {
            return Err(MeanValueError::WeightCount {
                expected: adj.neighbors.len(),
                got: weights.len(),
            });
        }
        let nf = self.free.len();
        let mut out: Vec<DVec2> = (0..mesh.vertex_count())
            .map(|v| {
                if self.slot[v] == FIXED {
                    self.fixed_pos[v]
                } else {
                    DVec2::ZERO
                }
            })
            .collect();
        if nf == 0 {
            return Ok(out);
        }
        // Row u (free vertex v): x_v − Σ λ_vw x_w = 0, fixed neighbours moved to the right.
        let mut triplets: Vec<Triplet<usize, usize, f64>> =
            Vec::with_capacity(nf + adj.neighbors.len());
        let mut rhs = vec![0.0f64; 2 * nf];
        for (u, &v) in self.free.iter().enumerate() {
            let range = adj.offsets[v as usize] as usize..adj.offsets[v as usize + 1] as usize;
            let sum: f64 = weights[range.clone()].iter().sum();
            triplets.push(Triplet::new(u, u, 1.0));
            for k in range {
                let w = adj.neighbors[k];
                let lambda = weights[k] / sum;
                match self.slot[w as usize] {
                    FIXED => {
                        let p = self.fixed_pos[w as usize];
                        rhs[u] += lambda * p.x;
                        rhs[nf + u] += lambda * p.y;
                    }
                    UNUSED => {}
                    col => triplets.push(Triplet::new(u, col as usize, -lambda)),
                }
            }
        }
        // Sequential: results must not depend on the thread count (DESIGN.md, Determinism).
        faer::set_global_parallelism(faer::Par::Seq);
        let mat = SparseColMat::<usize, f64>::try_new_from_triplets(nf, nf, &triplets)
            .map_err(|e| MeanValueError::Solve(format!("{e:?}")))?;
        let symbolic = match &self.symbolic {
            Some(s) => s.clone(),
            None => {
                let s = LuPattern::new(mat.symbolic())
                    .map_err(|e| MeanValueError::Solve(e.to_string()))?;
                self.symbolic = Some(s.clone());
                s
            }
        };
        symbolic
            .solve(&mat, &mut rhs, 2)
            .map_err(|e| MeanValueError::Solve(e.to_string()))?;
        for (u, &v) in self.free.iter().enumerate() {
            let p = DVec2::new(rhs[u], rhs[nf + u]);
            if !p.is_finite() {
                return Err(MeanValueError::NotFinite { vertex: v });
            }
            out[v as usize] = p;
        }
        Ok(out)
    }
}

/// Sander et al. (2001) L² stretch of one triangle with 3D corners `q` and parameter
/// corners `p`: sqrt((|∂q/∂s|² + |∂q/∂t|²) / 2). +inf for a flipped or flat parameter triangle.
pub fn triangle_l2_stretch(q: [DVec3; 3], p: [DVec2; 3]) -> f64 {
    let area2 = (p[1].x - p[0].x) * (p[2].y - p[0].y) - (p[2].x - p[0].x) * (p[1].y - p[0].y);
    if area2 <= 0.0 || !area2.is_finite() {
        return f64::INFINITY;
    }
    let ss =
        (q[0] * (p[1].y - p[2].y) + q[1] * (p[2].y - p[0].y) + q[2] * (p[0].y - p[1].y)) / area2;
    let st =
        (q[0] * (p[2].x - p[1].x) + q[1] * (p[0].x - p[2].x) + q[2] * (p[1].x - p[0].x)) / area2;
    ((ss.length_squared() + st.length_squared()) * 0.5).sqrt()
}

/// The global L² stretch of a map (Sander et al. 2001): the surface-area-weighted RMS of the
/// triangle stretches, scaled so that an isometry up to scale scores 1. +inf if any
/// non-degenerate triangle is flipped or flat in the plane.
pub fn l2_stretch(mesh: &Mesh, uv: &[DVec2]) -> f64 {
    let q = map_quality(mesh, uv);
    if q.flipped > 0 {
        f64::INFINITY
    } else {
        q.stretch
    }
}

/// How good a map is: the number of flipped or flat triangles (those with positive area in
/// 3D and non-positive signed area in the plane), and the global L² stretch of the others.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MapQuality {
    pub flipped: usize,
    pub stretch: f64,
}

impl MapQuality {
    /// Fewer flipped triangles first, then lower stretch.
    pub fn better_than(&self, other: &MapQuality) -> bool {
        self.flipped < other.flipped
            || (self.flipped == other.flipped && self.stretch < other.stretch)
    }
}

/// Per-triangle L² stretch, 3D area and parameter area; flipped or flat triangles get +inf.
fn triangle_stretches(mesh: &Mesh, uv: &[DVec2]) -> Vec<(f64, f64, f64)> {
    mesh.triangles
        .iter()
        .map(|t| {
            let q = t.map(|v| mesh.positions[v as usize].as_dvec3());
            let p = t.map(|v| uv[v as usize]);
            let a3 = 0.5 * (q[1] - q[0]).cross(q[2] - q[0]).length();
            let a2 = 0.5 * (p[1] - p[0]).perp_dot(p[2] - p[0]);
            (triangle_l2_stretch(q, p), a3, a2)
        })
        .collect()
}

/// See [`MapQuality`].
pub fn map_quality(mesh: &Mesh, uv: &[DVec2]) -> MapQuality {
    let (mut num, mut area3, mut area2, mut flipped) = (0.0f64, 0.0f64, 0.0f64, 0usize);
    for (s, a3, a2) in triangle_stretches(mesh, uv) {
        if a3 <= 0.0 {
            continue;
        }
        if !s.is_finite() {
            flipped += 1;
            continue;
        }
        num += a3 * s * s;
        area3 += a3;
        area2 += a2;
    }
    let stretch = if area3 > 0.0 {
        (num / area3).sqrt() * (area2 / area3).sqrt()
    } else {
        0.0
    };
    MapQuality { flipped, stretch }
}

/// Per-vertex stretch: the area-weighted RMS of the L² stretches of the vertex's triangles
/// (Yoshizawa et al. 2004). Flipped or flat triangles count with ten times the largest finite
/// triangle stretch, so the reweighting pushes them open. Vertices with no non-degenerate
/// triangle get 1.
fn vertex_stretch(mesh: &Mesh, uv: &[DVec2]) -> Vec<f64> {
    let n = mesh.vertex_count();
    let ts = triangle_stretches(mesh, uv);
    let max_finite = ts
        .iter()
        .filter(|x| x.0.is_finite() && x.1 > 0.0)
        .fold(1.0f64, |m, x| m.max(x.0));
    let mut num = vec![0.0f64; n];
    let mut den = vec![0.0f64; n];
    for (t, &(s, a3, _)) in mesh.triangles.iter().zip(&ts) {
        if a3 <= 0.0 {
            continue;
        }
        let s = if s.is_finite() { s } else { 10.0 * max_finite };
        for &v in t {
            num[v as usize] += a3 * s * s;
            den[v as usize] += a3;
        }
    }
    (0..n)
        .map(|v| {
            if den[v] > 0.0 {
                (num[v] / den[v]).sqrt()
            } else {
                1.0
            }
        })
        .collect()
}

/// The outcome of [`reduce_stretch`].
#[derive(Debug, Clone)]
pub struct StretchReduction {
    /// The best map found (the input if no iteration improved it).
    pub uv: Vec<DVec2>,
    /// The weights that produce `uv`.
    pub weights: Vec<f64>,
    /// Quality of the input map and of `uv`.
    pub before: MapQuality,
    pub after: MapQuality,
    /// The iteration that produced the best map (0: the input map).
    pub iterations: u32,
}

/// Stretch reduction by iterative reweighting (Yoshizawa et al. 2004): each iteration divides
/// every weight w(v → w) by the local stretch σ(w) of the current map and re-solves, so
/// neighbours of over-stretched (compressed) regions pull less and those regions grow in the
/// plane. The weights stay positive, so every iterate is again a convex-combination map
/// (bijective under the same boundary conditions; numerically, extremely compressed regions
/// can still collapse, which the reweighting then opens up). Runs at most `iterations` solves,
/// stops at the first that does not improve the map ([`MapQuality::better_than`]: fewer
/// flipped triangles, then lower global L² stretch), and returns the best map.
///
/// `weights` and `uv` must belong together (`uv` solved from `weights` with `solver`).
pub fn reduce_stretch(
    mesh: &Mesh,
    solver: &mut ConvexCombinationSolver,
    weights: Vec<f64>,
    uv: Vec<DVec2>,
    iterations: u32,
) -> Result<StretchReduction, MeanValueError> {
    let adj = mesh.adjacency();
    let before = map_quality(mesh, &uv);
    let mut best = StretchReduction {
        uv,
        weights,
        before,
        after: before,
        iterations: 0,
    };
    let mut cur_uv = best.uv.clone();
    let mut cur_w = best.weights.clone();
    for it in 0..iterations {
        let sigma = vertex_stretch(mesh, &cur_uv);
        let mut w = cur_w.clone();
        for v in 0..adj.vertex_count() {
            let range = adj.offsets[v] as usize..adj.offsets[v + 1] as usize;
            for k in range.clone() {
                let s = sigma[adj.neighbors[k] as usize];
                if s.is_finite() && s > 0.0 {
                    w[k] /= s;
                }
            }
            sanitize_row(&mut w[range]);
        }
        let uv = solver.solve(mesh, &w)?;
        let q = map_quality(mesh, &uv);
        if q.better_than(&best.after) {
            best.uv = uv.clone();
            best.weights = w.clone();
            best.after = q;
            best.iterations = it + 1;
        }
        // Carry on from this iterate even when it is worse: the reweighting often overshoots
        // once and then improves on the best so far.
        cur_uv = uv;
        cur_w = w;
    }
    Ok(best)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::PureMath;
    use glam::Vec3;

    /// An n×n grid of the unit square with interior vertices jittered (still a valid
    /// triangulation), in the plane z = 0, plus its boundary vertices in CCW order.
    fn jittered_grid(n: usize) -> (Mesh, Vec<u32>) {
        let mut pos = Vec::new();
        for i in 0..n {
            for j in 0..n {
                let mut p = Vec3::new(j as f32, i as f32, 0.0) / (n - 1) as f32;
                if i > 0 && j > 0 && i < n - 1 && j < n - 1 {
                    let h = crate::random::counter_unit(7, 0, (i * n + j) as u64) - 0.5;
                    let g = crate::random::counter_unit(7, 1, (i * n + j) as u64) - 0.5;
                    p += Vec3::new(h, g, 0.0) * 0.6 / (n - 1) as f32;
                }
                pos.push(p);
            }
        }
        let mut tris = Vec::new();
        let id = |i: usize, j: usize| (i * n + j) as u32;
        for i in 0..n - 1 {
            for j in 0..n - 1 {
                tris.push([id(i, j), id(i, j + 1), id(i + 1, j + 1)]);
                tris.push([id(i, j), id(i + 1, j + 1), id(i + 1, j)]);
            }
        }
        let mut bnd = Vec::new();
        for j in 0..n - 1 {
            bnd.push(id(0, j));
        }
        for i in 0..n - 1 {
            bnd.push(id(i, n - 1));
        }
        for j in (1..n).rev() {
            bnd.push(id(n - 1, j));
        }
        for i in (1..n).rev() {
            bnd.push(id(i, 0));
        }
        (Mesh::new(pos, tris), bnd)
    }

    #[test]
    fn mean_value_map_of_a_planar_mesh_reproduces_it() {
        // Linear precision: with the boundary at its own positions, mean value weights put
        // every interior vertex back where it was. Uniform or cotangent-free weights do not.
        let (mesh, bnd) = jittered_grid(9);
        let fixed: Vec<(u32, Vec2)> = bnd
            .iter()
            .map(|&v| (v, mesh.positions[v as usize].truncate()))
            .collect();
        let uv = convex_combination_map(&mesh, &fixed).unwrap();
        for (v, p) in mesh.positions.iter().enumerate() {
            assert!(
                (uv[v] - p.truncate()).length() < 1e-5,
                "vertex {v}: {} vs {p}",
                uv[v]
            );
        }
    }

    #[test]
    fn weights_match_floaters_formula_on_a_regular_fan() {
        // Centre of a regular hexagon fan with unit spokes: every angle is 60°, so each
        // weight is 2·tan(30°)/1.
        let mut pos = vec![Vec3::ZERO];
        for k in 0..6 {
            let a = k as f32 * std::f32::consts::PI / 3.0;
            pos.push(Vec3::new(a.cos_pure(), a.sin_pure(), 0.0));
        }
        let tris: Vec<[u32; 3]> = (0..6).map(|k| [0, 1 + k, 1 + (k + 1) % 6]).collect();
        let mesh = Mesh::new(pos, tris);
        let w = mean_value_weights(&mesh);
        let adj = mesh.adjacency();
        let want = 2.0 * (std::f64::consts::PI / 6.0).tan_pure();
        for k in adj.offsets[0] as usize..adj.offsets[1] as usize {
            assert!((w[k] - want).abs() < 1e-6, "{} vs {want}", w[k]);
        }
    }

    /// A hemisphere-like open mesh (a bumpy cap) whose boundary is a circle.
    fn cap(rings: usize, sectors: usize) -> (Mesh, Vec<u32>) {
        let mut pos = vec![Vec3::new(0.0, 0.0, 1.0)];
        for r in 1..=rings {
            let phi = r as f32 / rings as f32 * 2.3;
            for s in 0..sectors {
                let th = s as f32 / sectors as f32 * std::f32::consts::TAU;
                let bump = 1.0 + 0.15 * (3.0 * th).sin_pure() * (r as f32 / rings as f32);
                pos.push(
                    Vec3::new(
                        phi.sin_pure() * th.cos_pure(),
                        phi.sin_pure() * th.sin_pure(),
                        phi.cos_pure(),
                    ) * bump,
                );
            }
        }
        let id = |r: usize, s: usize| (1 + (r - 1) * sectors + s % sectors) as u32;
        let mut tris = Vec::new();
        for s in 0..sectors {
            tris.push([0, id(1, s), id(1, s + 1)]);
        }
        for r in 1..rings {
            for s in 0..sectors {
                tris.push([id(r, s), id(r + 1, s), id(r + 1, s + 1)]);
                tris.push([id(r, s), id(r + 1, s + 1), id(r, s + 1)]);
            }
        }
        let bnd = (0..sectors).map(|s| id(rings, s)).collect();
        (Mesh::new(pos, tris), bnd)
    }

    fn signed_areas(mesh: &Mesh, uv: &[DVec2]) -> Vec<f64> {
        mesh.triangles
            .iter()
            .map(|t| {
                let p = t.map(|v| uv[v as usize]);
                0.5 * (p[1] - p[0]).perp_dot(p[2] - p[0])
            })
            .collect()
    }

    #[test]
    fn cap_on_a_circle_has_no_flip_and_stretch_reduction_lowers_stretch() {
        let (mesh, bnd) = cap(12, 40);
        let fixed: Vec<(u32, DVec2)> = bnd
            .iter()
            .enumerate()
            .map(|(k, &v)| {
                let a = k as f64 / bnd.len() as f64 * std::f64::consts::TAU;
                (v, DVec2::new(a.cos_pure(), a.sin_pure()))
            })
            .collect();
        let mut solver = ConvexCombinationSolver::new(&mesh, &fixed).unwrap();
        let w = mean_value_weights(&mesh);
        let uv = solver.solve(&mesh, &w).unwrap();
        assert!(signed_areas(&mesh, &uv).iter().all(|&a| a > 0.0));
        let r = reduce_stretch(&mesh, &mut solver, w, uv, 4).unwrap();
        assert!(r.iterations >= 1);
        assert_eq!((r.before.flipped, r.after.flipped), (0, 0));
        assert!(
            r.after.stretch < 0.9 * r.before.stretch,
            "{:?} -> {:?} in {} iterations",
            r.before,
            r.after,
            r.iterations
        );
        assert!(signed_areas(&mesh, &r.uv).iter().all(|&a| a > 0.0));
        // The map really is the one its weights produce.
        let again = solver.solve(&mesh, &r.weights).unwrap();
        assert_eq!(again, r.uv);
    }

    #[test]
    fn stretch_of_an_isometry_is_one_and_of_a_squash_is_larger() {
        let q = [DVec3::ZERO, DVec3::X, DVec3::Y];
        let p = [DVec2::ZERO, DVec2::X, DVec2::Y];
        assert!((triangle_l2_stretch(q, p) - 1.0).abs() < 1e-12);
        let squashed = [DVec2::ZERO, DVec2::X, DVec2::Y * 0.5];
        // ∂q/∂t has length 2: sqrt((1 + 4) / 2).
        assert!((triangle_l2_stretch(q, squashed) - 2.5f64.sqrt()).abs() < 1e-12);
        let flipped = [DVec2::ZERO, DVec2::Y, DVec2::X];
        assert_eq!(triangle_l2_stretch(q, flipped), f64::INFINITY);
    }

    #[test]
    fn a_component_without_fixed_vertices_is_an_error_naming_a_vertex() {
        let (mesh, bnd) = jittered_grid(3);
        let mut pos = mesh.positions.clone();
        let mut tris = mesh.triangles.clone();
        let base = pos.len() as u32;
        pos.extend([
            Vec3::new(5.0, 0.0, 0.0),
            Vec3::new(6.0, 0.0, 0.0),
            Vec3::new(5.0, 1.0, 0.0),
        ]);
        tris.push([base, base + 1, base + 2]);
        let mesh = Mesh::new(pos, tris);
        let fixed: Vec<(u32, Vec2)> = bnd.iter().map(|&v| (v, Vec2::ZERO)).collect();
        match convex_combination_map(&mesh, &fixed) {
            Err(MeanValueError::Unconstrained { vertex }) => assert_eq!(vertex, base),
            other => panic!("{other:?}"),
        }
        let bad = [(99u32, Vec2::ZERO)];
        assert!(matches!(
            convex_combination_map(&mesh, &bad),
            Err(MeanValueError::FixedOutOfRange { vertex: 99, .. })
        ));
    }
}

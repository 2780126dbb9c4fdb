//! Orientation fields up to a half or a quarter turn, for textures with two- or four-way
//! symmetry (Zelinka & Garland, "Interactive Texture Synthesis on Surfaces Using Jump Maps", §3:
//! "optimizations of the relaxation process exist if the texture only requires two- or
//! four-way symmetry", after Wei & Levoy 2001), and the measures that compare fields.
//!
//! The paper names the option and no method. We use the N-th power representation (the
//! "representation vector" of N-symmetry direction fields, as in Palacios & Zhang 2007 and
//! Knöppel et al. 2013): a direction at angle θ in a vertex's tangent frame is the complex
//! number z = e^{iNθ}, which is the same for all N directions θ + k·2π/N. Smoothness is
//! the connection Dirichlet energy Σ_edges w_uv |z_v − r_uv z_u|², w the cotan weights and
//! r_uv = e^{iNρ_uv} carrying u's frame into v's (ρ: the angle of u's frame axis rotated by the
//! smallest rotation from u's normal to v's, in v's frame). Its minimizer is one sparse SPD
//! solve (2 real unknowns per vertex):
//! - Anchors given: their z fixed (the direction only up to its symmetry), the rest harmonic.
//! - Nothing given: the smoothest field that follows a `guide` field softly (the caller's
//!   default flow, see `orientation_field`): the energy plus λ Σ_v A_v |z_v − q_v|², q_v the
//!   N-th power of the guide's vector (its length squared as weight, so a zero vector says
//!   nothing), and λ = (4 / bounding-box diagonal)²: the field may turn over a quarter of the
//!   shape's size, not faster. Guided by the flow raised to the N-th power, the field keeps the
//!   flow's course (along a tube, round a handle) and drops only what the symmetry makes moot:
//!   the flow's turns by multiples of 2π/N.
//!
//! A direction is then read back as θ = arg(z)/N and **combed**: grown over a spanning tree
//! of the smoothest edges (Prim's order, smallest turn first), each vertex takes the one of
//! its N directions nearest its tree parent's, so neighbours agree except across edges where
//! the field turns most, around its singularities; the rest of texsyn (per-edge offsets,
//! §4.2.2) needs one vector per vertex and nothing else.
//!
//! [`measure`] reports, for any field and any N: the mean turn between neighbours up to the
//! symmetry, its smooth energy, and the singular triangles with their total |index|.

use crate::geom::Mesh;
use crate::geom::laplacian::cotan_weights;
use crate::linalg::{IterativeParams, SolveError, solve_spd};
use glam::{DQuat, DVec3, Vec3};
use serde::Serialize;
use std::f64::consts::{PI, TAU};
use texsyn_core::math::PureMath;

/// A vertex's tangent frame: `e1` from its first neighbour's edge, `e2 = n × e1`.
struct Frames {
    normal: Vec<DVec3>,
    e1: Vec<DVec3>,
    e2: Vec<DVec3>,
}

fn frames(mesh: &Mesh) -> Frames {
    let adj = mesh.adjacency();
    let n = mesh.vertex_count();
    let (mut normal, mut e1, mut e2) = (vec![DVec3::Z; n], vec![DVec3::X; n], vec![DVec3::Y; n]);
    for v in 0..n {
        let nv = mesh.vertex_normals()[v].as_dvec3();
        let nv = if nv.length_squared() > 0.5 {
            nv
        } else {
            DVec3::Z
        };
        let first = adj.neighbors(v).first().map(|&u| {
            let e = (mesh.positions[u as usize] - mesh.positions[v]).as_dvec3();
            e - e.dot(nv) * nv
        });
        let a = match first {
            Some(e) if e.length_squared() > 1e-30 => e.normalize(),
            _ => nv.any_orthonormal_vector(),
        };
        normal[v] = nv;
        e1[v] = a;
        e2[v] = nv.cross(a);
    }
    Frames { normal, e1, e2 }
}

/// The angle, in v's frame, of u's frame axis carried by the smallest rotation from u's normal
/// to v's.
fn transport(f: &Frames, u: usize, v: usize) -> f64 {
    let carried = DQuat::from_rotation_arc(f.normal[u], f.normal[v]) * f.e1[u];
    carried.dot(f.e2[v]).atan2_pure(carried.dot(f.e1[v]))
}

/// `x` reduced to (−π/N, π/N]: the turn between two N-directions.
fn reduce(x: f64, n: u32) -> f64 {
    let period = TAU / n as f64;
    let r = x.rem_euclid(period);
    if r > period / 2.0 { r - period } else { r }
}

/// The smoothest N-direction field (see the module doc), combed: one unit tangent per vertex
/// (zero for vertices of no triangle). `anchors` are (vertex, direction); `guide` (one vector
/// per vertex, missing ones zero) guides the field when there are none.
pub fn symmetric_field(
    mesh: &Mesh,
    n_sym: u32,
    anchors: &[(u32, Vec3)],
    guide: &[Vec3],
) -> Result<Vec<Vec3>, SolveError> {
    let n = mesh.vertex_count();
    let f = frames(mesh);
    let nf = n_sym as f64;
    let angle_of = |v: usize, d: DVec3| d.dot(f.e2[v]).atan2_pure(d.dot(f.e1[v]));
    let mut fixed: Vec<Option<(f64, f64)>> = vec![None; n];
    for &(v, d) in anchors {
        let (s, c) = (nf * angle_of(v as usize, d.as_dvec3())).sin_cos_pure();
        fixed[v as usize] = Some((c, s));
    }
    let mut unknown = vec![usize::MAX; n];
    let mut count = 0;
    for v in 0..n {
        if fixed[v].is_none() {
            unknown[v] = count;
            count += 1;
        }
    }
    let mut diag = vec![0.0f64; count];
    let mut rhs = vec![0.0f64; 2 * count];
    let mut triplets = Vec::new();
    for (i, j, w) in cotan_weights(mesh) {
        let (i, j) = (i as usize, j as usize);
        // z_j ≈ r z_i with r = e^{iNρ}; the block of row j, column i is −w R(Nρ).
        let (s, c) = (nf * transport(&f, i, j)).sin_cos_pure();
        let (ui, uj) = (unknown[i], unknown[j]);
        if ui != usize::MAX {
            diag[ui] += w;
        }
        if uj != usize::MAX {
            diag[uj] += w;
        }
        match (ui != usize::MAX, uj != usize::MAX) {
            (true, true) => {
                // Rows of j (2uj, 2uj+1), columns of i: −w [[c, −s], [s, c]]; stored in the
                // lower triangle whichever index is larger (the transpose otherwise).
                let block = [[-w * c, w * s], [-w * s, -w * c]];
                for (r, row) in block.iter().enumerate() {
                    for (k, &x) in row.iter().enumerate() {
                        let (a, b) = (2 * uj + r, 2 * ui + k);
                        triplets.push(if a > b { (a, b, x) } else { (b, a, x) });
                    }
                }
            }
            (true, false) => {
                // i free, j fixed: z_i ≈ r̄ z_j.
                let (zc, zs) = fixed[j].expect("fixed");
                rhs[2 * ui] += w * (c * zc + s * zs);
                rhs[2 * ui + 1] += w * (c * zs - s * zc);
            }
            (false, true) => {
                let (zc, zs) = fixed[i].expect("fixed");
                rhs[2 * uj] += w * (c * zc - s * zs);
                rhs[2 * uj + 1] += w * (s * zc + c * zs);
            }
            (false, false) => {}
        }
    }
    if anchors.is_empty() {
        let (lo, hi) = mesh.bounds();
        let diagonal = (hi - lo).length() as f64;
        let lambda = (4.0 / diagonal.max(1e-30)).powi(2);
        let area = vertex_areas(mesh);
        for v in 0..n {
            let u = unknown[v];
            let g = guide.get(v).map_or(DVec3::ZERO, |g| g.as_dvec3());
            let t = g - g.dot(f.normal[v]) * f.normal[v];
            let weight = lambda * area[v];
            diag[u] += weight;
            let (s, c) = (nf * angle_of(v, t)).sin_cos_pure();
            let m = t.length_squared();
            rhs[2 * u] += weight * m * c;
            rhs[2 * u + 1] += weight * m * s;
        }
    }
    let mean = diag.iter().sum::<f64>() / count.max(1) as f64;
    let eps = 1e-9 * mean.max(1e-12);
    for (u, d) in diag.iter().enumerate() {
        triplets.push((2 * u, 2 * u, d + eps));
        triplets.push((2 * u + 1, 2 * u + 1, d + eps));
    }
    if count > 0 {
        solve_spd(
            2 * count,
            &triplets,
            &mut rhs,
            1,
            &IterativeParams::default(),
        )?;
    }
    let directions: Vec<f64> = (0..n)
        .map(|v| {
            let (c, s) = match fixed[v] {
                Some(z) => z,
                None => (rhs[2 * unknown[v]], rhs[2 * unknown[v] + 1]),
            };
            s.atan2_pure(c) / nf
        })
        .collect();
    Ok(comb(mesh, &f, &directions, n_sym))
}

/// Each vertex's area share (a third of its triangles').
fn vertex_areas(mesh: &Mesh) -> Vec<f64> {
    let mut a = vec![0.0; mesh.vertex_count()];
    for t in &mesh.triangles {
        let p = t.map(|v| mesh.positions[v as usize].as_dvec3());
        let area = (p[1] - p[0]).cross(p[2] - p[0]).length() / 6.0;
        for &v in t {
            a[v as usize] += area;
        }
    }
    a
}

/// Combing: each vertex's direction turned by the multiple of 2π/N that brings it nearest a
/// combed neighbour's (compared in 3D, the neighbour's projected into its tangent plane),
/// grown from the lowest vertex of every piece along the smoothest edges first (Prim's order:
/// the edge whose best match turns least is taken next; ties by vertex ids). The edges left
/// out of that tree, where neighbours may hold directions a multiple of 2π/N apart, are then
/// the ones across which the field turns most, which gathers them near the singularities;
/// breadth-first growth would instead leave them wherever its wavefronts meet.
fn comb(mesh: &Mesh, f: &Frames, theta: &[f64], n_sym: u32) -> Vec<Vec3> {
    use std::cmp::Reverse;
    use std::collections::BinaryHeap;
    let n = mesh.vertex_count();
    let adj = mesh.adjacency();
    let dir = |v: usize, a: f64| {
        let (s, c) = a.sin_cos_pure();
        c * f.e1[v] + s * f.e2[v]
    };
    // u's representative nearest `to`, with 1 − its cosine to it (0: no turn).
    let nearest = |u: usize, to: DVec3| {
        (0..n_sym)
            .map(|k| {
                let d = dir(u, theta[u] + k as f64 * TAU / n_sym as f64);
                (d, d.dot(to))
            })
            .fold((DVec3::ZERO, f64::NEG_INFINITY), |b, x| {
                if x.1 > b.1 { x } else { b }
            })
    };
    let mut out = vec![DVec3::ZERO; n];
    let mut seen = vec![false; n];
    // (turn, vertex, from): 1 − cos ≥ 0, so its bits order as the number does.
    let mut heap: BinaryHeap<Reverse<(u64, u32, u32)>> = BinaryHeap::new();
    for root in 0..n {
        if seen[root] || adj.neighbors(root).is_empty() {
            continue;
        }
        seen[root] = true;
        out[root] = dir(root, theta[root]);
        let push = |heap: &mut BinaryHeap<_>, out: &[DVec3], seen: &[bool], v: usize| {
            for &u in adj.neighbors(v) {
                if !seen[u as usize] {
                    let turn = (1.0 - nearest(u as usize, out[v]).1).max(0.0);
                    heap.push(Reverse((turn.to_bits(), u, v as u32)));
                }
            }
        };
        push(&mut heap, &out, &seen, root);
        while let Some(Reverse((_, u, v))) = heap.pop() {
            let u = u as usize;
            if seen[u] {
                continue;
            }
            seen[u] = true;
            out[u] = nearest(u, out[v as usize]).0;
            push(&mut heap, &out, &seen, u);
        }
    }
    out.iter().map(|d| d.as_vec3()).collect()
}

/// How smooth a field is, taken up to an N-fold symmetry.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct FieldMeasures {
    /// The symmetry the field was measured with.
    pub symmetry: u32,
    /// Mean over edges of the turn between the endpoints' directions (transported, reduced
    /// modulo 2π/N), in degrees.
    pub mean_turn_deg: f64,
    /// Mean over edges of (1 − cos NΔ)/N², Δ that turn: the Dirichlet energy per edge of the
    /// N-th power representation, scaled so fields of any N compare (≈ Δ²/2 for small Δ).
    pub energy: f64,
    /// Triangles around which the directions turn by a non-zero multiple of 2π/N.
    pub singular_triangles: u32,
    /// Σ |index| over those triangles (an index is a multiple of 1/N).
    pub index_abs_total: f64,
}

/// [`FieldMeasures`] of `field` (one vector per vertex; zero vectors and the edges and
/// triangles touching them are left out) at symmetry `n_sym`.
pub fn measure(mesh: &Mesh, field: &[Vec3], n_sym: u32) -> FieldMeasures {
    let f = frames(mesh);
    let angle = |v: usize| {
        let d = field[v].as_dvec3();
        d.dot(f.e2[v]).atan2_pure(d.dot(f.e1[v]))
    };
    let usable = |v: usize| field[v] != Vec3::ZERO;
    let (mut turn, mut energy, mut edges) = (0.0, 0.0, 0usize);
    let nf = n_sym as f64;
    for (v, nb) in (0..mesh.vertex_count()).map(|v| (v, mesh.adjacency().neighbors(v))) {
        for &u in nb {
            let u = u as usize;
            if u <= v || !usable(u) || !usable(v) {
                continue;
            }
            let d = reduce(angle(u) - (angle(v) + transport(&f, v, u)), n_sym);
            turn += d.abs();
            energy += (1.0 - (nf * d).cos_pure()) / (nf * nf);
            edges += 1;
        }
    }
    let (mut singular, mut index_total) = (0u32, 0.0);
    for t in &mesh.triangles {
        let t = t.map(|v| v as usize);
        if !t.iter().all(|&v| usable(v)) {
            continue;
        }
        let p = t.map(|v| mesh.positions[v].as_dvec3());
        let normal = (p[1] - p[0]).cross(p[2] - p[0]);
        if normal.length_squared() < 1e-300 {
            continue;
        }
        let normal = normal.normalize();
        let a = (p[1] - p[0]).normalize();
        let b = normal.cross(a);
        // The directions projected into the triangle's plane, in one frame: no holonomy.
        let ang = t.map(|v| {
            let d = field[v].as_dvec3();
            (d.dot(b)).atan2_pure(d.dot(a))
        });
        let sum: f64 = (0..3)
            .map(|k| reduce(ang[(k + 1) % 3] - ang[k], n_sym))
            .sum();
        let index = (sum / TAU * nf).round() / nf;
        if index != 0.0 {
            singular += 1;
            index_total += index.abs();
        }
    }
    FieldMeasures {
        symmetry: n_sym,
        mean_turn_deg: if edges > 0 {
            turn / edges as f64 * 180.0 / PI
        } else {
            0.0
        },
        energy: if edges > 0 {
            energy / edges as f64
        } else {
            0.0
        },
        singular_triangles: singular,
        index_abs_total: index_total,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geom::primitives::{grid, torus};

    #[test]
    fn a_quarter_turned_anchor_is_the_same_four_fold_direction() {
        // Two anchors on a square, 90° apart: as 1-directions they force a turn across the
        // sheet; as 4-directions they are the same and the field is constant.
        let mesh = grid(9, 0.125);
        let anchors = [(0, Vec3::X), (80, Vec3::Y)];
        let f4 = symmetric_field(&mesh, 4, &anchors, &[]).unwrap();
        let m4 = measure(&mesh, &f4, 4);
        assert!(m4.mean_turn_deg < 1e-3, "{m4:?}");
        assert_eq!(m4.singular_triangles, 0);
        for d in &f4 {
            let c = d.dot(Vec3::X).abs().max(d.dot(Vec3::Y).abs());
            assert!((c - 1.0).abs() < 1e-4, "{d}");
        }
        // Combed: neighbours hold the same representative, not only the same 4-direction.
        assert!(measure(&mesh, &f4, 1).mean_turn_deg < 1e-3);
        // A two-fold field cannot identify them: it turns.
        let f2 = symmetric_field(&mesh, 2, &anchors, &[]).unwrap();
        assert!(measure(&mesh, &f2, 2).mean_turn_deg > 1.0);
    }

    #[test]
    fn the_index_of_a_vortex_is_counted_at_its_symmetry() {
        // Around the centre of a square: the radial field has index 1; half its angle (a
        // 2-direction field: θ/2) has index 1/2, and as a 1-field it is not continuous.
        let mesh = grid(21, 0.05);
        let c = Vec3::new(0.5, 0.5, 0.0) + Vec3::new(0.013, 0.007, 0.0);
        let radial: Vec<Vec3> = mesh
            .positions
            .iter()
            .map(|p| (*p - c).normalize())
            .collect();
        let m = measure(&mesh, &radial, 1);
        assert_eq!(m.singular_triangles, 1, "{m:?}");
        assert!((m.index_abs_total - 1.0).abs() < 1e-9);
        let half: Vec<Vec3> = mesh
            .positions
            .iter()
            .map(|p| {
                let d = *p - c;
                let a = (d.y as f64).atan2_pure(d.x as f64) / 2.0;
                let (s, co) = a.sin_cos_pure();
                Vec3::new(co as f32, s as f32, 0.0)
            })
            .collect();
        let m = measure(&mesh, &half, 2);
        assert_eq!(m.singular_triangles, 1, "{m:?}");
        assert!((m.index_abs_total - 0.5).abs() < 1e-9);
        assert!(measure(&mesh, &half, 1).mean_turn_deg > m.mean_turn_deg);
    }

    #[test]
    fn on_a_torus_a_four_fold_field_is_smooth_and_free_of_singularities() {
        // A torus has χ = 0: a field along its rings exists with no singularity. The
        // 4-field guided by the projected x axis finds one as smooth as that (the guide, x, would have
        // singularities where x is normal to the surface).
        let mesh = torus(48, 16, 0.3);
        let projected: Vec<Vec3> = mesh
            .vertex_normals()
            .iter()
            .map(|n| Vec3::X - Vec3::X.dot(*n) * *n)
            .collect();
        let f = symmetric_field(&mesh, 4, &[], &projected).unwrap();
        for (d, n) in f.iter().zip(mesh.vertex_normals()) {
            assert!((d.length() - 1.0).abs() < 1e-4 && d.dot(*n).abs() < 1e-4);
        }
        let m = measure(&mesh, &f, 4);
        let projected: Vec<Vec3> = projected.iter().map(|p| p.normalize_or_zero()).collect();
        let guide = measure(&mesh, &projected, 4);
        assert!(
            m.energy < guide.energy && m.index_abs_total < guide.index_abs_total,
            "{m:?} vs the projected axis {guide:?}"
        );
    }
}

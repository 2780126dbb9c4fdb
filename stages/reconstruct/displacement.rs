//! Reconstruction of the textured surface from a geometry image and synthesized geometry
//! texels (Lai et al., "Geometric Texture Synthesis and Transfer via Geometry Images", §4.4).
//!
//! Each sample moves by dx·x̂ + dy·ŷ + dn·n̂ in its local frame (eq. 5 frames of the input
//! geometry image; mates share their representative's frame, so one texel value is one
//! displacement on both sides of a cut). Flip avoidance (§4.4.1): the displacement is added
//! in `steps` increasing steps; after each, a sample whose surface normal has turned by more
//! than `flip_angle` from the input's is put back to its previous step and frozen there.
//!
//! The output mesh triangulates the grid (the shorter diagonal of each cell, the one through
//! the tip next to a cut's tip), merges mated samples into one vertex so a closed input gives
//! a closed, watertight manifold, and drops the triangles that merging collapses or folds
//! onto each other (see [`grid_mesh`]).
//!
//! Texel amplitudes are in units of the sample's texel spacing (see the extraction stage);
//! they are scaled here by the input's typical sample spacing S̄ (the median, as for R) times
//! `amplitude`, so the relief
//! keeps its proportions to the texture's features on the new surface. The paper transfers
//! between models of similar scale and leaves this implicit.

use crate::check::{ParamError, check_range};
use crate::geom::Mesh;
use crate::geom::geometry_image::{GeometryImage, TexelImage, local_frames};
use glam::Vec3;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use texsyn_core::math::PureMath;

/// `[reconstruct]` of the geometry-image method.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DisplacementParams {
    /// Multiplies the relief, 0..=100. Default: 1.
    pub amplitude: f32,
    /// Increasing steps in which the texture is added (§4.4.1), 1..=100. Default: 10.
    pub steps: u32,
    /// A sample stops growing where its normal turns by more than this, degrees, 1..=180.
    /// Default: 150 (the paper's example).
    pub flip_angle: f32,
}

impl Default for DisplacementParams {
    fn default() -> Self {
        DisplacementParams {
            amplitude: 1.0,
            steps: 10,
            flip_angle: 150.0,
        }
    }
}

impl DisplacementParams {
    pub fn validate(&self) -> Result<(), ParamError> {
        check_range("reconstruct.amplitude", self.amplitude, 0.0, 100.0)?;
        check_range("reconstruct.steps", self.steps, 1, 100)?;
        check_range("reconstruct.flip_angle", self.flip_angle, 1.0, 180.0)
    }
}

/// The displaced geometry image: new positions per sample, and which samples were held back
/// by flip avoidance.
pub struct Displaced {
    pub positions: Vec<Vec3>,
    pub held_back: usize,
}

/// The triangles of both diagonal splits of every grid cell, (i, j) → i·n + j,
/// counter-clockwise in (j, i): whichever diagonal [`grid_mesh`] picks, its triangles were
/// checked.
fn grid_triangles(n: usize) -> Vec<[usize; 3]> {
    let mut out = Vec::with_capacity(4 * (n - 1) * (n - 1));
    for i in 0..n - 1 {
        for j in 0..n - 1 {
            let (a, b, c, d) = (
                i * n + j,
                i * n + j + 1,
                (i + 1) * n + j,
                (i + 1) * n + j + 1,
            );
            out.extend([[a, b, d], [a, d, c], [a, b, c], [b, d, c]]);
        }
    }
    out
}

/// Adds the texels to the geometry image with flip avoidance.
pub fn displace(
    gi: &GeometryImage,
    texels: &TexelImage,
    unit: f32,
    p: &DisplacementParams,
) -> Displaced {
    let n = gi.n as usize;
    assert_eq!(
        (texels.width as usize, texels.height as usize),
        (n, n),
        "texels match the geometry image"
    );
    let frames = local_frames(gi.n, &gi.positions, &gi.normals, &gi.mate_rep);
    let scale = unit * p.amplitude;
    let offsets: Vec<Vec3> = (0..n * n)
        .map(|k| {
            // Mates take their representative's texel, so they move together.
            let r = gi.mate_rep[k] as usize;
            let t = texels.texel((r % n) as u32, (r / n) as u32);
            let f = frames[k];
            (t[0] * f.x + t[1] * f.y + t[2] * f.n) * scale
        })
        .collect();
    let cos_limit = p.flip_angle.to_radians().cos_pure();
    // Flips are judged per grid triangle: a triangle whose normal turns too far unwinds the
    // last step of all its samples (the "related vertices" of §4.4.1), whichever moved.
    let cells = grid_triangles(n);
    let face_normal =
        |pos: &[Vec3], t: &[usize; 3]| (pos[t[1]] - pos[t[0]]).cross(pos[t[2]] - pos[t[0]]);
    let base: Vec<Vec3> = cells
        .iter()
        .map(|t| face_normal(&gi.positions, t).normalize_or_zero())
        .collect();
    let mut frozen = vec![false; n * n];
    let mut reached = vec![0u32; n * n];
    let mut positions = gi.positions.clone();
    // Members of each mate group, by representative (most samples are alone).
    let mut members: std::collections::HashMap<usize, Vec<usize>> = Default::default();
    for (k, &r) in gi.mate_rep.iter().enumerate() {
        if r as usize != k {
            members
                .entry(r as usize)
                .or_insert_with(|| vec![r as usize])
                .push(k);
        }
    }
    for step in 1..=p.steps {
        let t = step as f32 / p.steps as f32;
        let mut trial: Vec<Vec3> = (0..n * n)
            .map(|k| {
                if frozen[k] {
                    positions[k]
                } else {
                    gi.positions[k] + offsets[k] * t
                }
            })
            .collect();
        // Unwinding a sample changes the triangles around it too, so check again until no
        // triangle is flipped (the frozen set only grows, so this ends).
        loop {
            let flips: Vec<bool> = cells
                .par_iter()
                .zip(&base)
                .map(|(t, b)| {
                    *b != Vec3::ZERO
                        && face_normal(&trial, t).normalize_or_zero().dot(*b) < cos_limit
                })
                .collect();
            let mut newly = false;
            for (cell, &f) in cells.iter().zip(&flips) {
                if !f {
                    continue;
                }
                for &k in cell {
                    // The whole mate group unwinds together.
                    let r = gi.mate_rep[k] as usize;
                    if !frozen[r] {
                        newly = true;
                        let group = members
                            .get(&r)
                            .map(|g| g.as_slice())
                            .unwrap_or(std::slice::from_ref(&r));
                        for &m in group {
                            frozen[m] = true;
                            trial[m] = positions[m];
                        }
                    }
                }
            }
            if !newly {
                break;
            }
        }
        for k in 0..n * n {
            if !frozen[k] {
                positions[k] = trial[k];
                reached[k] = step;
            }
        }
    }
    let held_back = (0..n * n)
        .filter(|&k| gi.mate_rep[k] as usize == k && reached[k] < p.steps)
        .count();
    Displaced {
        positions,
        held_back,
    }
}

/// Triangulates a grid of positions into a mesh, merging mated samples (one vertex per mate
/// group, at the representative's position). Returns the mesh and, per output vertex, its
/// representative sample.
///
/// Each cell is split along its shorter diagonal, except next to a *fold*: a border sample
/// whose two border neighbours are mates is the tip of a cut path that ends inside the
/// surface, and the border turns back on itself there. Its two cells take the diagonal
/// through the tip; the other diagonal would give both cells a triangle on the same three
/// vertices (a folded pair, the tip held by nothing else). Triangles that merging collapses
/// are dropped, and so are triangles that come out more than once on the same three vertices
/// (a fold at a corner of the square, where one cell folds onto itself), all copies of them:
/// keeping one would leave its edges with one or three triangles; the cells next to such a
/// corner take the diagonal through its border neighbours, where the fold turns instead.
/// Samples no triangle uses (a tip at a corner) are not output, so a closed input gives a
/// closed manifold without stray vertices.
pub fn grid_mesh(gi: &GeometryImage, positions: &[Vec3]) -> (Mesh, Vec<u32>) {
    let n = gi.n as usize;
    let rep = |k: usize| gi.mate_rep[k];
    // The border in perimeter order (counter-clockwise in (u = j, v = i)).
    let border: Vec<usize> = (0..n - 1)
        .chain((0..n - 1).map(|i| i * n + n - 1))
        .chain((0..n - 1).map(|j| (n - 1) * n + (n - 1 - j)))
        .chain((0..n - 1).map(|i| (n - 1 - i) * n))
        .collect();
    // Per cell (i, j) → i·(n − 1) + j, the sample its diagonal must pass through.
    let mut through = vec![u32::MAX; (n - 1) * (n - 1)];
    let nb = border.len();
    for t in 0..nb {
        let (k, before, after) = (border[t], border[(t + nb - 1) % nb], border[(t + 1) % nb]);
        if rep(before) != rep(after) || rep(k) == rep(before) {
            continue;
        }
        // A tip at a corner has one cell, which folds onto itself and holds nothing; the
        // fold then turns at the corner's two (mated) border neighbours instead.
        let corner =
            |s: usize| (s / n == 0 || s / n == n - 1) && (s.is_multiple_of(n) || s % n == n - 1);
        let pivots = if corner(k) {
            vec![before, after]
        } else {
            vec![k]
        };
        for s in pivots {
            let (i, j) = (s / n, s % n);
            for ci in i.saturating_sub(1)..=i.min(n - 2) {
                for cj in j.saturating_sub(1)..=j.min(n - 2) {
                    let c = &mut through[ci * (n - 1) + cj];
                    if *c == u32::MAX {
                        *c = s as u32;
                    }
                }
            }
        }
    }
    let mut vertex_of = vec![u32::MAX; n * n];
    let mut samples = Vec::new();
    // Vertices standing for more than one sample (mates, on the border).
    let mut merged = Vec::new();
    for k in 0..n * n {
        let r = rep(k) as usize;
        if vertex_of[r] == u32::MAX {
            vertex_of[r] = samples.len() as u32;
            samples.push(r as u32);
            merged.push(false);
        }
        vertex_of[k] = vertex_of[r];
        if r != k {
            merged[vertex_of[r] as usize] = true;
        }
    }
    let mut tris = Vec::with_capacity(2 * (n - 1) * (n - 1));
    for i in 0..n - 1 {
        for j in 0..n - 1 {
            let a = i * n + j; // (i, j)
            let b = a + 1; // (i, j+1)
            let c = a + n; // (i+1, j)
            let d = c + 1; // (i+1, j+1)
            let forced = through[i * (n - 1) + j] as usize;
            let along_ad = if forced != u32::MAX as usize {
                forced == a || forced == d
            } else {
                positions[a].distance_squared(positions[d])
                    <= positions[b].distance_squared(positions[c])
            };
            // Counter-clockwise in (u = j, v = i) keeps the parameterization's orientation.
            let cells = if along_ad {
                [[a, b, d], [a, d, c]]
            } else {
                [[a, b, c], [b, d, c]]
            };
            for t in cells {
                let v = t.map(|s| vertex_of[s]);
                if v[0] != v[1] && v[1] != v[2] && v[0] != v[2] {
                    tris.push(v);
                }
            }
        }
    }
    // Only a triangle with a merged vertex can come out twice: three distinct samples are three
    // corners of one cell, and a cell's two triangles differ. Counting those alone keeps the
    // count proportional to the border, not the whole grid (at 1025² the map of all 2 M
    // triangles was a fifth of the reconstruct stage, and grew faster than linearly).
    let on_merged = |t: &[u32; 3]| t.iter().any(|&v| merged[v as usize]);
    let mut count: std::collections::HashMap<[u32; 3], u32> = Default::default();
    for t in tris.iter().filter(|t| on_merged(t)) {
        let mut key = *t;
        key.sort_unstable();
        *count.entry(key).or_default() += 1;
    }
    tris.retain(|t| {
        if !on_merged(t) {
            return true;
        }
        let mut key = *t;
        key.sort_unstable();
        count[&key] == 1
    });
    // Keep the used vertices, in sample order.
    let mut used = vec![false; samples.len()];
    for t in &tris {
        for &v in t {
            used[v as usize] = true;
        }
    }
    let mut new_index = vec![u32::MAX; samples.len()];
    let mut kept = Vec::with_capacity(samples.len());
    for (v, &s) in samples.iter().enumerate() {
        if used[v] {
            new_index[v] = kept.len() as u32;
            kept.push(s);
        }
    }
    let verts: Vec<Vec3> = kept.iter().map(|&s| positions[s as usize]).collect();
    let tris = tris
        .into_iter()
        .map(|t| t.map(|v| new_index[v as usize]))
        .collect();
    (Mesh::new(verts, tris), kept)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn plane(n: u32) -> GeometryImage {
        let mut positions = Vec::new();
        for i in 0..n {
            for j in 0..n {
                positions.push(Vec3::new(j as f32, i as f32, 0.0));
            }
        }
        let c = (n * n) as usize;
        GeometryImage {
            n,
            positions,
            normals: vec![Vec3::Z; c],
            mate_rep: (0..c as u32).collect(),
        }
    }

    #[test]
    fn a_gentle_relief_is_added_along_the_normal_in_full() {
        let gi = plane(9);
        let mut t = TexelImage::new(9, 9, 3);
        for y in 0..9 {
            for x in 0..9 {
                t.texel_mut(x, y)[2] = ((x + y) % 3) as f32 * 0.1;
            }
        }
        let d = displace(&gi, &t, 2.0, &DisplacementParams::default());
        assert_eq!(d.held_back, 0);
        for y in 0..9u32 {
            for x in 0..9u32 {
                let k = (y * 9 + x) as usize;
                let want = gi.positions[k] + Vec3::Z * (((x + y) % 3) as f32 * 0.2);
                assert!((d.positions[k] - want).length() < 1e-5);
            }
        }
    }

    #[test]
    fn flip_avoidance_holds_back_a_spike_that_would_fold_the_surface() {
        let gi = plane(9);
        let mut t = TexelImage::new(9, 9, 3);
        // A huge sideways shove of one sample folds its neighbourhood over.
        t.texel_mut(4, 4)[0] = 3.0;
        let d = displace(&gi, &t, 1.0, &DisplacementParams::default());
        assert!(d.held_back > 0);
        let reached = d.positions[40].x - gi.positions[40].x;
        assert!(reached > 0.0 && reached < 3.0, "{reached}");
        let unchecked = displace(
            &gi,
            &t,
            1.0,
            &DisplacementParams {
                flip_angle: 180.0,
                ..Default::default()
            },
        );
        assert_eq!(unchecked.held_back, 0);
    }

    /// A sphere's layout with both cut tips at corners: the border folded in half at (0, 0)
    /// and at (n − 1, n − 1), border position t mated with 4(n − 1) − t.
    fn folded_at_two_corners(n: u32) -> GeometryImage {
        let mut gi = plane(n);
        let nn = n as usize;
        let border: Vec<usize> = (0..nn - 1)
            .chain((0..nn - 1).map(|i| i * nn + nn - 1))
            .chain((0..nn - 1).map(|j| (nn - 1) * nn + (nn - 1 - j)))
            .chain((0..nn - 1).map(|i| (nn - 1 - i) * nn))
            .collect();
        let p = border.len();
        for t in 1..p / 2 {
            let (a, b) = (border[t], border[p - t]);
            let r = a.min(b);
            gi.mate_rep[a] = r as u32;
            gi.mate_rep[b] = r as u32;
        }
        // Jittered off the plane so that no triangle is flat by accident.
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        let mut jitter = || {
            state = state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            (state >> 40) as f32 / (1u64 << 24) as f32 - 0.5
        };
        for k in 0..nn * nn {
            gi.positions[k] += Vec3::new(0.2 * jitter(), 0.2 * jitter(), jitter());
        }
        for k in 0..nn * nn {
            gi.positions[k] = gi.positions[gi.mate_rep[k] as usize];
        }
        gi
    }

    #[test]
    fn a_fold_at_a_corner_leaves_a_closed_manifold_without_its_tip() {
        let n = 9u32;
        let gi = folded_at_two_corners(n);
        let (mesh, samples) = grid_mesh(&gi, &gi.positions);
        let h = crate::geom::mesh_check::mesh_health(&mesh);
        assert!(h.is_closed_manifold(), "{}", h.summary());
        let he = crate::geom::half_edge::HalfEdgeMesh::new(&mesh).unwrap();
        assert_eq!(he.components()[0].genus, 0);
        // The two corner tips have no triangle of their own (their one cell folds onto
        // itself) and are left out; every other mate group is a vertex.
        let groups = (0..(n * n) as usize)
            .filter(|&k| gi.mate_rep[k] as usize == k)
            .count();
        assert_eq!(mesh.vertex_count(), groups - 2);
        let last = n * n - 1;
        assert!(!samples.contains(&0) && !samples.contains(&last));
    }

    #[test]
    fn merging_mates_closes_a_cylinder() {
        // Columns 0 and n-1 are one seam: merged, every interior edge has two faces.
        let n = 8u32;
        let mut gi = plane(n);
        for i in 0..n as usize {
            let (l, r) = (i * n as usize, i * n as usize + n as usize - 1);
            let angle = |j: usize| j as f32 / (n - 1) as f32 * std::f32::consts::TAU;
            for j in 0..n as usize {
                let a = angle(j);
                gi.positions[i * n as usize + j] =
                    Vec3::new(a.cos_pure(), i as f32 * 0.3, a.sin_pure());
            }
            gi.positions[r] = gi.positions[l];
            gi.mate_rep[r] = l as u32;
        }
        let (mesh, _) = grid_mesh(&gi, &gi.positions);
        assert_eq!(mesh.vertex_count(), (n * (n - 1)) as usize);
        let mut edges: std::collections::HashMap<(u32, u32), u32> = Default::default();
        for t in &mesh.triangles {
            for k in 0..3 {
                let (a, b) = (t[k].min(t[(k + 1) % 3]), t[k].max(t[(k + 1) % 3]));
                *edges.entry((a, b)).or_default() += 1;
            }
        }
        // Only the two rim loops are boundary.
        let boundary = edges.values().filter(|&&c| c == 1).count();
        assert_eq!(boundary, 2 * (n as usize - 1));
        assert!(edges.values().all(|&c| c <= 2));
    }
}

//! Texture blending over several triangles (Zelinka & Garland, "Interactive Texture Synthesis
//! on Surfaces Using Jump Maps", §4.4, last sentence: "if the texture scale is sufficiently
//! large with respect to the surface, it may be necessary to blend boundaries over multiple
//! triangles").
//!
//! §4.4's blend ramps each triangle's three corner sets over that one triangle. Where a
//! triangle spans a texel or two of the exemplar, that ramp is a step: the patches of the walk
//! meet in a hard line. The paper names the remedy and gives no method; this module's is the
//! image-based jump map's "small blend kernel" carried to the surface:
//!
//! - Every vertex `v` extends its own patch around it: at a vertex `c` reached from `v` by the
//!   shortest path of edge offsets (§4.2.2) of texture length `d < r`, `v`'s patch places `c`
//!   at `address(v) + offset(v → c)`, with the tent weight `1 − d / r`.
//! - Vertices reached from each other across edges the walk did not jump across ([`jumped`])
//!   are one patch; so are patches that place `c` within [`CONTINUOUS_TEXELS`] of each other.
//!   A patch counts once at `c`, placed and weighted by its nearest vertex: its weight falls
//!   linearly with the distance to it, so a seam becomes a cross-fade about `2r` texels wide,
//!   whatever the triangles' size. (Matching by place alone fails: the offsets around a loop
//!   do not close where the field turns or the surface curves, by over 2 texels within 8 on
//!   the demo's cow, so one patch would count several times.)
//! - Inside a patch every vertex agrees, so a triangle far from a seam has one patch and shows
//!   the exemplar unblended: the blend touches seams only.
//! - In a triangle a patch's coordinates and weight are interpolated from its corners, so that
//!   triangles sharing an edge agree along it. Each vertex searches one edge further than `r`
//!   (weight 0 there) so that it has a place for every patch its neighbours weight; only a
//!   patch cut by [`MAX_PATCHES`] is placed from its heaviest corner along the triangle's edge
//!   (as §4.3 places a triangle). A vertex's own patch always has weight 1 there,
//!   so the weights never vanish, and with `r` at or below the shortest edge the blend is §4.4's
//!   own ramp.
//! - A patch has weight 0 at a vertex where it places the vertex outside the exemplar: there it
//!   would read the clamped border (streaks), and the vertex's own patch lies inside (§4.2.4).

use crate::image::ImageView;
use crate::parameterize::jump_parameterization::ParamParts;
use crate::reconstruct::jump_blend::MissingEdge;
use glam::{Vec2, Vec3};
use rayon::prelude::*;
use std::cmp::Reverse;
use std::collections::BinaryHeap;

/// An edge whose ends' addresses differ from its offset by more than this many texels is
/// one the walk jumped across (a jump lands at least the jump map's exclusion radius, 4 texels
/// by default, away). Inside one patch the offsets along other paths close only up to the
/// field's turn and the surface's curvature: by over a texel on a fifth of the demo cow's
/// edges at 60 texels per unit. Across such an edge the two ends' places are interpolated,
/// which stretches the texture by the mismatch over the edge; at 2 texels that drew visible
/// streaks on the cow, at 1 it does not, and the larger mismatches are cross-faded instead.
pub const CONTINUOUS_TEXELS: f32 = 1.0;

/// Whether the walk jumped across an edge with offset `offset` whose ends have the addresses
/// `from` and `to` (see [`CONTINUOUS_TEXELS`]).
pub fn jumped(offset: Vec2, from: Vec2, to: Vec2) -> bool {
    ((to - from) - offset).length() > CONTINUOUS_TEXELS
}

/// Patches kept per vertex, the heaviest first: three patches meet at most at a point in the
/// common case, and more only where jumps crowd.
pub const MAX_PATCHES: usize = 8;

/// Largest `reconstruct.blend_radius`, in texels.
pub const MAX_RADIUS: f32 = 64.0;

/// One patch as a triangle sees it: its texel coordinates at the three corners and its blend
/// weight at each (0 where the patch does not reach the corner).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PatchCorners {
    pub coords: [Vec2; 3],
    pub weights: [f32; 3],
}

/// The patches of every triangle, in compressed form: those of face `f` are
/// `patches[start[f]..start[f + 1]]`.
pub struct WideBlend {
    start: Vec<u32>,
    patches: Vec<PatchCorners>,
}

impl WideBlend {
    pub fn face(&self, f: usize) -> &[PatchCorners] {
        &self.patches[self.start[f] as usize..self.start[f + 1] as usize]
    }

    /// Patches summed over all faces (one per face where no seam is near).
    pub fn patch_count(&self) -> usize {
        self.patches.len()
    }

    /// The blended colour at barycentrics `bary` of face `f`: the patches' lookups weighted by
    /// their interpolated weights.
    pub fn rgba(&self, texture: &ImageView, f: usize, bary: Vec3) -> [f32; 4] {
        let l = bary.to_array();
        let (mut out, mut total) = ([0.0f32; 4], 0.0f32);
        for p in self.face(f) {
            let w = l[0] * p.weights[0] + l[1] * p.weights[1] + l[2] * p.weights[2];
            if w <= 0.0 {
                continue;
            }
            let at = p.coords[0] * l[0] + p.coords[1] * l[1] + p.coords[2] * l[2];
            let c = texture.sample(at);
            for k in 0..4 {
                out[k] += w * c[k];
            }
            total += w;
        }
        if total > 0.0 {
            out.iter_mut().for_each(|c| *c /= total);
        }
        out
    }
}

/// One patch as a vertex sees it: where it places the vertex, and its weight there.
#[derive(Clone, Copy, Debug)]
struct VertexPatch {
    at: Vec2,
    weight: f32,
}

/// The patches of every triangle for a blend over `radius` texels (see the module doc).
/// `exemplar` is the exemplar's size, whose texels a patch must place a vertex within.
pub fn wide_blend(
    triangles: &[[u32; 3]],
    param: &ParamParts,
    addresses: &[Vec2],
    radius: f32,
    exemplar: (u32, u32),
) -> Result<WideBlend, MissingEdge> {
    let n = addresses.len();
    let per_vertex: Vec<Vec<VertexPatch>> = (0..n)
        .into_par_iter()
        .map(|c| vertex_patches(param, addresses, c, radius, exemplar))
        .collect();
    let faces: Vec<Result<Vec<PatchCorners>, MissingEdge>> = triangles
        .par_iter()
        .enumerate()
        .map(|(f, t)| face_patches(param, &per_vertex, f, t))
        .collect();
    let mut start = Vec::with_capacity(triangles.len() + 1);
    let mut patches = Vec::new();
    start.push(0u32);
    for face in faces {
        patches.extend(face?);
        start.push(patches.len() as u32);
    }
    Ok(WideBlend { start, patches })
}

/// The patches at vertex `c`: a shortest-path search over the edge offsets' lengths out to
/// `radius` plus `c`'s longest edge, so that every patch with a weight at a neighbour of `c`
/// also has a place at `c` (with weight 0 beyond `radius`), and the triangles around `c`
/// interpolate one place each. A vertex reached across an edge the walk did not jump across is in its
/// predecessor's patch; one reached across a jump is in the patch that places `c` within
/// [`CONTINUOUS_TEXELS`] of where it does, or starts one. A patch places `c` where its first
/// (nearest) vertex does: at that vertex's address minus the path's offset.
fn vertex_patches(
    param: &ParamParts,
    addresses: &[Vec2],
    c: usize,
    radius: f32,
    (w, h): (u32, u32),
) -> Vec<VertexPatch> {
    let inside =
        |p: Vec2| p.x >= -0.5 && p.y >= -0.5 && p.x <= w as f32 - 0.5 && p.y <= h as f32 - 0.5;
    let (first, last) = (
        param.adj_offsets[c] as usize,
        param.adj_offsets[c + 1] as usize,
    );
    let longest_edge = param.edge_offsets[first..last]
        .iter()
        .map(|o| o.length())
        .fold(0.0f32, f32::max);
    let reach = radius + longest_edge;
    // Per vertex queued or settled: distance, path offset c → v, predecessor; and per settled
    // vertex its patch (an index into `out`).
    struct Seen {
        d: f32,
        offset: Vec2,
        from: u32,
        patch: Option<usize>,
    }
    let mut seen: std::collections::HashMap<u32, Seen> = Default::default();
    let mut heap = BinaryHeap::new();
    seen.insert(
        c as u32,
        Seen {
            d: 0.0,
            offset: Vec2::ZERO,
            from: c as u32,
            patch: None,
        },
    );
    // Distances are non-negative floats, whose bits order as the numbers do.
    heap.push(Reverse((0u32, c as u32)));
    let mut out: Vec<VertexPatch> = Vec::new();
    while let Some(Reverse((bits, v))) = heap.pop() {
        let d = f32::from_bits(bits);
        let s = &seen[&v];
        if d > s.d || s.patch.is_some() {
            continue;
        }
        let (ov, from) = (s.offset, s.from);
        let at = addresses[v as usize] - ov;
        let inherited = (from != v)
            .then(|| {
                let edge = param.offset(from, v).expect("searched along an edge");
                let (a, b) = (addresses[from as usize], addresses[v as usize]);
                (!jumped(edge, a, b)).then(|| seen[&from].patch.expect("settled"))
            })
            .flatten();
        let patch = match inherited {
            Some(p) => p,
            None => match out
                .iter()
                .position(|p| p.at.distance(at) <= CONTINUOUS_TEXELS)
            {
                Some(k) => k,
                None => {
                    // A vertex's own patch always counts, so weights never vanish; one that
                    // would read outside the exemplar here is placed but not weighted.
                    let weight = if v as usize == c {
                        1.0
                    } else if inside(at) {
                        (1.0 - d / radius).max(0.0)
                    } else {
                        0.0
                    };
                    out.push(VertexPatch { at, weight });
                    out.len() - 1
                }
            },
        };
        seen.get_mut(&v).expect("queued").patch = Some(patch);
        let (a, b) = (
            param.adj_offsets[v as usize] as usize,
            param.adj_offsets[v as usize + 1] as usize,
        );
        for j in a..b {
            let u = param.neighbors[j];
            let du = d + param.edge_offsets[j].length();
            if du >= reach {
                continue;
            }
            let better = seen.get(&u).is_none_or(|s| s.patch.is_none() && du < s.d);
            if better {
                let offset = ov + param.edge_offsets[j];
                seen.insert(
                    u,
                    Seen {
                        d: du,
                        offset,
                        from: v,
                        patch: None,
                    },
                );
                heap.push(Reverse((du.to_bits(), u)));
            }
        }
    }
    // Heaviest first (the search settles in order, so ties keep that order).
    out.sort_by(|a, b| b.weight.total_cmp(&a.weight));
    out.truncate(MAX_PATCHES);
    out
}

/// The patches of face `f`: its corners' patches matched by where they place corner 0
/// (within [`CONTINUOUS_TEXELS`]).
fn face_patches(
    param: &ParamParts,
    per_vertex: &[Vec<VertexPatch>],
    f: usize,
    t: &[u32; 3],
) -> Result<Vec<PatchCorners>, MissingEdge> {
    let offset = |a: usize, b: usize| -> Result<Vec2, MissingEdge> {
        if a == b {
            return Ok(Vec2::ZERO);
        }
        param.offset(t[a], t[b]).ok_or(MissingEdge {
            face: f,
            from: t[a],
            to: t[b],
        })
    };
    // Per patch: where it places corner 0, its heaviest corner, its place and weight at each
    // corner it reaches.
    struct Found {
        at_first: Vec2,
        best: usize,
        at: [Option<Vec2>; 3],
        weights: [f32; 3],
    }
    let mut found: Vec<Found> = Vec::new();
    for c in 0..3 {
        let to_first = offset(c, 0)?;
        for p in &per_vertex[t[c] as usize] {
            let at_first = p.at + to_first;
            let same = found
                .iter_mut()
                .find(|q| q.at[c].is_none() && q.at_first.distance(at_first) <= CONTINUOUS_TEXELS);
            match same {
                Some(q) => {
                    if p.weight > q.weights[q.best] {
                        q.best = c;
                    }
                    (q.at[c], q.weights[c]) = (Some(p.at), p.weight);
                }
                None => {
                    let (mut at, mut weights) = ([None; 3], [0.0; 3]);
                    (at[c], weights[c]) = (Some(p.at), p.weight);
                    found.push(Found {
                        at_first,
                        best: c,
                        at,
                        weights,
                    });
                }
            }
        }
    }
    // A corner the patch reaches takes the place its vertex gives it, so two triangles that
    // share an edge agree along it; a corner it does not reach (weight 0 there) is placed from
    // the heaviest corner along the triangle's edge.
    found
        .into_iter()
        .filter(|q| q.weights.iter().any(|&w| w > 0.0))
        .map(|q| {
            let best_at = q.at[q.best].expect("the heaviest corner is reached");
            let mut coords = [Vec2::ZERO; 3];
            for (c, x) in coords.iter_mut().enumerate() {
                *x = match q.at[c] {
                    Some(at) => at,
                    None => best_at + offset(q.best, c)?,
                };
            }
            Ok(PatchCorners {
                coords,
                weights: q.weights,
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::image::Image;
    use crate::parameterize::jump_parameterization::ParamMeta;
    use crate::reconstruct::jump_blend::{BlendShader, corner_sets};
    use texsyn_core::geom::{VertexAdjacency, primitives::grid};

    /// A flat n×n grid, one texel per edge, with its edge offsets (x, y in texels).
    struct Sheet {
        triangles: Vec<[u32; 3]>,
        positions: Vec<Vec2>,
        adj: VertexAdjacency,
        offsets: Vec<Vec2>,
    }

    fn sheet(n: usize) -> Sheet {
        let mesh = grid(n, 1.0);
        let adj = VertexAdjacency::build(mesh.vertex_count(), &mesh.triangles);
        let positions: Vec<Vec2> = mesh.positions.iter().map(|p| p.truncate()).collect();
        let mut offsets = Vec::new();
        for a in 0..positions.len() {
            for j in adj.offsets[a] as usize..adj.offsets[a + 1] as usize {
                offsets.push(positions[adj.neighbors[j] as usize] - positions[a]);
            }
        }
        Sheet {
            triangles: mesh.triangles,
            positions,
            adj,
            offsets,
        }
    }

    fn parts(s: &Sheet) -> ParamParts<'_> {
        ParamParts {
            meta: ParamMeta {
                vertices: s.positions.len() as u64,
                scale: 1.0,
                exemplar: (64, 64),
                components: 1,
            },
            order: &[],
            seeds: &[],
            adj_offsets: &s.adj.offsets,
            neighbors: &s.adj.neighbors,
            edge_offsets: &s.offsets,
            boxes: &[],
        }
    }

    /// A 64² exemplar of seeded noise: any two places differ.
    fn noise() -> Image {
        Image::from_fn(64, 64, |x, y| {
            let v = crate::random::counter_unit(3, 0, (y * 64 + x) as u64);
            [v, 1.0 - v, 0.5, 1.0]
        })
    }

    /// Addresses of a walk that jumped once: vertices left of column `cut` from place `a`,
    /// the others from place `b` (both laid out along the sheet's own offsets).
    fn jumped_once(s: &Sheet, cut: f32, a: Vec2, b: Vec2) -> Vec<Vec2> {
        s.positions
            .iter()
            .map(|&p| if p.x < cut { a + p } else { b + p })
            .collect()
    }

    /// A smooth 64² ramp: neighbouring texels are alike, distant places are not.
    fn ramp() -> Image {
        Image::from_fn(64, 64, |x, y| [x as f32 / 63.0, y as f32 / 63.0, 0.5, 1.0])
    }

    /// The colour at vertex `v` as the first face holding it shows it.
    fn at_vertex(s: &Sheet, shade: &dyn Fn(usize, Vec3) -> [f32; 4], v: u32) -> [f32; 4] {
        let (f, t) = s
            .triangles
            .iter()
            .enumerate()
            .find(|(_, t)| t.contains(&v))
            .expect("a face");
        let k = t.iter().position(|&x| x == v).unwrap();
        shade(
            f,
            Vec3::from_array(std::array::from_fn(|i| (i == k) as u32 as f32)),
        )
    }

    fn distance(a: [f32; 4], b: [f32; 4]) -> f32 {
        (0..3).map(|k| (a[k] - b[k]).abs()).sum()
    }

    #[test]
    fn a_walk_without_jumps_is_looked_up_unblended() {
        let s = sheet(12);
        let addresses: Vec<Vec2> = s.positions.iter().map(|&p| p + Vec2::splat(20.0)).collect();
        let wide = wide_blend(&s.triangles, &parts(&s), &addresses, 6.0, (64, 64)).unwrap();
        let ex = noise();
        assert_eq!(wide.patch_count(), s.triangles.len(), "one patch a face");
        for (f, t) in s.triangles.iter().enumerate() {
            let p = wide.face(f)[0];
            assert_eq!(p.weights, [1.0; 3]);
            for c in 0..3 {
                assert!(p.coords[c].distance(addresses[t[c] as usize]) < 1e-4);
            }
            let bary = Vec3::new(0.2, 0.3, 0.5);
            let want = ex.view().sample(
                addresses[t[0] as usize] * 0.2
                    + addresses[t[1] as usize] * 0.3
                    + addresses[t[2] as usize] * 0.5,
            );
            let got = wide.rgba(&ex.view(), f, bary);
            assert!(distance(got, want) < 1e-5, "{got:?} {want:?}");
        }
    }

    #[test]
    fn a_seam_is_cross_faded_over_the_radius_and_left_alone_beyond_it() {
        let n = 24;
        let s = sheet(n);
        let (a, b) = (Vec2::new(4.0, 10.0), Vec2::new(30.0, 36.0));
        let addresses = jumped_once(&s, 12.0, a, b);
        let ex = ramp();
        let param = parts(&s);
        let radius = 4.0;
        let wide = wide_blend(&s.triangles, &param, &addresses, radius, (64, 64)).unwrap();
        let sets = corner_sets(&s.triangles, &param, &addresses).unwrap();
        let narrow = BlendShader {
            sets: &sets,
            texture: ex.view(),
            wide: None,
        };
        let blended = BlendShader {
            sets: &sets,
            texture: ex.view(),
            wide: Some(&wide),
        };
        let row = 12;
        let v = |x: usize| (row * n + x) as u32;
        let own = |x: usize| {
            let p = s.positions[v(x) as usize];
            ex.view().sample(if p.x < 12.0 { a + p } else { b + p })
        };
        // Beyond the radius from the seam (columns 11 | 12) each side shows its own patch.
        for x in (0..=7).chain(16..n) {
            let got = at_vertex(&s, &|f, l| blended.rgba(f, l), v(x));
            assert!(distance(got, own(x)) < 1e-5, "column {x}");
        }
        // Next to the seam both patches show: the jump edge's two ends differ less than under
        // §4.4's one-triangle ramp, where each end shows only its own patch (the exemplar is
        // smooth, so the difference is the seam's).
        let step = |shade: &dyn Fn(usize, Vec3) -> [f32; 4]| {
            distance(at_vertex(&s, shade, v(11)), at_vertex(&s, shade, v(12)))
        };
        let (sharp, soft) = (
            step(&|f, l| narrow.rgba(f, l)),
            step(&|f, l| blended.rgba(f, l)),
        );
        assert!(
            (sharp - distance(own(11), own(12))).abs() < 1e-5,
            "the one-triangle ramp shows each end's own patch"
        );
        assert!(soft < 0.5 * sharp, "{soft} vs {sharp}");
        // The weights fall with the distance: column 10 shows more of its own patch than 11.
        let mix = |x: usize| {
            let got = at_vertex(&s, &|f, l| blended.rgba(f, l), v(x));
            distance(got, own(x))
        };
        assert!(
            mix(10) < mix(11) && mix(9) < mix(10),
            "{} {} {}",
            mix(9),
            mix(10),
            mix(11)
        );
    }

    #[test]
    fn a_radius_below_the_edges_is_the_one_triangle_ramp() {
        let s = sheet(10);
        let addresses = jumped_once(&s, 5.0, Vec2::new(4.0, 4.0), Vec2::new(40.0, 30.0));
        let ex = noise();
        let param = parts(&s);
        let wide = wide_blend(&s.triangles, &param, &addresses, 0.9, (64, 64)).unwrap();
        let sets = corner_sets(&s.triangles, &param, &addresses).unwrap();
        let narrow = BlendShader {
            sets: &sets,
            texture: ex.view(),
            wide: None,
        };
        for f in 0..s.triangles.len() {
            for bary in [Vec3::new(0.2, 0.3, 0.5), Vec3::new(0.6, 0.1, 0.3)] {
                let (got, want) = (wide.rgba(&ex.view(), f, bary), narrow.rgba(f, bary));
                assert!(distance(got, want) < 1e-4, "face {f}: {got:?} {want:?}");
            }
        }
    }

    #[test]
    fn a_patch_that_would_read_outside_the_exemplar_is_left_out() {
        let s = sheet(12);
        // The right patch starts at the exemplar's left border: extended leftwards past the
        // seam it would place vertices at negative texels.
        let addresses = jumped_once(&s, 6.0, Vec2::new(10.0, 10.0), Vec2::new(-6.0, 10.0));
        let wide = wide_blend(&s.triangles, &parts(&s), &addresses, 4.0, (64, 64)).unwrap();
        for f in 0..s.triangles.len() {
            for p in wide.face(f) {
                for c in 0..3 {
                    if p.weights[c] > 0.0 {
                        assert!(p.coords[c].x >= -0.5, "face {f}: {p:?}");
                    }
                }
            }
        }
        // The left patch still reaches across the seam.
        let across = (0..s.triangles.len())
            .filter(|&f| wide.face(f).len() > 1)
            .count();
        assert!(across > 0);
    }
}

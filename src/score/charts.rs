//! Scoring the jump-map method (Zelinka & Garland, §4.3–4.4): its blended surface in
//! texture space, and its coordinate seams.
//!
//! **Unfolded discs.** The baked atlas (`baked_basecolor.png`) lays each triangle with its
//! longest edge horizontal and at the atlas's own scale, so its patches are rotated and
//! rescaled against the exemplar's, and a nearest-patch distance would mostly measure that;
//! single triangles are also smaller than a patch on most meshes (on the demo's cow no
//! 7 × 7 patch fits inside one). Instead, discs of the surface around 64 seeded vertices are unfolded into
//! texel coordinates by summing the parameterization's edge offsets (§4.2.2) outward from
//! the centre, so the texture is upright and at the exemplar's scale across many triangles,
//! and coloured with the §4.4 blend of the three corner sets (the `BlendShader` the bake
//! uses), which is what a viewer of `textured.glb` sees. Only texels a triangle covers are in
//! the mask (`patch_score_masked`), and not those where the unfolding tears, folds or
//! overlaps itself ([`unfolded_discs_with`]).
//!
//! **Seams.** Where two triangles that share an edge have different coordinates for its
//! ends (a coordinate seam), the OBJ shows the exemplar at two places side by side. The seam
//! score samples both sides' exemplar colour at 8 points along each seam edge (RMS over RGB)
//! and divides the mean by the same measure with the second side placed at a seeded random
//! position in the exemplar ("randomly placed triangles"): 0 means invisible seams, 1 seams as
//! visible as pasting unrelated pieces together.
//!
//! **Blended seams.** The seam score reads the OBJ's single coordinate set; the blended
//! surface has no coordinate seam, but where a jump falls inside a small triangle its colour
//! still changes across that triangle as abruptly as at a seam. The blended seam score takes
//! every triangle edge the walk jumped across and compares the surface's colours at its two
//! ends with the exemplar's at the first end's address and one edge offset further: 1 means the
//! surface changes across a jump no more than the texture does over that distance, more means
//! a visible seam. A wider blend (`reconstruct.blend_radius`) lowers it; blur would too, which
//! the discs' patch ratio and gradient ratio show.

use super::{Item, Run, ScoreFailure};
use crate::artifact::jump_maps::{JumpParameterization, TexelAddresses};
use crate::geom::Mesh;
use crate::graph::Csr;
use crate::image::{Image, ImageView};
use crate::pipeline::Handle;
use crate::random::{counter_hash, counter_unit};
use crate::stages::parameterize::jump_parameterization::ParamParts;
use crate::stages::reconstruct::jump_blend::{BlendShader, corner_sets, random_base_set};
use crate::stages::reconstruct::jump_export::wide_blend_of;
use crate::stages::reconstruct::wide_blend::jumped;
use glam::{Vec2, Vec3};
use std::collections::HashMap;

/// Discs unfolded (at most; fewer on a mesh with fewer vertices).
const DISCS: usize = 64;
/// Their radius in exemplar texels: several patches across, and small enough that the
/// unfolding rarely meets itself.
const DISC_RADIUS: usize = 24;
/// How much longer or shorter than its own length an unfolded edge may be before
/// [`unfolded_discs_with`] takes its triangle as torn: a walk that closes, even over a
/// curved surface, keeps edges near their length; a tear spans the gap between two paths.
/// A texel more either way is allowed as well: a walk's error below a texel is not a tear.
pub const TORN_STRETCH: f32 = 2.0;
/// The area in texels above which a triangle unfolded the other way round from its disc is
/// a fold (or above half its own area, for triangles smaller than a texel): a sliver turned
/// over by the walk's error is not.
const FOLDED_AREA: f32 = 0.5;
const STREAM_DISC: u64 = 0x5ea0_0003;
/// Samples along each seam edge.
const SEAM_SAMPLES: usize = 8;
const STREAM_SEAM_X: u64 = 0x5ea0_0001;
const STREAM_SEAM_Y: u64 = 0x5ea0_0002;

/// The nodes of a jump-map run that its score reads.
#[derive(Clone, Copy)]
pub struct JumpMapNodes {
    pub mesh: Handle<Mesh>,
    pub parameterize: Handle<JumpParameterization>,
    pub synthesize: Handle<TexelAddresses>,
    pub exemplar: Handle<Image>,
    /// `reconstruct.blend_radius`: the discs show the blend the export bakes.
    pub blend_radius: f32,
}

impl super::Planned for JumpMapNodes {
    fn score(&self, run: &Run<'_>, _: &mut Vec<String>) -> Result<Vec<Item>, ScoreFailure> {
        jump_maps(run, self)
    }
}

pub fn jump_maps(run: &Run, nodes: &JumpMapNodes) -> Result<Vec<Item>, ScoreFailure> {
    let mesh = run.view(nodes.mesh)?;
    let param = run.view(nodes.parameterize)?;
    let walk = run.view(nodes.synthesize)?;
    let ex = run.view(nodes.exemplar)?;
    let sets = corner_sets(&mesh.triangles, &param, walk.addresses)
        .map_err(|e| ScoreFailure::new(format!("internal error: {e}")))?;
    let single = random_base_set(&sets);
    let size = (ex.width, ex.height);
    let wide = wide_blend_of(&mesh, &param, walk.addresses, nodes.blend_radius, size)
        .map_err(|e| ScoreFailure::new(format!("internal error: {e}")))?;
    let shader = BlendShader {
        sets: &sets,
        texture: ex,
        wide: wide.as_ref(),
    };
    let charts = unfolded_discs(
        &mesh.triangles,
        &(&param).into(),
        run.params.seed,
        |f, b| shader.rgba(f, b),
    );
    let mut item = Item::new(
        format!(
            "the blended surface, {} discs unfolded into texel coordinates",
            charts.discs
        ),
        "inputs.exemplar",
    );
    item.extra.insert(
        "cut_share".into(),
        serde_json::json!(super::round3(charts.cut_share)),
    );
    run.score_into(&mut item, charts.image.view(), Some(&charts.mask), ex)?;
    let seams = seam_score(&mesh.triangles, &single, ex, run.params.seed);
    item.extra.insert(
        "seams".into(),
        serde_json::to_value(&seams).expect("plain numbers"),
    );
    let blended = blended_seam_score(
        &mesh.triangles,
        &param,
        walk.addresses,
        |f, b| shader.rgba(f, b),
        ex,
    );
    item.extra.insert(
        "blended_seams".into(),
        serde_json::to_value(&blended).expect("plain numbers"),
    );
    Ok(vec![item])
}

/// The texture-coordinate offset of every half-edge, in compressed adjacency form: the
/// neighbours of `v` are `neighbors[adj_offsets[v]..adj_offsets[v + 1]]`, with the offsets
/// from `v` to them at the same places of `edge_offsets` (as [`ParamParts`] holds them).
pub struct EdgeOffsets<'a> {
    pub adj_offsets: &'a [u32],
    pub neighbors: &'a [u32],
    pub edge_offsets: &'a [Vec2],
}

impl<'a> From<&ParamParts<'a>> for EdgeOffsets<'a> {
    fn from(p: &ParamParts<'a>) -> Self {
        EdgeOffsets {
            adj_offsets: p.adj_offsets,
            neighbors: p.neighbors,
            edge_offsets: p.edge_offsets,
        }
    }
}

/// Discs of the surface unfolded into texel coordinates, packed on one canvas.
pub struct Charts {
    pub image: Image,
    /// Texels that some triangle covers, less those cut out where the unfolding tears, folds
    /// or overlaps itself ([`unfolded_discs_with`]).
    pub mask: Vec<bool>,
    /// Discs laid out.
    pub discs: usize,
    /// Of the texels the discs' triangles cover, torn ones included, the share cut out.
    pub cut_share: f64,
}

/// The top-left texel of disc `k`'s tile, `per_row` tiles to a row, one texel apart.
fn tile_corner(k: usize, per_row: usize) -> (usize, usize) {
    let pitch = 2 * DISC_RADIUS + 2;
    ((k % per_row) * pitch, (k / per_row) * pitch)
}

/// Where disc `k`'s centre vertex lands: the middle of its tile's middle texel.
fn disc_centre(k: usize, per_row: usize) -> Vec2 {
    let (x0, y0) = tile_corner(k, per_row);
    Vec2::new(x0 as f32, y0 as f32) + Vec2::splat(DISC_RADIUS as f32 + 0.5)
}

/// Unfolds [`DISCS`] discs of the surface, each around a seeded vertex, into the texel
/// coordinates the parameterization gives (§4.2.2's edge offsets, summed outward from the
/// centre breadth first, to [`DISC_RADIUS`] texels), rasterizes their triangles there at one
/// texel per exemplar texel, coloured by `colour(face, barycentrics)`, and packs the discs
/// in a grid of tiles one texel apart. Where the unfolding tears, folds or overlaps itself,
/// the texels are left out of the mask ([`unfolded_discs_with`]).
pub fn unfolded_discs(
    triangles: &[[u32; 3]],
    offsets: &EdgeOffsets,
    seed: u64,
    colour: impl Fn(usize, Vec3) -> [f32; 4],
) -> Charts {
    unfolded_discs_with(
        triangles,
        offsets,
        seed,
        |_, _, j| offsets.edge_offsets[j],
        |_, j| offsets.edge_offsets[j].length(),
        colour,
    )
}

/// How a disc's breadth-first unfolding steps along one edge: `step(centre, from, j)` is the
/// texel offset from vertex `from` to its neighbour `neighbors[j]`, in the disc around
/// `centre`. Every disc visits its vertices in breadth-first order from its centre and steps
/// each reached vertex's edges to unreached neighbours once, parents before children, so a
/// step may carry state outward along the walk (a frame transported from the centre), which
/// it starts afresh when `centre` changes.
pub trait DiscStep: FnMut(usize, usize, usize) -> Vec2 {}
impl<F: FnMut(usize, usize, usize) -> Vec2> DiscStep for F {}

/// [`unfolded_discs`] with the edge offsets given by `step` (see [`DiscStep`]) instead of
/// a fixed table; `offsets.edge_offsets` is not read. `length(from, j)` is the texel length
/// of the edge from `from` to `neighbors[j]`, what a walk that closes unfolds it at.
///
/// The walk unfolds a disc along a tree of edges, so a triangle whose corners it reached
/// along paths that do not close (around a singularity of the field, or where a disc wider
/// than a thin part, a leg a few texels round, wraps around it) lands torn, folded over, or
/// on top of other triangles. None of that is the texture, and a nearest-patch score would
/// count its shards and seams as the method's. So the mask leaves out every texel that a
/// torn triangle (an edge unfolded [`TORN_STRETCH`] times longer or shorter than its own
/// length, and a texel more) or a folded one (turned the other way round from most of its
/// disc's area, over more than [`FOLDED_AREA`] or half its own area) covers, and every texel
/// that two triangles more than a ring apart both cover. What the mask loses shows as fewer
/// scored patches; it depends on the geometry and the steps alone, never on the colours.
pub fn unfolded_discs_with(
    triangles: &[[u32; 3]],
    offsets: &EdgeOffsets,
    seed: u64,
    mut step: impl DiscStep,
    length: impl Fn(usize, usize) -> f32,
    colour: impl Fn(usize, Vec3) -> [f32; 4],
) -> Charts {
    let param = offsets;
    let n = param.adj_offsets.len() - 1;
    let faces_of: Csr<u32> = Csr::from_pairs(
        n,
        triangles
            .iter()
            .enumerate()
            .flat_map(|(f, t)| t.iter().map(move |&v| (v as usize, f as u32))),
    );
    // Centres: the vertices with the smallest seeded hashes among those with a face.
    let mut order: Vec<(u64, usize)> = (0..n)
        .filter(|&v| !faces_of.row(v).is_empty())
        .map(|v| (counter_hash(seed, STREAM_DISC, v as u64), v))
        .collect();
    order.sort_unstable();
    order.truncate(DISCS);
    let tile = 2 * DISC_RADIUS + 1;
    let per_row = (order.len() as f64).sqrt().ceil().max(1.0) as usize;
    let rows = order.len().div_ceil(per_row).max(1);
    let (cw, ch) = (per_row * (tile + 1), rows * (tile + 1));
    let mut pixels = vec![[0.0f32; 4]; cw * ch];
    let mut mask = vec![false; cw * ch];
    // The triangles that first and last covered each texel, and whether the texel is cut
    // out: two triangles more than a ring apart cover it, or a torn or folded one does.
    let mut first = vec![u32::MAX; cw * ch];
    let mut owner = vec![u32::MAX; cw * ch];
    let mut cut = vec![false; cw * ch];
    let mut coord: Vec<Option<Vec2>> = vec![None; n];
    // Two triangles within a ring of each other: a corner of one is a corner of the other or
    // its neighbour. Such triangles may overlap by the walk's error; two farther apart that
    // cover one texel are two layers of the surface.
    let near = |s: [u32; 3], t: [u32; 3]| {
        s.iter().any(|&a| {
            let (lo, hi) = (
                param.adj_offsets[a as usize],
                param.adj_offsets[a as usize + 1],
            );
            t.contains(&a)
                || (param.neighbors[lo as usize..hi as usize].iter()).any(|b| t.contains(b))
        })
    };
    for (k, &(_, centre)) in order.iter().enumerate() {
        // Breadth-first unfolding from the centre.
        let mut reached = vec![centre];
        coord[centre] = Some(Vec2::ZERO);
        let mut i = 0;
        while i < reached.len() {
            let u = reached[i];
            i += 1;
            let cu = coord[u].expect("reached");
            if cu.length() > DISC_RADIUS as f32 {
                continue;
            }
            let (a, b) = (
                param.adj_offsets[u] as usize,
                param.adj_offsets[u + 1] as usize,
            );
            for j in a..b {
                let w = param.neighbors[j] as usize;
                if coord[w].is_none() {
                    coord[w] = Some(cu + step(centre, u, j));
                    reached.push(w);
                }
            }
        }
        let (x0, y0) = tile_corner(k, per_row);
        let origin = disc_centre(k, per_row);
        let mut faces: Vec<usize> = reached
            .iter()
            .flat_map(|&v| faces_of.row(v).iter().map(|&f| f as usize))
            .collect();
        faces.sort_unstable();
        faces.dedup();
        // Each face's unfolded corners, its signed area (doubled), its own area (doubled, from
        // its edges' own lengths), and whether it is torn: an edge unfolded at a length other
        // than its own (beyond TORN_STRETCH either way, and a texel).
        let unfolded: Vec<(usize, [Vec2; 3], f32, f32, bool)> = (faces.into_iter())
            .filter_map(|f| {
                let t = triangles[f];
                let c = [0, 1, 2].map(|k| coord[t[k] as usize].map(|p| p + origin));
                let c = [c[0]?, c[1]?, c[2]?];
                let det = (c[1] - c[0]).perp_dot(c[2] - c[0]);
                if det.abs() < 1e-12 || !det.is_finite() {
                    return None;
                }
                let own = [0, 1, 2].map(|k| {
                    let (a, b) = (t[k] as usize, t[(k + 1) % 3]);
                    let (lo, hi) = (param.adj_offsets[a] as usize, param.adj_offsets[a + 1]);
                    let j = (lo..hi as usize).find(|&j| param.neighbors[j] == b);
                    debug_assert!(j.is_some(), "edge {a}–{b} of face {f} not in the adjacency");
                    j.map(|j| length(a, j))
                });
                let torn = (0..3).any(|k| {
                    let now = c[k].distance(c[(k + 1) % 3]);
                    own[k].is_some_and(|own| {
                        now > TORN_STRETCH * own + 1.0 || now * TORN_STRETCH + 1.0 < own
                    })
                });
                let own_det = match own {
                    [Some(a), Some(b), Some(c)] => 2.0 * heron(a, b, c),
                    _ => det.abs(),
                };
                Some((f, c, det, own_det, torn))
            })
            .collect();
        // The walk keeps the surface's orientation (the centre's ring is stepped straight
        // from its frame): faces unfolded the other way round from most of the disc's area
        // are folded over (the disc past a rim, or past where geodesics meet). A sliver
        // turned over by the walk's error, over less than half its own area and
        // FOLDED_AREA, is not a fold.
        let signed: f32 = unfolded.iter().map(|u| u.2).sum();
        let upright = signed >= 0.0;
        for (f, c, det, own_det, torn) in unfolded {
            let fold_area = (2.0 * FOLDED_AREA).min(0.5 * own_det);
            let folded = (det > 0.0) != upright && det.abs() > fold_area;
            let cut_out = torn || folded;
            let (a, e1, e2) = (c[0], c[1] - c[0], c[2] - c[0]);
            let lo = c[0]
                .min(c[1])
                .min(c[2])
                .floor()
                .max(Vec2::new(x0 as f32, y0 as f32));
            let hi = c[0]
                .max(c[1])
                .max(c[2])
                .ceil()
                .min(Vec2::new((x0 + tile) as f32, (y0 + tile) as f32));
            for y in lo.y as usize..hi.y.max(lo.y) as usize {
                for x in lo.x as usize..hi.x.max(lo.x) as usize {
                    let p = Vec2::new(x as f32 + 0.5, y as f32 + 0.5) - a;
                    let u = p.perp_dot(e2) / det;
                    let v = e1.perp_dot(p) / det;
                    let bary = Vec3::new(1.0 - u - v, u, v);
                    if bary.min_element() < 0.0 {
                        continue;
                    }
                    let at = y * cw + x;
                    if cut_out {
                        cut[at] = true;
                        continue;
                    }
                    // Against the first and the last triangle that covered the texel, so the
                    // order they are drawn in cannot hide a layer between near ones.
                    for before in [first[at], owner[at]] {
                        if before != u32::MAX && !near(triangles[before as usize], triangles[f]) {
                            cut[at] = true;
                        }
                    }
                    if first[at] == u32::MAX {
                        first[at] = f as u32;
                    }
                    owner[at] = f as u32;
                    pixels[at] = colour(f, bary);
                    mask[at] = true;
                }
            }
        }
        for &v in &reached {
            coord[v] = None;
        }
    }
    for (m, &o) in mask.iter_mut().zip(&cut) {
        *m &= !o;
    }
    let (cut, kept) = (count(&cut), count(&mask));
    Charts {
        image: Image {
            width: cw as u32,
            height: ch as u32,
            pixels,
        },
        mask,
        discs: order.len(),
        cut_share: if cut + kept > 0 {
            cut as f64 / (cut + kept) as f64
        } else {
            0.0
        },
    }
}

/// The area of a triangle with sides `a`, `b`, `c` (Heron); 0 for sides that close no triangle.
fn heron(a: f32, b: f32, c: f32) -> f32 {
    let s = (a + b + c) / 2.0;
    (s * (s - a) * (s - b) * (s - c)).max(0.0).sqrt()
}

fn count(flags: &[bool]) -> usize {
    flags.iter().filter(|&&f| f).count()
}

const STREAM_FLOOR_DISC: u64 = 0x5ea0_0004;
/// The smallest exemplar side [`verbatim_discs`] lays a disc into: the disc and the two
/// texels a bicubic read reaches past it, on either side (one more than it needs).
pub const VERBATIM_SIDE: u32 = 2 * (DISC_RADIUS as u32 + 2) + 1;

/// The discs' floor: `charts`' mask filled with the exemplar copied verbatim, each disc from
/// one seeded place (its centre at a sub-texel position, the whole disc inside the exemplar)
/// and read by `read` at `place + (pixel − disc centre)`, as a flawless layout would look
/// through the same discs when its addresses are read as `read` reads them. The disc's own
/// frame is the exemplar's axes, so nothing turns: what the floor costs is the read between
/// texels alone (none for whole-texel reads). `None` when a disc does not fit the exemplar.
pub fn verbatim_discs(
    charts: &Charts,
    exemplar: (u32, u32),
    seed: u64,
    read: impl Fn(Vec2) -> [f32; 4],
) -> Option<Image> {
    let tile = 2 * DISC_RADIUS + 1;
    let (w, h) = (charts.image.width as usize, charts.image.height as usize);
    let per_row = w / (tile + 1);
    // Centres at least a radius and two texels (the bicubic read's reach) inside.
    let margin = DISC_RADIUS as f32 + 2.0;
    let room = Vec2::new(exemplar.0 as f32, exemplar.1 as f32) - Vec2::splat(VERBATIM_SIDE as f32);
    if per_row == 0 || room.min_element() < 0.0 {
        return None;
    }
    let mut out = Image::new(w as u32, h as u32);
    for (i, px) in out.pixels.iter_mut().enumerate() {
        if !charts.mask[i] {
            continue;
        }
        let (x, y) = (i % w, i / w);
        let k = (y / (tile + 1)) * per_row + x / (tile + 1);
        let place = Vec2::splat(margin)
            + room
                * Vec2::new(
                    counter_unit(seed, STREAM_FLOOR_DISC, 2 * k as u64),
                    counter_unit(seed, STREAM_FLOOR_DISC, 2 * k as u64 + 1),
                );
        let local = Vec2::new(x as f32 + 0.5, y as f32 + 0.5) - disc_centre(k, per_row);
        *px = read(place + local);
    }
    Some(out)
}

/// How visible coordinate seams are; see the module doc.
#[derive(Clone, Debug, serde::Serialize)]
pub struct SeamScore {
    /// Seam edge colour difference over the random placement's (0 = invisible).
    pub ratio: f64,
    /// Mean RMS colour difference across seam edges.
    pub seam_rms: f64,
    /// The same with one side placed at random.
    pub random_rms: f64,
    /// Interior edges whose two triangles disagree on the coordinates of its ends.
    pub seam_edges: usize,
    pub interior_edges: usize,
}

/// The seam score of a mesh whose triangle `f` has corner texel coordinates `coords[f]` into
/// `ex`.
pub fn seam_score(
    triangles: &[[u32; 3]],
    coords: &[[Vec2; 3]],
    ex: ImageView,
    seed: u64,
) -> SeamScore {
    let mut first: HashMap<(u32, u32), (usize, usize)> = HashMap::new();
    let mut pairs = Vec::new();
    for (f, t) in triangles.iter().enumerate() {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            let key = (a.min(b), a.max(b));
            match first.get(&key) {
                None => {
                    first.insert(key, (f, k));
                }
                Some(&(g, m)) => pairs.push(((f, k), (g, m))),
            }
        }
    }
    let corner = |f: usize, v: u32| -> Vec2 {
        let i = triangles[f]
            .iter()
            .position(|&x| x == v)
            .expect("edge of the face");
        coords[f][i]
    };
    let (w, h) = (ex.width as f32, ex.height as f32);
    let (mut seam, mut random, mut seams) = (0.0f64, 0.0f64, 0usize);
    for &((f, k), (g, _)) in &pairs {
        let (a, b) = (triangles[f][k], triangles[f][(k + 1) % 3]);
        let (fa, fb) = (corner(f, a), corner(f, b));
        let (ga, gb) = (corner(g, a), corner(g, b));
        if fa.distance(ga) < 1e-3 && fb.distance(gb) < 1e-3 {
            continue;
        }
        // The random placement: g's side moved so its midpoint falls at a seeded point.
        let r = Vec2::new(
            counter_unit(seed, STREAM_SEAM_X, seams as u64) * w,
            counter_unit(seed, STREAM_SEAM_Y, seams as u64) * h,
        ) - (ga + gb) * 0.5;
        seams += 1;
        for s in 0..SEAM_SAMPLES {
            let t = (s as f32 + 0.5) / SEAM_SAMPLES as f32;
            let cf = bilinear(ex, fa.lerp(fb, t));
            let cg = bilinear(ex, ga.lerp(gb, t));
            let cr = bilinear(ex, ga.lerp(gb, t) + r);
            seam += rms(cf, cg);
            random += rms(cf, cr);
        }
    }
    let n = (seams * SEAM_SAMPLES).max(1) as f64;
    let (seam_rms, random_rms) = (seam / n, random / n);
    SeamScore {
        ratio: if random_rms > 0.0 {
            seam_rms / random_rms
        } else {
            0.0
        },
        seam_rms,
        random_rms,
        seam_edges: seams,
        interior_edges: pairs.len(),
    }
}

/// How visible the walk's jumps are on the blended surface; see the module doc.
#[derive(Clone, Debug, serde::Serialize)]
pub struct BlendedSeamScore {
    /// The surface's colour difference across jump edges over the exemplar's across the same
    /// offsets (1 = the seams are as smooth as the texture itself).
    pub ratio: f64,
    /// Mean RMS colour difference of the blended surface between a jump edge's ends.
    pub surface_rms: f64,
    /// The same in the exemplar, from the first end's address along the edge's offset.
    pub exemplar_rms: f64,
    /// Triangle edges across which the walk jumped (each counted once per triangle).
    pub jump_edges: usize,
}

/// The blended seam score: over every triangle edge the walk jumped across
/// ([`jumped`]), the colour `shade` gives its two corners, against the exemplar read at the
/// first end's address and at that address plus the edge's offset.
pub fn blended_seam_score(
    triangles: &[[u32; 3]],
    param: &ParamParts,
    addresses: &[Vec2],
    shade: impl Fn(usize, Vec3) -> [f32; 4],
    ex: ImageView,
) -> BlendedSeamScore {
    let rgb = |c: [f32; 4]| [c[0], c[1], c[2]];
    let corner = |k: usize| Vec3::from_array(std::array::from_fn(|i| (i == k) as u32 as f32));
    let (mut surface, mut exemplar, mut n) = (0.0f64, 0.0f64, 0usize);
    for (f, t) in triangles.iter().enumerate() {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            let Some(o) = param.offset(a, b) else {
                continue;
            };
            let (pa, pb) = (addresses[a as usize], addresses[b as usize]);
            if !jumped(o, pa, pb) {
                continue;
            }
            surface += rms(rgb(shade(f, corner(k))), rgb(shade(f, corner((k + 1) % 3))));
            exemplar += rms(
                bilinear(ex, pa + Vec2::splat(0.5)),
                bilinear(ex, pa + o + Vec2::splat(0.5)),
            );
            n += 1;
        }
    }
    let (surface_rms, exemplar_rms) = (surface / n.max(1) as f64, exemplar / n.max(1) as f64);
    BlendedSeamScore {
        ratio: if exemplar_rms > 0.0 {
            surface_rms / exemplar_rms
        } else {
            0.0
        },
        surface_rms,
        exemplar_rms,
        jump_edges: n,
    }
}

fn rms(a: [f32; 3], b: [f32; 3]) -> f64 {
    let s: f64 = (0..3).map(|c| ((a[c] - b[c]) as f64).powi(2)).sum();
    (s / 3.0).sqrt()
}

/// RGB at texel coordinates `p` (texel centres at half-integers), clamped to the border and
/// to [0, 1].
pub fn bilinear(img: ImageView, p: Vec2) -> [f32; 3] {
    let q = p - Vec2::splat(0.5);
    let (x0, y0) = (q.x.floor(), q.y.floor());
    let (fx, fy) = (q.x - x0, q.y - y0);
    let (x0, y0) = (x0 as i64, y0 as i64);
    let at = |x: i64, y: i64| img.get_clamped(x, y);
    let mut out = [0.0f32; 3];
    let (p00, p10, p01, p11) = (
        at(x0, y0),
        at(x0 + 1, y0),
        at(x0, y0 + 1),
        at(x0 + 1, y0 + 1),
    );
    for c in 0..3 {
        let top = p00[c] + (p10[c] - p00[c]) * fx;
        let bottom = p01[c] + (p11[c] - p01[c]) * fx;
        out[c] = (top + (bottom - top) * fy).clamp(0.0, 1.0);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two triangles of a unit square in texel units, scaled by `s`, the second moved by
    /// `second_offset`.
    fn square(s: f32, second_offset: Vec2) -> (Vec<[u32; 3]>, Vec<[Vec2; 3]>) {
        let p = |x: f32, y: f32| Vec2::new(x, y) * s + Vec2::splat(4.0);
        (
            vec![[0, 1, 2], [0, 2, 3]],
            vec![
                [p(0.0, 0.0), p(1.0, 0.0), p(1.0, 1.0)],
                [
                    p(0.0, 0.0) + second_offset,
                    p(1.0, 1.0) + second_offset,
                    p(0.0, 1.0) + second_offset,
                ],
            ],
        )
    }

    /// Stripes with seeded noise, so that no two patches are equal.
    fn stripes() -> Image {
        Image::from_fn(128, 128, |x, y| {
            let v = ((x * 7 + y * 3) % 11) as f32 / 10.0;
            let e = 0.2 * counter_unit(5, 0, (y * 128 + x) as u64);
            [0.8 * v + e, 1.0 - v, (y % 5) as f32 / 4.0, 1.0]
        })
    }

    #[test]
    fn continuous_coordinates_have_no_seam_and_jumps_do() {
        let ex = stripes();
        let (tris, coords) = square(20.0, Vec2::ZERO);
        let s = seam_score(&tris, &coords, ex.view(), 0);
        assert_eq!((s.seam_edges, s.interior_edges), (0, 1), "{s:?}");
        let (tris, coords) = square(20.0, Vec2::new(13.0, 5.0));
        let s = seam_score(&tris, &coords, ex.view(), 0);
        assert_eq!(s.seam_edges, 1, "{s:?}");
        assert!(s.seam_rms > 0.05 && s.ratio > 0.3, "{s:?}");
    }

    /// A `w` × `h` grid whose edge offsets are `place(to) − place(from)`, plus
    /// `extra(from, to)`, unfolded from `seed`'s discs; each texel coloured by the grid point
    /// it shows.
    fn grid_discs(
        w: u32,
        h: u32,
        place: impl Fn(u32, u32) -> Vec2,
        extra: impl Fn((u32, u32), (u32, u32)) -> Vec2,
    ) -> Charts {
        grid_discs_coloured(w, h, place, extra, 4, |grid, _| [grid.x, grid.y, 0.0, 1.0])
    }

    /// [`grid_discs`] with the seed and the colour, `colour(grid point, placed point)`, given.
    fn grid_discs_coloured(
        w: u32,
        h: u32,
        place: impl Fn(u32, u32) -> Vec2,
        extra: impl Fn((u32, u32), (u32, u32)) -> Vec2,
        seed: u64,
        colour: impl Fn(Vec2, Vec2) -> [f32; 4],
    ) -> Charts {
        let idx = |i: u32, j: u32| j * w + i;
        let ij = |v: u32| (v % w, v / w);
        let mut tris = Vec::new();
        for j in 0..h - 1 {
            for i in 0..w - 1 {
                tris.push([idx(i, j), idx(i + 1, j), idx(i + 1, j + 1)]);
                tris.push([idx(i, j), idx(i + 1, j + 1), idx(i, j + 1)]);
            }
        }
        let adjacency = crate::geom::VertexAdjacency::build((w * h) as usize, &tris);
        let offs: Vec<Vec2> = (0..(w * h) as usize)
            .flat_map(|v| {
                let a = ij(v as u32);
                let (place, extra) = (&place, &extra);
                (adjacency.neighbors(v).iter()).map(move |&n| {
                    let b = ij(n);
                    place(b.0, b.1) - place(a.0, a.1) + extra(a, b)
                })
            })
            .collect();
        let (adj, neighbors) = (&adjacency.offsets, &adjacency.neighbors);
        let offsets = EdgeOffsets {
            adj_offsets: adj,
            neighbors,
            edge_offsets: &offs,
        };
        let at = |t: [Vec2; 3], b: Vec3| t[0] * b.x + t[1] * b.y + t[2] * b.z;
        unfolded_discs(&tris, &offsets, seed, |f, bary| {
            let grid = tris[f].map(|v| Vec2::new(ij(v).0 as f32, ij(v).1 as f32));
            let placed = tris[f].map(|v| place(ij(v).0, ij(v).1));
            colour(at(grid, bary), at(placed, bary))
        })
    }

    /// The grid points the mask keeps, per texel: (texel, point).
    fn kept(c: &Charts) -> Vec<((usize, usize), Vec2)> {
        let w = c.image.width as usize;
        (0..c.mask.len())
            .filter(|&k| c.mask[k])
            .map(|k| {
                let [x, y, _, _] = c.image.pixels[k];
                ((k % w, k / w), Vec2::new(x, y))
            })
            .collect()
    }

    /// A strip folded back over itself at column 20 (columns 21–27 unfold onto 19–13, turned
    /// over): neither layer of the doubled part is the surface laid out once, so no texel of
    /// it is kept (a ring of triangles either side of the fold aside), while the single part
    /// is.
    #[test]
    fn a_disc_folded_over_itself_keeps_only_its_single_layer() {
        let fold = |i: u32, j: u32| {
            let x = if i <= 20 { i as f32 } else { 40.0 - i as f32 };
            Vec2::new(x, j as f32)
        };
        let c = grid_discs(28, 10, fold, |_, _| Vec2::ZERO);
        let points = kept(&c);
        // Of the strip's 27 columns, the 7 folded back and the 7 under them are cut out.
        assert!((0.3..0.7).contains(&c.cut_share), "{}", c.cut_share);
        let single = points.iter().filter(|(_, p)| p.x < 12.0).count();
        assert!(
            single > DISCS * 10 * 8,
            "{single} texels of the single part"
        );
        // Within a ring of the fold the two layers may overlap by the walk's error.
        for &(texel, p) in &points {
            let doubled = (13.5..19.0).contains(&p.x) || p.x > 22.0;
            assert!(!doubled, "texel {texel:?} shows {p}, in the doubled part");
        }
    }

    /// A grid whose offsets do not close: an edge crossing column 15.5 in rows 15 and up
    /// moves 6 texels down (a walk around the slit's end does not), as a field turning
    /// around a singular point makes walks disagree. The slit is a seam its edges declare;
    /// past its end, triangles the walks reach from both sides tear open, stretched 6×.
    /// What is kept shows the grid at its own scale on either side of the slit: a step of
    /// about one grid unit per texel.
    #[test]
    fn a_disc_torn_open_keeps_only_the_surface_at_its_scale() {
        let slit = |a: (u32, u32), b: (u32, u32)| {
            let crosses = a.1.min(b.1) >= 15 && (a.0 <= 15) != (b.0 <= 15);
            match (crosses, b.0 > a.0) {
                (false, _) => Vec2::ZERO,
                (true, true) => Vec2::new(0.0, 6.0),
                (true, false) => Vec2::new(0.0, -6.0),
            }
        };
        let grid = |i: u32, j: u32| Vec2::new(i as f32, j as f32);
        let c = grid_discs(32, 32, grid, slit);
        let points: HashMap<(usize, usize), Vec2> = kept(&c).into_iter().collect();
        let mut checked = 0;
        for (&(x, y), &p) in &points {
            for (dx, dy) in [(1, 0), (0, 1)] {
                let Some(&q) = points.get(&(x + dx, y + dy)) else {
                    continue;
                };
                if (p.x > 15.5) != (q.x > 15.5) {
                    continue; // across the slit, whose edges say so
                }
                let step = (q - p).length();
                assert!(
                    (0.5..1.5).contains(&step),
                    "({x}, {y}) shows {p}, its neighbour {q}"
                );
                checked += 1;
            }
        }
        assert!(checked > DISCS * 1000, "{checked}");
    }

    /// A planar grid whose parameterization is the identity (offsets = the edges in
    /// texels): every disc is the exemplar itself, so its patches are verbatim.
    #[test]
    fn unfolded_discs_of_a_continuous_parameterization_are_verbatim() {
        let ex = stripes();
        // Vertices at texel centres (half-integers), so the discs' texels land on them.
        let pos = |i: u32, j: u32| Vec2::new(i as f32, j as f32) * 3.0 + Vec2::splat(2.5);
        let c = grid_discs_coloured(
            40,
            40,
            pos,
            |_, _| Vec2::ZERO,
            1,
            |_, p| {
                let [r, g, b] = bilinear(ex.view(), p);
                [r, g, b, 1.0]
            },
        );
        assert_eq!((c.discs, c.cut_share), (DISCS, 0.0));
        let covered = c.mask.iter().filter(|&&m| m).count();
        assert!(covered > DISCS * DISC_RADIUS * DISC_RADIUS, "{covered}");
        let s = crate::image::patch_score::patch_score_masked(
            c.image.view(),
            Some(&c.mask),
            ex.view(),
            &crate::image::patch_score::ScoreParams::default(),
        )
        .unwrap();
        assert!(s.mean_rms < 1e-3 && s.queries > 1000, "{s:?}");
    }

    /// The floor's layout: each disc reads one place of the exemplar plus the pixel's offset
    /// from the disc's centre (so neighbouring pixels read one texel apart, unturned), the
    /// place far enough inside for the disc and a bicubic read's reach, and another place
    /// for another disc; an exemplar smaller than that gets no floor.
    #[test]
    fn a_verbatim_disc_reads_one_place_of_the_exemplar_plus_its_offset() {
        let tile = 2 * DISC_RADIUS + 1;
        let (w, h) = (2 * (tile + 1), 2 * (tile + 1));
        let r = DISC_RADIUS as f32;
        let centre_of = |x: usize, y: usize| disc_centre((y / (tile + 1)) * 2 + x / (tile + 1), 2);
        let local =
            |x: usize, y: usize| Vec2::new(x as f32 + 0.5, y as f32 + 0.5) - centre_of(x, y);
        let mask: Vec<bool> = (0..w * h)
            .map(|i| local(i % w, i / w).length() <= r)
            .collect();
        let charts = Charts {
            image: Image::new(w as u32, h as u32),
            mask,
            discs: 4,
            cut_share: 0.0,
        };
        let size = (120u32, 90u32);
        let floor = verbatim_discs(&charts, size, 7, |at| [at.x, at.y, 0.0, 1.0]).unwrap();
        let mut places: Vec<Vec2> = Vec::new();
        for (i, px) in floor.pixels.iter().enumerate() {
            let (x, y) = (i % w, i / w);
            if !charts.mask[i] {
                assert_eq!(px[0], 0.0, "({x}, {y}) outside the mask was filled");
                continue;
            }
            let place = Vec2::new(px[0], px[1]) - local(x, y);
            let k = (y / (tile + 1)) * 2 + x / (tile + 1);
            if places.len() <= k {
                places.resize(k + 1, Vec2::NAN);
            }
            if places[k].is_nan() {
                places[k] = place;
            }
            assert!(
                place.distance(places[k]) < 1e-3,
                "disc {k}: {place} and {}",
                places[k]
            );
            let lo = r + 2.0;
            assert!(
                place.x >= lo
                    && place.y >= lo
                    && place.x <= size.0 as f32 - 1.0 - lo
                    && place.y <= size.1 as f32 - 1.0 - lo,
                "disc {k} at {place} reaches past the exemplar"
            );
        }
        assert_eq!(places.len(), 4);
        assert!(places[0].distance(places[1]) > 1.0, "{places:?}");
        let small = (VERBATIM_SIDE - 1, 200);
        assert!(verbatim_discs(&charts, small, 7, |_| [0.0; 4]).is_none());
        assert!(verbatim_discs(&charts, (VERBATIM_SIDE, VERBATIM_SIDE), 7, |_| [0.0; 4]).is_some());
    }
}

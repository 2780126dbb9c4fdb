//! Region matching on a √2 hierarchy with graph-cut transfer (Bangay & Morkel, "Graph Matching
//! with Subdivision Surfaces for Texture Synthesis on Surfaces", AFRIGRAPH 2006, §3.3–3.4 and
//! Algorithm 1; the passes of §4).
//!
//! Colours live on vertices. Level by level, coarse to fine, every vertex `P` is visited (sweep
//! order on level 0, seeded random order after, §3.1.2); its *k-region* (the vertices within `k`
//! edges) is laid into texture space, the texel `Q` whose neighbourhood best matches the
//! region's colours is found, and the texel colours are copied into the region through a graph
//! cut. A vertex new at a level starts with the mean colour of the face it was made from, so the
//! coarse pattern guides the finer levels.
//!
//! - Texture-space offsets (§3.3.1): a neighbour's offset is its edge projected onto `P`'s
//!   tangent frame (`t` = the field's direction = texture "up", `b = t × n` = texture "right";
//!   image rows go down, so up is `−y`); a farther vertex's offset is its predecessor's plus
//!   the last edge projected into the predecessor's frame, "averaged over all such (shortest)
//!   paths" (weighted by how many shortest paths pass through each predecessor, which is that
//!   average exactly). Choice: a projected edge keeps its 3D length (curved regions unroll
//!   instead of shrinking). Offsets are in level-0 texels: `scale` × object units.
//! - Metric: the sum of *squared* colour differences, as the text says (Algorithm 1 prints an
//!   unsquared norm; we follow the text). Only coloured vertices count; `P` itself counts when
//!   it has a colour (every level after the first).
//! - Region size (§3.3.2): `k` solves `(k+1)² + k² = (aᵐ n / (scale · ē))²`, where the paper's
//!   `r_scale` alone lacks the edge length: `scale · ē` (texels per edge) is what turns the
//!   region's side `aᵐ n` (texels of stack level `m`) into a count of edges. `k` is rounded and
//!   kept in `1..=max_k` (with `k = 0` the region would be `P` alone and there is nothing to match).
//!   A region that `max_k` cuts short covers fewer than `n` texels: such vertices are counted
//!   per mesh level and named in a warning with the `max_k` that keeps them whole.
//!   Departure: `aᵐ` is `2ᵐ` for stacks too. A stack's level `m` holds features of `2ᵐ`
//!   texels, as a pyramid's does; with the paper's `a = 1` a coarse level's region would be as
//!   small in texels as a fine one's (one ring, a few texels wide), and the coarse levels could
//!   not lay out structure larger than `n` texels (the courses of a brick wall).
//! - Oversampling (§3.3.3): region vertices that land on one texel of their level are compared
//!   once, by their mean colour, weighted by their count (the constant `C` dropped).
//! - Anti-aliasing (§3.3.4): each vertex is copied from stack level `round(log2(scale · ē_v))`
//!   (clamped to the stack), and a colour is compared with the stack level it was copied from
//!   (the same level, for colours of this mesh level). Departure: a colour carried over from a
//!   coarser level (the vertex's own, or the mean given to a new vertex) is compared with that
//!   coarser level, not with the finer level its vertex now reads: comparing blurred colours
//!   with sharp texels picks the flattest texels and blurs the result (the gradient energy of
//!   a flat-grid synthesis fell to 0.15–0.37 of the exemplar's that way). Without
//!   anti-aliasing, a whole mesh level copies from the stack level of its mean edge.
//! - Search: `exact` is Algorithm 1, every texel `Q` at which the region's coloured vertices
//!   fall inside the exemplar (all texels, with clamped reads, when they span more than the
//!   exemplar); uncoloured vertices copied to read clamped texels.
//!   `coherent` (the default) evaluates the same metric at a few candidates only, in the manner
//!   of Ashikhmin (2001): for each coloured region vertex the `Q` that would continue its own
//!   source address, `P`'s own source, and `random_candidates` seeded random texels.
//! - Transfer (§3.4): graph cut over the region. `P` is tied to the texture terminal, coloured
//!   vertices on the region's border (ring `k`) to the surface terminal, both with infinite
//!   weight; region edges weigh `M(A,B)·exp(−(x_A² + x_B²)/(σ r²))` (eq. 1) with
//!   `M = |Cs(A) − Ct(A)| + |Cs(B) − Ct(B)|` (Euclidean RGB norms), `x` the texel distance from
//!   `P`, and `r` the region's diameter in texels (twice its largest offset). Where the mesh
//!   ends before ring `k` (a piece smaller than the region), its outermost ring is the border. Vertices on the
//!   texture side take the texel colours, uncoloured region vertices always do (they have
//!   nothing to keep), and every vertex coloured this way is not matched again in the same pass
//!   (the speed-up the paper reports). `transfer = "vertex"` copies to `P` alone.
//! - Passes (§4): `first_level_passes` on level 0 (default 2: the two-pass fill, "first fills in
//!   missing values, then refines"), `passes` on every later level.
//!
//! Deterministic: vertices are visited one after the other; only the exact search's texel scan
//! runs in parallel, reduced by (cost, texel index).

use crate::analyse_exemplar::gaussian_stack::GaussianStackRef;
use crate::check::{ParamError, check_range};
use crate::field::sweep_field::{SweepField, sweep_order};
use crate::parameterize::sqrt2_subdivision::Sqrt2Hierarchy;
use crate::random::counter_hash;
use glam::{Vec2, Vec3};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use texsyn_core::algorithm::Failure;
use texsyn_core::math::PureMath;
use texsyn_core::max_flow::MaxFlow;

/// The `graph_matching` node's algorithm and version (part of its key; bump on any change of output).
pub const NODE: texsyn_core::algorithm::Algorithm =
    texsyn_core::algorithm::Algorithm::new("graph_matching", 5);

/// How the best texel is searched.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Search {
    /// Algorithm 1: every texel.
    Exact,
    /// Coherent candidates plus random ones (see the module doc).
    #[default]
    Coherent,
}

/// How a match is copied to the surface.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Transfer {
    /// §3.4: a graph cut over the region.
    #[default]
    GraphCut,
    /// The matched vertex alone.
    Vertex,
}

/// `[synthesize]` of the graph-matching method.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MatchParams {
    /// Region size `n`: the side, in texels of the matched stack level, of the texture square
    /// a region covers (Table 1 uses 3), 1..=64. Default: 3.
    pub region: u32,
    /// σ of the cut weights (eq. 1), 0.001..=100. The paper gives no value. Default: 0.05:
    /// weights fall to e⁻¹⁰ at the region's border, so where the colours agree the cut reaches
    /// it and the whole interior is copied; with σ = 1 they only fall to e⁻⁰·⁵ and the cut
    /// hugs the matched vertex (configs/graph_matching.toml: 1.4 vertices copied per match
    /// against 6.0, and 2.9 times the matches).
    pub sigma: f32,
    /// Passes on every level after the first, 1..=16. Default: 1.
    pub passes: u32,
    /// Passes on level 0, 1..=16. Default: 2 (fill, then refine).
    pub first_level_passes: u32,
    pub seed: u64,
    /// `"coherent"` (default) or `"exact"`.
    pub search: Search,
    /// Random candidates per match in coherent search, 0..=1024. Default: 2 (more make the
    /// result noisier: each lets a vertex leave its neighbours' patch).
    pub random_candidates: u32,
    /// `"graph_cut"` (default) or `"vertex"`.
    pub transfer: Transfer,
    /// Largest region radius `k` in edges, 1..=32. Default: 8.
    pub max_k: u32,
    /// Compare vertices that share a texel once, by their mean (§3.3.3). Default: true.
    pub oversampling: bool,
    /// Per-vertex stack level from the vertex's edge length (§3.3.4). Default: true.
    pub anti_aliasing: bool,
}

impl Default for MatchParams {
    fn default() -> Self {
        MatchParams {
            region: 3,
            sigma: 0.05,
            passes: 1,
            first_level_passes: 2,
            seed: 1,
            search: Search::Coherent,
            random_candidates: 2,
            transfer: Transfer::GraphCut,
            max_k: 8,
            oversampling: true,
            anti_aliasing: true,
        }
    }
}

/// The largest `synthesize.max_k` accepted.
const MAX_K: u32 = 32;

/// A vertex's region radius `k` in edges (§3.3.2): the `k` that solves
/// `(k+1)² + k² = side²`, rounded, and kept in `1..=max_k`.
#[derive(Clone, Copy, Debug, PartialEq)]
struct RegionRadius {
    /// The radius used.
    k: u8,
    /// The rounded radius the region's side asks for, before `max_k` (at least 1).
    wanted: u32,
}

impl RegionRadius {
    /// `side`: the region's side in edges.
    fn of(side: f32, max_k: u32) -> RegionRadius {
        let rhs = side * side;
        let kf = ((2.0 * rhs - 1.0).max(0.0).sqrt() - 1.0) / 2.0;
        let wanted = kf.round().clamp(1.0, 1.0e6) as u32;
        RegionRadius {
            k: wanted.min(max_k) as u8,
            wanted,
        }
    }

    /// Whether `max_k` made the region smaller than its side asks.
    fn capped(&self) -> bool {
        self.wanted > self.k as u32
    }
}

/// The vertices of one mesh level whose region `max_k` cut short.
#[derive(Default)]
struct CappedRegions {
    count: usize,
    /// The largest radius any of them wanted.
    widest: u32,
}

impl MatchParams {
    pub fn validate(&self) -> Result<(), ParamError> {
        check_range("synthesize.region", self.region, 1, 64)?;
        check_range("synthesize.sigma", self.sigma, 0.001, 100.0)?;
        check_range("synthesize.passes", self.passes, 1, 16)?;
        check_range(
            "synthesize.first_level_passes",
            self.first_level_passes,
            1,
            16,
        )?;
        check_range(
            "synthesize.random_candidates",
            self.random_candidates,
            0,
            1024,
        )?;
        check_range("synthesize.max_k", self.max_k, 1, MAX_K)
    }
}

/// Why synthesis cannot start.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum MatchError {
    #[error(
        "synthesize.region = {region} texels does not fit the {width}×{height} exemplar: use at most {max}, or a larger exemplar"
    )]
    RegionTooLarge {
        region: u32,
        width: u32,
        height: u32,
        max: u32,
    },
}

/// What the synthesis did, for the run log and the benchmarks (Table 1's columns).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct MatchStats {
    /// Regions matched.
    pub matches: u64,
    /// Region entries compared per candidate texel, summed over matches: with oversampling,
    /// one per occupied texel; without, one per coloured vertex (Table 1's "vertex
    /// comparisons").
    pub comparisons: u64,
    /// The same count had every coloured vertex been compared on its own.
    pub comparisons_without_averaging: u64,
    /// Vertices coloured by transfers (a vertex coloured twice counts twice).
    pub transferred: u64,
    /// Matches with no coloured vertex to compare (a random texel was taken).
    pub random_starts: u64,
}

/// The result: colours of the finest level, every level's colours (for the previews of the
/// texture growing) and where each vertex's colour came from.
#[derive(Clone, Debug, PartialEq)]
pub struct GraphMatching {
    /// One RGB colour per vertex of the finest level.
    pub colours: Vec<[f32; 3]>,
    /// Level `l`'s colours (its vertices, ids `< level_vertices[l]`), levels concatenated.
    pub level_colours: Vec<[f32; 3]>,
    /// The exemplar address (finest texels, between texels: the match plus the vertex's
    /// offset, clamped to the exemplar) each vertex's colour was read at; NaN for colours only
    /// interpolated from a coarser level.
    pub sources: Vec<[f32; 2]>,
    pub stats: MatchStats,
}

/// What synthesis reads.
pub struct MatchInput<'a> {
    pub hierarchy: &'a Sqrt2Hierarchy,
    pub field: &'a SweepField,
    pub stack: GaussianStackRef<'a>,
    /// Level-0 texels per object unit.
    pub scale: f32,
}

/// Checks what can be checked before synthesis starts.
pub fn check_region(stack: GaussianStackRef, p: &MatchParams) -> Result<(), MatchError> {
    let (w, h) = stack.size();
    let max = w.min(h) / 2;
    if p.region > max {
        return Err(MatchError::RegionTooLarge {
            region: p.region,
            width: w,
            height: h,
            max,
        });
    }
    Ok(())
}

const NO_SOURCE: [f32; 2] = [f32::NAN, f32::NAN];

/// Synthesizes vertex colours over the hierarchy (see the module doc).
pub fn graph_matching(
    input: &MatchInput,
    p: &MatchParams,
    progress: &dyn Fn(f32),
) -> Result<GraphMatching, MatchError> {
    check_region(input.stack, p)?;
    let h = input.hierarchy;
    let finest = *h.level_vertices.last().expect("a level") as usize;
    let mut state = State {
        colours: vec![[0.0; 3]; finest],
        coloured: vec![false; finest],
        colour_level: vec![0; finest],
        sources: vec![NO_SOURCE; finest],
        stats: MatchStats::default(),
    };
    let mut level_colours = Vec::new();
    let total: f64 = h.level_vertices.iter().map(|&v| v as f64).sum();
    let mut done_work = 0.0;
    let mut region = RegionBuilder::new(finest);
    let mut flow = MaxFlow::new();
    for l in 0..h.levels() {
        let nv = h.level_vertices[l] as usize;
        if l > 0 {
            state.interpolate_new(h, h.level_vertices[l - 1] as usize..nv);
        }
        let level = Level::new(input, l, p);
        let order: Vec<u32> = if l == 0 {
            sweep_order(&level.mesh, &input.field.sweep)
        } else {
            let mut o: Vec<u32> = (0..nv as u32)
                .filter(|&v| !level.adj.of(v as usize).is_empty())
                .collect();
            o.sort_by_key(|&v| (counter_hash(p.seed, 1 + l as u64, v as u64), v));
            o
        };
        let passes = if l == 0 {
            p.first_level_passes
        } else {
            p.passes
        };
        for pass in 0..passes {
            let mut done = vec![false; nv];
            for (i, &pv) in order.iter().enumerate() {
                if done[pv as usize] {
                    continue;
                }
                let stream = ((l as u64) << 40) | ((pass as u64) << 32);
                let ctx = MatchCtx {
                    level: &level,
                    p,
                    stream,
                };
                region.build(&ctx, &state, pv);
                let q = ctx.search(&region, &mut state, i as u64);
                ctx.transfer(&region, &mut state, &mut flow, q, &mut done);
                if i % 256 == 0 {
                    progress(
                        ((done_work + nv as f64 * (i as f64 / order.len() as f64)) / total) as f32,
                    );
                }
            }
        }
        done_work += nv as f64;
        level_colours.extend_from_slice(&state.colours[..nv]);
    }
    progress(1.0);
    Ok(GraphMatching {
        colours: state.colours,
        level_colours,
        sources: state.sources,
        stats: state.stats,
    })
}

/// The colours as they are being synthesized.
struct State {
    colours: Vec<[f32; 3]>,
    coloured: Vec<bool>,
    /// The stack level each colour was taken from (for an interpolated colour, the coarsest
    /// of its parents'): the level it is compared with.
    colour_level: Vec<u8>,
    sources: Vec<[f32; 2]>,
    stats: MatchStats,
}

impl State {
    /// New vertices start at the mean colour of the coloured vertices of their parent face.
    fn interpolate_new(&mut self, h: &Sqrt2Hierarchy, new: std::ops::Range<usize>) {
        for v in new {
            let mut sum = [0.0f32; 3];
            let mut n = 0;
            let mut level = 0;
            for &u in h.parents(v) {
                if self.coloured[u as usize] {
                    level = level.max(self.colour_level[u as usize]);
                    let c = self.colours[u as usize];
                    for k in 0..3 {
                        sum[k] += c[k];
                    }
                    n += 1;
                }
            }
            if n > 0 {
                self.colours[v] = sum.map(|s| s / n as f32);
                self.coloured[v] = true;
                self.colour_level[v] = level;
            }
        }
    }
}

/// One level of the hierarchy, with what matching needs per vertex.
struct Level<'a> {
    mesh: crate::geom::poly_mesh::PolyMesh,
    adj: crate::geom::poly_mesh::Adjacency,
    /// Texture "up" and "right" per vertex.
    up: Vec<Vec3>,
    right: Vec<Vec3>,
    /// Stack level and region radius `k` per vertex.
    stack_level: Vec<u8>,
    k: Vec<u8>,
    stack: GaussianStackRef<'a>,
    level_start: Vec<usize>,
    scale: f32,
}

impl<'a> Level<'a> {
    fn new(input: &MatchInput<'a>, l: usize, p: &MatchParams) -> Self {
        let mesh = input.hierarchy.level(l);
        let adj = mesh.vertex_neighbours();
        let normals = mesh.vertex_normals();
        let ebar = mesh.mean_edge_lengths();
        let stack = input.stack;
        let top = stack.levels() as f32 - 1.0;
        let level_of = |e: f32| {
            (input.scale * e)
                .max(1e-9)
                .log2_pure()
                .round()
                .clamp(0.0, top) as u8
        };
        let mean_level = level_of(mesh.mean_edge_length());
        let n = mesh.vertex_count();
        let mut up = vec![Vec3::ZERO; n];
        let mut right = vec![Vec3::ZERO; n];
        let mut stack_level = vec![0u8; n];
        let mut k = vec![1u8; n];
        let mut capped = CappedRegions::default();
        for v in 0..n {
            (up[v], right[v]) = texture_frame(normals[v], input.field.orientation[v]);
            let m = if p.anti_aliasing {
                level_of(ebar[v])
            } else {
                mean_level
            };
            stack_level[v] = m;
            // (k+1)² + k² = rhs  ⇒  k = (√(2·rhs − 1) − 1) / 2
            // A region covers `n` texels of its level, `2^m` finest texels each (see the doc).
            let side = (1u32 << m) as f32 * p.region as f32 / (input.scale * ebar[v]).max(1e-9);
            let radius = RegionRadius::of(side, p.max_k);
            k[v] = radius.k;
            if radius.capped() {
                capped.count += 1;
                capped.widest = capped.widest.max(radius.wanted);
            }
        }
        if capped.count > 0 {
            let remedy = if capped.widest <= MAX_K {
                format!(
                    "max_k = {} keeps them whole (larger regions take longer to match)",
                    capped.widest
                )
            } else {
                format!(
                    "max_k is at most {MAX_K}, so a larger region or a finer mesh level keeps more of them"
                )
            };
            tracing::warn!(
                "synthesize: on mesh level {l}, {} of {n} vertices wanted a region radius above \
                 synthesize.max_k = {} (up to {} edges): their regions cover fewer than \
                 region = {} texels of their stack level; {remedy}",
                capped.count,
                p.max_k,
                capped.widest,
                p.region,
            );
        }
        let level_start = (0..stack.levels()).map(|m| stack.level_start(m)).collect();
        Level {
            mesh,
            adj,
            up,
            right,
            stack_level,
            k,
            stack,
            level_start,
            scale: input.scale,
        }
    }

    /// The texture-space offset (level-0 texels) of the edge `from → to`, in `from`'s frame,
    /// keeping the edge's length.
    fn step(&self, from: usize, to: usize) -> Vec2 {
        let d = self.mesh.positions[to] - self.mesh.positions[from];
        let proj = Vec2::new(d.dot(self.right[from]), -d.dot(self.up[from]));
        let len = proj.length();
        if len > 0.0 {
            proj * (d.length() / len * self.scale)
        } else {
            Vec2::ZERO
        }
    }

    /// The stack colour of level `m` at finest address `a` (clamped).
    fn texel_colour(&self, m: u8, a: Vec2) -> [f32; 3] {
        let m = m as usize;
        self.stack.texels[self.stack.texel(m, self.level_start[m], a.x, a.y)]
    }
}

/// A vertex's texture frame (§3.3.1): `up`, the field `o` projected on the tangent plane of
/// normal `nrm` (any tangent where it vanishes), and `right = up × n`.
pub fn texture_frame(nrm: Vec3, o: Vec3) -> (Vec3, Vec3) {
    let t = (o - o.dot(nrm) * nrm)
        .try_normalize()
        .unwrap_or_else(|| any_tangent(nrm));
    (t, t.cross(nrm))
}

/// Per vertex, the map from a surface offset `d` to the texel offset a patch is laid with:
/// `(d · right, −d · up) · scale` in [`texture_frame`], as [`Level::step`] reads an edge
/// (without its length correction).
pub fn texture_axes(normals: &[Vec3], field: &[Vec3], scale: f32) -> Vec<[Vec3; 2]> {
    normals
        .iter()
        .zip(field)
        .map(|(&nrm, &o)| {
            let (up, right) = texture_frame(nrm, o);
            [right * scale, -up * scale]
        })
        .collect()
}

fn any_tangent(n: Vec3) -> Vec3 {
    let a = if n.x.abs() < 0.9 { Vec3::X } else { Vec3::Y };
    (a - a.dot(n) * n).normalize_or_zero()
}

/// A vertex's k-region: its vertices (P first), ring, texture offset.
struct RegionBuilder {
    stamp: Vec<u32>,
    slot: Vec<u32>,
    epoch: u32,
    verts: Vec<u32>,
    ring: Vec<u8>,
    offset: Vec<Vec2>,
    paths: Vec<f64>,
    k: u8,
    groups: Vec<Group>,
}

/// Region vertices that share a texel of their stack level (or one vertex, without
/// oversampling): compared once, by their mean, weighted by their count.
#[derive(Clone, Copy, Debug)]
struct Group {
    level: u8,
    offset: Vec2,
    mean: [f32; 3],
    weight: f32,
}

impl RegionBuilder {
    fn new(n: usize) -> Self {
        RegionBuilder {
            stamp: vec![0; n],
            slot: vec![0; n],
            epoch: 0,
            verts: Vec::new(),
            ring: Vec::new(),
            offset: Vec::new(),
            paths: Vec::new(),
            k: 0,
            groups: Vec::new(),
        }
    }

    fn index_of(&self, v: u32) -> Option<usize> {
        (self.stamp[v as usize] == self.epoch).then(|| self.slot[v as usize] as usize)
    }

    fn build(&mut self, ctx: &MatchCtx, state: &State, p: u32) {
        let level = ctx.level;
        self.epoch = self.epoch.wrapping_add(1);
        if self.epoch == 0 {
            self.stamp.fill(0);
            self.epoch = 1;
        }
        self.verts.clear();
        self.ring.clear();
        self.offset.clear();
        self.paths.clear();
        self.k = level.k[p as usize];
        self.push(p, 0);
        self.paths[0] = 1.0;
        let mut sums: Vec<glam::DVec2> = vec![glam::DVec2::ZERO];
        let mut layer = 0..1;
        for ring in 1..=self.k {
            let next_start = self.verts.len();
            for i in layer.clone() {
                let v = self.verts[i];
                for &u in level.adj.of(v as usize) {
                    let j = match self.index_of(u) {
                        Some(j) => j,
                        None => {
                            self.push(u, ring);
                            sums.push(glam::DVec2::ZERO);
                            self.verts.len() - 1
                        }
                    };
                    if self.ring[j] == ring {
                        let w = self.paths[i];
                        let o = self.offset[i] + level.step(v as usize, u as usize);
                        sums[j] += o.as_dvec2() * w;
                        self.paths[j] += w;
                    }
                }
            }
            for j in next_start..self.verts.len() {
                self.offset[j] = (sums[j] / self.paths[j]).as_vec2();
            }
            layer = next_start..self.verts.len();
            if layer.is_empty() {
                break;
            }
        }
        self.group(ctx, state);
    }

    fn push(&mut self, v: u32, ring: u8) {
        self.stamp[v as usize] = self.epoch;
        self.slot[v as usize] = self.verts.len() as u32;
        self.verts.push(v);
        self.ring.push(ring);
        self.offset.push(Vec2::ZERO);
        self.paths.push(0.0);
    }

    /// The comparison groups of the coloured region vertices (§3.3.3).
    fn group(&mut self, ctx: &MatchCtx, state: &State) {
        let level = ctx.level;
        let mut entries: Vec<((u8, i32, i32), usize)> = Vec::with_capacity(self.verts.len());
        for (i, &v) in self.verts.iter().enumerate() {
            if !state.coloured[v as usize] {
                continue;
            }
            let m = state.colour_level[v as usize];
            let s = level.stack.spacing(m as usize) as f32;
            let key = if ctx.p.oversampling {
                let q = (self.offset[i] / s).round();
                (m, q.x as i32, q.y as i32)
            } else {
                (m, i as i32, 0)
            };
            entries.push((key, i));
        }
        entries.sort_unstable();
        self.groups.clear();
        let mut start = 0;
        while start < entries.len() {
            let key = entries[start].0;
            let mut end = start;
            let mut sum = [0.0f32; 3];
            while end < entries.len() && entries[end].0 == key {
                let c = state.colours[self.verts[entries[end].1] as usize];
                for k in 0..3 {
                    sum[k] += c[k];
                }
                end += 1;
            }
            let n = (end - start) as f32;
            let s = level.stack.spacing(key.0 as usize) as f32;
            let offset = if ctx.p.oversampling {
                Vec2::new(key.1 as f32, key.2 as f32) * s
            } else {
                self.offset[entries[start].1]
            };
            self.groups.push(Group {
                level: key.0,
                offset,
                mean: sum.map(|x| x / n),
                weight: n,
            });
            start = end;
        }
    }
}

/// One match: the level, the parameters and the random stream.
struct MatchCtx<'a, 'b> {
    level: &'b Level<'a>,
    p: &'b MatchParams,
    stream: u64,
}

impl MatchCtx<'_, '_> {
    /// The cost of texel `q` (finest address) for the region's groups, abandoned (returning
    /// something ≥ `bound`) once it passes `bound`.
    fn cost(&self, groups: &[Group], q: Vec2, bound: f32) -> f32 {
        let mut d = 0.0;
        for g in groups {
            let c = self.level.texel_colour(g.level, q + g.offset);
            let e = (c[0] - g.mean[0]).powi(2)
                + (c[1] - g.mean[1]).powi(2)
                + (c[2] - g.mean[2]).powi(2);
            d += g.weight * e;
            if d >= bound {
                return d;
            }
        }
        d
    }

    /// The range of finest texel addresses `q` that lie inside the exemplar and at which
    /// every compared group does too, or the whole exemplar (reads clamped) when the groups
    /// span more than the exemplar. Uncoloured vertices are left out: requiring them inside
    /// as well pushed coherent candidates off their neighbours' patches near the exemplar's
    /// edge (the flat-grid score went from 0.95 to 1.02); their reads are clamped instead.
    fn valid_range(&self, groups: &[Group]) -> (Vec2, Vec2) {
        let (w, h) = self.level.stack.size();
        let last = Vec2::new(w as f32 - 1.0, h as f32 - 1.0);
        let (mut lo, mut hi) = (Vec2::ZERO, Vec2::ZERO);
        for g in groups {
            lo = lo.min(g.offset);
            hi = hi.max(g.offset);
        }
        let (a, b) = ((-lo).ceil(), (last - hi).floor());
        if a.x > b.x || a.y > b.y {
            (Vec2::ZERO, last)
        } else {
            (a, b)
        }
    }

    /// The best texel for the region (finest address).
    fn search(&self, r: &RegionBuilder, state: &mut State, index: u64) -> Vec2 {
        state.stats.matches += 1;
        let coloured = r.groups.iter().map(|g| g.weight as u64).sum::<u64>();
        state.stats.comparisons += r.groups.len() as u64;
        state.stats.comparisons_without_averaging += coloured;
        let (lo, hi) = self.valid_range(&r.groups);
        let random = |j: u64| {
            let hsh = counter_hash(self.p.seed, self.stream | index, j);
            let x = lo.x + ((hsh & 0xffff_ffff) % ((hi.x - lo.x) as u64 + 1)) as f32;
            let y = lo.y + ((hsh >> 32) % ((hi.y - lo.y) as u64 + 1)) as f32;
            Vec2::new(x, y)
        };
        if r.groups.is_empty() {
            state.stats.random_starts += 1;
            return random(0);
        }
        match self.p.search {
            Search::Exact => self.exact(&r.groups, lo, hi),
            Search::Coherent => {
                let mut cands: Vec<Vec2> = Vec::with_capacity(r.verts.len() + 16);
                for (i, &v) in r.verts.iter().enumerate() {
                    let s = state.sources[v as usize];
                    if !s[0].is_nan() {
                        cands.push((Vec2::from(s) - r.offset[i]).round().clamp(lo, hi));
                    }
                }
                for j in 0..self.p.random_candidates as u64 {
                    cands.push(random(j));
                }
                let mut best = (f32::INFINITY, Vec2::ZERO);
                for q in cands {
                    let d = self.cost(&r.groups, q, best.0);
                    if d < best.0 {
                        best = (d, q);
                    }
                }
                best.1
            }
        }
    }

    /// Algorithm 1: every texel in `lo..=hi` (a stack level's spacing apart on a pyramid),
    /// the best by (cost, row, column) whatever the thread count.
    fn exact(&self, groups: &[Group], lo: Vec2, hi: Vec2) -> Vec2 {
        let step = self.level.stack.spacing(groups[0].level as usize).max(1) as usize;
        let (x0, x1, y0, y1) = (lo.x as i64, hi.x as i64, lo.y as i64, hi.y as i64);
        let rows: Vec<i64> = (y0..=y1).step_by(step).collect();
        let none = (f32::INFINITY, i64::MAX, i64::MAX);
        let best = rows
            .par_iter()
            .map(|&y| {
                let mut best = none;
                for x in (x0..=x1).step_by(step) {
                    let d = self.cost(groups, Vec2::new(x as f32, y as f32), best.0);
                    if d < best.0 {
                        best = (d, y, x);
                    }
                }
                best
            })
            .reduce(
                || none,
                |a, b| {
                    if (b.0, b.1, b.2) < (a.0, a.1, a.2) {
                        b
                    } else {
                        a
                    }
                },
            );
        if best.1 == i64::MAX {
            return lo;
        }
        Vec2::new(best.2 as f32, best.1 as f32)
    }

    /// Copies the texels at `q` into the region (§3.4).
    fn transfer(
        &self,
        r: &RegionBuilder,
        state: &mut State,
        flow: &mut MaxFlow,
        q: Vec2,
        done: &mut [bool],
    ) {
        let level = self.level;
        let texel: Vec<[f32; 3]> = r
            .verts
            .iter()
            .zip(&r.offset)
            .map(|(&v, &o)| level.texel_colour(level.stack_level[v as usize], q + o))
            .collect();
        let n = r.verts.len();
        let mut take = vec![false; n];
        take[0] = true;
        match self.p.transfer {
            Transfer::Vertex => {}
            Transfer::GraphCut => {
                flow.reset(n);
                flow.add_terminal(0, f64::INFINITY, 0.0);
                let mismatch: Vec<f32> = (0..n)
                    .map(|i| {
                        let v = r.verts[i] as usize;
                        if state.coloured[v] {
                            dist(state.colours[v], texel[i])
                        } else {
                            0.0
                        }
                    })
                    .collect();
                let radius = r.offset.iter().map(|o| o.length()).fold(0.5f32, f32::max);
                // The border is ring k, or the outermost ring there is when the mesh ends
                // before it (a small component): its colours are kept either way.
                let border = r.ring.iter().copied().max().unwrap_or(0);
                let diameter2 = (2.0 * radius).powi(2);
                for i in 0..n {
                    let v = r.verts[i];
                    if i > 0 && r.ring[i] == border && state.coloured[v as usize] {
                        flow.add_terminal(i, 0.0, f64::INFINITY);
                    }
                    for &u in level.adj.of(v as usize) {
                        if let Some(j) = r.index_of(u)
                            && j > i
                        {
                            let x2 = r.offset[i].length_squared() + r.offset[j].length_squared();
                            let w = (mismatch[i] + mismatch[j])
                                * (-x2 / (self.p.sigma * diameter2)).exp_pure();
                            flow.add_edge(i, j, w as f64, w as f64);
                        }
                    }
                }
                flow.solve();
                for i in 1..n {
                    take[i] = flow.is_source_side(i) || !state.coloured[r.verts[i] as usize];
                }
            }
        }
        for i in 0..n {
            if take[i] {
                let v = r.verts[i] as usize;
                state.colours[v] = texel[i];
                state.coloured[v] = true;
                state.colour_level[v] = level.stack_level[v];
                // The address read, kept between texels (the read takes its nearest texel of
                // the vertex's stack level, clamped to the exemplar): a bake interpolates these
                // inside one copied patch, and coherent search continues from them.
                let (w, h) = level.stack.size();
                let a = q + r.offset[i];
                state.sources[v] = [
                    a.x.clamp(0.0, w as f32 - 1.0),
                    a.y.clamp(0.0, h as f32 - 1.0),
                ];
                done[v] = true;
                state.stats.transferred += 1;
            }
        }
    }
}

fn dist(a: [f32; 3], b: [f32; 3]) -> f32 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

/// Whether an exemplar of `width × height` texels suits graph matching with `p`: the config
/// key at fault and what is wrong with it, read from the image header before any node runs.
pub fn check_exemplar_fits(
    (w, h): (u32, u32),
    path: &std::path::Path,
    p: &MatchParams,
) -> (&'static str, Result<(), String>) {
    let path = path.display();
    if w.min(h) < 8 {
        let m = format!("{path} is {w}×{h} texels; graph matching needs at least 8×8");
        return ("inputs.exemplar", Err(m));
    }
    let max = w.min(h) / 2;
    if p.region > max {
        let m = format!(
            "{} texels does not fit the {w}×{h} exemplar {path}: use at most {max}, or a larger exemplar",
            p.region
        );
        return ("synthesize.region", Err(m));
    }
    ("synthesize.region", Ok(()))
}

/// What the synthesize node reads besides its inputs: its own parameters and the texture
/// scale (level-0 texels per object unit).
#[derive(Debug, Clone, Serialize)]
pub struct MatchKey {
    pub scale: f32,
    pub matching: MatchParams,
}

/// The synthesize node: [`graph_matching`] over the hierarchy, logged.
pub fn node(
    hierarchy: &Sqrt2Hierarchy,
    field: &SweepField,
    stack: GaussianStackRef,
    key: &MatchKey,
    progress: &dyn Fn(f32),
) -> Result<GraphMatching, Failure> {
    if field.orientation.len() != hierarchy.positions.len()
        || field.sweep.len() != hierarchy.level_vertices[0] as usize
    {
        return Err(Failure::internal("the field and the hierarchy disagree"));
    }
    let input = MatchInput {
        hierarchy,
        field,
        stack,
        scale: key.scale,
    };
    let out = graph_matching(&input, &key.matching, progress).map_err(Failure::input)?;
    let s = &out.stats;
    tracing::info!(
        "synthesize: {} matches, {} comparisons ({} without averaging), {} vertices transferred, {} random starts",
        s.matches,
        s.comparisons,
        s.comparisons_without_averaging,
        s.transferred,
        s.random_starts
    );
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn region_radius_solves_the_region_equation_and_says_when_max_k_cuts_it() {
        // (k+1)² + k² = side²: side 5 gives k = 3 exactly (16 + 9 = 25), side √145 gives
        // k = 8 exactly (81 + 64 = 145).
        let r = RegionRadius::of(5.0, 8);
        assert_eq!((r.k, r.wanted, r.capped()), (3, 3, false));
        let r = RegionRadius::of(5.0, 2);
        assert_eq!((r.k, r.wanted, r.capped()), (2, 3, true));
        let r = RegionRadius::of(145f32.sqrt(), 8);
        assert_eq!((r.k, r.wanted, r.capped()), (8, 8, false));
        // A side under one edge still matches one ring.
        let r = RegionRadius::of(0.5, 8);
        assert_eq!((r.k, r.wanted, r.capped()), (1, 1, false));
    }
    use crate::analyse_exemplar::gaussian_stack::{GaussianStack, StackParams, build_stack};
    use crate::field::orientation_field::Anchor;
    use crate::field::sweep_field::{SweepFieldParams, resolve_keys, sweep_field};
    use crate::geom::Mesh;
    use crate::geom::primitives::grid;
    use crate::image::Image;
    use crate::image::patch_score::{ScoreParams, patch_score};
    use crate::parameterize::sqrt2_subdivision::{SubdivisionParams, build_hierarchy};
    use crate::random::counter_unit;

    /// A flat mesh, its hierarchy at `scale` and a field whose "up" is +y everywhere.
    fn flat(mesh: &Mesh, scale: f32) -> (Sqrt2Hierarchy, SweepField) {
        let h = build_hierarchy(mesh, scale, &SubdivisionParams::default()).unwrap();
        let p = SweepFieldParams {
            keys: vec![Anchor {
                vertex: Some(0),
                at: None,
                direction: [0.0, 1.0, 0.0],
            }],
            ..Default::default()
        };
        let keys = resolve_keys(mesh, &p).unwrap();
        let f = sweep_field(&h, &keys, &p).unwrap();
        (h, f)
    }

    fn noise(w: u32, h: u32, seed: u64) -> Image {
        Image::from_fn(w, h, |x, y| {
            let i = (y * w + x) as u64;
            [
                counter_unit(seed, 0, i),
                counter_unit(seed, 1, i),
                counter_unit(seed, 2, i),
                1.0,
            ]
        })
    }

    fn stack_of(img: &Image) -> GaussianStack {
        build_stack(img.view(), &StackParams::default()).unwrap()
    }

    #[test]
    fn exact_and_coherent_search_find_a_planted_match() {
        // About one texel per edge (the mean of sides and diagonals is 0.143): scale 7 on a
        // grid 1/8 apart is not subdivided.
        let mesh = grid(9, 0.125);
        let (h, field) = flat(&mesh, 7.0);
        assert_eq!(h.levels(), 1);
        let img = noise(32, 32, 7);
        let stack = stack_of(&img);
        let input = MatchInput {
            hierarchy: &h,
            field: &field,
            stack: stack.view(),
            scale: 7.0,
        };
        for search in [Search::Exact, Search::Coherent] {
            let p = MatchParams {
                search,
                ..Default::default()
            };
            let level = Level::new(&input, 0, &p);
            let centre = 40u32; // (0.5, 0.5)
            assert_eq!(level.k[centre as usize], 2);
            // Colour every vertex with the texel it has at the planted match: x right, y up
            // on the mesh is +x, −y in the image.
            let planted = Vec2::new(15.0, 12.0);
            let mut state = State {
                colours: vec![[0.0; 3]; 81],
                coloured: vec![true; 81],
                colour_level: vec![0; 81],
                sources: vec![NO_SOURCE; 81],
                stats: MatchStats::default(),
            };
            let at = |v: usize| {
                let d = mesh.positions[v] - mesh.positions[centre as usize];
                planted + Vec2::new(d.x, -d.y) * 7.0
            };
            for v in 0..81 {
                let a = at(v);
                state.colours[v] = stack.view().colour(0, a.x, a.y);
            }
            // Coherent search must find it from one neighbour's source.
            state.sources[31] = at(31).to_array();
            let ctx = MatchCtx {
                level: &level,
                p: &p,
                stream: 0,
            };
            let mut region = RegionBuilder::new(81);
            region.build(&ctx, &state, centre);
            // A triangle grid has 6 neighbours per vertex: 1 + 6 + 12 vertices within 2 edges
            // (a quad mesh's would be (k+1)² + k² = 13).
            assert_eq!(region.verts.len(), 19);
            // The frames a bake continues patches with map surface offsets the same way.
            let axes = texture_axes(&level.mesh.vertex_normals(), &field.orientation, 7.0);
            let [ax, ay] = axes[centre as usize];
            for (i, &v) in region.verts.iter().enumerate() {
                let want = at(v as usize) - planted;
                assert!(region.offset[i].distance(want) < 1e-3, "{search:?} {v}");
                let d = mesh.positions[v as usize] - mesh.positions[centre as usize];
                let o = Vec2::new(d.dot(ax), d.dot(ay));
                assert!(
                    o.distance(want) < 1e-3,
                    "texture_axes at {v}: {o} against {want}"
                );
            }
            let q = ctx.search(&region, &mut state, 0);
            assert_eq!(q, planted, "{search:?}");
            // The same with `P` and everything right of it uncoloured (level 0's first pass):
            // the search still ranges over texels where the whole region fits.
            for v in 0..81 {
                if mesh.positions[v].x >= mesh.positions[centre as usize].x {
                    state.coloured[v] = false;
                }
            }
            state.sources[31] = NO_SOURCE;
            state.sources[39] = at(39).to_array();
            region.build(&ctx, &state, centre);
            assert!(region.groups.iter().all(|g| g.offset.x < 0.0));
            let q = ctx.search(&region, &mut state, 1);
            assert_eq!(q, planted, "{search:?}, one-sided region");
        }
    }

    /// The synthesized colours of a flat unit square, read back as a `side`² image (nearest
    /// vertex per pixel, image up = +y).
    fn as_image(h: &Sqrt2Hierarchy, colours: &[[f32; 3]], side: u32) -> Image {
        Image::from_fn(side, side, |i, j| {
            let p = Vec3::new(
                (i as f32 + 0.5) / side as f32,
                1.0 - (j as f32 + 0.5) / side as f32,
                0.0,
            );
            let v = (0..colours.len())
                .min_by(|&a, &b| {
                    h.positions[a]
                        .distance_squared(p)
                        .total_cmp(&h.positions[b].distance_squared(p))
                })
                .unwrap();
            let c = colours[v];
            [c[0], c[1], c[2], 1.0]
        })
    }

    fn exemplar(name: &str) -> Image {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../tests/data/exemplars")
            .join(name);
        crate::image::decode_image(&path, &std::fs::read(&path).unwrap()).unwrap()
    }

    #[test]
    fn a_flat_grid_is_textured_like_the_exemplar_without_one_verbatim_copy() {
        let mesh = grid(17, 1.0 / 16.0);
        let (h, field) = flat(&mesh, 64.0);
        assert!(h.levels() >= 4);
        let img = exemplar("wood1.png");
        let stack = stack_of(&img);
        let input = MatchInput {
            hierarchy: &h,
            field: &field,
            stack: stack.view(),
            scale: 64.0,
        };
        let mut scores = Vec::new();
        for search in [Search::Coherent, Search::Exact] {
            let p = MatchParams {
                search,
                ..Default::default()
            };
            let out = graph_matching(&input, &p, &|_| {}).unwrap();
            let synth = as_image(&h, &out.colours, 64);
            let s = patch_score(synth.view(), img.view(), &ScoreParams::default()).unwrap();
            eprintln!("{search:?}: {s:?}");
            assert!(s.ratio <= 1.0, "{search:?}: {s:?}");
            assert!(s.largest_offset <= 0.5, "{search:?}: {s:?}");
            scores.push(s);
        }
        // The stated margin of the default (coherent) search against exact search: a
        // nearest-patch ratio at most 20% higher, and no blurrier (exact search matches the
        // blurred coarse colours best with the flattest texels; the ratio rewards that blur).
        let (coherent, exact) = (&scores[0], &scores[1]);
        assert!(coherent.ratio <= 1.2 * exact.ratio, "{scores:?}");
        assert!(
            coherent.gradient_ratio >= exact.gradient_ratio,
            "{scores:?}"
        );
    }

    #[test]
    fn regions_larger_than_the_exemplar_are_refused() {
        let img = noise(20, 30, 1);
        let stack = stack_of(&img);
        let p = MatchParams {
            region: 11,
            ..Default::default()
        };
        assert_eq!(
            check_region(stack.view(), &p),
            Err(MatchError::RegionTooLarge {
                region: 11,
                width: 20,
                height: 30,
                max: 10
            })
        );
    }
}

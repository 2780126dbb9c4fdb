//! The jump-map walk over a mesh (Zelinka & Garland, "Interactive Texture Synthesis on
//! Surfaces Using Jump Maps", §4.2): vertices are visited in the region-growing order, and
//! each gets a texel address chosen at random from what its synthesized neighbours suggest.
//!
//! - Floating-point look-ups (§4.2.3): a neighbour's address is fractional, so its jump list
//!   is the concatenation of the lists of the 4 surrounding pixels, weights scaled bilinearly
//!   and destinations shifted by the same sub-pixel offset.
//! - Probabilistically good matching (§4.2.5): the table of candidates is built from *all*
//!   synthesized neighbours: each contributes a continuation entry ("do not jump": its
//!   address plus the edge offset) with weight `continuation / |offset|`, decreased linearly
//!   to zero as its address nears the exemplar's border (boundary avoidance), and its
//!   jumps, offset the same way. Entries whose address is not valid for the vertex (§4.2.4:
//!   its validity box would leave the exemplar) are dropped; one random number picks from the
//!   rest. With no valid entry at all, a random valid address is assigned.
//!
//! Randomness is a counter-based hash of (seed, vertex index), so the result depends only on
//! the inputs, not on how they were scheduled.

use crate::analyse_exemplar::jump_map::JumpMapRef;
use crate::check::{ParamError, check_range};
use crate::parameterize::jump_parameterization::WalkInput;
use crate::random::counter_unit;
use glam::Vec2;
use texsyn_core::algorithm::Failure;

/// The `jump_walk` node's algorithm and version (part of its key; bump on any change of output).
pub const NODE: texsyn_core::algorithm::Algorithm =
    texsyn_core::algorithm::Algorithm::new("jump_walk", 2);

/// `[synthesize]` parameters of the jump walk.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct WalkParams {
    /// Seed of the counter-based random numbers. Default: 1.
    pub seed: u64,
    /// Weight of a continuation entry per texel of edge offset: about the mean run, in
    /// texels, between jumps (§4.2.5). Larger gives bigger patches (fewer seams); patches
    /// still end where they would leave the exemplar. Range 0.01..=10000. Default: 200.
    pub continuation: f32,
    /// Fraction of the exemplar's size within which a continuation's weight fades to zero
    /// towards the border (boundary avoidance, §4.2.1). Range 0..=0.5. Default: 0.1.
    pub boundary_fraction: f32,
}

impl Default for WalkParams {
    fn default() -> Self {
        WalkParams {
            seed: 1,
            continuation: 200.0,
            boundary_fraction: 0.1,
        }
    }
}

impl WalkParams {
    pub fn validate(&self) -> Result<(), ParamError> {
        check_range("synthesize.continuation", self.continuation, 0.01, 10000.0)?;
        check_range(
            "synthesize.boundary_fraction",
            self.boundary_fraction,
            0.0,
            0.5,
        )
    }
}

/// The walk's result: a texel address per vertex, and for each vertex the vertex where its
/// patch began (itself after a jump or a random assignment; the neighbour's patch after a
/// continuation), which shows the patch structure of §4.2 (Fig. 3, right).
#[derive(Debug, Clone, PartialEq)]
pub struct Walk {
    pub addresses: Vec<Vec2>,
    pub patches: Vec<u32>,
    pub jumps: u64,
    pub random_assignments: u64,
}

const STREAM_FALLBACK_X: u64 = 2;
const STREAM_FALLBACK_Y: u64 = 3;
const STREAM_EXACT: u64 = 4;
/// Rejection attempts use streams STREAM_CHOICE, STREAM_CHOICE + 1, ….
const STREAM_CHOICE: u64 = 16;

pub fn jump_walk(
    input: WalkInput,
    jm: JumpMapRef,
    params: &WalkParams,
    progress: &dyn Fn(f32),
) -> Walk {
    let n = input.boxes.len();
    let (w, h) = (jm.width, jm.height);
    let mut addresses = vec![Vec2::ZERO; n];
    let mut patches = vec![u32::MAX; n];
    let mut done = vec![false; n];
    let (mut jumps, mut random_assignments) = (0u64, 0u64);
    let inv_margin = if params.boundary_fraction > 0.0 {
        Vec2::new(w as f32, h as f32).recip() / params.boundary_fraction
    } else {
        Vec2::ZERO
    };
    let top = Vec2::new((w - 1) as f32, (h - 1) as f32);
    // Continuation weight fades to zero near the border.
    let border_factor = |a: Vec2| -> f32 {
        if params.boundary_fraction <= 0.0 {
            return 1.0;
        }
        let near = a.min(top - a) * inv_margin;
        near.x.clamp(0.0, 1.0).min(near.y.clamp(0.0, 1.0))
    };
    // Each pixel's total jump weight: an upper bound of what its jumps offer once invalid
    // destinations are dropped.
    let pixel_weight: Vec<f32> = (0..w * h)
        .map(|p| jm.jumps_at(p % w, p / w).iter().map(|j| j.weight).sum())
        .collect();
    let mut conts: Vec<(Vec2, f32, u32)> = Vec::with_capacity(32);
    let mut sources: Vec<JumpSource> = Vec::with_capacity(32);
    let mut table = Table::default();
    for (pos, &v) in input.order.iter().enumerate() {
        if pos % 65536 == 0 {
            progress(pos as f32 / input.order.len() as f32);
        }
        let vu = v as usize;
        let (lo, hi) = input.boxes[vu].valid_range(w, h);
        let valid = |a: Vec2| a.x >= lo.x && a.y >= lo.y && a.x <= hi.x && a.y <= hi.y;
        conts.clear();
        sources.clear();
        let (mut cont_total, mut jump_bound) = (0.0f32, 0.0f32);
        for e in input.adj_offsets[vu] as usize..input.adj_offsets[vu + 1] as usize {
            let nb = input.neighbors[e];
            if !done[nb as usize] {
                continue;
            }
            let a = addresses[nb as usize];
            let d = -input.edge_offsets[e]; // the offset from the neighbour to v
            let c = a + d;
            if valid(c) {
                let weight = params.continuation / d.length().max(0.5) * border_factor(a);
                if weight > 0.0 {
                    cont_total += weight;
                    conts.push((c, cont_total, nb));
                }
            }
            let src = JumpSource::new(a, d, w, h, &pixel_weight);
            jump_bound += src.bound;
            sources.push(src);
        }
        let chosen = draw(
            &conts,
            cont_total,
            &sources,
            jump_bound,
            jm,
            valid,
            &mut table,
            params.seed,
            v as u64,
        );
        match chosen {
            Some((a, Some(nb))) => {
                addresses[vu] = a;
                patches[vu] = patches[nb as usize];
            }
            Some((a, None)) => {
                addresses[vu] = a;
                patches[vu] = v;
                jumps += 1;
            }
            None => {
                // A seed, or no neighbour could offer a valid address.
                if !sources.is_empty() {
                    random_assignments += 1;
                }
                let ux = counter_unit(params.seed, STREAM_FALLBACK_X, v as u64);
                let uy = counter_unit(params.seed, STREAM_FALLBACK_Y, v as u64);
                let pick = |lo: f32, hi: f32, u: f32| {
                    if lo <= hi {
                        lo + u * (hi - lo)
                    } else {
                        0.5 * (lo + hi)
                    }
                };
                addresses[vu] = Vec2::new(pick(lo.x, hi.x, ux), pick(lo.y, hi.y, uy));
                patches[vu] = v;
            }
        }
        done[vu] = true;
    }
    progress(1.0);
    Walk {
        addresses,
        patches,
        jumps,
        random_assignments,
    }
}

const MAX_REJECTIONS: u64 = 8;

/// One weighted choice from the table of §4.2.5: continuations (all valid) and the jumps of
/// every source whose destination is valid. Returns the address and, for a continuation, the
/// neighbour it continues.
///
/// Draws from continuations plus *all* jumps, rejecting a jump whose destination is not
/// valid: an accepted draw has exactly the distribution of the filtered table, but the jump
/// entries (a few percent of the weight) are only enumerated when a draw lands on them. After
/// a few rejections in a row the filtered table is built outright (still exact: attempts are
/// independent, so the accepted one is distributed as the table whichever attempt it is).
#[allow(clippy::too_many_arguments)]
fn draw(
    conts: &[(Vec2, f32, u32)],
    cont_total: f32,
    sources: &[JumpSource],
    jump_bound: f32,
    jm: JumpMapRef,
    valid: impl Fn(Vec2) -> bool,
    table: &mut Table,
    seed: u64,
    index: u64,
) -> Option<(Vec2, Option<u32>)> {
    let total = cont_total + jump_bound;
    if total <= 0.0 {
        return None;
    }
    for attempt in 0..MAX_REJECTIONS {
        let r = counter_unit(seed, STREAM_CHOICE + attempt, index) * total;
        if r < cont_total {
            let k = conts.partition_point(|c| c.1 <= r).min(conts.len() - 1);
            return Some((conts[k].0, Some(conts[k].2)));
        }
        if let Some(target) = pick_jump(sources, r - cont_total, jm)
            && valid(target)
        {
            return Some((target, None));
        }
    }
    table.fill(conts, sources, jm, &valid);
    if table.total <= 0.0 {
        return None;
    }
    let r = counter_unit(seed, STREAM_EXACT, index) * table.total;
    let k = table
        .cumulative
        .partition_point(|&c| c <= r)
        .min(table.cumulative.len() - 1);
    Some(table.entries[k])
}

/// A synthesized neighbour's jump list at its fractional address (§4.2.3): the four
/// surrounding pixels with bilinear weights, destinations shifted by the sub-pixel offset and
/// the edge offset.
struct JumpSource {
    /// Pixel index and bilinear weight × the pixel's total jump weight, per corner.
    corners: [(u32, f32, f32); 4],
    /// Added to a jump's destination pixel: (address − corner pixel) + edge offset.
    shifts: [Vec2; 4],
    bound: f32,
}

impl JumpSource {
    #[inline]
    fn new(a: Vec2, d: Vec2, w: u32, h: u32, pixel_weight: &[f32]) -> Self {
        let base = a.floor();
        let t = a - base;
        let (bx, by) = (base.x as i64, base.y as i64);
        let mut corners = [(0u32, 0.0f32, 0.0f32); 4];
        let mut shifts = [Vec2::ZERO; 4];
        let mut bound = 0.0;
        for (k, (dx, dy, bw)) in [
            (0, 0, (1.0 - t.x) * (1.0 - t.y)),
            (1, 0, t.x * (1.0 - t.y)),
            (0, 1, (1.0 - t.x) * t.y),
            (1, 1, t.x * t.y),
        ]
        .into_iter()
        .enumerate()
        {
            let (px, py) = (bx + dx, by + dy);
            if bw <= 0.0 || px < 0 || py < 0 || px >= w as i64 || py >= h as i64 {
                continue;
            }
            let p = (py as u32) * w + px as u32;
            let mass = bw * pixel_weight[p as usize];
            corners[k] = (p, bw, mass);
            shifts[k] = a - Vec2::new(px as f32, py as f32) + d;
            bound += mass;
        }
        JumpSource {
            corners,
            shifts,
            bound,
        }
    }
}

/// The jump (valid or not) at position `r` of the concatenated jump lists.
#[inline]
fn pick_jump(sources: &[JumpSource], mut r: f32, jm: JumpMapRef) -> Option<Vec2> {
    for s in sources {
        if r >= s.bound {
            r -= s.bound;
            continue;
        }
        for (k, &(p, bw, mass)) in s.corners.iter().enumerate() {
            if r >= mass {
                r -= mass;
                continue;
            }
            let list = jm.jumps_at(p % jm.width, p / jm.width);
            for j in list {
                let m = j.weight * bw;
                if r < m {
                    return Some(Vec2::new(j.x as f32, j.y as f32) + s.shifts[k]);
                }
                r -= m;
            }
            return list
                .last()
                .map(|j| Vec2::new(j.x as f32, j.y as f32) + s.shifts[k]);
        }
    }
    None
}

/// The filtered table of §4.2.5, built only when rejection keeps failing.
#[derive(Default)]
struct Table {
    entries: Vec<(Vec2, Option<u32>)>,
    cumulative: Vec<f32>,
    total: f32,
}

impl Table {
    fn fill(
        &mut self,
        conts: &[(Vec2, f32, u32)],
        sources: &[JumpSource],
        jm: JumpMapRef,
        valid: &impl Fn(Vec2) -> bool,
    ) {
        self.entries.clear();
        self.cumulative.clear();
        let mut prev = 0.0;
        for &(c, cum, nb) in conts {
            self.entries.push((c, Some(nb)));
            self.cumulative.push(cum);
            prev = cum;
        }
        let mut total = prev;
        for s in sources {
            for (k, &(p, bw, _)) in s.corners.iter().enumerate() {
                if bw <= 0.0 {
                    continue;
                }
                for j in jm.jumps_at(p % jm.width, p / jm.width) {
                    let target = Vec2::new(j.x as f32, j.y as f32) + s.shifts[k];
                    if valid(target) {
                        total += j.weight * bw;
                        self.entries.push((target, None));
                        self.cumulative.push(total);
                    }
                }
            }
        }
        self.total = total;
    }
}

/// The synthesize node (§4.2): the walk over the parameterization with the jump map, logged
/// with the random assignments a user can avoid.
pub fn node(
    param: &crate::parameterize::jump_parameterization::ParamParts,
    jm: JumpMapRef,
    params: &WalkParams,
    progress: &dyn Fn(f32),
) -> Result<Walk, Failure> {
    if param.meta.exemplar != (jm.width, jm.height) {
        return Err(Failure::internal(
            "parameterization and jump map disagree on the exemplar size",
        ));
    }
    let walk = jump_walk(param.walk_input(), jm, params, progress);
    let n = param.order.len();
    tracing::info!(
        "synthesize: {n} vertices, {} jumps, {} random assignments",
        walk.jumps,
        walk.random_assignments
    );
    if walk.random_assignments > 0 {
        tracing::warn!(
            "synthesize: {} of {n} vertices had no valid continuation or jump and got a random \
             address; a smaller parameterize.scale or a larger exemplar avoids this",
            walk.random_assignments
        );
    }
    Ok(walk)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::analyse_exemplar::jump_map::Jump;
    use crate::geom::Mesh;
    use crate::parameterize::edge_offsets::OffsetBox;
    use crate::parameterize::edge_offsets::{edge_offsets, validity_boxes};
    use crate::parameterize::region_growing::region_growing_order;
    use glam::Vec3;

    fn grid(n: usize) -> Mesh {
        crate::geom::primitives::grid(n, 1.0)
    }

    /// A jump map whose every pixel jumps to a fixed pixel (or nowhere).
    fn jump_map(w: u32, h: u32, to: Option<(u16, u16)>) -> Vec<Jump> {
        (0..w * h)
            .map(|_| match to {
                Some((x, y)) => Jump { x, y, weight: 1.0 },
                None => Jump {
                    x: 0,
                    y: 0,
                    weight: 0.0,
                },
            })
            .collect()
    }

    struct Setup {
        mesh: Mesh,
        offsets: Vec<Vec2>,
        boxes: Vec<OffsetBox>,
        order: Vec<u32>,
    }

    fn setup(n: usize, scale: f32) -> Setup {
        let mesh = grid(n);
        let up = vec![Vec3::Y; mesh.vertex_count()];
        let offsets = edge_offsets(&mesh, mesh.adjacency(), &up, scale);
        let boxes = validity_boxes(mesh.adjacency(), &offsets);
        let order = region_growing_order(mesh.adjacency(), 0).order;
        Setup {
            mesh,
            offsets,
            boxes,
            order,
        }
    }

    fn walk(s: &Setup, jumps: &[Jump], w: u32, h: u32, params: &WalkParams) -> Walk {
        let adj = s.mesh.adjacency();
        let input = WalkInput {
            adj_offsets: &adj.offsets,
            neighbors: &adj.neighbors,
            edge_offsets: &s.offsets,
            boxes: &s.boxes,
            order: &s.order,
        };
        let jm = JumpMapRef::new(w, h, 1, jumps).unwrap();
        jump_walk(input, jm, params, &|_| {})
    }

    #[test]
    fn every_address_is_valid_for_its_vertex() {
        let s = setup(30, 1.5);
        let jumps = jump_map(40, 40, Some((20, 20)));
        let wk = walk(
            &s,
            &jumps,
            40,
            40,
            &WalkParams {
                continuation: 2.0,
                ..Default::default()
            },
        );
        for (v, a) in wk.addresses.iter().enumerate() {
            assert!(s.boxes[v].admits(*a, 40, 40), "vertex {v} at {a}");
        }
        assert!(
            wk.jumps > 0,
            "with a weak continuation some jumps must be taken"
        );
    }

    #[test]
    fn without_jumps_patches_carry_edge_offsets_exactly() {
        // An empty jump map: every vertex continues from a neighbour unless no continuation
        // is valid. On a flat grid with a constant field, offsets are path-independent, so
        // any edge inside one patch carries its offset, and new patches come only from
        // random assignments.
        let s = setup(12, 2.0);
        let jumps = jump_map(48, 48, None);
        let params = WalkParams {
            boundary_fraction: 0.0,
            ..Default::default()
        };
        let wk = walk(&s, &jumps, 48, 48, &params);
        assert_eq!(wk.jumps, 0);
        let adj = s.mesh.adjacency();
        let mut inside = 0;
        for v in 0..s.mesh.vertex_count() {
            for &nb in adj.neighbors(v) {
                if wk.patches[v] != wk.patches[nb as usize] {
                    continue;
                }
                inside += 1;
                let d = s.offsets[adj.half_edge(v, nb).unwrap()];
                let got = wk.addresses[nb as usize] - wk.addresses[v];
                assert!((got - d).length() < 1e-3, "edge {v}-{nb}: {got} vs {d}");
            }
        }
        let mut patches = wk.patches.clone();
        patches.sort();
        patches.dedup();
        assert_eq!(patches.len() as u64, 1 + wk.random_assignments);
        assert!(
            inside > adj.neighbors.len() / 2,
            "most edges should lie inside patches"
        );
    }

    #[test]
    fn rejection_sampling_draws_with_the_filtered_tables_probabilities() {
        // Two sources on a 6×6 exemplar whose jumps partly land outside the valid region.
        let (w, h) = (6u32, 6u32);
        let jumps: Vec<Jump> = (0..w * h)
            .flat_map(|p| {
                [
                    Jump {
                        x: ((p * 5) % w) as u16,
                        y: ((p * 3) % h) as u16,
                        weight: 0.7,
                    },
                    Jump {
                        x: ((p + 2) % w) as u16,
                        y: ((p / 2) % h) as u16,
                        weight: 0.3,
                    },
                ]
            })
            .collect();
        let jm = JumpMapRef::new(w, h, 2, &jumps).unwrap();
        let pixel_weight = vec![1.0f32; (w * h) as usize];
        let sources = vec![
            JumpSource::new(
                Vec2::new(1.3, 2.6),
                Vec2::new(0.5, -0.25),
                w,
                h,
                &pixel_weight,
            ),
            JumpSource::new(
                Vec2::new(3.0, 4.5),
                Vec2::new(-0.75, 0.5),
                w,
                h,
                &pixel_weight,
            ),
        ];
        let bound: f32 = sources.iter().map(|s| s.bound).sum();
        let conts = vec![
            (Vec2::new(2.0, 2.0), 0.4, 7u32),
            (Vec2::new(2.5, 2.0), 1.0, 8u32),
        ];
        let valid = |a: Vec2| a.x >= 1.0 && a.y >= 1.0 && a.x <= 3.5 && a.y <= 4.0;
        let mut table = Table::default();
        table.fill(&conts, &sources, jm, &valid);
        assert!(
            table.entries.len() > 3 && table.entries.len() < 2 + 16,
            "some jumps must be invalid"
        );
        // Expected probability of each distinct outcome.
        let key = |e: &(Vec2, Option<u32>)| (e.0.x.to_bits(), e.0.y.to_bits(), e.1);
        let mut expected = std::collections::HashMap::new();
        let mut prev = 0.0;
        for (e, &c) in table.entries.iter().zip(&table.cumulative) {
            *expected.entry(key(e)).or_insert(0.0) += (c - prev) as f64 / table.total as f64;
            prev = c;
        }
        let n = 200_000u64;
        let mut seen = std::collections::HashMap::new();
        for i in 0..n {
            let e = draw(&conts, 1.0, &sources, bound, jm, valid, &mut table, 5, i).unwrap();
            assert!(valid(e.0));
            *seen.entry(key(&e)).or_insert(0u64) += 1;
        }
        for (k, p) in &expected {
            let f = *seen.get(k).unwrap_or(&0) as f64 / n as f64;
            let sigma = (p * (1.0 - p) / n as f64).sqrt();
            assert!(
                (f - p).abs() < 5.0 * sigma + 1e-4,
                "{k:?}: drawn {f}, expected {p}"
            );
        }
        assert_eq!(seen.len(), expected.len());
    }

    #[test]
    fn the_same_seed_gives_the_same_walk_and_another_seed_another() {
        let s = setup(20, 1.0);
        let jumps = jump_map(32, 32, Some((5, 9)));
        let p1 = WalkParams {
            continuation: 3.0,
            ..Default::default()
        };
        let a = walk(&s, &jumps, 32, 32, &p1);
        let b = walk(&s, &jumps, 32, 32, &p1);
        assert_eq!(a, b);
        let c = walk(&s, &jumps, 32, 32, &WalkParams { seed: 2, ..p1 });
        assert_ne!(a.addresses, c.addresses);
    }
}

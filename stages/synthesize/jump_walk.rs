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

use crate::random::counter_unit;
use crate::stages::analyse_exemplar::jump_map::JumpMapRef;
use crate::stages::parameterize::edge_offsets::OffsetBox;
use glam::Vec2;

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
    pub fn validate(&self) -> Result<(), String> {
        if !(self.continuation.is_finite() && (0.01..=10000.0).contains(&self.continuation)) {
            return Err(format!(
                "synthesize.continuation must be in 0.01..=10000, got {}",
                self.continuation
            ));
        }
        if !(self.boundary_fraction.is_finite() && (0.0..=0.5).contains(&self.boundary_fraction)) {
            return Err(format!(
                "synthesize.boundary_fraction must be in 0..=0.5, got {}",
                self.boundary_fraction
            ));
        }
        Ok(())
    }
}

/// What the walk reads: the mesh's connectivity and the parameterization.
#[derive(Clone, Copy)]
pub struct WalkInput<'a> {
    /// One-ring in compressed-row form (as [`crate::geom::VertexAdjacency`]).
    pub adj_offsets: &'a [u32],
    pub neighbors: &'a [u32],
    /// Texture-space offset of each half-edge `v → neighbors[h]`.
    pub edge_offsets: &'a [Vec2],
    pub boxes: &'a [OffsetBox],
    pub order: &'a [u32],
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

const STREAM_CHOICE: u64 = 1;
const STREAM_FALLBACK_X: u64 = 2;
const STREAM_FALLBACK_Y: u64 = 3;

#[derive(Clone, Copy)]
enum Source {
    Continue(u32),
    Jump,
}

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
    let margin = Vec2::new(w as f32, h as f32) * params.boundary_fraction;
    let top = Vec2::new((w - 1) as f32, (h - 1) as f32);
    // Continuation weight fades to zero near the border.
    let border_factor = |a: Vec2| -> f32 {
        if params.boundary_fraction <= 0.0 {
            return 1.0;
        }
        let near = a.min(top - a);
        (near.x / margin.x)
            .clamp(0.0, 1.0)
            .min((near.y / margin.y).clamp(0.0, 1.0))
    };
    let mut dest: Vec<Vec2> = Vec::with_capacity(256);
    let mut cumulative: Vec<f32> = Vec::with_capacity(256);
    let mut source: Vec<Source> = Vec::with_capacity(256);
    for (pos, &v) in input.order.iter().enumerate() {
        if pos % 65536 == 0 {
            progress(pos as f32 / input.order.len() as f32);
        }
        let vu = v as usize;
        let (lo, hi) = input.boxes[vu].valid_range(w, h);
        let valid = |a: Vec2| a.x >= lo.x && a.y >= lo.y && a.x <= hi.x && a.y <= hi.y;
        dest.clear();
        cumulative.clear();
        source.clear();
        let mut total = 0.0f32;
        let edges = input.adj_offsets[vu] as usize..input.adj_offsets[vu + 1] as usize;
        for e in edges {
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
                    total += weight;
                    dest.push(c);
                    cumulative.push(total);
                    source.push(Source::Continue(nb));
                }
            }
            let base = a.floor();
            let t = a - base;
            let (bx, by) = (base.x as i64, base.y as i64);
            for (dx, dy, bw) in [
                (0, 0, (1.0 - t.x) * (1.0 - t.y)),
                (1, 0, t.x * (1.0 - t.y)),
                (0, 1, (1.0 - t.x) * t.y),
                (1, 1, t.x * t.y),
            ] {
                let (px, py) = (bx + dx, by + dy);
                if bw <= 0.0 || px < 0 || py < 0 || px >= w as i64 || py >= h as i64 {
                    continue;
                }
                let shift = a - Vec2::new(px as f32, py as f32) + d;
                for j in jm.jumps_at(px as u32, py as u32) {
                    let target = Vec2::new(j.x as f32, j.y as f32) + shift;
                    if valid(target) {
                        total += j.weight * bw;
                        dest.push(target);
                        cumulative.push(total);
                        source.push(Source::Jump);
                    }
                }
            }
        }
        if total > 0.0 {
            let r = counter_unit(params.seed, STREAM_CHOICE, v as u64) * total;
            let k = cumulative.partition_point(|&c| c <= r).min(dest.len() - 1);
            addresses[vu] = dest[k];
            patches[vu] = match source[k] {
                Source::Continue(nb) => patches[nb as usize],
                Source::Jump => {
                    jumps += 1;
                    v
                }
            };
        } else {
            // A seed, or no neighbour could offer a valid address.
            if cumulative.is_empty() && has_done_neighbour(&input, &done, vu) {
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

fn has_done_neighbour(input: &WalkInput, done: &[bool], v: usize) -> bool {
    (input.adj_offsets[v] as usize..input.adj_offsets[v + 1] as usize)
        .any(|e| done[input.neighbors[e] as usize])
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geom::Mesh;
    use crate::stages::analyse_exemplar::jump_map::Jump;
    use crate::stages::parameterize::edge_offsets::{edge_offsets, validity_boxes};
    use crate::stages::parameterize::region_growing::region_growing_order;
    use glam::Vec3;

    fn grid(n: usize) -> Mesh {
        let mut p = Vec::new();
        for y in 0..n {
            for x in 0..n {
                p.push(Vec3::new(x as f32, y as f32, 0.0));
            }
        }
        let mut t = Vec::new();
        for y in 0..n - 1 {
            for x in 0..n - 1 {
                let i = (y * n + x) as u32;
                let n = n as u32;
                t.push([i, i + 1, i + n + 1]);
                t.push([i, i + n + 1, i + n]);
            }
        }
        Mesh::new(p, t)
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

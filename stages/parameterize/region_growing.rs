//! Region-growing vertex order (Zelinka & Garland, "Interactive Texture Synthesis on Surfaces
//! Using Jump Maps", §4.1): repeatedly take the unsynthesized vertex whose proportion of
//! already-synthesized neighbours is greatest, so every vertex is synthesized with as many
//! neighbours as possible to continue from (§4.2.5).
//!
//! Ties go to the vertex that reached its proportion first, which grows the region in
//! breadth-first rings around the seed rather than in a spiral arm. Each connected component
//! gets its own seed: the configured seed for its component, the lowest-numbered vertex for
//! the others.

use crate::geom::VertexAdjacency;
use std::collections::BinaryHeap;

/// The synthesis order: `order` lists every vertex that has a neighbour (vertices in no
/// triangle are left out), and `seeds` the positions in `order` where a new component starts
/// (those vertices have no synthesized neighbour when their turn comes).
#[derive(Debug, Clone, PartialEq)]
pub struct VertexOrder {
    pub order: Vec<u32>,
    pub seeds: Vec<u32>,
}

/// Computes the region-growing order starting at `seed` (clamped to a vertex with
/// neighbours).
pub fn region_growing_order(adj: &VertexAdjacency, seed: u32) -> VertexOrder {
    let n = adj.vertex_count();
    let mut done_count = vec![0u32; n];
    let mut synthesized = vec![false; n];
    let mut order = Vec::with_capacity(n);
    let mut seeds = Vec::new();
    // Max-heap on (proportion, earliest push). The proportion s/d is compared exactly as
    // the f64 quotient (its bits order like the value for non-negative numbers).
    let mut heap: BinaryHeap<(u64, u64, u32)> = BinaryHeap::new();
    let mut pushes: u64 = 0;
    let first = if (seed as usize) < n && adj.degree(seed as usize) > 0 {
        Some(seed)
    } else {
        None
    };
    let mut next_unvisited = 0usize;
    let mut start = first;
    loop {
        let s = match start.take() {
            Some(s) => s,
            None => {
                while next_unvisited < n
                    && (synthesized[next_unvisited] || adj.degree(next_unvisited) == 0)
                {
                    next_unvisited += 1;
                }
                if next_unvisited == n {
                    break;
                }
                next_unvisited as u32
            }
        };
        seeds.push(order.len() as u32);
        heap.push((0, u64::MAX, s));
        while let Some((_, _, v)) = heap.pop() {
            let vu = v as usize;
            if synthesized[vu] {
                continue;
            }
            // Proportions only grow, so a vertex's freshest entry pops before its stale
            // ones, which are then skipped here.
            synthesized[vu] = true;
            order.push(v);
            for &w in adj.neighbors(vu) {
                let wu = w as usize;
                if synthesized[wu] {
                    continue;
                }
                done_count[wu] += 1;
                let ratio = done_count[wu] as f64 / adj.degree(wu) as f64;
                pushes += 1;
                heap.push((ratio.to_bits(), u64::MAX - pushes, w));
            }
        }
    }
    VertexOrder { order, seeds }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn path_and_triangle() -> VertexAdjacency {
        // Component A: triangle 0-1-2 plus 3 attached to 2; component B: triangle 4-5-6.
        VertexAdjacency::build(8, &[[0, 1, 2], [1, 3, 2], [4, 5, 6]])
    }

    #[test]
    fn order_is_a_permutation_of_connected_vertices_with_one_seed_per_component() {
        let adj = path_and_triangle();
        let o = region_growing_order(&adj, 1);
        let mut sorted = o.order.clone();
        sorted.sort();
        assert_eq!(sorted, vec![0, 1, 2, 3, 4, 5, 6]); // 7 is isolated
        assert_eq!(o.order[0], 1);
        assert_eq!(o.seeds.len(), 2);
        let mut done = [false; 8];
        for (i, &v) in o.order.iter().enumerate() {
            let has_done_neighbour = adj.neighbors(v as usize).iter().any(|&w| done[w as usize]);
            assert_eq!(
                !has_done_neighbour,
                o.seeds.contains(&(i as u32)),
                "position {i}"
            );
            done[v as usize] = true;
        }
    }

    #[test]
    fn picks_the_vertex_with_the_largest_done_proportion() {
        // Star with centre 0 and rim 1..6 (a fan); start at a rim vertex.
        let tris: Vec<[u32; 3]> = (1..=6).map(|i| [0, i, i % 6 + 1]).collect();
        let adj = VertexAdjacency::build(7, &tris);
        let o = region_growing_order(&adj, 1);
        // After 1: the centre has 1/6, rim 2 and 6 have 1/3 each: a rim vertex is next.
        assert!(o.order[1] == 2 || o.order[1] == 6);
        // After 1 and 2: vertex 3 has 1/3, vertex 6 has 1/3, centre 2/6 = 1/3, but the
        // greedy choice must never pick a vertex whose proportion is below another's.
        let mut done = [false; 7];
        for &v in &o.order {
            let prop = |w: usize| {
                adj.neighbors(w)
                    .iter()
                    .filter(|&&x| done[x as usize])
                    .count() as f64
                    / adj.degree(w) as f64
            };
            let best = (0..7).filter(|&w| !done[w]).map(prop).fold(0.0, f64::max);
            if done.iter().any(|&d| d) {
                assert_eq!(prop(v as usize), best, "vertex {v}");
            }
            done[v as usize] = true;
        }
    }
}

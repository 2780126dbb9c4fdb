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
///
/// The proportions s/d (done neighbours over degree) take few distinct values, so instead of
/// a binary heap the queue is an array of FIFO buckets, one per distinct fraction, ranked by
/// value: pushing and popping are O(1), and FIFO order within a bucket is the heap's
/// tie-break (earliest push first). Meshes with a vertex of very high degree (a fan) would need
/// too many buckets and use the heap.
pub fn region_growing_order(adj: &VertexAdjacency, seed: u32) -> VertexOrder {
    let max_degree = (0..adj.vertex_count())
        .map(|v| adj.degree(v))
        .max()
        .unwrap_or(0);
    if max_degree <= MAX_BUCKET_DEGREE {
        grow(adj, seed, BucketQueue::new(max_degree))
    } else {
        grow(adj, seed, HeapQueue::default())
    }
}

const MAX_BUCKET_DEGREE: usize = 64;

/// A max-priority queue of vertices keyed by (done, degree), FIFO among equal proportions.
trait ProportionQueue {
    fn push(&mut self, done: u32, degree: u32, v: u32);
    fn pop(&mut self) -> Option<u32>;
}

#[derive(Default)]
struct HeapQueue {
    heap: BinaryHeap<(u64, u64, u32)>,
    pushes: u64,
}

impl ProportionQueue for HeapQueue {
    fn push(&mut self, done: u32, degree: u32, v: u32) {
        // The f64 quotient's bits order like its value for non-negative numbers.
        let ratio = if degree == 0 {
            0.0
        } else {
            done as f64 / degree as f64
        };
        self.pushes += 1;
        self.heap.push((ratio.to_bits(), u64::MAX - self.pushes, v));
    }
    fn pop(&mut self) -> Option<u32> {
        self.heap.pop().map(|e| e.2)
    }
}

struct BucketQueue {
    /// rank[d * (max_degree + 1) + s]: the rank of s/d among all fractions with d ≤ max_degree.
    rank: Vec<u32>,
    stride: usize,
    buckets: Vec<std::collections::VecDeque<u32>>,
    /// No bucket above this one holds anything.
    top: usize,
}

impl BucketQueue {
    fn new(max_degree: usize) -> Self {
        let stride = max_degree + 1;
        let mut fractions: Vec<(u32, u32)> = vec![(0, 1)];
        for d in 1..=max_degree as u32 {
            for s in 1..=d {
                fractions.push((s, d));
            }
        }
        // Exact comparison of s1/d1 and s2/d2 by cross-multiplication.
        let cmp = |a: &(u32, u32), b: &(u32, u32)| {
            (a.0 as u64 * b.1 as u64).cmp(&(b.0 as u64 * a.1 as u64))
        };
        fractions.sort_by(cmp);
        fractions.dedup_by(|a, b| cmp(a, b).is_eq());
        let mut rank = vec![0u32; stride * stride];
        for d in 1..=max_degree as u32 {
            for s in 0..=d {
                let r = fractions.partition_point(|f| cmp(f, &(s, d)).is_lt());
                rank[d as usize * stride + s as usize] = r as u32;
            }
        }
        BucketQueue {
            rank,
            stride,
            buckets: vec![std::collections::VecDeque::new(); fractions.len()],
            top: 0,
        }
    }
}

impl ProportionQueue for BucketQueue {
    fn push(&mut self, done: u32, degree: u32, v: u32) {
        let r = self.rank[degree as usize * self.stride + done as usize] as usize;
        self.buckets[r].push_back(v);
        self.top = self.top.max(r);
    }
    fn pop(&mut self) -> Option<u32> {
        loop {
            if let Some(v) = self.buckets[self.top].pop_front() {
                return Some(v);
            }
            if self.top == 0 {
                return None;
            }
            self.top -= 1;
        }
    }
}

fn grow(adj: &VertexAdjacency, seed: u32, mut queue: impl ProportionQueue) -> VertexOrder {
    let n = adj.vertex_count();
    let mut done_count = vec![0u32; n];
    let mut synthesized = vec![false; n];
    let mut order = Vec::with_capacity(n);
    let mut seeds = Vec::new();
    let mut start = ((seed as usize) < n && adj.degree(seed as usize) > 0).then_some(seed);
    let mut next_unvisited = 0usize;
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
        queue.push(0, adj.degree(s as usize) as u32, s);
        while let Some(v) = queue.pop() {
            let vu = v as usize;
            // Proportions only grow, so a vertex's freshest entry pops before its stale
            // ones, which are then skipped here.
            if synthesized[vu] {
                continue;
            }
            synthesized[vu] = true;
            order.push(v);
            for &w in adj.neighbors(vu) {
                let wu = w as usize;
                if !synthesized[wu] {
                    done_count[wu] += 1;
                    queue.push(done_count[wu], adj.degree(wu) as u32, w);
                }
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
    fn bucket_queue_and_heap_give_the_same_order() {
        // A bumpy grid with irregular degrees: both queues must agree exactly.
        let n = 30u32;
        let mut tris = Vec::new();
        for y in 0..n - 1 {
            for x in 0..n - 1 {
                let i = y * n + x;
                if (x * 7 + y * 3) % 5 == 0 {
                    tris.push([i, i + 1, i + n]);
                    tris.push([i + 1, i + n + 1, i + n]);
                } else {
                    tris.push([i, i + 1, i + n + 1]);
                    tris.push([i, i + n + 1, i + n]);
                }
            }
        }
        let adj = VertexAdjacency::build((n * n) as usize, &tris);
        for seed in [0, 17, 450] {
            let a = grow(&adj, seed, HeapQueue::default());
            let max_degree = (0..adj.vertex_count())
                .map(|v| adj.degree(v))
                .max()
                .unwrap();
            let b = grow(&adj, seed, BucketQueue::new(max_degree));
            assert_eq!(a, b, "seed {seed}");
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

//! Dijkstra's shortest paths, deterministic to the bit: the search the mesh code and the
//! stages share (edge paths, geodesic fronts, cut graphs).
//!
//! The graph is implicit: the caller pops the next settled node and relaxes its neighbours
//! with distances it computes itself, so each use keeps its own edge weights and arithmetic.
//! Distances are f64. The heap pops the smallest distance first (by `f64::total_cmp`), ties
//! to the smaller node index, and a node's distance only ever drops strictly, so the order
//! in which nodes are settled depends on the graph alone, never on the heap's layout. Edge
//! weights are expected non-negative: then no node is reached again once settled.
//!
//! [`Dijkstra::run`] is the usual loop (with targets to stop at); [`Dijkstra::pop`] and
//! [`Dijkstra::relax`] are its steps, for searches that stop on their own condition. The
//! arrays are reset only where a search touched them, so many short searches on one big
//! graph cost what they visit.

use std::cmp::Ordering;
use std::collections::BinaryHeap;

/// A heap entry ordered so the max-heap pops the smallest distance, then the smallest node.
#[derive(Debug, Clone, PartialEq)]
struct Entry(f64, u32);

impl Eq for Entry {}

impl PartialOrd for Entry {
    fn partial_cmp(&self, o: &Self) -> Option<Ordering> {
        Some(self.cmp(o))
    }
}

impl Ord for Entry {
    fn cmp(&self, o: &Self) -> Ordering {
        o.0.total_cmp(&self.0).then(o.1.cmp(&self.1))
    }
}

/// Search state over nodes `0..n`: per node its distance, its predecessor (any `Copy` value
/// the caller records with a relaxation: a node, an edge, both) and whether it is settled.
#[derive(Debug, Clone)]
pub struct Dijkstra<P: Copy = u32> {
    dist: Vec<f64>,
    pred: Vec<P>,
    settled: Vec<bool>,
    touched: Vec<u32>,
    heap: BinaryHeap<Entry>,
    none: P,
}

impl<P: Copy> Dijkstra<P> {
    /// No node reached; predecessors read `none` until a relaxation sets them.
    pub fn new(n: usize, none: P) -> Self {
        Dijkstra {
            dist: vec![f64::INFINITY; n],
            pred: vec![none; n],
            settled: vec![false; n],
            touched: Vec::new(),
            heap: BinaryHeap::new(),
            none,
        }
    }

    /// Back to no node reached, clearing only the nodes the last search touched.
    pub fn reset(&mut self) {
        for &v in &self.touched {
            self.dist[v as usize] = f64::INFINITY;
            self.pred[v as usize] = self.none;
            self.settled[v as usize] = false;
        }
        self.touched.clear();
        self.heap.clear();
    }

    /// Starts the search at `s` (distance 0). A node added twice is searched once.
    pub fn add_source(&mut self, s: u32) {
        let d = &mut self.dist[s as usize];
        if *d > 0.0 {
            if *d == f64::INFINITY {
                self.touched.push(s);
            }
            *d = 0.0;
            self.heap.push(Entry(0.0, s));
        }
    }

    /// The next node to settle and its distance, marked settled; None when no reached node
    /// is left. Entries a later relaxation has bettered are skipped.
    pub fn pop(&mut self) -> Option<(u32, f64)> {
        while let Some(Entry(d, v)) = self.heap.pop() {
            let i = v as usize;
            if self.settled[i] || d > self.dist[i] {
                continue;
            }
            self.settled[i] = true;
            return Some((v, d));
        }
        None
    }

    /// Offers distance `d` to `w` through `p`: taken when strictly shorter than what `w`
    /// has (settled or not: callers whose weights can be negative check
    /// [`Self::is_settled`] first). Returns whether it was taken.
    pub fn relax(&mut self, w: u32, d: f64, p: P) -> bool {
        let old = self.dist[w as usize];
        if d < old {
            self.set(w, d, p, old);
            self.heap.push(Entry(d, w));
            true
        } else {
            false
        }
    }

    fn set(&mut self, w: u32, d: f64, p: P, old: f64) {
        if old == f64::INFINITY {
            self.touched.push(w);
        }
        self.dist[w as usize] = d;
        self.pred[w as usize] = p;
    }

    /// Pops and calls `expand(self, v, d)` on each settled node until every node of
    /// `targets` is settled (the last one is not expanded) or, with no targets, until no
    /// node is left. `expand` relaxes `v`'s neighbours. Returns whether every target was
    /// settled.
    pub fn run(&mut self, targets: &[u32], mut expand: impl FnMut(&mut Self, u32, f64)) -> bool {
        let mut want = targets.to_vec();
        want.sort_unstable();
        want.dedup();
        let mut left = want.len();
        while let Some((v, d)) = self.pop() {
            if left > 0 && want.binary_search(&v).is_ok() {
                left -= 1;
                if left == 0 {
                    return true;
                }
            }
            expand(self, v, d);
        }
        left == 0
    }

    /// Distance of `v` (infinite when not reached).
    pub fn dist(&self, v: u32) -> f64 {
        self.dist[v as usize]
    }

    /// The predecessor recorded with `v`'s distance (`none` for a source or an unreached node).
    pub fn pred(&self, v: u32) -> P {
        self.pred[v as usize]
    }

    pub fn is_settled(&self, v: u32) -> bool {
        self.settled[v as usize]
    }

    /// Every node's distance.
    pub fn distances(&self) -> &[f64] {
        &self.dist
    }

    /// Every node's distance and predecessor.
    pub fn into_parts(self) -> (Vec<f64>, Vec<P>) {
        (self.dist, self.pred)
    }
}

impl<P: Copy + Ord> Dijkstra<P> {
    /// [`Self::relax`], except that a distance equal to `w`'s (settled or not) still moves
    /// its predecessor to `p` when `p` is smaller: among equally short paths the one through
    /// the smallest predecessors wins, whatever order they were found in.
    pub fn relax_lowest_pred(&mut self, w: u32, d: f64, p: P) -> bool {
        let old = self.dist[w as usize];
        if d < old || (d == old && p < self.pred[w as usize]) {
            self.set(w, d, p, old);
            if d < old {
                self.heap.push(Entry(d, w));
            }
            true
        } else {
            false
        }
    }
}

impl Dijkstra<u32> {
    /// The path from `source` to `target` (both included) along node predecessors; call it
    /// once `target` is settled in a search from `source`.
    pub fn path(&self, source: u32, target: u32) -> Vec<u32> {
        let mut path = vec![target];
        let mut v = target;
        while v != source {
            v = self.pred[v as usize];
            path.push(v);
        }
        path.reverse();
        path
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// A random graph: `n` nodes, undirected edges with small integer-valued lengths (so
    /// sums are exact and ties common).
    fn graph(n: usize, edges: &[(usize, usize, u8)]) -> Vec<Vec<(u32, f64)>> {
        let mut adj = vec![Vec::new(); n];
        for &(a, b, w) in edges {
            let (a, b) = (a % n, b % n);
            adj[a].push((b as u32, w as f64));
            adj[b].push((a as u32, w as f64));
        }
        adj
    }

    /// Bellman–Ford from `sources`: the reference distances.
    fn bellman_ford(adj: &[Vec<(u32, f64)>], sources: &[u32]) -> Vec<f64> {
        let mut d = vec![f64::INFINITY; adj.len()];
        for &s in sources {
            d[s as usize] = 0.0;
        }
        for _ in 0..adj.len() {
            for v in 0..adj.len() {
                for &(w, l) in &adj[v] {
                    d[w as usize] = d[w as usize].min(d[v] + l);
                }
            }
        }
        d
    }

    /// The settling order by its definition: repeatedly the unsettled reached node of least
    /// (tentative distance, index), its neighbours then relaxed; quadratic, without a heap.
    fn naive_order(adj: &[Vec<(u32, f64)>], sources: &[u32]) -> Vec<u32> {
        let mut d = vec![f64::INFINITY; adj.len()];
        for &s in sources {
            d[s as usize] = 0.0;
        }
        let mut settled = vec![false; adj.len()];
        let mut order = Vec::new();
        while let Some(v) = (0..adj.len())
            .filter(|&v| !settled[v] && d[v].is_finite())
            .min_by(|&a, &b| d[a].total_cmp(&d[b]).then(a.cmp(&b)))
        {
            settled[v] = true;
            order.push(v as u32);
            for &(w, l) in &adj[v] {
                d[w as usize] = d[w as usize].min(d[v] + l);
            }
        }
        order
    }

    fn search(adj: &[Vec<(u32, f64)>], sources: &[u32], targets: &[u32]) -> (Dijkstra, Vec<u32>) {
        let mut dj = Dijkstra::new(adj.len(), u32::MAX);
        for &s in sources {
            dj.add_source(s);
        }
        let mut order = Vec::new();
        dj.run(targets, |dj, v, d| {
            order.push(v);
            for &(w, l) in &adj[v as usize] {
                dj.relax(w, d + l, v);
            }
        });
        (dj, order)
    }

    proptest! {
        #[test]
        fn distances_equal_bellman_ford_and_nodes_settle_by_least_tentative_distance_then_index(
            n in 1usize..24,
            edges in proptest::collection::vec((0usize..24, 0usize..24, 0u8..5), 0..60),
            sources in proptest::collection::vec(0usize..24, 1..4),
        ) {
            let adj = graph(n, &edges);
            let sources: Vec<u32> = sources.iter().map(|&s| (s % n) as u32).collect();
            let want = bellman_ford(&adj, &sources);
            let (dj, order) = search(&adj, &sources, &[]);
            prop_assert_eq!(dj.distances(), want.as_slice());
            prop_assert_eq!(&order, &naive_order(&adj, &sources));
            prop_assert!(order.windows(2).all(|w| want[w[0] as usize] <= want[w[1] as usize]));
            // Predecessors lie on shortest paths and lead back to a source.
            for &v in &order {
                if sources.contains(&v) {
                    prop_assert_eq!(dj.pred(v), u32::MAX);
                    continue;
                }
                let p = dj.pred(v);
                let l = adj[p as usize].iter().filter(|e| e.0 == v).map(|e| e.1).fold(f64::INFINITY, f64::min);
                prop_assert_eq!(want[p as usize] + l, want[v as usize]);
            }
        }

        #[test]
        fn targets_stop_the_search_once_all_are_settled_with_their_final_distances(
            n in 2usize..24,
            edges in proptest::collection::vec((0usize..24, 0usize..24, 0u8..5), 0..60),
            source in 0usize..24,
            targets in proptest::collection::vec(0usize..24, 1..4),
        ) {
            let adj = graph(n, &edges);
            let source = (source % n) as u32;
            let targets: Vec<u32> = targets.iter().map(|&t| (t % n) as u32).collect();
            let want = bellman_ford(&adj, &[source]);
            let (_, full_order) = search(&adj, &[source], &[]);
            let (dj, order) = search(&adj, &[source], &targets);
            let all_reached = targets.iter().all(|&t| want[t as usize].is_finite());
            // The same settling order, cut short after the last target.
            prop_assert_eq!(&order[..], &full_order[..order.len()]);
            for &t in &targets {
                prop_assert_eq!(dj.is_settled(t), want[t as usize].is_finite());
                prop_assert_eq!(dj.dist(t), want[t as usize]);
            }
            if all_reached {
                let last = *targets.iter().max_by_key(|&&t| full_order.iter().position(|&v| v == t)).unwrap();
                // Stopped at the last target, which was not expanded.
                prop_assert_eq!(order.len(), full_order.iter().position(|&v| v == last).unwrap());
                let path = dj.path(source, last);
                prop_assert_eq!(path[0], source);
                prop_assert_eq!(*path.last().unwrap(), last);
                prop_assert_eq!(path.len() > 1, last != source);
            } else {
                prop_assert_eq!(order.len(), full_order.len());
            }
        }

        #[test]
        fn equal_paths_take_the_lowest_predecessors_and_reset_forgets_the_last_search(
            n in 2usize..24,
            edges in proptest::collection::vec((0usize..24, 0usize..24, 0u8..3), 0..60),
            source in 0usize..24,
        ) {
            let adj = graph(n, &edges);
            let source = (source % n) as u32;
            let want = bellman_ford(&adj, &[source]);
            let mut dj = Dijkstra::new(n, u32::MAX);
            for round in 0..2 {
                dj.add_source(source);
                dj.run(&[], |dj, v, d| {
                    for &(w, l) in &adj[v as usize] {
                        dj.relax_lowest_pred(w, d + l, v);
                    }
                });
                for w in 0..n as u32 {
                    prop_assert_eq!(dj.dist(w), want[w as usize], "round {}", round);
                    if w == source || !want[w as usize].is_finite() {
                        continue;
                    }
                    // The smallest neighbour on a shortest path (itself, through a
                    // zero-length loop).
                    let best = adj[w as usize]
                        .iter()
                        .filter(|&&(p, l)| want[p as usize] + l == want[w as usize])
                        .map(|&(p, _)| p)
                        .min()
                        .unwrap();
                    prop_assert_eq!(dj.pred(w), best);
                }
                dj.reset();
                prop_assert!((0..n as u32).all(|v| dj.dist(v) == f64::INFINITY
                    && dj.pred(v) == u32::MAX
                    && !dj.is_settled(v)));
            }
        }
    }

    #[test]
    fn a_source_added_twice_is_settled_once_and_unreachable_targets_run_to_the_end() {
        let adj = graph(4, &[(0, 1, 1), (1, 2, 1)]);
        let (dj, order) = search(&adj, &[0, 0], &[3]);
        assert_eq!(order, vec![0, 1, 2]);
        assert!(!dj.is_settled(3));
        assert_eq!(dj.dist(3), f64::INFINITY);
        // Equal distances settle by index among the nodes reached: a node reached at the
        // same distance only through a later one settles after it.
        let star = graph(4, &[(0, 3, 2), (0, 2, 2), (0, 1, 2)]);
        assert_eq!(search(&star, &[0], &[]).1, vec![0, 1, 2, 3]);
        let zero = graph(3, &[(2, 1, 0), (1, 0, 0)]);
        assert_eq!(search(&zero, &[2], &[]).1, vec![2, 1, 0]);
    }
}

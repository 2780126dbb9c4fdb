//! Max-flow / min-cut on small graphs with the Boykov–Kolmogorov algorithm: Y. Boykov and
//! V. Kolmogorov, "An experimental comparison of min-cut/max-flow algorithms for energy
//! minimization in vision", IEEE PAMI 26(9), 2004.
//!
//! texsyn uses it for graph-cut texture transfer (Kwatra et al. 2003, "Graphcut textures", as
//! used by Bangay & Morkel 2006, §3.4): the nodes are the texels where an old and a new patch
//! overlap, the source is the old patch, the sink the new one, and the minimum cut is the seam.
//! Graphs are small (tens to a few thousand nodes) and one is built per vertex match, so one
//! [`MaxFlow`] is meant to be [`reset`](MaxFlow::reset) and reused: it keeps its allocations.
//!
//! The algorithm grows two search trees, S from the source and T from the sink, through
//! residual arcs; where they touch there is an augmenting path. After augmenting, the nodes
//! whose tree arc was saturated are orphans, which look for a new parent in their own tree
//! (preferring the one closest to the terminal, using the paper's timestamp/distance marks) or
//! are freed. Active nodes are processed first in, first out.
//!
//! Capacities are `f64`, non-negative and finite or `f64::INFINITY` (hard constraints).
//! Infinity needs no special value: IEEE arithmetic never lowers it (`∞ − f = ∞`), and a path's
//! bottleneck is finite unless the path is made only of infinite capacities, in which case the
//! minimum cut is infinite: [`solve`](MaxFlow::solve) then returns `f64::INFINITY` and the
//! partition is unspecified. So is a node tied with infinity to both terminals.
//!
//! Everything is sequential and ordered by insertion (arc lists, FIFO queues), so the same
//! calls give the same flow and cut bit for bit. If all capacities are multiples of one power
//! of two and their sums stay below 2^53 of it (e.g. `f32` values in [0, 1) times small
//! integers), every operation is exact.
//!
//! Complexity: BK's worst case is O(m·n²·|C|) for integer capacities (|C| the cut's cost), but
//! on grid-like vision graphs it is close to linear in practice. Memory: a node is 32 bytes,
//! each [`add_edge`](MaxFlow::add_edge) with a non-zero capacity adds two 16-byte arcs.

use std::collections::VecDeque;

/// End of an arc list / no parent.
const NONE: u32 = u32::MAX;
/// The node's parent is its tree's terminal.
const TERMINAL: u32 = u32::MAX - 1;
/// The node lost its parent and waits for adoption.
const ORPHAN: u32 = u32::MAX - 2;

#[derive(Clone, Copy, PartialEq, Eq, Debug)]
enum Tree {
    Free,
    Source,
    Sink,
}

#[derive(Clone, Copy, Debug)]
struct Node {
    /// First outgoing arc.
    first: u32,
    /// The arc from this node to its parent in its tree, or `TERMINAL`, `ORPHAN`, `NONE`.
    parent: u32,
    /// Residual t-link: > 0 towards the source, < 0 towards the sink (only one can be left).
    tr_cap: f64,
    /// When `dist` (distance to the terminal along the tree) was last known to be right.
    ts: u32,
    dist: u32,
    tree: Tree,
    /// In the active queue (possibly stale: freed nodes are skipped when popped).
    active: bool,
}

/// An arc and its residual capacity. Arcs come in pairs: `a ^ 1` is `a`'s reverse.
#[derive(Clone, Copy, Debug)]
struct Arc {
    head: u32,
    next: u32,
    cap: f64,
}

/// A reusable Boykov–Kolmogorov max-flow solver with `f64` capacities (module docs).
#[derive(Clone, Debug, Default)]
pub struct MaxFlow {
    nodes: Vec<Node>,
    arcs: Vec<Arc>,
    /// Flow found so far, including flow straight from source to sink through one node.
    flow: f64,
    active: VecDeque<u32>,
    orphans: VecDeque<u32>,
    time: u32,
}

impl MaxFlow {
    pub fn new() -> Self {
        Self::default()
    }

    /// Makes this an empty graph of `nodes` nodes (no edges, no t-links), keeping allocations.
    pub fn reset(&mut self, nodes: usize) {
        assert!(nodes < ORPHAN as usize, "too many nodes: {nodes}");
        let free = Node {
            first: NONE,
            parent: NONE,
            tr_cap: 0.0,
            ts: 0,
            dist: 0,
            tree: Tree::Free,
            active: false,
        };
        self.nodes.clear();
        self.nodes.resize(nodes, free);
        self.arcs.clear();
        self.active.clear();
        self.orphans.clear();
        self.flow = 0.0;
        self.time = 0;
    }

    /// Adds an edge with capacity `cap_ab` from `a` to `b` and `cap_ba` from `b` to `a`.
    /// Parallel edges add up; an edge with both capacities zero is not stored.
    pub fn add_edge(&mut self, a: usize, b: usize, cap_ab: f64, cap_ba: f64) {
        debug_assert!(cap_ab >= 0.0 && cap_ba >= 0.0, "{cap_ab} {cap_ba}");
        assert!(a < self.nodes.len() && b < self.nodes.len(), "edge {a}-{b}");
        if cap_ab == 0.0 && cap_ba == 0.0 {
            return;
        }
        assert!(self.arcs.len() + 2 < ORPHAN as usize, "too many edges");
        for (from, to, cap) in [(a, b, cap_ab), (b, a, cap_ba)] {
            let next = self.nodes[from].first;
            self.nodes[from].first = self.arcs.len() as u32;
            self.arcs.push(Arc {
                head: to as u32,
                next,
                cap,
            });
        }
    }

    /// Adds t-links: `source_cap` from the source to `v`, `sink_cap` from `v` to the sink.
    /// Repeated calls add up.
    pub fn add_terminal(&mut self, v: usize, source_cap: f64, sink_cap: f64) {
        debug_assert!(
            source_cap >= 0.0 && sink_cap >= 0.0,
            "t-link {source_cap}, {sink_cap}"
        );
        let node = &mut self.nodes[v];
        let (mut from_source, mut to_sink) = (source_cap, sink_cap);
        if node.tr_cap > 0.0 {
            from_source += node.tr_cap;
        } else {
            to_sink -= node.tr_cap;
        }
        if from_source == f64::INFINITY && to_sink == f64::INFINITY {
            // An infinite path source → v → sink: no finite cut exists.
            self.flow = f64::INFINITY;
            node.tr_cap = 0.0;
            return;
        }
        // Route source → v → sink at once; only the larger t-link keeps a residual.
        self.flow += from_source.min(to_sink);
        node.tr_cap = from_source - to_sink;
    }

    /// Computes a maximum flow and returns its value, which is the cost of a minimum cut
    /// (`f64::INFINITY` if every cut is infinite). Calling it again returns the same value.
    pub fn solve(&mut self) -> f64 {
        self.active.clear();
        self.orphans.clear();
        self.time = 0;
        for v in 0..self.nodes.len() {
            let node = &mut self.nodes[v];
            node.active = false;
            node.ts = 0;
            node.dist = 1;
            node.parent = TERMINAL;
            node.tree = if node.tr_cap > 0.0 {
                Tree::Source
            } else if node.tr_cap < 0.0 {
                Tree::Sink
            } else {
                node.parent = NONE;
                Tree::Free
            };
            if node.tree != Tree::Free {
                self.activate(v as u32);
            }
        }
        if self.flow == f64::INFINITY {
            return self.flow;
        }
        while let Some(bridge) = self.grow() {
            self.time += 1;
            let pushed = self.augment(bridge);
            if pushed == f64::INFINITY {
                self.flow = pushed;
                break;
            }
            self.flow += pushed;
            while let Some(orphan) = self.orphans.pop_front() {
                self.adopt(orphan);
            }
        }
        self.flow
    }

    /// After [`solve`](Self::solve): whether `v` is on the source side of the minimum cut
    /// whose source side is the set of nodes reachable from the source in the residual graph
    /// (the smallest source side of all minimum cuts).
    pub fn is_source_side(&self, v: usize) -> bool {
        self.nodes[v].tree == Tree::Source
    }

    fn activate(&mut self, v: u32) {
        let node = &mut self.nodes[v as usize];
        if !node.active {
            node.active = true;
            self.active.push_back(v);
        }
    }

    /// Residual capacity usable by `tree` along arc `a` from a node to its neighbour: the
    /// arc itself in S (flow goes away from the source), its reverse in T.
    fn tree_cap(&self, tree: Tree, a: u32) -> f64 {
        match tree {
            Tree::Sink => self.arcs[(a ^ 1) as usize].cap,
            _ => self.arcs[a as usize].cap,
        }
    }

    /// Grows the trees from the active nodes until they touch; returns the arc from the S
    /// node to the T node where they do, or `None` when no augmenting path is left.
    fn grow(&mut self) -> Option<u32> {
        while let Some(&p) = self.active.front() {
            let tree = self.nodes[p as usize].tree;
            if tree != Tree::Free {
                let mut a = self.nodes[p as usize].first;
                while a != NONE {
                    let q = self.arcs[a as usize].head as usize;
                    if self.tree_cap(tree, a) > 0.0 {
                        let (qt, pn) = (self.nodes[q].tree, self.nodes[p as usize]);
                        if qt == Tree::Free {
                            let qn = &mut self.nodes[q];
                            (qn.tree, qn.parent) = (tree, a ^ 1);
                            (qn.ts, qn.dist) = (pn.ts, pn.dist + 1);
                            self.activate(q as u32);
                        } else if qt != tree {
                            // p stays at the front: it may have more neighbours in the other tree.
                            return Some(if tree == Tree::Source { a } else { a ^ 1 });
                        }
                    }
                    a = self.arcs[a as usize].next;
                }
            }
            self.active.pop_front();
            self.nodes[p as usize].active = false;
        }
        None
    }

    /// Pushes the bottleneck along the path through `bridge` and returns it; nodes whose
    /// tree link got saturated become orphans.
    fn augment(&mut self, bridge: u32) -> f64 {
        let ends = [
            self.arcs[(bridge ^ 1) as usize].head,
            self.arcs[bridge as usize].head,
        ];
        // The arc towards the sink along the path is `a ^ 1` in S (the parent arc points
        // up, against the flow) and `a` in T (with the flow).
        let down = |tree: Tree, a: u32| if tree == Tree::Source { a ^ 1 } else { a };
        let mut pushed = self.arcs[bridge as usize].cap;
        for (end, tree) in ends.into_iter().zip([Tree::Source, Tree::Sink]) {
            let mut v = end as usize;
            while self.nodes[v].parent != TERMINAL {
                let a = self.nodes[v].parent;
                pushed = pushed.min(self.arcs[down(tree, a) as usize].cap);
                v = self.arcs[a as usize].head as usize;
            }
            pushed = pushed.min(self.nodes[v].tr_cap.abs());
        }
        if pushed == f64::INFINITY {
            return pushed;
        }
        self.arcs[bridge as usize].cap -= pushed;
        self.arcs[(bridge ^ 1) as usize].cap += pushed;
        for (end, tree) in ends.into_iter().zip([Tree::Source, Tree::Sink]) {
            let mut v = end as usize;
            loop {
                let a = self.nodes[v].parent;
                let saturated = if a == TERMINAL {
                    let node = &mut self.nodes[v];
                    // S roots have tr_cap > 0, T roots < 0: both move towards zero.
                    node.tr_cap -= pushed.copysign(node.tr_cap);
                    node.tr_cap == 0.0
                } else {
                    self.arcs[down(tree, a) as usize].cap -= pushed;
                    self.arcs[(down(tree, a) ^ 1) as usize].cap += pushed;
                    self.arcs[down(tree, a) as usize].cap == 0.0
                };
                if saturated {
                    self.nodes[v].parent = ORPHAN;
                    self.orphans.push_back(v as u32);
                }
                if a == TERMINAL {
                    break;
                }
                v = self.arcs[a as usize].head as usize;
            }
        }
        pushed
    }

    /// Finds orphan `p` a new parent in its tree whose own path reaches the terminal,
    /// closest to the terminal; if there is none, frees `p` and orphans its children.
    fn adopt(&mut self, p: u32) {
        let tree = self.nodes[p as usize].tree;
        let time = self.time;
        let (mut best, mut best_dist) = (NONE, u32::MAX);
        let mut a = self.nodes[p as usize].first;
        while a != NONE {
            let q = self.arcs[a as usize].head;
            // q can be p's parent if the tree can reach p from q: arc a's reverse q → p.
            if self.nodes[q as usize].tree == tree && self.tree_cap(tree, a ^ 1) > 0.0 {
                // Walk up from q to the terminal or to a node whose distance is current.
                let (mut v, mut dist) = (q as usize, 0);
                loop {
                    let node = self.nodes[v];
                    if node.ts == time {
                        dist += node.dist;
                        break;
                    }
                    dist += 1;
                    if node.parent == TERMINAL {
                        (self.nodes[v].ts, self.nodes[v].dist) = (time, 1);
                        break;
                    }
                    if node.parent == ORPHAN {
                        dist = u32::MAX;
                        break;
                    }
                    v = self.arcs[node.parent as usize].head as usize;
                }
                if dist != u32::MAX {
                    if dist < best_dist {
                        (best, best_dist) = (a, dist);
                    }
                    // Mark the path so later walks stop early.
                    let mut v = q as usize;
                    while self.nodes[v].ts != time {
                        (self.nodes[v].ts, self.nodes[v].dist) = (time, dist);
                        dist -= 1;
                        v = self.arcs[self.nodes[v].parent as usize].head as usize;
                    }
                }
            }
            a = self.arcs[a as usize].next;
        }
        let node = &mut self.nodes[p as usize];
        if best != NONE {
            (node.parent, node.ts, node.dist) = (best, time, best_dist + 1);
            return;
        }
        (node.tree, node.parent) = (Tree::Free, NONE);
        let mut a = self.nodes[p as usize].first;
        while a != NONE {
            let q = self.arcs[a as usize].head;
            if self.nodes[q as usize].tree == tree {
                // A neighbour that could grow into p again must be active.
                if self.tree_cap(tree, a ^ 1) > 0.0 {
                    self.activate(q);
                }
                if self.nodes[q as usize].parent == a ^ 1 {
                    self.nodes[q as usize].parent = ORPHAN;
                    self.orphans.push_back(q);
                }
            }
            a = self.arcs[a as usize].next;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::random::counter_unit;

    /// A graph as plain lists, to build a [`MaxFlow`] from and to check cuts against.
    #[derive(Default)]
    struct Graph {
        n: usize,
        edges: Vec<(usize, usize, f64, f64)>,
        terminals: Vec<(usize, f64, f64)>,
    }

    impl Graph {
        fn load(&self, mf: &mut MaxFlow) {
            mf.reset(self.n);
            for &(a, b, ab, ba) in &self.edges {
                mf.add_edge(a, b, ab, ba);
            }
            for &(v, s, t) in &self.terminals {
                mf.add_terminal(v, s, t);
            }
        }

        /// The cost of the cut whose source side is `{v : source(v)}`.
        fn cut_cost(&self, source: impl Fn(usize) -> bool) -> f64 {
            let mut cost = 0.0;
            for &(v, s, t) in &self.terminals {
                cost += if source(v) { t } else { s };
            }
            for &(a, b, ab, ba) in &self.edges {
                if source(a) && !source(b) {
                    cost += ab;
                } else if source(b) && !source(a) {
                    cost += ba;
                }
            }
            cost
        }

        /// Minimum cut cost over all 2^n partitions, and the intersection of the source sides
        /// of all minimum cuts (as a bit mask): the set reachable from the source after any
        /// maximum flow.
        fn brute_force(&self) -> (f64, u32) {
            let (mut best, mut meet) = (f64::INFINITY, 0u32);
            for mask in 0u32..1 << self.n {
                let cost = self.cut_cost(|v| mask >> v & 1 == 1);
                if cost < best {
                    (best, meet) = (cost, mask);
                } else if cost == best {
                    meet &= mask;
                }
            }
            (best, meet)
        }
    }

    /// Counter-based uniform numbers in [0, 1) for one seed.
    struct Rng(u64, u64);

    impl Rng {
        fn unit(&mut self) -> f64 {
            self.1 += 1;
            counter_unit(self.0, 7, self.1) as f64
        }

        /// 0 one time in five, otherwise a multiple of 1/4 below 10 (exact sums).
        fn cap(&mut self) -> f64 {
            if self.unit() < 0.2 {
                0.0
            } else {
                (self.unit() * 40.0).floor() / 4.0
            }
        }
    }

    /// A random sparse graph on at most 10 nodes with parallel edges, repeated t-links and
    /// zeros; with `infinite`, some capacities and t-links are infinite.
    fn random_graph(seed: u64, infinite: bool) -> Graph {
        let mut rng = Rng(seed, 0);
        let n = 1 + (rng.unit() * 10.0) as usize;
        let mut g = Graph {
            n,
            ..Graph::default()
        };
        let cap = |rng: &mut Rng| {
            if infinite && rng.unit() < 0.15 {
                f64::INFINITY
            } else {
                rng.cap()
            }
        };
        for a in 0..n {
            for b in a + 1..n {
                let copies = if rng.unit() < 0.1 { 2 } else { 1 };
                for _ in 0..copies {
                    if rng.unit() < 0.35 {
                        let (ab, ba) = (cap(&mut rng), cap(&mut rng));
                        let e = if rng.unit() < 0.5 {
                            (a, b, ab, ba)
                        } else {
                            (b, a, ba, ab)
                        };
                        g.edges.push(e);
                    }
                }
            }
        }
        for v in 0..n {
            for _ in 0..(rng.unit() * 3.0) as usize {
                let (s, t) = (rng.cap(), rng.cap());
                g.terminals.push((v, s, t));
            }
            if infinite && rng.unit() < 0.4 {
                let hard = if rng.unit() < 0.5 {
                    (v, f64::INFINITY, 0.0)
                } else {
                    (v, 0.0, f64::INFINITY)
                };
                g.terminals.push(hard);
            }
        }
        g
    }

    fn sides(mf: &MaxFlow, n: usize) -> u32 {
        (0..n)
            .filter(|&v| mf.is_source_side(v))
            .map(|v| 1 << v)
            .sum()
    }

    #[test]
    fn max_flow_equals_brute_force_min_cut() {
        let mut mf = MaxFlow::new();
        for seed in 0..3000 {
            let g = random_graph(seed, false);
            g.load(&mut mf);
            let flow = mf.solve();
            let (best, meet) = g.brute_force();
            // Quarter-integer capacities: every sum is exact, so compare exactly.
            assert_eq!(flow, best, "seed {seed}");
            assert_eq!(g.cut_cost(|v| mf.is_source_side(v)), best, "seed {seed}");
            assert_eq!(
                sides(&mf, g.n),
                meet,
                "seed {seed}: not the residual-reachable set"
            );
        }
    }

    #[test]
    fn max_flow_respects_infinite_capacities() {
        let (mut finite, mut infinite, mut hard) = (0, 0, 0);
        let mut mf = MaxFlow::new();
        for seed in 0..1500 {
            let g = random_graph(100_000 + seed, true);
            g.load(&mut mf);
            let flow = mf.solve();
            let (best, meet) = g.brute_force();
            assert_eq!(flow, best, "seed {seed}");
            if best == f64::INFINITY {
                infinite += 1;
                continue;
            }
            finite += 1;
            assert_eq!(g.cut_cost(|v| mf.is_source_side(v)), best, "seed {seed}");
            assert_eq!(sides(&mf, g.n), meet, "seed {seed}");
            for &(v, s, t) in &g.terminals {
                hard += (s == f64::INFINITY || t == f64::INFINITY) as usize;
                if s == f64::INFINITY {
                    assert!(
                        mf.is_source_side(v),
                        "seed {seed}: node {v} tied to the source"
                    );
                }
                if t == f64::INFINITY {
                    assert!(
                        !mf.is_source_side(v),
                        "seed {seed}: node {v} tied to the sink"
                    );
                }
            }
        }
        // Both kinds of graph and many hard t-links were exercised.
        assert!(
            finite > 300 && infinite > 30 && hard > 300,
            "{finite}, {infinite}, {hard}"
        );
    }

    #[test]
    fn max_flow_infinite_paths_give_infinity() {
        let mut mf = MaxFlow::new();
        mf.reset(2);
        mf.add_terminal(0, f64::INFINITY, 1.0);
        mf.add_terminal(0, 0.0, f64::INFINITY);
        assert_eq!(mf.solve(), f64::INFINITY);
        mf.reset(3);
        mf.add_terminal(0, f64::INFINITY, 0.0);
        mf.add_edge(0, 1, f64::INFINITY, 0.0);
        mf.add_edge(1, 2, f64::INFINITY, 2.0);
        mf.add_terminal(2, 1.0, f64::INFINITY);
        assert_eq!(mf.solve(), f64::INFINITY);
        // Reversed, the same edges block nothing: only 2's source t-link and 1 → 0 cross.
        mf.reset(3);
        mf.add_terminal(2, f64::INFINITY, 0.0);
        mf.add_edge(0, 1, f64::INFINITY, 3.0);
        mf.add_edge(1, 2, f64::INFINITY, 2.0);
        mf.add_terminal(0, 1.0, f64::INFINITY);
        assert_eq!(mf.solve(), 3.0);
        assert_eq!(sides(&mf, 3), 0b100);
    }

    /// Cormen et al., "Introduction to Algorithms" (3rd ed.), Figure 26.1: maximum flow 23,
    /// minimum cut ({s, v1, v2, v4}, {v3, t}) through v1→v3 (12), v4→v3 (7) and v4→t (4).
    #[test]
    fn max_flow_textbook_example() {
        let (v1, v2, v3, v4) = (0, 1, 2, 3);
        let mut mf = MaxFlow::new();
        mf.reset(4);
        mf.add_terminal(v1, 16.0, 0.0);
        mf.add_terminal(v2, 13.0, 0.0);
        mf.add_edge(v2, v1, 4.0, 0.0);
        mf.add_edge(v1, v3, 12.0, 0.0);
        mf.add_edge(v3, v2, 9.0, 0.0);
        mf.add_edge(v2, v4, 14.0, 0.0);
        mf.add_edge(v4, v3, 7.0, 0.0);
        mf.add_terminal(v3, 0.0, 20.0);
        mf.add_terminal(v4, 0.0, 4.0);
        assert_eq!(mf.solve(), 23.0);
        assert_eq!(
            [v1, v2, v3, v4].map(|v| mf.is_source_side(v)),
            [true, true, false, true]
        );
        // Solving again changes nothing.
        assert_eq!(mf.solve(), 23.0);
        assert_eq!(sides(&mf, 4), 0b1011);
    }

    /// A w×h 4-connected grid with quarter-integer weights, the left column tied to the
    /// source and the right one to the sink with infinity, random t-links elsewhere.
    fn grid(seed: u64, w: usize, h: usize) -> Graph {
        let mut rng = Rng(seed, 0);
        let mut g = Graph {
            n: w * h,
            ..Graph::default()
        };
        for y in 0..h {
            for x in 0..w {
                let v = y * w + x;
                let weight = |rng: &mut Rng| (rng.unit() * 400.0).floor() / 4.0;
                if x + 1 < w {
                    g.edges.push((v, v + 1, weight(&mut rng), weight(&mut rng)));
                }
                if y + 1 < h {
                    g.edges.push((v, v + w, weight(&mut rng), weight(&mut rng)));
                }
                if x == 0 {
                    g.terminals.push((v, f64::INFINITY, 0.0));
                } else if x + 1 == w {
                    g.terminals.push((v, 0.0, f64::INFINITY));
                } else if rng.unit() < 0.1 {
                    g.terminals.push((v, weight(&mut rng), weight(&mut rng)));
                }
            }
        }
        g
    }

    #[test]
    fn max_flow_reset_reuses_like_fresh_instances() {
        let graphs: Vec<Graph> = [
            grid(1, 20, 20),
            random_graph(3, false),
            Graph::default(),
            random_graph(4, true),
            grid(2, 30, 10),
            random_graph(5, false),
        ]
        .into_iter()
        .collect();
        let mut reused = MaxFlow::new();
        let mut arc_capacity = 0;
        for (i, g) in graphs.iter().enumerate() {
            g.load(&mut reused);
            let flow = reused.solve();
            let mut fresh = MaxFlow::new();
            g.load(&mut fresh);
            assert_eq!(flow.to_bits(), fresh.solve().to_bits(), "graph {i}");
            for v in 0..g.n {
                assert_eq!(
                    reused.is_source_side(v),
                    fresh.is_source_side(v),
                    "graph {i}"
                );
            }
            // reset keeps the allocations of the largest graph so far.
            assert!(reused.arcs.capacity() >= arc_capacity);
            arc_capacity = reused.arcs.capacity();
        }
        assert!(arc_capacity >= 2 * 2 * 20 * 19);
    }

    /// Edmonds–Karp (shortest augmenting paths by breadth-first search), independent of the
    /// code above. Returns the flow and the set reachable from the source afterwards.
    fn edmonds_karp(g: &Graph) -> (f64, Vec<bool>) {
        let (source, sink) = (g.n, g.n + 1);
        let mut out: Vec<Vec<usize>> = vec![Vec::new(); g.n + 2];
        let (mut head, mut cap) = (Vec::new(), Vec::new());
        let mut arc = |a: usize, b: usize, c: f64, out: &mut Vec<Vec<usize>>| {
            out[a].push(head.len());
            head.push(b);
            cap.push(c);
        };
        for &(a, b, ab, ba) in &g.edges {
            arc(a, b, ab, &mut out);
            arc(b, a, ba, &mut out);
        }
        for &(v, s, t) in &g.terminals {
            arc(source, v, s, &mut out);
            arc(v, source, 0.0, &mut out);
            arc(v, sink, t, &mut out);
            arc(sink, v, 0.0, &mut out);
        }
        let mut flow = 0.0;
        loop {
            let mut via = vec![usize::MAX; g.n + 2];
            let mut seen = vec![false; g.n + 2];
            seen[source] = true;
            let mut queue = VecDeque::from([source]);
            while let Some(v) = queue.pop_front() {
                for &a in &out[v] {
                    if cap[a] > 0.0 && !seen[head[a]] {
                        seen[head[a]] = true;
                        via[head[a]] = a;
                        queue.push_back(head[a]);
                    }
                }
            }
            if !seen[sink] {
                seen.truncate(g.n);
                return (flow, seen);
            }
            let mut pushed = f64::INFINITY;
            let mut v = sink;
            while v != source {
                pushed = pushed.min(cap[via[v]]);
                v = head[via[v] ^ 1];
            }
            let mut v = sink;
            while v != source {
                cap[via[v]] -= pushed;
                cap[via[v] ^ 1] += pushed;
                v = head[via[v] ^ 1];
            }
            flow += pushed;
        }
    }

    #[test]
    fn max_flow_grid_agrees_with_edmonds_karp() {
        for seed in 0..2 {
            let g = grid(100 + seed, 50, 50);
            let mut mf = MaxFlow::new();
            g.load(&mut mf);
            let flow = mf.solve();
            let (expected, reachable) = edmonds_karp(&g);
            assert!(flow > 0.0 && flow.is_finite());
            assert_eq!(flow, expected, "seed {seed}");
            assert_eq!(g.cut_cost(|v| mf.is_source_side(v)), flow, "seed {seed}");
            for v in 0..g.n {
                assert_eq!(mf.is_source_side(v), reachable[v], "seed {seed}, node {v}");
            }
        }
    }
}

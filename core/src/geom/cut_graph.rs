//! Cut graphs that open a mesh into a topological disk, and the cutting itself.
//!
//! The cut is the tree-cotree construction with Erickson & Whittlesey's greedy choice
//! ("Greedy optimal homotopy and homology generators", SODA 2005): a shortest-path tree T
//! (Dijkstra on edge lengths) from a root, then a maximum spanning tree C of the dual graph
//! over the edges not in T, weighted by the length of each edge's loop (the edge plus the
//! tree paths from its ends to the root). The 2g edges in neither tree, with their tree paths,
//! are the shortest system of loops through the root; dangling tree branches are pruned.
//! Several roots are tried (farthest-point samples) and the shortest cut is kept.
//!
//! Open meshes: each boundary loop is closed by a virtual vertex joined to every loop vertex
//! by a zero-length spoke (a fan of virtual triangles), the construction runs on the closed
//! surface, the virtual vertices are kept from pruning (so the cut joins every loop, along
//! shortest paths between loops), and the spokes are dropped. Loop edges go first into the
//! dual tree, so they never become cut edges. Closed genus-0 meshes get the shortest path
//! between two far-apart vertices (a double Dijkstra sweep), lengthened to two edges when it
//! has fewer (a one-edge cut splits no vertex, so it opens nothing: the tetrahedron).
//!
//! Optional extremity cuts (a simple form of Gu et al. 2002's iterative cuts and of Zhu et
//! al. 2003's skeleton-based seams): shortest paths from the cut to the vertex farthest from
//! it, one at a time; they let protrusions open up in the plane, which lowers stretch.
//!
//! [`cut_to_disk`] splits the mesh along a cut: a vertex whose triangles are separated by d
//! cut edges (or by the boundary and d cut edges) becomes d (or d + 1) *wedge* vertices.

use super::Mesh;
use super::half_edge::{HalfEdgeMesh, NONE, TopologyError};
use crate::graph::{Csr, Dijkstra};
use glam::Vec3;

#[derive(Debug, thiserror::Error)]
pub enum CutError {
    #[error(transparent)]
    Topology(#[from] TopologyError),
    #[error(
        "the mesh has {count} connected components; a geometry image needs exactly one \
         (split the mesh or remove the extra pieces)"
    )]
    SeveralComponents { count: usize },
    #[error("the cut has {got} entries but the mesh has {expected} edges")]
    CutLength { expected: usize, got: usize },
    #[error("internal error in the cut graph (a bug, please report): {0}")]
    Internal(String),
}

/// Roots tried by the tree-cotree construction (the shortest cut wins).
const ROOT_CANDIDATES: usize = 6;
/// At most this many passes over the cut paths when straightening a cut.
const STRAIGHTEN_PASSES: usize = 8;

/// A cut graph on the edges of a [`HalfEdgeMesh`].
#[derive(Debug, Clone)]
pub struct CutGraph {
    /// Per edge of the half-edge mesh: whether it is cut.
    pub is_cut: Vec<bool>,
    /// The cut edges, ascending.
    pub edges: Vec<u32>,
    /// Total length of the cut edges.
    pub length: f64,
    /// Genus and boundary loops of the (single) component.
    pub genus: i64,
    pub boundary_loops: usize,
    /// The vertices the extremity cuts and then the cuts to `targets` run to, in the order
    /// they were added (a target already on the cut is not listed).
    pub extremities: Vec<u32>,
}

impl CutGraph {
    /// Number of cut edges at each vertex.
    pub fn degrees(&self, he: &HalfEdgeMesh) -> Vec<u32> {
        let mut d = vec![0u32; he.vertex_count()];
        for &e in &self.edges {
            let (a, b) = he.edge_vertices(e);
            d[a as usize] += 1;
            d[b as usize] += 1;
        }
        d
    }
}

/// The surface closed by virtual fans, as an edge list with a compressed adjacency, plus the
/// dual graph's edge endpoints.
struct Augmented {
    /// Real vertices `0..nv`, then one virtual vertex per boundary loop.
    node_count: usize,
    /// Real edges `0..ne`, then one spoke per boundary vertex.
    ends: Vec<(u32, u32)>,
    len: Vec<f64>,
    /// Dual endpoints per edge: faces `0..nf`, then one virtual triangle per boundary edge.
    dual: Vec<(u32, u32)>,
    dual_count: usize,
    /// Whether the edge is a boundary edge of the input (its dual goes first into C).
    loop_edge: Vec<bool>,
    /// Per node, its (neighbour, edge) pairs.
    adj: Csr<(u32, u32)>,
    real_edges: usize,
}

impl Augmented {
    fn new(he: &HalfEdgeMesh, positions: &[Vec3]) -> Self {
        let nv = he.vertex_count();
        let ne = he.edge_count();
        let nf = he.face_count();
        let loops = he.boundary_loops();
        let mut ends = Vec::with_capacity(ne + ne / 8);
        let mut len = Vec::with_capacity(ends.capacity());
        let mut loop_edge = vec![false; ne];
        // Running index of each boundary face half-edge over all loops.
        let mut loop_pos = std::collections::HashMap::new();
        let mut s = 0u32;
        for lp in loops {
            for &h in lp {
                loop_pos.insert(h, s);
                s += 1;
            }
        }
        let mut dual = Vec::with_capacity(ends.capacity());
        for e in 0..ne as u32 {
            let (a, b) = he.edge_vertices(e);
            ends.push((a, b));
            len.push(
                (positions[a as usize].as_dvec3() - positions[b as usize].as_dvec3()).length(),
            );
            let h = he.edge_half_edge(e);
            let t = he.twin(h);
            if he.is_boundary_half_edge(t) {
                loop_edge[e as usize] = true;
                dual.push((he.face(h), nf as u32 + loop_pos[&h]));
            } else {
                dual.push((he.face(h), he.face(t)));
            }
        }
        let mut offset = 0u32;
        for (i, lp) in loops.iter().enumerate() {
            let w = (nv + i) as u32;
            let n = lp.len() as u32;
            for k in 0..n {
                // The spoke at the start of lp[k], between the virtual triangles of lp[k - 1]
                // and lp[k].
                ends.push((he.origin(lp[k as usize]), w));
                len.push(0.0);
                loop_edge.push(false);
                let prev = offset + (k + n - 1) % n;
                dual.push((nf as u32 + prev, nf as u32 + offset + k));
            }
            offset += n;
        }
        let node_count = nv + loops.len();
        let adj = Csr::from_pairs(
            node_count,
            ends.iter().enumerate().flat_map(|(e, &(a, b))| {
                [(a as usize, (b, e as u32)), (b as usize, (a, e as u32))]
            }),
        );
        Augmented {
            node_count,
            ends,
            len,
            dual,
            dual_count: nf + offset as usize,
            loop_edge,
            adj,
            real_edges: ne,
        }
    }

    fn neighbors(&self, v: u32) -> &[(u32, u32)] {
        self.adj.row(v as usize)
    }

    /// Multi-source Dijkstra. Returns (distance, parent edge) per node; unreached nodes have
    /// +inf and `NONE`. With `real_only`, spokes are not used. Ties go to the smaller node
    /// index ([`Dijkstra`]'s order).
    fn dijkstra(&self, sources: &[u32], real_only: bool) -> (Vec<f64>, Vec<u32>) {
        let mut search = Dijkstra::new(self.node_count, NONE);
        for &s in sources {
            search.add_source(s);
        }
        search.run(&[], |search, v, d| {
            for &(w, e) in self.neighbors(v) {
                if real_only && e as usize >= self.real_edges {
                    continue;
                }
                search.relax(w, d + self.len[e as usize], e);
            }
        });
        search.into_parts()
    }

    fn other(&self, e: u32, v: u32) -> u32 {
        let (a, b) = self.ends[e as usize];
        if a == v { b } else { a }
    }

    /// Removes dangling branches from `selected`: repeatedly drops the edge at a vertex of
    /// degree 1 that is not a terminal.
    fn prune(&self, selected: &mut [bool], terminal: &[bool]) {
        let mut degree = vec![0u32; self.node_count];
        for (e, &s) in selected.iter().enumerate() {
            if s {
                let (a, b) = self.ends[e];
                degree[a as usize] += 1;
                degree[b as usize] += 1;
            }
        }
        let mut stack: Vec<u32> = (0..self.node_count as u32)
            .filter(|&v| degree[v as usize] == 1 && !terminal[v as usize])
            .collect();
        while let Some(v) = stack.pop() {
            if degree[v as usize] != 1 {
                continue;
            }
            let Some(&(w, e)) = self
                .neighbors(v)
                .iter()
                .find(|&&(_, e)| selected[e as usize])
            else {
                continue;
            };
            selected[e as usize] = false;
            degree[v as usize] -= 1;
            degree[w as usize] -= 1;
            if degree[w as usize] == 1 && !terminal[w as usize] {
                stack.push(w);
            }
        }
    }

    /// Tree-cotree from `root`: the selected (pruned) edges, the root's distances, and the
    /// number of leftover edges (2g).
    fn tree_cotree(&self, root: u32, terminal: &[bool]) -> (Vec<bool>, Vec<f64>, usize) {
        let (dist, parent) = self.dijkstra(&[root], false);
        let ne = self.ends.len();
        let mut in_tree = vec![false; ne];
        for &p in &parent {
            if p != NONE {
                in_tree[p as usize] = true;
            }
        }
        // Dual edges not in T, loop edges first, then by decreasing loop length.
        let mut order: Vec<(bool, u64, u32)> = (0..ne as u32)
            .filter(|&e| !in_tree[e as usize])
            .map(|e| {
                let (a, b) = self.ends[e as usize];
                let l = dist[a as usize] + dist[b as usize] + self.len[e as usize];
                (!self.loop_edge[e as usize], u64::MAX - l.to_bits(), e)
            })
            .collect();
        order.sort_unstable();
        let mut uf = UnionFind::new(self.dual_count);
        let mut selected = in_tree;
        let mut leftovers = 0;
        for &(_, _, e) in &order {
            let (f, g) = self.dual[e as usize];
            if !uf.union(f, g) {
                selected[e as usize] = true;
                leftovers += 1;
            }
        }
        self.prune(&mut selected, terminal);
        (selected, dist, leftovers)
    }

    fn length(&self, selected: &[bool]) -> f64 {
        selected
            .iter()
            .enumerate()
            .filter(|&(_, &s)| s)
            .map(|(e, _)| self.len[e])
            .sum()
    }
}

struct UnionFind(Vec<u32>);

impl UnionFind {
    fn new(n: usize) -> Self {
        UnionFind((0..n as u32).collect())
    }

    fn find(&mut self, mut x: u32) -> u32 {
        while self.0[x as usize] != x {
            let p = self.0[self.0[x as usize] as usize];
            self.0[x as usize] = p;
            x = p;
        }
        x
    }

    /// Joins the sets of a and b; false if they were already one set.
    fn union(&mut self, a: u32, b: u32) -> bool {
        let (ra, rb) = (self.find(a), self.find(b));
        if ra == rb {
            return false;
        }
        let (lo, hi) = (ra.min(rb), ra.max(rb));
        self.0[hi as usize] = lo;
        true
    }
}

/// The farthest reached node (largest finite distance, smallest index on ties) among
/// `0..limit`.
fn farthest(dist: &[f64], limit: usize) -> Option<(u32, f64)> {
    let mut best: Option<(u32, f64)> = None;
    for (v, &d) in dist[..limit].iter().enumerate() {
        if d.is_finite() && best.is_none_or(|(_, bd)| d > bd) {
            best = Some((v as u32, d));
        }
    }
    best
}

/// A cut graph that opens the single component of `he` into a disk (see the module doc),
/// plus `extremity_cuts` paths to extremities, then a shortest path from the cut to each of
/// `targets` (vertices of `he`; one already on the cut adds nothing).
pub fn cut_graph(
    he: &HalfEdgeMesh,
    positions: &[Vec3],
    extremity_cuts: u32,
    targets: &[u32],
) -> Result<CutGraph, CutError> {
    let comps = he.components();
    if comps.len() != 1 {
        return Err(CutError::SeveralComponents { count: comps.len() });
    }
    let comp = comps[0];
    let aug = Augmented::new(he, positions);
    let nv = he.vertex_count();
    let nl = he.boundary_loops().len();
    let first_used = (0..nv as u32)
        .find(|&v| he.is_used(v))
        .expect("a component has vertices");
    let mut terminal = vec![false; aug.node_count];
    for i in 0..nl {
        terminal[nv + i] = true;
    }
    let ne_real = he.edge_count();
    let sphere = comp.genus == 0 && nl == 0;
    let selected: Vec<bool> = if sphere {
        // Closed sphere: the path between two far-apart vertices (double sweep).
        let (d0, _) = aug.dijkstra(&[first_used], true);
        let (a, _) = farthest(&d0, nv).expect("reached");
        let (da, parent) = aug.dijkstra(&[a], true);
        let (b, _) = farthest(&da, nv).expect("reached");
        let mut sel = vec![false; aug.ends.len()];
        let mut path = 0;
        let mut v = b;
        while v != a {
            let e = parent[v as usize];
            sel[e as usize] = true;
            path += 1;
            v = aug.other(e, v);
        }
        // Cutting a path splits only its inner vertices: a path of one edge (a tetrahedron,
        // or coincident vertices at zero distance) opens nothing, and of none cuts nothing.
        // Such a path is lengthened at its far end by the neighbour farthest from `a` (ties:
        // smaller index), which exists since every vertex of a closed surface has three.
        let mut end = b;
        while path < 2 {
            let mut next: Option<(u32, u32)> = None;
            for &(w, e) in aug.neighbors(end) {
                if (e as usize) < ne_real && !sel[e as usize] && w != a && w != end {
                    let better = next.is_none_or(|(bw, _)| {
                        da[w as usize] > da[bw as usize]
                            || (da[w as usize] == da[bw as usize] && w < bw)
                    });
                    if better {
                        next = Some((w, e));
                    }
                }
            }
            let Some((w, e)) = next else {
                return Err(CutError::Internal(format!(
                    "vertex {end} has no neighbour to lengthen the sphere's cut"
                )));
            };
            sel[e as usize] = true;
            path += 1;
            end = w;
        }
        sel
    } else if comp.genus == 0 && nl == 1 {
        // Already a disk.
        vec![false; aug.ends.len()]
    } else {
        // Root candidates: the first loop's virtual vertex (open meshes), then farthest-point
        // samples of the real vertices. The shortest cut wins; ties keep the earlier root.
        let mut best: Option<(f64, Vec<bool>)> = None;
        let mut min_dist = aug.dijkstra(&[first_used], true).0;
        let mut roots = Vec::new();
        if nl > 0 {
            roots.push(nv as u32);
        }
        let mut k = 0;
        while k < ROOT_CANDIDATES {
            let root = if k < roots.len() {
                roots[k]
            } else {
                let (r, _) = farthest(&min_dist, nv).expect("reached");
                roots.push(r);
                r
            };
            let (sel, dist, leftovers) = aug.tree_cotree(root, &terminal);
            if leftovers as i64 != 2 * comp.genus {
                return Err(CutError::Internal(format!(
                    "tree-cotree left {leftovers} edges, expected 2g = {}",
                    2 * comp.genus
                )));
            }
            for v in 0..nv {
                min_dist[v] = min_dist[v].min(dist[v]);
            }
            let l = aug.length(&sel);
            if best.as_ref().is_none_or(|(bl, _)| l < *bl) {
                best = Some((l, sel));
            }
            k += 1;
        }
        best.expect("at least one root").1
    };
    let ne = he.edge_count();
    let mut is_cut = vec![false; ne];
    for e in 0..ne {
        if selected[e] {
            if aug.loop_edge[e] {
                return Err(CutError::Internal(format!(
                    "boundary edge {e} ended up in the cut"
                )));
            }
            is_cut[e] = true;
        }
    }
    // A sphere's cut is already a shortest path (or one lengthened on purpose, above).
    if !sphere {
        straighten(he, &aug.len[..ne], &mut is_cut, STRAIGHTEN_PASSES);
    }
    // Extremity cuts: shortest paths from the cut (and the boundary) to the farthest vertex.
    let mut extremities = Vec::new();
    let mut on_cut = vec![false; nv];
    for e in 0..ne {
        if is_cut[e] || aug.loop_edge[e] {
            let (a, b) = aug.ends[e];
            on_cut[a as usize] = true;
            on_cut[b as usize] = true;
        }
    }
    // Cuts the shortest path from the cut to `x` (found in `parent`) into the cut.
    let mut cut_path_to = |x: u32, parent: &[u32], on_cut: &mut [bool]| {
        let mut v = x;
        while !on_cut[v as usize] {
            on_cut[v as usize] = true;
            let e = parent[v as usize];
            is_cut[e as usize] = true;
            v = aug.other(e, v);
        }
    };
    let sources_of =
        |on_cut: &[bool]| -> Vec<u32> { (0..nv as u32).filter(|&v| on_cut[v as usize]).collect() };
    for _ in 0..extremity_cuts {
        let (dist, parent) = aug.dijkstra(&sources_of(&on_cut), true);
        let Some((x, d)) = farthest(&dist, nv) else {
            break;
        };
        if d <= 0.0 {
            break;
        }
        extremities.push(x);
        cut_path_to(x, &parent, &mut on_cut);
    }
    for &x in targets {
        if (x as usize) >= nv || !he.is_used(x) {
            return Err(CutError::Internal(format!(
                "cut target {x} is not a vertex of the mesh"
            )));
        }
        if on_cut[x as usize] {
            continue;
        }
        let (dist, parent) = aug.dijkstra(&sources_of(&on_cut), true);
        if !dist[x as usize].is_finite() {
            return Err(CutError::Internal(format!(
                "cut target {x} is not reachable from the cut"
            )));
        }
        extremities.push(x);
        cut_path_to(x, &parent, &mut on_cut);
    }
    let edges: Vec<u32> = (0..ne as u32).filter(|&e| is_cut[e as usize]).collect();
    // A fold from +0 (an empty float sum is -0).
    let length = edges.iter().fold(0.0, |acc, &e| acc + aug.len[e as usize]);
    Ok(CutGraph {
        is_cut,
        edges,
        length,
        genus: comp.genus,
        boundary_loops: nl,
        extremities,
    })
}

/// The wedges of a cut: per face corner (half-edge `3f + k`) its wedge vertex, and per wedge
/// its original vertex. A vertex's corners are split wherever the ring around it crosses a
/// cut edge or the boundary. Wedges are numbered by original vertex, then around it.
fn split_wedges(he: &HalfEdgeMesh, is_cut: &[bool]) -> (Vec<u32>, Vec<u32>) {
    let mut corner_vertex = vec![NONE; 3 * he.face_count()];
    let mut original_vertex = Vec::new();
    let mut ring = Vec::new();
    for v in 0..he.vertex_count() as u32 {
        ring.clear();
        ring.extend(he.outgoing(v));
        if ring.is_empty() {
            continue;
        }
        let separates = |h: u32| he.is_boundary_half_edge(h) || is_cut[he.edge(h) as usize];
        let start = ring.iter().position(|&h| separates(h)).unwrap_or(0);
        for i in 0..ring.len() {
            let h = ring[(start + i) % ring.len()];
            if i == 0 || separates(h) {
                original_vertex.push(v);
            }
            if !he.is_boundary_half_edge(h) {
                corner_vertex[h as usize] = original_vertex.len() as u32 - 1;
            }
        }
    }
    (corner_vertex, original_vertex)
}

/// Whether cutting along `is_cut` (interior edges only) leaves one disk: the triangles stay
/// connected and the Euler characteristic of the cut surface is 1.
fn cuts_to_disk(he: &HalfEdgeMesh, is_cut: &[bool]) -> bool {
    // A cut edge between two interior vertices that are both cut only there splits neither:
    // its two sides would be two edges between the same vertices, which a triangle mesh
    // cannot hold (the count below would still come out as a disk).
    let mut degree = vec![0u32; he.vertex_count()];
    for e in 0..he.edge_count() as u32 {
        if is_cut[e as usize] {
            let (a, b) = he.edge_vertices(e);
            degree[a as usize] += 1;
            degree[b as usize] += 1;
        }
    }
    let tip = |v: u32| degree[v as usize] == 1 && !he.is_boundary_vertex(v);
    if (0..he.edge_count() as u32).any(|e| {
        let (a, b) = he.edge_vertices(e);
        is_cut[e as usize] && tip(a) && tip(b)
    }) {
        return false;
    }
    let (_, ov) = split_wedges(he, is_cut);
    let cut_count = is_cut.iter().filter(|&&c| c).count();
    let chi = ov.len() as i64 - (he.edge_count() + cut_count) as i64 + he.face_count() as i64;
    if chi != 1 {
        return false;
    }
    let mut uf = UnionFind::new(he.face_count());
    let mut parts = he.face_count();
    for e in 0..he.edge_count() as u32 {
        let h = he.edge_half_edge(e);
        let t = he.twin(h);
        if !is_cut[e as usize] && !he.is_boundary_half_edge(t) && uf.union(he.face(h), he.face(t)) {
            parts -= 1;
        }
    }
    parts == 1
}

/// One path of a cut graph between cut-nodes (vertices of cut degree ≠ 2, and cut vertices on
/// the mesh boundary): its end vertices (the same for a loop at one node) and edges in order.
struct CutPath {
    a: u32,
    b: u32,
    edges: Vec<u32>,
    length: f64,
}

/// The cut graph's paths between cut-nodes (cycles with no node are left out).
fn cut_paths(he: &HalfEdgeMesh, is_cut: &[bool], len: &[f64]) -> Vec<CutPath> {
    let mut degree = vec![0u32; he.vertex_count()];
    for e in 0..he.edge_count() as u32 {
        if is_cut[e as usize] {
            let (a, b) = he.edge_vertices(e);
            degree[a as usize] += 1;
            degree[b as usize] += 1;
        }
    }
    let is_node = |v: u32| {
        let d = degree[v as usize];
        d != 0 && (d != 2 || he.is_boundary_vertex(v))
    };
    let mut seen = vec![false; he.edge_count()];
    let mut paths = Vec::new();
    for a in 0..he.vertex_count() as u32 {
        if !is_node(a) {
            continue;
        }
        for h0 in he.outgoing(a) {
            let e0 = he.edge(h0);
            if !is_cut[e0 as usize] || seen[e0 as usize] {
                continue;
            }
            seen[e0 as usize] = true;
            let mut edges = vec![e0];
            let mut v = he.dest(h0);
            let mut last = e0;
            while !is_node(v) {
                let Some(h) = he
                    .outgoing(v)
                    .find(|&h| is_cut[he.edge(h) as usize] && he.edge(h) != last)
                else {
                    break;
                };
                last = he.edge(h);
                seen[last as usize] = true;
                edges.push(last);
                v = he.dest(h);
            }
            let length = edges.iter().map(|&e| len[e as usize]).sum();
            paths.push(CutPath {
                a,
                b: v,
                edges,
                length,
            });
        }
    }
    paths
}

/// Straightens a cut graph path by path (keeping it a cut to a disk): each path between
/// cut-nodes a and b is replaced by the shortest path from a to b on the surface cut along
/// the rest of the cut graph, where running along the rest of the cut (or the mesh boundary)
/// costs nothing. That surface is an annulus, and the wedges of a and b that the old path
/// leaves from and arrives at lie on different boundary circles, so any path between them
/// reopens it into a disk; the replacement is kept when the total cut is
/// shorter and the result checks out as a disk. This merges cut paths that a shortest-path
/// tree leaves running side by side (thin strips between them would be crushed by the map to
/// the square) and shortens the cut. Each pass tries every path once, longest first; passes
/// repeat while they change something, at most `max_passes`.
fn straighten(he: &HalfEdgeMesh, len: &[f64], is_cut: &mut Vec<bool>, max_passes: usize) {
    let total = |c: &[bool]| -> f64 {
        c.iter()
            .enumerate()
            .filter(|&(_, &x)| x)
            .map(|(e, _)| len[e])
            .sum()
    };
    let mut scratch = CrossingScratch::new(he);
    // A path that could not be improved is not retried: other replacements rarely open a
    // shortcut for it, and the search is the expensive part.
    let mut failed = std::collections::HashSet::new();
    // Every replacement keeps a disk (see above), so the disk test runs once per pass; should
    // it ever fail, the pass is redone testing each replacement.
    let mut checked = false;
    let mut pass = 0;
    while pass < max_passes {
        let before = is_cut.clone();
        let failed_before = failed.clone();
        let mut current = total(is_cut);
        let mut paths = cut_paths(he, is_cut, len);
        paths.sort_by(|p, q| {
            q.length
                .total_cmp(&p.length)
                .then(p.edges[0].cmp(&q.edges[0]))
        });
        let mut changed = false;
        for p in &paths {
            let key = blake3::hash(bytemuck::cast_slice(&p.edges));
            // Earlier replacements in this pass may have removed some of its edges. (A path
            // whose ends stopped being nodes is still fine: any stretch of a cut path whose
            // inner vertices have cut degree 2 opens the same kind of annulus.)
            if failed.contains(&key) || p.edges.iter().any(|&e| !is_cut[e as usize]) {
                continue;
            }
            let mut rest = is_cut.clone();
            for &e in &p.edges {
                rest[e as usize] = false;
            }
            let ends = ((p.a, p.edges[0]), (p.b, *p.edges.last().unwrap()));
            let bound = p.length * (1.0 - 1e-9);
            let Some(route) =
                shortest_crossing(he, len, &rest, ends.0, ends.1, bound, &mut scratch)
            else {
                failed.insert(key);
                continue;
            };
            let mut candidate = rest;
            for e in route {
                if !he.is_boundary_edge(e) {
                    candidate[e as usize] = true;
                }
            }
            let l = total(&candidate);
            if l < current * (1.0 - 1e-9) && (!checked || cuts_to_disk(he, &candidate)) {
                *is_cut = candidate;
                current = l;
                changed = true;
            } else {
                failed.insert(key);
            }
        }
        if changed && !checked && !cuts_to_disk(he, is_cut) {
            *is_cut = before;
            failed = failed_before;
            checked = true;
            continue;
        }
        if !changed {
            break;
        }
        pass += 1;
    }
}

/// Scratch space for [`shortest_crossing`], reused across calls: the search over corners
/// (face half-edges), recording with each wedge the (wedge, edge) it was reached from.
struct CrossingScratch {
    search: Dijkstra<(u32, u32)>,
    /// Per vertex, its smallest outgoing face half-edge (the name of an uncut ring's wedge).
    ring_min: Vec<u32>,
    /// Per vertex, whether its ring is split (by the cut or the boundary).
    split: Vec<bool>,
}

impl CrossingScratch {
    fn new(he: &HalfEdgeMesh) -> Self {
        let n = 3 * he.face_count();
        let mut ring_min = vec![NONE; he.vertex_count()];
        for h in 0..n as u32 {
            let v = he.origin(h) as usize;
            ring_min[v] = ring_min[v].min(h);
        }
        CrossingScratch {
            search: Dijkstra::new(n, (NONE, NONE)),
            ring_min,
            split: vec![false; he.vertex_count()],
        }
    }
}

/// The shortest path on the surface cut along `cut` between the wedges of `a` and `b` that
/// hold the (uncut) edges `ea` at a and `eb` at b, where edges on the cut surface's boundary
/// are free; returned as edges of the input (some may be cut or boundary edges already).
/// `None` unless some path costs less than `bound`.
///
/// The cut surface is explored lazily: a wedge is named by its first corner counter-clockwise
/// (the outgoing half-edge just after a separating edge, or the smallest of a whole ring), so
/// the search touches only the region within `bound` of a.
fn shortest_crossing(
    he: &HalfEdgeMesh,
    len: &[f64],
    cut: &[bool],
    (a, ea): (u32, u32),
    (b, eb): (u32, u32),
    bound: f64,
    scratch: &mut CrossingScratch,
) -> Option<Vec<u32>> {
    let separates = |h: u32| cut[he.edge(h) as usize] || he.is_boundary_half_edge(he.twin(h));
    let ring_min = std::mem::take(&mut scratch.ring_min);
    let mut split = std::mem::take(&mut scratch.split);
    for v in 0..he.vertex_count() as u32 {
        split[v as usize] = he.is_boundary_vertex(v);
    }
    for e in 0..he.edge_count() as u32 {
        if cut[e as usize] {
            let (x, y) = he.edge_vertices(e);
            split[x as usize] = true;
            split[y as usize] = true;
        }
    }
    // The wedge of the corner `h` (a face half-edge leaving its vertex).
    let wedge = |h: u32| -> u32 {
        if !split[he.origin(h) as usize] {
            return ring_min[he.origin(h) as usize];
        }
        let mut g = h;
        loop {
            if separates(g) {
                return g;
            }
            // The outgoing half-edge before g, clockwise (g's edge does not separate, so
            // twin(g) has a face).
            g = he.next(he.twin(g));
            if g == h {
                // A whole ring with no separator: its smallest corner.
                return ring_min[he.origin(h) as usize];
            }
        }
    };
    let corner_at = |v: u32, e: u32| {
        let h = he.edge_half_edge(e);
        let h = if he.origin(h) == v { h } else { he.twin(h) };
        if he.is_boundary_half_edge(h) {
            he.next(he.twin(h))
        } else {
            h
        }
    };
    let (source, target) = (wedge(corner_at(a, ea)), wedge(corner_at(b, eb)));
    if source == target {
        scratch.ring_min = ring_min;
        scratch.split = split;
        return None;
    }
    let search = &mut scratch.search;
    search.reset();
    search.add_source(source);
    let mut found = false;
    while let Some((w, d)) = search.pop() {
        if d >= bound {
            break;
        }
        if w == target {
            found = true;
            break;
        }
        // The wedge's corners, counter-clockwise from its first.
        let mut h = w;
        loop {
            // Along edge h to its head (corner next(h)), and along prev(h) to its tail
            // (corner prev(h)).
            for (g, corner) in [(h, he.next(h)), (he.prev(h), he.prev(h))] {
                let e = he.edge(g);
                let cost = if cut[e as usize] || he.is_boundary_edge(e) {
                    0.0
                } else {
                    len[e as usize]
                };
                search.relax(wedge(corner), d + cost, (w, e));
            }
            let n = he.twin(he.prev(h));
            if n == w || he.is_boundary_half_edge(n) || separates(n) {
                break;
            }
            h = n;
        }
    }
    scratch.ring_min = ring_min;
    scratch.split = split;
    if !found {
        return None;
    }
    let mut route = Vec::new();
    let mut w = target;
    while w != source {
        let (p, e) = scratch.search.pred(w);
        route.push(e);
        w = p;
    }
    Some(route)
}

/// A mesh cut open into a disk.
#[derive(Debug, Clone)]
pub struct DiskCut {
    /// The disk: triangle f is triangle f of the input, with wedge vertices.
    pub disk: Mesh,
    /// Per disk vertex, the input vertex it is a wedge of.
    pub original_vertex: Vec<u32>,
    /// The disk's connectivity.
    pub he: HalfEdgeMesh,
    /// The disk boundary as half-edges of `he` (with faces; interior on the left) in order.
    /// Half-edge `3f + k` is the same corner and edge as in the input's half-edge mesh.
    pub boundary: Vec<u32>,
    /// Per boundary position: the position of the boundary edge on the other side of the
    /// same cut edge, `NONE` for an edge of the input's own boundary.
    pub mate: Vec<u32>,
}

/// Splits `mesh` (with connectivity `he`) along the edges marked in `is_cut`. Fails (as an
/// internal error) unless the result is one disk: Euler characteristic 1, one boundary loop.
pub fn cut_to_disk(mesh: &Mesh, he: &HalfEdgeMesh, is_cut: &[bool]) -> Result<DiskCut, CutError> {
    if is_cut.len() != he.edge_count() {
        return Err(CutError::CutLength {
            expected: he.edge_count(),
            got: is_cut.len(),
        });
    }
    let nf = he.face_count();
    let (corner_vertex, original_vertex) = split_wedges(he, is_cut);
    let triangles: Vec<[u32; 3]> = (0..nf)
        .map(|f| [0, 1, 2].map(|k| corner_vertex[3 * f + k]))
        .collect();
    let positions = original_vertex
        .iter()
        .map(|&v| mesh.positions[v as usize])
        .collect();
    let colors = mesh
        .colors
        .as_ref()
        .map(|c| original_vertex.iter().map(|&v| c[v as usize]).collect());
    let disk = Mesh::with_colors(positions, triangles, colors);
    let dhe = HalfEdgeMesh::new(&disk)
        .map_err(|e| CutError::Internal(format!("the cut mesh is not a surface: {e}")))?;
    let comps = dhe.components();
    if comps.len() != 1 || comps[0].euler_characteristic != 1 || dhe.boundary_loops().len() != 1 {
        return Err(CutError::Internal(format!(
            "cutting did not give a disk: {} components, Euler characteristic {}, {} \
             boundary loops",
            comps.len(),
            dhe.euler_characteristic(),
            dhe.boundary_loops().len()
        )));
    }
    let boundary = dhe.boundary_loops()[0].clone();
    let mut position = vec![NONE; 3 * nf];
    for (k, &h) in boundary.iter().enumerate() {
        position[h as usize] = k as u32;
    }
    let mut mate = vec![NONE; boundary.len()];
    for (k, &h) in boundary.iter().enumerate() {
        if is_cut[he.edge(h) as usize] {
            let t = he.twin(h);
            let p = position[t as usize];
            if p == NONE {
                return Err(CutError::Internal(format!(
                    "the two sides of cut edge {} are not both on the disk boundary",
                    he.edge(h)
                )));
            }
            mate[k] = p;
        }
    }
    Ok(DiskCut {
        disk,
        original_vertex,
        he: dhe,
        boundary,
        mate,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geom::primitives::octahedron;
    use crate::math::PureMath;

    fn torus(n: u32, m: u32) -> Mesh {
        crate::geom::primitives::torus(n, m, 0.5)
    }

    fn check_disk(mesh: &Mesh, cut: &CutGraph) -> DiskCut {
        let he = HalfEdgeMesh::new(mesh).unwrap();
        let d = cut_to_disk(mesh, &he, &cut.is_cut).unwrap();
        assert_eq!(d.he.euler_characteristic(), 1);
        assert_eq!(d.he.boundary_loops().len(), 1);
        // Every cut edge appears twice on the boundary, mated both ways, reversed.
        let mated = d.mate.iter().filter(|&&m| m != NONE).count();
        assert_eq!(mated, 2 * cut.edges.len());
        for (k, &m) in d.mate.iter().enumerate() {
            if m != NONE {
                assert_eq!(d.mate[m as usize], k as u32);
                let (h, g) = (d.boundary[k], d.boundary[m as usize]);
                let ov = |v: u32| d.original_vertex[v as usize];
                assert_eq!(ov(d.he.origin(h)), ov(d.he.dest(g)));
                assert_eq!(ov(d.he.dest(h)), ov(d.he.origin(g)));
            }
        }
        d
    }

    #[test]
    fn octahedron_is_cut_along_a_path_between_opposite_vertices() {
        let m = octahedron();
        let he = HalfEdgeMesh::new(&m).unwrap();
        let cut = cut_graph(&he, &m.positions, 0, &[]).unwrap();
        // Opposite vertices are two edges apart; the cut is a path of two edges.
        assert_eq!(cut.edges.len(), 2);
        let d = check_disk(&m, &cut);
        assert_eq!(d.disk.vertex_count(), 6 + 1);
    }

    #[test]
    fn torus_cut_is_two_short_loops_and_gives_a_disk() {
        let m = torus(24, 10);
        let he = HalfEdgeMesh::new(&m).unwrap();
        let cut = cut_graph(&he, &m.positions, 0, &[]).unwrap();
        assert_eq!(cut.genus, 1);
        // One tube circle (≈ π) and one loop the long way round the inside (≈ 2π·1.5),
        // measured on the polygonal mesh: well under a generous bound and over the minimum.
        let tube = 10.0 * 2.0 * 0.5 * (std::f64::consts::PI / 10.0).sin_pure();
        let inner = 24.0 * 2.0 * 1.5 * (std::f64::consts::PI / 24.0).sin_pure();
        assert!(cut.length >= 0.999 * (tube + inner), "{}", cut.length);
        assert!(
            cut.length < 1.3 * (tube + inner),
            "{} vs {}",
            cut.length,
            tube + inner
        );
        let d = check_disk(&m, &cut);
        // No dangling branch, and a genus-1 cut graph has E − V = 2g − 1 = 1, so
        // Σ (degree − 2) over its vertices is 2 (two loops crossing, or a theta graph).
        let degrees = cut.degrees(&he);
        assert!(degrees.iter().all(|&x| x != 1));
        let excess: i64 = degrees
            .iter()
            .filter(|&&x| x > 0)
            .map(|&x| x as i64 - 2)
            .sum();
        assert_eq!(excess, 2);
        assert_eq!(
            d.disk.vertex_count(),
            m.vertex_count() + cut.edges.len() + 1
        );
    }

    #[test]
    fn straightening_replaces_a_long_loop_by_a_short_one() {
        // A valid but poor cut of the torus: the tube circle at i = 0 and the outer equator
        // (j = 0), crossing at vertex 0. Straightening must swap the outer equator (radius
        // 2.5) for a loop the long way round that is no longer than the inner equator (1.5).
        let (n, m) = (24u32, 10u32);
        let mesh = torus(n, m);
        let he = HalfEdgeMesh::new(&mesh).unwrap();
        let mut is_cut = vec![false; he.edge_count()];
        let mut mark = |a: u32, b: u32| {
            let e = (0..he.edge_count() as u32)
                .find(|&e| {
                    let (x, y) = he.edge_vertices(e);
                    (x, y) == (a, b) || (x, y) == (b, a)
                })
                .unwrap();
            is_cut[e as usize] = true;
        };
        for j in 0..m {
            mark(j, (j + 1) % m);
        }
        for i in 0..n {
            mark(i * m, ((i + 1) % n) * m);
        }
        assert!(cuts_to_disk(&he, &is_cut));
        let len: Vec<f64> = (0..he.edge_count() as u32)
            .map(|e| {
                let (a, b) = he.edge_vertices(e);
                (mesh.positions[a as usize] - mesh.positions[b as usize]).length() as f64
            })
            .collect();
        let total = |c: &[bool]| -> f64 { (0..c.len()).filter(|&e| c[e]).map(|e| len[e]).sum() };
        let before = total(&is_cut);
        straighten(&he, &len, &mut is_cut, 8);
        let after = total(&is_cut);
        let tube = m as f64 * 2.0 * 0.5 * (std::f64::consts::PI / m as f64).sin_pure();
        let inner = n as f64 * 2.0 * 1.5 * (std::f64::consts::PI / n as f64).sin_pure();
        assert!(after < before - 1.0, "{before} -> {after}");
        assert!(after <= tube + inner + 1e-6, "{after} vs {}", tube + inner);
        assert!(cuts_to_disk(&he, &is_cut));
        let d = cut_to_disk(&mesh, &he, &is_cut).unwrap();
        assert_eq!(d.he.euler_characteristic(), 1);
    }

    #[test]
    fn annulus_cut_joins_its_two_loops_by_a_shortest_path() {
        // The torus minus one ring of quads: an open tube.
        let m = torus(24, 10);
        let tris = m.triangles[20..].to_vec();
        let m = Mesh::new(m.positions.clone(), tris);
        let he = HalfEdgeMesh::new(&m).unwrap();
        let cut = cut_graph(&he, &m.positions, 0, &[]).unwrap();
        assert_eq!((cut.genus, cut.boundary_loops), (0, 2));
        // The loops are 23 ring steps apart along the tube; the shortest path between them
        // runs along the inner equator (radius 1.5).
        assert_eq!(cut.edges.len(), 23);
        let inner_step = 2.0 * 1.5 * (std::f64::consts::PI / 24.0).sin_pure();
        assert!(
            (cut.length - 23.0 * inner_step).abs() < 1e-4,
            "{}",
            cut.length
        );
        let d = check_disk(&m, &cut);
        assert!(d.mate.contains(&NONE));
    }

    #[test]
    fn a_target_gets_a_path_from_the_cut_and_a_bad_target_is_an_error() {
        let m = octahedron();
        let he = HalfEdgeMesh::new(&m).unwrap();
        let plain = cut_graph(&he, &m.positions, 0, &[]).unwrap();
        let on_plain = |v: u32| {
            plain.edges.iter().any(|&e| {
                let (a, b) = he.edge_vertices(e);
                a == v || b == v
            })
        };
        let target = (0..6)
            .find(|&v| !on_plain(v))
            .expect("a vertex off the cut");
        let cut = cut_graph(&he, &m.positions, 0, &[target]).unwrap();
        assert_eq!(cut.extremities, vec![target]);
        assert!(cut.edges.len() > plain.edges.len());
        assert!(cut.edges.iter().any(|&e| {
            let (a, b) = he.edge_vertices(e);
            a == target || b == target
        }));
        check_disk(&m, &cut);
        // A vertex already on the cut adds nothing.
        let on = (0..6).find(|&v| on_plain(v)).unwrap();
        let same = cut_graph(&he, &m.positions, 0, &[on]).unwrap();
        assert_eq!(same.edges, plain.edges);
        assert!(matches!(
            cut_graph(&he, &m.positions, 0, &[6]),
            Err(CutError::Internal(_))
        ));
    }

    #[test]
    fn extremity_cuts_reach_the_farthest_vertex() {
        // A long box-like strip closed into a sphere: octahedron stretched along x.
        let mut m = octahedron();
        m.positions[0] = Vec3::new(10.0, 0.0, 0.0);
        let m = Mesh::new(m.positions.clone(), m.triangles.clone());
        let he = HalfEdgeMesh::new(&m).unwrap();
        let cut = cut_graph(&he, &m.positions, 1, &[]).unwrap();
        assert_eq!(cut.extremities.len(), 1);
        let d = check_disk(&m, &cut);
        assert!(d.disk.vertex_count() > 7);
    }

    #[test]
    fn several_components_are_an_error_naming_the_count() {
        let a = octahedron();
        let mut p = a.positions.clone();
        let mut t = a.triangles.clone();
        p.extend(a.positions.iter().map(|x| *x + Vec3::splat(5.0)));
        t.extend(a.triangles.iter().map(|x| x.map(|v| v + 6)));
        let m = Mesh::new(p, t);
        let he = HalfEdgeMesh::new(&m).unwrap();
        let err = cut_graph(&he, &m.positions, 0, &[]).unwrap_err();
        assert!(matches!(err, CutError::SeveralComponents { count: 2 }));
        assert!(err.to_string().contains("2 connected components"));
    }
}

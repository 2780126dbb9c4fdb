//! A small kd-tree over f32 points of a dimension chosen at run time, with a filtered k-nearest
//! query: the k nearest points *for which a predicate holds*. Jump maps need this: a pixel's
//! nearest neighbours in feature space are its own spatial neighbours, which must be skipped,
//! and a plain kNN would spend k on them.
//!
//! Results are exact (with [`KdTreeRef::nearest`]) and ordered by (squared distance, index), so
//! they are deterministic and do not depend on the tree's shape. The tree is built by median
//! splits along the widest coordinate, the median chosen under the total order (coordinate,
//! index).
//!
//! A tree can be exported as flat Pod arrays ([`KdTree::parts`]) and viewed in place again
//! ([`KdTreeRef::from_parts`]), so it can be stored in a cached artifact and searched straight
//! from the memory-mapped file.
//!
//! The searches are methods of the view, [`KdTreeRef`]; a built [`KdTree`] hands out its own
//! with [`KdTree::as_ref`].

/// Points per leaf.
const LEAF_SIZE: usize = 8;
const NO_CHILD: u32 = u32::MAX;

/// One node of a [`KdTree`], as stored in its flat node array. Nodes are in pre-order: the
/// root is node 0 and both children of a node come after it.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct KdNode {
    /// Range of `ids` / `points` (tree order) under this node.
    pub start: u32,
    pub end: u32,
    /// Split dimension; `u32::MAX` for a leaf.
    pub axis: u32,
    pub split: f32,
    pub left: u32,
    pub right: u32,
}

type Node = KdNode;

/// Deepest tree [`KdTreeRef::from_parts`] accepts (a built tree over 2³² points is about 30
/// deep; the bound keeps the recursive search's stack use small for any input).
pub const MAX_DEPTH: usize = 96;

/// A kd-tree viewed in borrowed arrays (e.g. in place in a mapped artifact, or a [`KdTree`]'s
/// own through [`KdTree::as_ref`]): the searches.
#[derive(Clone, Copy, Debug)]
pub struct KdTreeRef<'a> {
    dim: usize,
    points: &'a [f32],
    ids: &'a [u32],
    nodes: &'a [KdNode],
}

/// A kd-tree; see the module docs.
#[derive(Clone, Debug)]
pub struct KdTree {
    dim: usize,
    /// Points in tree order, `dim` values each.
    points: Vec<f32>,
    /// Original index of each point in tree order.
    ids: Vec<u32>,
    nodes: Vec<Node>,
}

/// Squared Euclidean distance, summed in coordinate order (the value every query reports).
#[inline]
pub fn squared_distance(a: &[f32], b: &[f32]) -> f32 {
    let mut s = 0.0f32;
    for (x, y) in a.iter().zip(b) {
        let d = x - y;
        s += d * d;
    }
    s
}

/// [`squared_distance`] if it is at most `bound`, else `None` (possibly without summing every
/// coordinate: partial sums only grow).
#[inline]
fn distance_within(a: &[f32], b: &[f32], bound: f32) -> Option<f32> {
    let mut s = 0.0f32;
    let mut ca = a.chunks_exact(4);
    let mut cb = b.chunks_exact(4);
    for (x, y) in (&mut ca).zip(&mut cb) {
        for t in 0..4 {
            let d = x[t] - y[t];
            s += d * d;
        }
        if s > bound {
            return None;
        }
    }
    for (x, y) in ca.remainder().iter().zip(cb.remainder()) {
        let d = x - y;
        s += d * d;
    }
    (s <= bound).then_some(s)
}

/// What one query searches with: the bound's scale (`(1 + eps)²`, less a little slack), the
/// points it may return and the nodes it need not enter.
struct Search<F, E> {
    scale: f32,
    filter: F,
    excluded: E,
}

/// A bounded, sorted list of the best candidates so far.
struct Best {
    k: usize,
    items: Vec<(u32, f32)>,
}

impl Best {
    #[inline]
    fn worse(a: (u32, f32), b: (u32, f32)) -> bool {
        a.1 > b.1 || (a.1 == b.1 && a.0 > b.0)
    }

    /// Squared distance a candidate must not exceed to be of interest.
    #[inline]
    fn bound(&self) -> f32 {
        if self.items.len() < self.k {
            f32::INFINITY
        } else {
            self.items[self.k - 1].1
        }
    }

    /// Keeps `(id, d)` if it is among the `k` best so far; a point offered again (a seed the
    /// search reaches) is kept once.
    #[inline]
    fn offer(&mut self, id: u32, d: f32) {
        let c = (id, d);
        let full = self.items.len() == self.k;
        if full && !Self::worse(self.items[self.k - 1], c) {
            return;
        }
        let pos = self.items.partition_point(|&x| !Self::worse(x, c));
        if pos > 0 && self.items[pos - 1].0 == id {
            return;
        }
        if full {
            self.items.pop();
        }
        self.items.insert(pos, c);
    }
}

impl KdTree {
    /// Builds a tree over `points.len() / dim` points stored one after the other.
    /// Panics if `dim == 0`, if the length is not a multiple of `dim`, or if there are 2³² or
    /// more points.
    pub fn build(points: &[f32], dim: usize) -> KdTree {
        assert!(
            dim > 0 && points.len().is_multiple_of(dim),
            "points are not a whole number of vectors"
        );
        let n = points.len() / dim;
        assert!(n < u32::MAX as usize, "too many points for a kd-tree");
        let mut perm: Vec<u32> = (0..n as u32).collect();
        let mut nodes = Vec::with_capacity(2 * n / LEAF_SIZE + 1);
        if n > 0 {
            build_node(points, dim, &mut perm, 0, &mut nodes);
        }
        let mut tree_points = Vec::with_capacity(points.len());
        for &i in &perm {
            tree_points.extend_from_slice(&points[i as usize * dim..(i as usize + 1) * dim]);
        }
        KdTree {
            dim,
            points: tree_points,
            ids: perm,
            nodes,
        }
    }

    /// Number of points.
    pub fn len(&self) -> usize {
        self.as_ref().len()
    }

    pub fn is_empty(&self) -> bool {
        self.as_ref().is_empty()
    }

    pub fn dim(&self) -> usize {
        self.as_ref().dim()
    }

    /// The flat arrays of the tree: dimension, points in tree order (`dim` values each), the
    /// original index of each point in tree order, and the nodes. [`KdTreeRef::from_parts`]
    /// views them again.
    pub fn parts(&self) -> (usize, &[f32], &[u32], &[KdNode]) {
        (self.dim, &self.points, &self.ids, &self.nodes)
    }

    /// A borrowed view, which does the searches.
    pub fn as_ref(&self) -> KdTreeRef<'_> {
        KdTreeRef {
            dim: self.dim,
            points: &self.points,
            ids: &self.ids,
            nodes: &self.nodes,
        }
    }
}

/// Why stored kd-tree arrays cannot be searched (see [`KdTreeRef::from_parts`]).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum KdTreeError {
    #[error("kd-tree: dimension 0")]
    ZeroDimension,
    #[error("kd-tree: {values} point values for {ids} ids of dimension {dim}")]
    PointCount {
        values: usize,
        ids: usize,
        dim: usize,
    },
    #[error("kd-tree: id {id} at {at} is not below {bound}")]
    IdBound { id: u32, at: usize, bound: u32 },
    #[error("kd-tree: nodes without points or points without nodes")]
    NodesWithoutPoints,
    #[error("kd-tree: the root does not cover every point")]
    Root,
    #[error("kd-tree: too deep or cyclic")]
    TooDeep,
    #[error("kd-tree: node {node} has a bad range")]
    Range { node: u32 },
    #[error("kd-tree: node {node} has a bad split")]
    Split { node: u32 },
    #[error("kd-tree: node {node} has a bad child {child}")]
    Child { node: u32, child: u32 },
    #[error("kd-tree: node {node} is not inside its parent")]
    Nesting { node: u32 },
}

impl<'a> KdTreeRef<'a> {
    /// Views arrays exported by [`KdTree::parts`], checking everything a search relies on:
    /// lengths agree, nodes are in pre-order with children after their parent, ranges nest
    /// inside the point array, split axes are below `dim`, the tree is at most [`MAX_DEPTH`]
    /// deep, and every id is below `id_bound`. Damaged arrays give an error, never a panic
    /// or an endless search later.
    pub fn from_parts(
        dim: usize,
        points: &'a [f32],
        ids: &'a [u32],
        nodes: &'a [KdNode],
        id_bound: u32,
    ) -> Result<KdTreeRef<'a>, KdTreeError> {
        if dim == 0 {
            return Err(KdTreeError::ZeroDimension);
        }
        if points.len() != ids.len() * dim {
            return Err(KdTreeError::PointCount {
                values: points.len(),
                ids: ids.len(),
                dim,
            });
        }
        if let Some(i) = ids.iter().position(|&i| i >= id_bound) {
            return Err(KdTreeError::IdBound {
                id: ids[i],
                at: i,
                bound: id_bound,
            });
        }
        if ids.is_empty() != nodes.is_empty() {
            return Err(KdTreeError::NodesWithoutPoints);
        }
        if !nodes.is_empty() {
            let n = ids.len() as u32;
            let root = nodes[0];
            if root.start != 0 || root.end != n {
                return Err(KdTreeError::Root);
            }
            // Walk from the root, checking each reachable node once (pre-order indices only
            // grow, so a node is reached through one parent at most if indices are increasing).
            let mut stack = vec![(0u32, 1usize)];
            let mut seen = 0usize;
            while let Some((i, depth)) = stack.pop() {
                seen += 1;
                if depth > MAX_DEPTH || seen > nodes.len() {
                    return Err(KdTreeError::TooDeep);
                }
                let nd = nodes[i as usize];
                if nd.start > nd.end || nd.end > n {
                    return Err(KdTreeError::Range { node: i });
                }
                if nd.axis == u32::MAX {
                    continue;
                }
                if nd.axis as usize >= dim || !nd.split.is_finite() {
                    return Err(KdTreeError::Split { node: i });
                }
                for c in [nd.left, nd.right] {
                    if c <= i || c as usize >= nodes.len() {
                        return Err(KdTreeError::Child { node: i, child: c });
                    }
                    let cn = nodes[c as usize];
                    if cn.start < nd.start || cn.end > nd.end {
                        return Err(KdTreeError::Nesting { node: c });
                    }
                    stack.push((c, depth + 1));
                }
            }
        }
        Ok(KdTreeRef {
            dim,
            points,
            ids,
            nodes,
        })
    }

    /// Number of points.
    pub fn len(&self) -> usize {
        self.ids.len()
    }

    pub fn is_empty(&self) -> bool {
        self.ids.is_empty()
    }

    pub fn dim(&self) -> usize {
        self.dim
    }

    /// The `k` nearest points to `query` among those whose index passes `filter`, as
    /// `(index, squared distance)` by increasing distance, ties by increasing index. Fewer than
    /// `k` if fewer points pass.
    pub fn nearest(
        &self,
        query: &[f32],
        k: usize,
        filter: impl Fn(u32) -> bool,
    ) -> Vec<(u32, f32)> {
        self.nearest_approx(query, k, 0.0, filter)
    }

    /// As [`Self::nearest`], but a subtree is skipped once every point in it is farther than
    /// `1 + eps` times the current k-th distance, so the i-th result is within `1 + eps` of the
    /// true i-th nearest distance (Arya & Mount's approximate search). Still deterministic.
    pub fn nearest_approx(
        &self,
        query: &[f32],
        k: usize,
        eps: f32,
        filter: impl Fn(u32) -> bool,
    ) -> Vec<(u32, f32)> {
        self.nearest_approx_seeded(query, k, eps, filter, |_| false, &[])
    }

    /// As [`Self::nearest_approx`], with two ways to find the result sooner:
    /// - `seeds`, `(index, squared distance to query)` pairs offered before the search starts
    ///   (those that pass `filter`), so that it starts from a tight bound: e.g. the previous
    ///   query's results, moved along with the query. The distance must be
    ///   [`squared_distance`] of `query` and that point, as the search would measure it.
    /// - `excluded(node)`: a node for which it holds is not entered. It is the caller's promise
    ///   that no point under that node (its `start..end` of [`Self::ids`]) passes `filter`.
    ///   Where the points that fail the filter cluster in the tree (a texel's spatial
    ///   neighbours, which are also its nearest in feature space), whole subtrees of them are
    ///   skipped instead of measured one by one.
    ///
    /// With `eps = 0` the result is exactly [`Self::nearest`]'s. With `eps > 0` skipping
    /// excluded nodes changes nothing, but seeds do: a different bound prunes differently, so
    /// the result is as approximate as [`Self::nearest_approx`]'s but not always the same.
    pub fn nearest_approx_seeded(
        &self,
        query: &[f32],
        k: usize,
        eps: f32,
        filter: impl Fn(u32) -> bool,
        excluded: impl Fn(u32) -> bool,
        seeds: &[(u32, f32)],
    ) -> Vec<(u32, f32)> {
        assert_eq!(query.len(), self.dim, "query dimension");
        let mut best = Best {
            k,
            items: Vec::with_capacity(k + 1),
        };
        if k == 0 || self.nodes.is_empty() {
            return best.items;
        }
        for &(id, d) in seeds {
            if filter(id) {
                best.offer(id, d);
            }
        }
        // Bounds are compared with a little slack so float rounding in the incremental cell
        // distance never prunes a cell holding a point at exactly the k-th distance.
        let scale = (1.0 + eps.max(0.0)).powi(2) * (1.0 - 1e-5);
        let mut off = vec![0.0f32; self.dim];
        let search = Search {
            scale,
            filter,
            excluded,
        };
        self.search(0, query, 0.0, &mut off, &search, &mut best);
        best.items
    }

    /// The nodes, in pre-order (node 0 is the root); a node's points are `ids[start..end]`.
    pub fn nodes(&self) -> &'a [KdNode] {
        self.nodes
    }

    /// The original index of each point, in tree order.
    pub fn ids(&self) -> &'a [u32] {
        self.ids
    }

    /// The single nearest point (approximate as in [`Self::nearest_approx`], no filter), as
    /// `(index, squared distance)`; `None` for an empty tree. `scratch` is reused between
    /// calls to avoid allocating.
    pub fn nearest1_approx(
        &self,
        query: &[f32],
        eps: f32,
        scratch: &mut Vec<f32>,
    ) -> Option<(u32, f32)> {
        assert_eq!(query.len(), self.dim, "query dimension");
        if self.nodes.is_empty() {
            return None;
        }
        let scale = (1.0 + eps.max(0.0)).powi(2) * (1.0 - 1e-5);
        scratch.clear();
        scratch.resize(self.dim, 0.0);
        let mut best = Best {
            k: 1,
            items: Vec::with_capacity(2),
        };
        let search = Search {
            scale,
            filter: |_| true,
            excluded: |_| false,
        };
        self.search(0, query, 0.0, scratch, &search, &mut best);
        best.items.first().copied()
    }

    fn search(
        &self,
        node: u32,
        q: &[f32],
        rd: f32,
        off: &mut [f32],
        search: &Search<impl Fn(u32) -> bool, impl Fn(u32) -> bool>,
        best: &mut Best,
    ) {
        if (search.excluded)(node) {
            return;
        }
        let nd = self.nodes[node as usize];
        if nd.axis == u32::MAX {
            let dim = self.dim;
            for i in nd.start as usize..nd.end as usize {
                let bound = best.bound();
                if let Some(d) = distance_within(q, &self.points[i * dim..(i + 1) * dim], bound) {
                    let id = self.ids[i];
                    if (search.filter)(id) {
                        best.offer(id, d);
                    }
                }
            }
            return;
        }
        let axis = nd.axis as usize;
        let diff = q[axis] - nd.split;
        let (near, far) = if diff < 0.0 {
            (nd.left, nd.right)
        } else {
            (nd.right, nd.left)
        };
        self.search(near, q, rd, off, search, best);
        let old = off[axis];
        let new_rd = rd - old * old + diff * diff;
        if new_rd * search.scale <= best.bound() {
            off[axis] = diff;
            self.search(far, q, new_rd, off, search, best);
            off[axis] = old;
        }
    }
}

fn build_node(
    points: &[f32],
    dim: usize,
    perm: &mut [u32],
    start: usize,
    nodes: &mut Vec<Node>,
) -> u32 {
    let me = nodes.len() as u32;
    let n = perm.len();
    nodes.push(Node {
        start: start as u32,
        end: (start + n) as u32,
        axis: u32::MAX,
        split: 0.0,
        left: NO_CHILD,
        right: NO_CHILD,
    });
    if n <= LEAF_SIZE {
        return me;
    }
    // Widest coordinate (lowest index on ties).
    let mut axis = 0;
    let mut widest = -1.0f32;
    for d in 0..dim {
        let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
        for &i in perm.iter() {
            let x = points[i as usize * dim + d];
            lo = lo.min(x);
            hi = hi.max(x);
        }
        if hi - lo > widest {
            widest = hi - lo;
            axis = d;
        }
    }
    if widest <= 0.0 {
        // All points coincide: keep them in one (large) leaf.
        return me;
    }
    let mid = n / 2;
    let key = |i: u32| points[i as usize * dim + axis];
    perm.select_nth_unstable_by(mid, |&a, &b| key(a).total_cmp(&key(b)).then(a.cmp(&b)));
    let split = key(perm[mid]);
    let (lo, hi) = perm.split_at_mut(mid);
    let left = build_node(points, dim, lo, start, nodes);
    let right = build_node(points, dim, hi, start + mid, nodes);
    let node = &mut nodes[me as usize];
    node.axis = axis as u32;
    node.split = split;
    node.left = left;
    node.right = right;
    me
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn brute(
        points: &[f32],
        dim: usize,
        q: &[f32],
        k: usize,
        filter: impl Fn(u32) -> bool,
    ) -> Vec<(u32, f32)> {
        let mut all: Vec<(u32, f32)> = points
            .chunks(dim)
            .enumerate()
            .filter(|(i, _)| filter(*i as u32))
            .map(|(i, p)| (i as u32, squared_distance(q, p)))
            .collect();
        all.sort_by(|a, b| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0)));
        all.truncate(k);
        all
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(200))]
        #[test]
        fn matches_brute_force(
            dim in 1usize..6,
            n in 0usize..300,
            // Small integer coordinates make exact ties common.
            seed in any::<u64>(),
            k in 1usize..12,
            modulus in 1u32..5,
            coarse in any::<bool>(),
        ) {
            let mut s = seed | 1;
            let mut next = || { s ^= s << 13; s ^= s >> 7; s ^= s << 17; s };
            let points: Vec<f32> = (0..n * dim).map(|_| {
                let r = next();
                if coarse { (r % 5) as f32 } else { (r % 100_000) as f32 / 997.0 }
            }).collect();
            let tree = KdTree::build(&points, dim);
            for t in 0..5 {
                let q: Vec<f32> = (0..dim).map(|_| {
                    let r = next();
                    if coarse { (r % 6) as f32 - 0.5 } else { (r % 100_000) as f32 / 997.0 }
                }).collect();
                let keep = t % modulus;
                let filter = |i: u32| i % modulus != keep || modulus == 1;
                let got = tree.as_ref().nearest(&q, k, filter);
                let want = brute(&points, dim, &q, k, filter);
                prop_assert_eq!(got, want);
            }
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(100))]
        /// Points on a grid whose first coordinate follows position (as a texel's spatial
        /// neighbours are also its nearest in feature space), a query that must skip a window
        /// around its own position: seeds (some passing, some not, some the answer itself) and
        /// subtrees skipped by their bounding boxes change nothing.
        #[test]
        fn seeds_and_excluded_subtrees_give_the_exact_result(
            seed in any::<u64>(),
            side in 4usize..24,
            k in 1usize..16,
            gap in 1i64..6,
            seeds in proptest::collection::vec((any::<u32>(), any::<bool>()), 0..20),
        ) {
            let mut s = seed | 1;
            let mut next = || { s ^= s << 13; s ^= s >> 7; s ^= s << 17; s };
            let dim = 3;
            let n = side * side;
            let at = |i: u32| ((i as usize % side) as i64, (i as usize / side) as i64);
            let points: Vec<f32> = (0..n as u32).flat_map(|i| {
                let (x, y) = at(i);
                [x as f32 + y as f32 * 0.3, (next() % 7) as f32, (next() % 1000) as f32 / 250.0]
            }).collect();
            let tree = KdTree::build(&points, dim);
            let tree = tree.as_ref();
            // Per node, the box of the positions under it.
            let boxes: Vec<(i64, i64, i64, i64)> = tree.nodes().iter().map(|nd| {
                tree.ids()[nd.start as usize..nd.end as usize].iter().fold(
                    (i64::MAX, i64::MIN, i64::MAX, i64::MIN),
                    |b, &i| { let (x, y) = at(i); (b.0.min(x), b.1.max(x), b.2.min(y), b.3.max(y)) },
                )
            }).collect();
            for t in 0..4u32 {
                let me = (next() % n as u64) as u32;
                let (x, y) = at(me);
                let q = &points[me as usize * dim..(me as usize + 1) * dim];
                let far = |i: u32| { let (ux, uy) = at(i); (ux - x).abs() >= gap || (uy - y).abs() >= gap };
                let near = |node: u32| {
                    let b = boxes[node as usize];
                    b.0 > x - gap && b.1 < x + gap && b.2 > y - gap && b.3 < y + gap
                };
                let want = brute(&points, dim, q, k, far);
                let mut given: Vec<(u32, f32)> = seeds.iter().map(|&(r, answer)| {
                    let i = if answer && !want.is_empty() {
                        want[r as usize % want.len()].0
                    } else {
                        r % n as u32
                    };
                    (i, squared_distance(q, &points[i as usize * dim..(i as usize + 1) * dim]))
                }).collect();
                let turn = t as usize % given.len().max(1);
                given.rotate_left(turn);
                let got = tree.nearest_approx_seeded(q, k, 0.0, far, near, &given);
                prop_assert_eq!(&got, &want);
                prop_assert_eq!(&tree.nearest_approx_seeded(q, k, 0.0, far, |_| false, &[]), &want);
                // Approximate: skipping excluded subtrees still changes nothing.
                prop_assert_eq!(
                    tree.nearest_approx_seeded(q, k, 0.5, far, near, &[]),
                    tree.nearest_approx(q, k, 0.5, far)
                );
            }
        }
    }

    #[test]
    fn approximate_search_stays_within_factor() {
        let dim = 8;
        let mut s = 12345u64;
        let mut next = || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            (s % 10_000) as f32 / 10_000.0
        };
        let points: Vec<f32> = (0..4000 * dim).map(|_| next()).collect();
        let tree = KdTree::build(&points, dim);
        let eps = 0.5f32;
        for _ in 0..50 {
            let q: Vec<f32> = (0..dim).map(|_| next()).collect();
            let got = tree.as_ref().nearest_approx(&q, 5, eps, |_| true);
            let want = brute(&points, dim, &q, 5, |_| true);
            assert_eq!(got.len(), 5);
            for (g, w) in got.iter().zip(&want) {
                assert!(g.1 <= w.1 * (1.0 + eps).powi(2) + 1e-6);
            }
        }
    }

    #[test]
    fn duplicate_points_do_not_break_the_tree() {
        let points = vec![1.0f32; 3 * 100];
        let tree = KdTree::build(&points, 3);
        let got = tree.as_ref().nearest(&[1.0, 1.0, 1.0], 3, |i| i >= 50);
        assert_eq!(got, vec![(50, 0.0), (51, 0.0), (52, 0.0)]);
    }

    #[test]
    fn exported_parts_search_like_the_tree_and_damage_is_an_error() {
        let dim = 3;
        let points: Vec<f32> = (0..300 * dim)
            .map(|i| ((i as u64 * 2654435761) % 1000) as f32 / 100.0)
            .collect();
        let tree = KdTree::build(&points, dim);
        let (d, pts, ids, nodes) = tree.parts();
        // Through bytes, as an artifact would store them.
        let pts_b: Vec<f32> = bytemuck::cast_slice::<u8, f32>(bytemuck::cast_slice(pts)).to_vec();
        let view = KdTreeRef::from_parts(d, &pts_b, ids, nodes, 300).unwrap();
        let mut scratch = Vec::new();
        for t in 0..40 {
            let q = [t as f32 * 0.25, 5.0 - t as f32 * 0.1, (t % 7) as f32];
            assert_eq!(
                view.nearest_approx(&q, 4, 0.0, |_| true),
                tree.as_ref().nearest(&q, 4, |_| true)
            );
            let one = view.nearest1_approx(&q, 0.0, &mut scratch);
            assert_eq!(one, tree.as_ref().nearest(&q, 1, |_| true).first().copied());
        }
        assert!(KdTreeRef::from_parts(d, pts, ids, nodes, 299).is_err());
        assert!(KdTreeRef::from_parts(d, &pts[1..], ids, nodes, 300).is_err());
        let mut bad = nodes.to_vec();
        let inner = bad.iter().position(|n| n.axis != u32::MAX).unwrap();
        bad[inner].left = inner as u32; // a cycle
        assert!(KdTreeRef::from_parts(d, pts, ids, &bad, 300).is_err());
        let mut bad = nodes.to_vec();
        bad[inner].axis = 7;
        assert!(KdTreeRef::from_parts(d, pts, ids, &bad, 300).is_err());
        let mut bad = nodes.to_vec();
        let last = bad.len() - 1;
        bad[last].end = 301;
        assert!(KdTreeRef::from_parts(d, pts, ids, &bad, 300).is_err());
        let empty = KdTree::build(&[], 2);
        let (d, p, i, n) = empty.parts();
        let e = KdTreeRef::from_parts(d, p, i, n, 0).unwrap();
        assert_eq!(e.nearest1_approx(&[0.0, 0.0], 0.0, &mut scratch), None);
    }
}

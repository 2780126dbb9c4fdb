//! One pyramid level's grid: its mate groups, the pairing of the square's sides across the
//! cuts, where a tap outside the square is read (across a cut or mirrored), the quarter turn
//! between two sides' axes, and the boundary strip the resynthesis passes visit.

use crate::geom::geometry_image::GeometryImage;
use crate::image::neighbourhood::mirror;

/// Quarter turns of the tangent of each side (top, right, bottom, left) in `(x, y)` axes.
pub(super) const SIDE_TOP: u8 = 0;
pub(super) const SIDE_RIGHT: u8 = 1;
pub(super) const SIDE_BOTTOM: u8 = 2;
pub(super) const SIDE_LEFT: u8 = 3;

/// `(di, dj)` of the tangent and of the inward normal of each side.
pub(super) const TANGENT: [(i64, i64); 4] = [(0, 1), (1, 0), (0, -1), (-1, 0)];
pub(super) const NORMAL: [(i64, i64); 4] = [(1, 0), (0, -1), (-1, 0), (0, 1)];

/// Turns `(dx, dy)` by `r` quarter turns (`(x, y) → (−y, x)` each). Exact.
#[inline]
pub(super) fn quarter_turn(r: u8, v: &mut [f32]) {
    let (x, y) = (v[0], v[1]);
    let (nx, ny) = match r & 3 {
        0 => (x, y),
        1 => (-y, x),
        2 => (-x, -y),
        _ => (y, -x),
    };
    v[0] = nx;
    v[1] = ny;
}

/// One level's grid: size, mate groups and how to read across its cuts.
pub(super) struct LevelGrid {
    pub(super) n: usize,
    pub(super) rep: Vec<u32>,
    /// Mate groups with more than one member, members by increasing index.
    pub(super) groups: Vec<Vec<u32>>,
    /// Per sample, quarter turns from its grid axes to its representative's.
    pub(super) to_rep: Vec<u8>,
    /// Per `(side, position along the side as i or j)`, the sample and side across the cut.
    pub(super) across: Vec<Option<(u32, u8)>>,
    /// Texels of the boundary strip in scanline order.
    pub(super) strip: Vec<u32>,
}

impl LevelGrid {
    pub(super) fn sides_of(&self, i: i64, j: i64) -> impl Iterator<Item = u8> {
        let last = self.n as i64 - 1;
        [
            (SIDE_TOP, i == 0),
            (SIDE_RIGHT, j == last),
            (SIDE_BOTTOM, i == last),
            (SIDE_LEFT, j == 0),
        ]
        .into_iter()
        .filter(|s| s.1)
        .map(|s| s.0)
    }

    #[inline]
    pub(super) fn inside(&self, i: i64, j: i64) -> bool {
        let n = self.n as i64;
        (0..n).contains(&i) && (0..n).contains(&j)
    }

    #[inline]
    pub(super) fn idx(&self, i: i64, j: i64) -> usize {
        i as usize * self.n + j as usize
    }

    pub(super) fn coords(&self, k: u32) -> (i64, i64) {
        ((k as usize / self.n) as i64, (k as usize % self.n) as i64)
    }

    /// Whether side `sp` at `p` and side `sq` at `q` are the two sides of one cut, running in
    /// opposite directions: the border neighbours of `p` and `q` are mated.
    pub(super) fn paired(&self, p: u32, sp: u8, q: u32, sq: u8) -> bool {
        let (pi, pj) = self.coords(p);
        let (qi, qj) = self.coords(q);
        let (tp, tq) = (TANGENT[sp as usize], TANGENT[sq as usize]);
        for d in [1i64, -1] {
            let a = (pi + d * tp.0, pj + d * tp.1);
            let b = (qi - d * tq.0, qj - d * tq.1);
            if self.inside(a.0, a.1)
                && self.inside(b.0, b.1)
                && self.rep[self.idx(a.0, a.1)] == self.rep[self.idx(b.0, b.1)]
            {
                return true;
            }
        }
        false
    }

    /// The grid of pyramid level `l` of `gi`: its mates are those of the level-0 samples
    /// `(i · 2^l, j · 2^l)` restricted to that lattice.
    pub(super) fn of_level(gi: &GeometryImage, l: usize, strip_width: u32) -> LevelGrid {
        let n0 = gi.n as usize;
        let n = (n0 - 1) / (1 << l) + 1;
        let mut first: Vec<u32> = vec![u32::MAX; n0 * n0];
        let mut rep = vec![0u32; n * n];
        for i in 0..n {
            for j in 0..n {
                let key = gi.mate_rep[(i << l) * n0 + (j << l)] as usize;
                if first[key] == u32::MAX {
                    first[key] = (i * n + j) as u32;
                }
                rep[i * n + j] = first[key];
            }
        }
        LevelGrid::build(n, rep, strip_width)
    }

    /// The texel at `(i, j)` as a neighbour of a texel inside: itself when inside, the texel
    /// across the cut when `(i, j)` lies beyond one side sample that has a confirmed mate, and
    /// `None` otherwise (beyond a corner, or an open side: there is no surface there).
    pub(super) fn neighbour(&self, i: i64, j: i64) -> Option<usize> {
        if self.inside(i, j) {
            return Some(self.idx(i, j));
        }
        let n = self.n as i64;
        let within = |v: i64| (0..n).contains(&v);
        let (side, pos, b) = if i < 0 && within(j) {
            (SIDE_TOP, j, -i)
        } else if j >= n && within(i) {
            (SIDE_RIGHT, i, j - (n - 1))
        } else if i >= n && within(j) {
            (SIDE_BOTTOM, j, i - (n - 1))
        } else if j < 0 && within(i) {
            (SIDE_LEFT, i, -j)
        } else {
            return None;
        };
        let (q, sq) = self.across[side as usize * self.n + pos as usize]?;
        let (qi, qj) = self.coords(q);
        let m = NORMAL[sq as usize];
        let (ti, tj) = (qi + b * m.0, qj + b * m.1);
        self.inside(ti, tj).then(|| self.idx(ti, tj))
    }

    pub(super) fn build(n: usize, rep: Vec<u32>, strip_width: u32) -> LevelGrid {
        let mut members: Vec<Vec<u32>> = vec![Vec::new(); n * n];
        for (k, &r) in rep.iter().enumerate() {
            if r as usize != k {
                if members[r as usize].is_empty() {
                    members[r as usize].push(r);
                }
                members[r as usize].push(k as u32);
            }
        }
        let groups: Vec<Vec<u32>> = members.into_iter().filter(|g| g.len() > 1).collect();
        let mut g = LevelGrid {
            n,
            rep,
            groups,
            to_rep: vec![0; n * n],
            across: vec![None; 4 * n],
            strip: Vec::new(),
        };
        let mut group_of: Vec<u32> = vec![u32::MAX; n * n];
        for (gi, grp) in g.groups.iter().enumerate() {
            for &m in grp {
                group_of[m as usize] = gi as u32;
            }
        }
        // Turns to the representative.
        let mut to_rep = vec![0u8; n * n];
        for grp in &g.groups {
            let r = grp[0];
            let (ri, rj) = g.coords(r);
            for &p in &grp[1..] {
                let (pi, pj) = g.coords(p);
                'found: for sp in g.sides_of(pi, pj) {
                    for sr in g.sides_of(ri, rj) {
                        if g.paired(p, sp, r, sr) {
                            to_rep[p as usize] = (sr + 6 - sp) % 4;
                            break 'found;
                        }
                    }
                }
            }
        }
        g.to_rep = to_rep;
        // Across each side sample.
        let last = n as i64 - 1;
        let mut across = vec![None; 4 * n];
        for side in 0..4u8 {
            for pos in 0..n as i64 {
                let (pi, pj) = match side {
                    SIDE_TOP => (0, pos),
                    SIDE_RIGHT => (pos, last),
                    SIDE_BOTTOM => (last, pos),
                    _ => (pos, 0),
                };
                let p = g.idx(pi, pj) as u32;
                let gi = group_of[p as usize];
                if gi == u32::MAX {
                    continue;
                }
                'found: for &q in &g.groups[gi as usize] {
                    if q == p {
                        continue;
                    }
                    let (qi, qj) = g.coords(q);
                    for sq in g.sides_of(qi, qj) {
                        if g.paired(p, side, q, sq) {
                            across[side as usize * n + pos as usize] = Some((q, sq));
                            break 'found;
                        }
                    }
                }
            }
        }
        g.across = across;
        // The strip: texels near a side sample that has a partner across the cut.
        let w = strip_width as i64;
        for i in 0..n as i64 {
            for j in 0..n as i64 {
                let near = [
                    (SIDE_TOP, i, j),
                    (SIDE_RIGHT, last - j, i),
                    (SIDE_BOTTOM, last - i, j),
                    (SIDE_LEFT, j, i),
                ]
                .iter()
                .any(|&(s, d, pos)| d < w && g.across[s as usize * n + pos as usize].is_some());
                if near {
                    g.strip.push(g.idx(i, j) as u32);
                }
            }
        }
        g
    }

    /// Where tap `(i, j)` is read, by how many quarter turns its `(dx, dy)` turn into the
    /// reader's axes, and whether the tap lies outside the square.
    #[inline]
    pub(super) fn locate(&self, i: i64, j: i64) -> (usize, u8, bool) {
        let n = self.n as i64;
        if self.inside(i, j) {
            return (self.idx(i, j), 0, false);
        }
        let over = |v: i64| {
            if v < 0 {
                -v
            } else if v >= n {
                v - (n - 1)
            } else {
                0
            }
        };
        let (mut i, mut j) = (i, j);
        let (oi, oj) = (over(i), over(j));
        if oi > 0 && oj > 0 {
            if oi <= oj {
                i = mirror(i, n);
            } else {
                j = mirror(j, n);
            }
        }
        let (side, pos, b) = if i < 0 {
            (SIDE_TOP, j, -i)
        } else if j >= n {
            (SIDE_RIGHT, i, j - (n - 1))
        } else if i >= n {
            (SIDE_BOTTOM, j, i - (n - 1))
        } else {
            (SIDE_LEFT, i, -j)
        };
        match self.across[side as usize * self.n + pos as usize] {
            None => (self.idx(mirror(i, n), mirror(j, n)), 0, true),
            Some((q, sq)) => {
                let (qi, qj) = self.coords(q);
                let m = NORMAL[sq as usize];
                let (ti, tj) = (mirror(qi + b * m.0, n), mirror(qj + b * m.1, n));
                (self.idx(ti, tj), (side + 6 - sq) % 4, true)
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid_with(n: usize, pairs: &[(usize, usize)]) -> LevelGrid {
        let mut rep: Vec<u32> = (0..(n * n) as u32).collect();
        for &(a, b) in pairs {
            let (lo, hi) = (a.min(b), a.max(b));
            rep[hi] = rep[lo];
        }
        LevelGrid::build(n, rep, 2)
    }

    #[test]
    fn quarter_turns_compose_and_are_exact() {
        let mut v = [0.3f32, -1.7];
        for _ in 0..4 {
            quarter_turn(1, &mut v);
        }
        assert_eq!(v, [0.3, -1.7]);
        let mut a = [0.3f32, -1.7];
        quarter_turn(1, &mut a);
        assert_eq!(a, [1.7, 0.3]);
        quarter_turn(3, &mut a);
        assert_eq!(a, [0.3, -1.7]);
    }

    #[test]
    fn cylinder_cut_reads_the_other_side_without_turning() {
        // Column 0 mated with column n−1, row by row.
        let n = 9;
        let pairs: Vec<_> = (0..n).map(|i| (i * n, i * n + n - 1)).collect();
        let g = grid_with(n, &pairs);
        // Two texels left of (4, 0) is column n−3 of row 4.
        assert_eq!(g.locate(4, -2), (4 * n + n - 3, 0, true));
        // One right of (3, n−1) is column 1.
        assert_eq!(g.locate(3, n as i64), (3 * n + 1, 0, true));
        assert_eq!(g.locate(3, 5), (3 * n + 5, 0, false));
        // The top is a true boundary: mirrored.
        assert_eq!(g.locate(-1, 4), (n + 4, 0, true));
        // Beyond a corner: mirrored along the smaller overshoot (rows), then across the cut.
        assert_eq!(g.locate(-1, -2), (n + n - 3, 0, true));
        assert!(g.to_rep.iter().all(|&r| r == 0));
        // The strip holds the columns near both sides, not the top-only texels.
        assert!(g.strip.contains(&(5 * n as u32 + 1)));
        assert!(g.strip.contains(&(5 * n as u32 + n as u32 - 2)));
        assert!(!g.strip.contains(&4));
    }

    #[test]
    fn folded_cut_between_top_and_left_turns_vectors_a_quarter() {
        // The top side (0, j) glued to the left side (j, 0): a cut folded at the corner.
        // Perimeter: top runs j up, left runs i down, so they run opposite along the cut.
        let n = 9;
        let pairs: Vec<_> = (1..n).map(|j| (j, j * n)).collect();
        let g = grid_with(n, &pairs);
        // One above (0, 3) is one right of (3, 0), i.e. (3, 1).
        let (k, r, _) = g.locate(-1, 3);
        assert_eq!(k, 3 * n + 1);
        // Moving +j along the top is moving +i down the left side: grid x maps to y.
        // A vector stored at (3, 1) in its axes, turned by r into the reader's axes.
        let mut v = [0.0f32, 1.0]; // +y at the left side = +x at the top
        quarter_turn(r, &mut v);
        assert_eq!(v, [1.0, 0.0]);
        // Left side members turn into their representative's (top) axes the inverse way.
        let (k2, r2, _) = g.locate(3, -1);
        assert_eq!(k2, n + 3);
        assert_eq!((r + r2) % 4, 0);
        // and a left member's value turns into the top's axes like a value read from there.
        assert_eq!(g.to_rep[3 * n], r);
    }
}

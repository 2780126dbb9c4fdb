//! The dependent set of one pyramid level, computed backwards from the voxels whose final
//! values are wanted (Zhang, Du, Lai, Ni & Hu, "Sketch guided solid texturing", §5: spatial
//! determinism; Lefebvre & Hoppe 2005, §3.5 and Dong et al. 2008, §6 for the idea).
//!
//! A voxel's versions are `0` (upsampled) to the level's correction count (see
//! `history_window.rs`). If version `c ≥ 1` of `v` is needed, so are its versions below (a
//! voxel reads itself at its latest version), and every neighbour `w` within the reach `r` of
//! `v` at the version the step's history window gives. So the needed versions of a voxel are
//! always a prefix, stored as one byte: 0 = not needed, `1 + c` = versions `0..=c` needed
//! (and only `1` = just the upsampled value).
//!
//! Working from the last step back to the first, the active voxels of a step whose new
//! version is needed are dilated by the stencil of what a correction reads: restricted to the
//! same barrier cell they ask for the neighbours' latest versions, otherwise for the
//! stage-start versions. The stencil is the cube of radius `r` (the paper's `D × D × D`
//! history window, `D = 2r + 1`), or, where every read lies in the axis planes of the
//! weighted exemplars (the trivial field: Dong et al.'s crossbars), only those planes'
//! `D × D` squares ([`Stencil`]; a departure from the paper's window, which is a bound: the
//! cube's other voxels are never read, and dilating by them only thickens the set). Boxes and
//! axis-aligned cells make both dilations separable, so each step costs three one-axis
//! prefix-sum sweeps over the bounding box of that step's active voxels (four for three
//! planes). Every pass skips the x rows with nothing set: most rows of a surface's box, and
//! three in four of a subpass step's sources (its class fixes the parity of y and z).
//!
//! The result is exact for the stencil: synthesizing exactly these versions gives every
//! wanted voxel the value a synthesis of the whole domain would give, whatever else was
//! requested (spatial determinism).

use super::history_window::{Cells, Schedule, class_of};
use glam::IVec3;
use rayon::prelude::*;

/// Needed versions per voxel over a box of a level (see the module docs).
#[derive(Clone, Debug, PartialEq)]
pub struct NeedGrid {
    /// The box `[lo, lo + n)` in level voxels.
    pub lo: IVec3,
    pub n: IVec3,
    /// `0`: not needed; `1 + c`: versions `0..=c` needed.
    pub need: Vec<u8>,
}

impl NeedGrid {
    pub fn empty() -> NeedGrid {
        NeedGrid {
            lo: IVec3::ZERO,
            n: IVec3::ZERO,
            need: Vec::new(),
        }
    }

    #[inline]
    pub fn index(&self, p: IVec3) -> usize {
        let q = p - self.lo;
        ((q.z as usize * self.n.y as usize) + q.y as usize) * self.n.x as usize + q.x as usize
    }

    #[inline]
    pub fn contains(&self, p: IVec3) -> bool {
        let q = p - self.lo;
        q.cmpge(IVec3::ZERO).all() && q.cmplt(self.n).all()
    }

    /// The byte of `p` (0 outside the box).
    #[inline]
    pub fn get(&self, p: IVec3) -> u8 {
        if self.contains(p) {
            self.need[self.index(p)]
        } else {
            0
        }
    }

    #[inline]
    pub fn position(&self, i: usize) -> IVec3 {
        let (nx, ny) = (self.n.x as usize, self.n.y as usize);
        self.lo
            + IVec3::new(
                (i % nx) as i32,
                ((i / nx) % ny) as i32,
                (i / (nx * ny)) as i32,
            )
    }

    /// Voxels synthesized (upsampled at least).
    pub fn voxels(&self) -> u64 {
        self.need.iter().filter(|&&x| x > 0).count() as u64
    }

    /// Corrections performed.
    pub fn corrections(&self) -> u64 {
        self.need.iter().map(|&x| x.saturating_sub(1) as u64).sum()
    }
}

/// What one correction reads around its voxel, which the dependent set dilates by.
///
/// In general the cube of radius `reach`. Where the reads are known to lie in axis planes
/// through the voxel (the trivial field: each exemplar's `N × N` neighbourhood and its
/// candidates' `3 × 3` positions are whole voxel steps along two axes, Dong et al. 2008's
/// crossbars), only the union of those planes' squares: the cube's other voxels are never
/// read, and every ring of the set that the cube would add there is one the synthesis does
/// not need (the same voxels from a thinner set).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Stencil {
    pub reach: i32,
    /// `Some(planes)`: only the planes `p` with `planes[p]`, spanned by axes `p` and
    /// `(p + 1) % 3` (the solid's exemplar planes `xy`, `yz`, `zx`), each a square of
    /// radius `reach`. `None`: the whole cube.
    pub planes: Option<[bool; 3]>,
}

impl Stencil {
    pub fn cube(reach: i32) -> Stencil {
        Stencil {
            reach,
            planes: None,
        }
    }

    /// The per-axis radii of each square whose union the stencil is (one cube, or one per
    /// plane, flat along the axis that plane does not span).
    fn squares(&self) -> Vec<[i32; 3]> {
        let r = self.reach;
        match self.planes {
            None => vec![[r; 3]],
            Some(planes) => (0..3)
                .filter(|&p| planes[p])
                .map(|p| {
                    let mut radii = [r; 3];
                    radii[(p + 2) % 3] = 0;
                    radii
                })
                .collect(),
        }
    }
}

impl From<i32> for Stencil {
    fn from(reach: i32) -> Stencil {
        Stencil::cube(reach)
    }
}

/// Works out the needed versions at one level; see the module docs. `domain` is the level's
/// extent `[0, domain)`, `targets` boxes `[lo, hi)` of voxels whose final version is wanted
/// (clipped to the domain here), `stencil` what a correction reads (a radius: the cube).
pub fn dependent_set(
    schedule: &Schedule,
    domain: IVec3,
    targets: &[(IVec3, IVec3)],
    stencil: impl Into<Stencil>,
) -> NeedGrid {
    let stencil = stencil.into();
    let reach = stencil.reach;
    let targets: Vec<(IVec3, IVec3)> = targets
        .iter()
        .map(|&(lo, hi)| (lo.max(IVec3::ZERO), hi.min(domain)))
        .filter(|(lo, hi)| hi.cmpgt(*lo).all())
        .collect();
    if targets.is_empty() {
        return NeedGrid::empty();
    }
    let total = schedule.corrections();
    assert!(total < 255, "at most 254 corrections per level");
    let (lo, hi) = dependent_box(schedule, domain, &targets, reach).expect("targets in the domain");
    let n = hi - lo;
    let mut grid = NeedGrid {
        lo,
        n,
        need: vec![0u8; n.x as usize * n.y as usize * n.z as usize],
    };
    for &(a, b) in &targets {
        for z in a.z..b.z {
            for y in a.y..b.y {
                let i = grid.index(IVec3::new(a.x, y, z));
                grid.need[i..i + (b.x - a.x) as usize].fill(1 + total as u8);
            }
        }
    }
    let stages = &schedule.stages;
    // The dilation's two buffers, reused by every step (one allocation, not six per step).
    let (mut mask, mut tmp) = (Vec::new(), Vec::new());
    for step in schedule.steps().iter().rev() {
        let threshold = 1 + step.version_after() as u8;
        // Active voxels whose new version is needed, and their bounding box.
        // Row by row in parallel; min and max do not depend on the order of the reduction.
        let nx = grid.n.x as usize;
        let (alo, ahi) = grid
            .need
            .par_chunks(nx.max(1))
            .enumerate()
            .map(|(row, xs)| {
                let (mut lo, mut hi) = (IVec3::MAX, IVec3::MIN);
                let p0 = grid.position(row * nx);
                let parity = step.class.is_none_or(|c| class_of(p0.with_x(0)) == c & 6);
                if parity && xs.iter().any(|&x| x >= threshold) {
                    for (x, &b) in xs.iter().enumerate() {
                        if b >= threshold {
                            let p = p0 + IVec3::new(x as i32, 0, 0);
                            if step.active(p) {
                                lo = lo.min(p);
                                hi = hi.max(p);
                            }
                        }
                    }
                }
                (lo, hi)
            })
            .reduce(
                || (IVec3::MAX, IVec3::MIN),
                |a, b| (a.0.min(b.0), a.1.max(b.1)),
            );
        if alo.x > ahi.x {
            continue;
        }
        let rlo = (alo - IVec3::splat(reach)).max(grid.lo);
        let rhi = (ahi + IVec3::splat(reach + 1)).min(grid.lo + grid.n);
        let rn = rhi - rlo;
        let len = rn.x as usize * rn.y as usize * rn.z as usize;
        mask.resize(len, 0);
        // Both bits: the sources of the plain dilation (bit 0) and of the one within cells.
        mask.par_chunks_mut(rn.x as usize)
            .enumerate()
            .for_each(|(row, out)| {
                let y = rlo.y + (row % rn.y as usize) as i32;
                let z = rlo.z + (row / rn.y as usize) as i32;
                let start = grid.index(IVec3::new(rlo.x, y, z));
                let src = &grid.need[start..start + out.len()];
                // A subpass's class fixes the parity of y and z: three rows in four hold
                // no active voxel.
                let parity = step
                    .class
                    .is_none_or(|c| class_of(IVec3::new(0, y, z)) == c & 6);
                if !parity || !src.iter().any(|&b| b >= threshold) {
                    out.fill(0);
                    return;
                }
                for (x, (o, &b)) in out.iter_mut().zip(src).enumerate() {
                    let p = IVec3::new(rlo.x + x as i32, y, z);
                    *o = 3 * (b >= threshold && step.active(p)) as u8;
                }
            });
        let barriers = &stages[step.stage].window.barriers;
        dilate_stencil(&mut mask, &mut tmp, rlo, rn, &stencil, barriers);
        let dilated = &mask;
        let latest: [u8; 8] = std::array::from_fn(|c| 1 + step.latest_for_class(c as u8) as u8);
        let start = 1 + step.stage_start as u8;
        let (gn, glo) = (grid.n, grid.lo);
        // Rows of the region are disjoint rows of the grid: update them in parallel.
        let mut rows: Vec<(usize, &mut [u8])> = Vec::new();
        {
            let mut rest: &mut [u8] = &mut grid.need;
            let mut consumed = 0usize;
            for z in 0..rn.z {
                for y in 0..rn.y {
                    let q = IVec3::new(rlo.x, rlo.y + y, rlo.z + z) - glo;
                    let at = ((q.z as usize * gn.y as usize) + q.y as usize) * gn.x as usize
                        + q.x as usize;
                    let (_, tail) = rest.split_at_mut(at - consumed);
                    let (row, tail) = tail.split_at_mut(rn.x as usize);
                    rows.push(((z as usize * rn.y as usize + y as usize), row));
                    rest = tail;
                    consumed = at + rn.x as usize;
                }
            }
        }
        rows.into_par_iter().for_each(|(r, row)| {
            let y = rlo.y + (r % rn.y as usize) as i32;
            let z = rlo.z + (r / rn.y as usize) as i32;
            let base = r * rn.x as usize;
            let drow = &dilated[base..base + row.len()];
            if !any_set(drow) {
                return;
            }
            for (x, need) in row.iter_mut().enumerate() {
                let d = drow[x];
                if d & 1 == 0 {
                    continue;
                }
                let in_cell = barriers.is_empty() || d & 2 != 0;
                let v = if in_cell {
                    latest[class_of(IVec3::new(rlo.x + x as i32, y, z)) as usize]
                } else {
                    start
                };
                if v > *need {
                    *need = v;
                }
            }
        });
    }
    grid
}

/// The box `[lo, hi)` that [`dependent_set`] allocates one byte per voxel of (its targets'
/// bounding box grown by the impact distance, within the domain), or `None` when no target
/// lies in the domain: what a caller bounds to bound that function's memory.
pub fn dependent_box(
    schedule: &Schedule,
    domain: IVec3,
    targets: &[(IVec3, IVec3)],
    reach: i32,
) -> Option<(IVec3, IVec3)> {
    let clipped = targets
        .iter()
        .map(|&(lo, hi)| (lo.max(IVec3::ZERO), hi.min(domain)))
        .filter(|(lo, hi)| hi.cmpgt(*lo).all());
    let (tlo, thi) = clipped.fold((IVec3::MAX, IVec3::MIN), |(a, b), t| {
        (a.min(t.0), b.max(t.1))
    });
    if tlo.x > thi.x {
        return None;
    }
    let grow = IVec3::splat(schedule.impact_distance(reach));
    Some(((tlo - grow).max(IVec3::ZERO), (thi + grow).min(domain)))
}

/// `log2` of [`CHUNK`].
pub const CHUNK_BITS: i32 = 3;
/// Side of the chunks of a [`ChunkedNeed`] (and of the working values that follow it).
pub const CHUNK: i32 = 1 << CHUNK_BITS;
/// Voxels per chunk.
pub const CHUNK_VOXELS: usize = (CHUNK * CHUNK * CHUNK) as usize;
const NO_CHUNK: u32 = u32::MAX;

/// A [`NeedGrid`] kept only in the `8³` chunks (aligned with the grid's box) that hold a
/// needed voxel. The dense grid spans the bounding box of the dependent set, most of it empty
/// for a surface; this keeps about one byte per needed voxel, so the dependent sets of every
/// batch of every level can wait, planned, while the levels below are synthesized.
#[derive(Clone, Debug, PartialEq)]
pub struct ChunkedNeed {
    /// The dense grid's box `[lo, lo + n)`; chunk `c` starts at `lo + 8c`.
    pub lo: IVec3,
    pub n: IVec3,
    /// Chunks per axis.
    cn: IVec3,
    /// Per chunk of the box, its index in `origins`, or `NO_CHUNK`.
    table: Vec<u32>,
    /// First voxel of each kept chunk, z-major then y then x.
    origins: Vec<IVec3>,
    /// `CHUNK_VOXELS` bytes per kept chunk, x fastest; 0 outside the box.
    bytes: Vec<u8>,
}

impl ChunkedNeed {
    pub fn from_grid(g: &NeedGrid) -> ChunkedNeed {
        let cn = (g.n + (CHUNK - 1)) / CHUNK;
        let cn = cn.max(IVec3::ZERO);
        // Kept chunks per chunk slab (z), in parallel, then concatenated in order.
        let slabs: Vec<Vec<(IVec3, Vec<u8>)>> = (0..cn.z)
            .into_par_iter()
            .map(|cz| {
                let mut out = Vec::new();
                for cy in 0..cn.y {
                    for cx in 0..cn.x {
                        let c = IVec3::new(cx, cy, cz);
                        let mut buf = vec![0u8; CHUNK_VOXELS];
                        let mut any = false;
                        let base = c * CHUNK;
                        let w = (g.n.x - base.x).min(CHUNK) as usize;
                        for z in 0..CHUNK.min(g.n.z - base.z) {
                            for y in 0..CHUNK.min(g.n.y - base.y) {
                                let i = g.index(g.lo + base + IVec3::new(0, y, z));
                                let row = &g.need[i..i + w];
                                any |= row.iter().any(|&b| b > 0);
                                let o = ((z * CHUNK + y) * CHUNK) as usize;
                                buf[o..o + w].copy_from_slice(row);
                            }
                        }
                        if any {
                            out.push((g.lo + base, buf));
                        }
                    }
                }
                out
            })
            .collect();
        let kept: usize = slabs.iter().map(Vec::len).sum();
        let mut table = vec![NO_CHUNK; (cn.x * cn.y * cn.z) as usize];
        let mut origins = Vec::with_capacity(kept);
        let mut bytes = Vec::with_capacity(kept * CHUNK_VOXELS);
        for (origin, buf) in slabs.into_iter().flatten() {
            let c = (origin - g.lo) / CHUNK;
            table[((c.z * cn.y + c.y) * cn.x + c.x) as usize] = origins.len() as u32;
            origins.push(origin);
            bytes.extend_from_slice(&buf);
        }
        ChunkedNeed {
            lo: g.lo,
            n: g.n,
            cn,
            table,
            origins,
            bytes,
        }
    }

    /// The kept chunks' first voxels (chunk `k`'s voxels are slots `k·512 ..`).
    pub fn origins(&self) -> &[IVec3] {
        &self.origins
    }

    /// The needed-version bytes of kept chunk `k`, x fastest.
    pub fn chunk(&self, k: usize) -> &[u8] {
        &self.bytes[k * CHUNK_VOXELS..(k + 1) * CHUNK_VOXELS]
    }

    /// Voxels of the kept chunks: what working values over this set take room for.
    pub fn chunk_voxels(&self) -> u64 {
        self.bytes.len() as u64
    }

    /// The slot of `p` among the kept chunks' voxels, if its chunk is kept.
    #[inline]
    pub fn slot(&self, p: IVec3) -> Option<usize> {
        let q = p - self.lo;
        if !(q.cmpge(IVec3::ZERO).all() && q.cmplt(self.n).all()) {
            return None;
        }
        let c = q / CHUNK;
        let t = self.table[((c.z * self.cn.y + c.y) * self.cn.x + c.x) as usize];
        if t == NO_CHUNK {
            return None;
        }
        let m = q - c * CHUNK;
        Some(t as usize * CHUNK_VOXELS + ((m.z * CHUNK + m.y) * CHUNK + m.x) as usize)
    }

    /// The slot of `p`, which must be in a kept chunk (the working values' reads: every
    /// voxel a correction reads is in the dependent set).
    #[inline]
    pub fn slot_in_set(&self, p: IVec3) -> usize {
        let q = p - self.lo;
        debug_assert!(q.cmpge(IVec3::ZERO).all() && q.cmplt(self.n).all());
        let c = q >> CHUNK_BITS;
        let t = self.table[((c.z * self.cn.y + c.y) * self.cn.x + c.x) as usize];
        debug_assert!(t != NO_CHUNK, "read of a voxel outside the dependent set");
        let m = q & (CHUNK - 1);
        t as usize * CHUNK_VOXELS + ((m.z * CHUNK + m.y) * CHUNK + m.x) as usize
    }

    /// What coordinate `x` on `axis` (0, 1, 2 for x, y, z) adds to [`ChunkedNeed::slot_in_set`]:
    /// its part of the chunk-table index and its part of the offset in the chunk. A voxel's
    /// slot is [`ChunkedNeed::slot_of_parts`] of the sums of its three axes' parts. The
    /// correction kernel's gather computes the same parts inline from
    /// [`ChunkedNeed::axis_multipliers`] (`axis_parts` in `solid_synthesis/correction.rs`), which must agree.
    #[inline]
    pub fn axis_part(&self, axis: usize, x: i32) -> (usize, usize) {
        let (origin, table, local) = self.axis_multipliers(axis);
        let q = x - origin;
        debug_assert!(q >= 0 && q < self.n[axis]);
        let (c, m) = ((q >> CHUNK_BITS) as usize, (q & (CHUNK - 1)) as usize);
        (c * table, m * local)
    }

    /// [`ChunkedNeed::axis_part`] as numbers: the box's first coordinate on `axis`, and what
    /// a chunk step and a step within a chunk along it add to the table and local parts
    /// (`axis_part(axis, x)` is `(q >> CHUNK_BITS) · table, (q & (CHUNK − 1)) · local` for
    /// `q = x − origin`).
    #[inline]
    pub fn axis_multipliers(&self, axis: usize) -> (i32, usize, usize) {
        let side = CHUNK as usize;
        let (t, l) = match axis {
            0 => (1, 1),
            1 => (self.cn.x as usize, side),
            _ => ((self.cn.x * self.cn.y) as usize, side * side),
        };
        (self.lo[axis], t, l)
    }

    /// The slot of the voxel whose summed [`ChunkedNeed::axis_part`]s are `table` and `local`
    /// (in a kept chunk, as for [`ChunkedNeed::slot_in_set`]).
    #[inline]
    pub fn slot_of_parts(&self, table: usize, local: usize) -> usize {
        let t = self.table[table];
        debug_assert!(t != NO_CHUNK, "read of a voxel outside the dependent set");
        t as usize * CHUNK_VOXELS + local
    }

    /// The byte of `p` (0 where not needed).
    #[inline]
    pub fn get(&self, p: IVec3) -> u8 {
        self.slot(p).map_or(0, |s| self.bytes[s])
    }

    /// Voxels synthesized (upsampled at least).
    pub fn voxels(&self) -> u64 {
        self.bytes.iter().filter(|&&x| x > 0).count() as u64
    }

    /// Corrections performed.
    pub fn corrections(&self) -> u64 {
        self.bytes.iter().map(|&x| x.saturating_sub(1) as u64).sum()
    }
}

/// The offset of slot `m` of a chunk from the chunk's first voxel.
#[inline]
pub fn chunk_local(m: usize) -> IVec3 {
    let m = m as i32;
    IVec3::new(m % CHUNK, (m / CHUNK) % CHUNK, m / (CHUNK * CHUNK))
}

/// Dilation of a 0/1 mask over the box `[lo, lo + n)` by `stencil`; with barriers, only
/// within the cell (of every lattice) of each source voxel.
pub fn dilate(
    mask: &[u8],
    lo: IVec3,
    n: IVec3,
    stencil: impl Into<Stencil>,
    barriers: &[Cells],
) -> Vec<u8> {
    let mut buf: Vec<u8> = mask.iter().map(|&m| 3 * (m != 0) as u8).collect();
    dilate_stencil(&mut buf, &mut Vec::new(), lo, n, &stencil.into(), barriers);
    let bit = if barriers.is_empty() { 1 } else { 2 };
    buf.iter().map(|&d| (d & bit != 0) as u8).collect()
}

/// [`dilate_both`] by a [`Stencil`]: the cube in place, or the union of its planes' squares
/// (a square and a cell are both boxes, so the cut to the cell is separable per square and
/// the union of the cut squares is the cut union), factored so that planes sharing an axis
/// share its pass.
pub fn dilate_stencil(
    buf: &mut Vec<u8>,
    tmp: &mut Vec<u8>,
    lo: IVec3,
    n: IVec3,
    stencil: &Stencil,
    barriers: &[Cells],
) {
    let squares = stencil.squares();
    if let [radii] = squares[..] {
        dilate_both(buf, tmp, lo, n, radii, barriers);
        return;
    }
    let r = stencil.reach;
    let along = |axis: usize| {
        let mut radii = [0; 3];
        radii[axis] = r;
        radii
    };
    if let [p, q] = squares[..] {
        // Two planes share one axis `c`: (d_c d_a S) ∪ (d_c d_b S) = d_c (d_a S ∪ d_b S),
        // three one-axis passes as for the cube instead of four.
        let own = |sq: [i32; 3], other: [i32; 3]| (0..3).find(|&x| sq[x] != 0 && other[x] == 0);
        let (Some(a), Some(b)) = (own(p, q), own(q, p)) else {
            unreachable!("two distinct planes each have an axis of their own")
        };
        let c = 3 - a - b;
        let mut other = buf.clone();
        dilate_both(buf, tmp, lo, n, along(a), barriers);
        dilate_both(&mut other, tmp, lo, n, along(b), barriers);
        buf.par_iter_mut()
            .zip(other.par_iter())
            .for_each(|(u, s)| *u |= s);
        dilate_both(buf, tmp, lo, n, along(c), barriers);
        return;
    }
    // All three planes xy, yz, zx: with A = d_y S and B = d_z S, xy ∪ zx = d_x (A ∪ B) and
    // yz = d_z A, four one-axis passes.
    let or = |into: &mut [u8], from: &[u8]| {
        into.par_iter_mut()
            .zip(from.par_iter())
            .for_each(|(u, s)| *u |= s)
    };
    let mut b = buf.clone();
    dilate_both(buf, tmp, lo, n, along(1), barriers);
    dilate_both(&mut b, tmp, lo, n, along(2), barriers);
    let mut yz = buf.clone();
    dilate_both(&mut yz, tmp, lo, n, along(2), barriers);
    or(buf, &b);
    dilate_both(buf, tmp, lo, n, along(0), barriers);
    or(buf, &yz);
}

/// Two dilations of one box at once, in place in `buf` (`tmp` is scratch, resized): bit 0
/// by the box of per-axis radii `r`, bit 1 by the same box cut to the cell of every lattice
/// in `barriers` (the cell's window lies inside the box's, so one pass over a window serves
/// both). Each axis in turn ORs the window's rows or slabs (an axis of radius 0 is left as
/// it is); no buffer but the two is allocated, so a step of [`dependent_set`] costs two
/// bytes per voxel of its region.
pub fn dilate_both(
    buf: &mut Vec<u8>,
    tmp: &mut Vec<u8>,
    lo: IVec3,
    n: IVec3,
    radii: [i32; 3],
    barriers: &[Cells],
) {
    let dims = [n.x as usize, n.y as usize, n.z as usize];
    tmp.resize(buf.len(), 0);
    for axis in 0..3 {
        let r = radii[axis];
        if r == 0 {
            // The source voxel's own position, which is in its own cell: both bits stay.
            continue;
        }
        let origin = lo[axis];
        let len = dims[axis] as i32;
        // Windows [a, b] (inclusive, local) per position along the axis: the cube's, then
        // the cell's.
        let bounds: Vec<[(usize, usize); 2]> = (0..len)
            .map(|i| {
                let g = origin + i;
                let clip = |a: i32, b: i32| {
                    let a = (a - origin).max(0) as usize;
                    let b = (b - origin).min(len - 1).max(0) as usize;
                    (a, b)
                };
                let (mut a, mut b) = (g - r, g + r);
                let all = clip(a, b);
                for c in barriers {
                    let s = c.start(g);
                    a = a.max(s);
                    b = b.min(s + c.size - 1);
                }
                [all, clip(a, b)]
            })
            .collect();
        dilate_axis(buf, tmp, dims, axis, &bounds);
        std::mem::swap(buf, tmp);
    }
}

/// `out` (bit 0) = OR of `src`'s bit 0 over the first window of each position along `axis`,
/// (bit 1) = OR of bit 1 over the second.
fn dilate_axis(
    src: &[u8],
    out: &mut [u8],
    d: [usize; 3],
    axis: usize,
    bounds: &[[(usize, usize); 2]],
) {
    let [nx, ny, _] = d;
    if nx == 0 {
        return;
    }
    // Most x rows of a surface's box are empty (and three in four of a subpass step's
    // sources): the windows skip them, and an empty row dilates to an empty row.
    let row_any: Vec<bool> = if axis == 0 {
        Vec::new()
    } else {
        src.par_chunks(nx).map(any_set).collect()
    };
    // ORs the window of x rows `j` at row index `row(j)` into `o`.
    let or_window =
        |o: &mut [u8], [(a, b), (ca, cb)]: [(usize, usize); 2], row: &dyn Fn(usize) -> usize| {
            o.fill(0);
            if a > b {
                return;
            }
            for j in a..=b {
                let r = row(j);
                if !row_any[r] {
                    continue;
                }
                let m = if ca <= j && j <= cb { 3 } else { 1 };
                let s = &src[r * nx..(r + 1) * nx];
                for (x, y) in o.iter_mut().zip(s) {
                    *x |= y & m;
                }
            }
        };
    match axis {
        0 => {
            out.par_chunks_mut(nx)
                .zip(src.par_chunks(nx))
                .for_each_init(
                    || (vec![0u32; nx + 1], vec![0u32; nx + 1]),
                    |(p0, p1), (o, s)| {
                        if !any_set(s) {
                            o.fill(0);
                            return;
                        }
                        for i in 0..nx {
                            p0[i + 1] = p0[i] + (s[i] & 1) as u32;
                            p1[i + 1] = p1[i] + (s[i] >> 1 & 1) as u32;
                        }
                        for (i, x) in o.iter_mut().enumerate() {
                            let [(a, b), (ca, cb)] = bounds[i];
                            let all = a <= b && p0[b + 1] > p0[a];
                            let cell = ca <= cb && p1[cb + 1] > p1[ca];
                            *x = all as u8 | (cell as u8) << 1;
                        }
                    },
                );
        }
        1 => {
            out.par_chunks_mut(nx * ny).enumerate().for_each(|(z, o)| {
                for (y, row) in o.chunks_mut(nx).enumerate() {
                    or_window(row, bounds[y], &|j| z * ny + j);
                }
            });
        }
        _ => {
            out.par_chunks_mut(nx * ny).enumerate().for_each(|(z, o)| {
                for (y, row) in o.chunks_mut(nx).enumerate() {
                    or_window(row, bounds[z], &|j| j * ny + y);
                }
            });
        }
    }
}

/// Whether any byte of `row` is non-zero (an OR over the row, which vectorizes).
#[inline]
fn any_set(row: &[u8]) -> bool {
    row.iter().fold(0u8, |a, &b| a | b) != 0
}

#[cfg(test)]
mod tests {
    use super::*;

    fn brute_dilate(mask: &[u8], lo: IVec3, n: IVec3, r: i32, barriers: &[Cells]) -> Vec<u8> {
        let g = NeedGrid {
            lo,
            n,
            need: mask.to_vec(),
        };
        let mut out = vec![0u8; mask.len()];
        for i in 0..mask.len() {
            let w = g.position(i);
            'search: for dz in -r..=r {
                for dy in -r..=r {
                    for dx in -r..=r {
                        let v = w + IVec3::new(dx, dy, dz);
                        if g.get(v) != 0 && barriers.iter().all(|c| c.cell_of(v) == c.cell_of(w)) {
                            out[i] = 1;
                            break 'search;
                        }
                    }
                }
            }
        }
        out
    }

    #[test]
    fn separable_dilation_matches_brute_force() {
        let lo = IVec3::new(-3, 2, 5);
        let n = IVec3::new(13, 9, 11);
        let len = (n.x * n.y * n.z) as usize;
        let mut mask = vec![0u8; len];
        for i in (0..len).step_by(97) {
            mask[i] = 1;
        }
        let cells = [Cells { size: 4, offset: 1 }];
        for r in [0, 1, 2] {
            assert_eq!(
                dilate(&mask, lo, n, r, &[]),
                brute_dilate(&mask, lo, n, r, &[])
            );
            assert_eq!(
                dilate(&mask, lo, n, r, &cells),
                brute_dilate(&mask, lo, n, r, &cells)
            );
        }
    }

    #[test]
    fn flat_dilation_matches_brute_force() {
        let lo = IVec3::new(-3, 2, 5);
        let n = IVec3::new(13, 9, 11);
        let len = (n.x * n.y * n.z) as usize;
        let mut mask = vec![0u8; len];
        for i in (0..len).step_by(89) {
            mask[i] = 1;
        }
        let g = NeedGrid {
            lo,
            n,
            need: mask.clone(),
        };
        let cells = [Cells { size: 4, offset: 1 }];
        for planes in [
            [true, false, true],
            [true, true, true],
            [false, true, false],
        ] {
            for barriers in [&[][..], &cells[..]] {
                let r = 2;
                let got = dilate(
                    &mask,
                    lo,
                    n,
                    Stencil {
                        reach: r,
                        planes: Some(planes),
                    },
                    barriers,
                );
                let mut flat = 0;
                for i in 0..len {
                    let w = g.position(i);
                    // Some source within a square of a read plane (and the same cells).
                    let mut hit = false;
                    for p in (0..3).filter(|&p| planes[p]) {
                        for a in -r..=r {
                            for b in -r..=r {
                                let mut o = IVec3::ZERO;
                                o[p] = a;
                                o[(p + 1) % 3] = b;
                                let v = w + o;
                                hit |= g.get(v) != 0
                                    && barriers.iter().all(|c| c.cell_of(v) == c.cell_of(w));
                            }
                        }
                    }
                    assert_eq!(got[i] != 0, hit, "planes {planes:?} at {w}");
                    flat += hit as usize;
                }
                let cube = dilate(&mask, lo, n, r, barriers);
                let cube = cube.iter().filter(|&&x| x != 0).count();
                assert!(flat < cube, "planes {planes:?}: {flat} vs {cube}");
            }
        }
    }

    /// [`dependent_set`] worked out voxel by voxel, straight from the module docs: every
    /// step backwards, every needed active voxel asks each voxel of its stencil for the latest
    /// version (same cell) or the stage-start one.
    fn brute_dependent_set(
        schedule: &Schedule,
        domain: IVec3,
        targets: &[(IVec3, IVec3)],
        stencil: Stencil,
    ) -> NeedGrid {
        let (lo, hi) = dependent_box(schedule, domain, targets, stencil.reach).unwrap();
        let n = hi - lo;
        let mut g = NeedGrid {
            lo,
            n,
            need: vec![0; (n.x * n.y * n.z) as usize],
        };
        let total = 1 + schedule.corrections() as u8;
        for &(a, b) in targets {
            let (a, b) = (a.max(IVec3::ZERO), b.min(domain));
            for z in a.z..b.z {
                for y in a.y..b.y {
                    for x in a.x..b.x {
                        let i = g.index(IVec3::new(x, y, z));
                        g.need[i] = total;
                    }
                }
            }
        }
        let r = stencil.reach;
        let offsets: Vec<IVec3> = (-r..=r)
            .flat_map(|z| (-r..=r).flat_map(move |y| (-r..=r).map(move |x| IVec3::new(x, y, z))))
            .filter(|d| match stencil.planes {
                None => true,
                Some(planes) => (0..3).any(|p| planes[p] && d[(p + 2) % 3] == 0),
            })
            .collect();
        for step in schedule.steps().iter().rev() {
            let threshold = 1 + step.version_after() as u8;
            let barriers = &schedule.stages[step.stage].window.barriers;
            let before = g.need.clone();
            for i in 0..before.len() {
                let v = g.position(i);
                if before[i] < threshold || !step.active(v) {
                    continue;
                }
                for d in &offsets {
                    let w = v + *d;
                    if !g.contains(w) {
                        continue;
                    }
                    let same = barriers.iter().all(|c| c.cell_of(w) == c.cell_of(v));
                    let version = if same {
                        1 + step.latest(w) as u8
                    } else {
                        1 + step.stage_start as u8
                    };
                    let j = g.index(w);
                    g.need[j] = g.need[j].max(version);
                }
            }
        }
        g
    }

    #[test]
    fn dependent_set_matches_the_voxel_by_voxel_definition() {
        // Targets that leave parts of the box empty (whole rows and slabs, as a surface's
        // box does), in a domain that clips some of them; subpasses so that a step's active
        // voxels are a quarter of the rows.
        let domain = IVec3::new(37, 30, 26);
        let targets = [
            (IVec3::new(3, 4, 2), IVec3::new(6, 6, 4)),
            (IVec3::new(28, 22, 20), IVec3::new(40, 24, 21)),
            (IVec3::new(15, 2, 12), IVec3::new(16, 3, 13)),
        ];
        let schedules = [
            Schedule::dual_grid(2, true, 6),
            Schedule::grid(2, true, 8),
            Schedule::plain(2, true),
            Schedule::plain(2, false),
        ];
        let stencils = [
            Stencil::cube(2),
            Stencil {
                reach: 2,
                planes: Some([true, false, true]),
            },
            Stencil {
                reach: 3,
                planes: Some([true, true, true]),
            },
            Stencil {
                reach: 1,
                planes: Some([false, true, false]),
            },
        ];
        for schedule in &schedules {
            for &stencil in &stencils {
                let got = dependent_set(schedule, domain, &targets, stencil);
                let want = brute_dependent_set(schedule, domain, &targets, stencil);
                assert_eq!((got.lo, got.n), (want.lo, want.n));
                let differ = (0..got.need.len())
                    .filter(|&i| got.need[i] != want.need[i])
                    .count();
                assert_eq!(differ, 0, "{schedule:?} {stencil:?}");
                // Not trivially equal: the set grew beyond the targets' 18 voxels.
                assert!(got.voxels() > 100, "{schedule:?} {stencil:?}");
            }
        }
    }

    #[test]
    fn plain_dependent_set_grows_by_the_reach_per_step() {
        // Passes without subpasses, reach 2, a single target: (passes, voxels, corrections).
        for (passes, voxels, corrections) in [
            // One pass: the target's 5³ cube upsampled.
            (1, 125, 1),
            // Two passes: the target's cube corrected once, the 9³ cube upsampled.
            (2, 729, 1 + 125),
        ] {
            let g = dependent_set(
                &Schedule::plain(passes, false),
                IVec3::splat(40),
                &[(IVec3::splat(20), IVec3::splat(21))],
                2,
            );
            assert_eq!((g.voxels(), g.corrections()), (voxels, corrections));
        }
    }

    #[test]
    fn barriers_stop_the_growth() {
        let target = [(IVec3::splat(20), IVec3::splat(21))];
        let plain = dependent_set(&Schedule::plain(4, true), IVec3::splat(64), &target, 3);
        let grid = dependent_set(&Schedule::grid(4, true, 8), IVec3::splat(64), &target, 3);
        assert!(grid.voxels() < plain.voxels());
        // The grid cell of 20 is 16..24; its 3-neighbourhood 13..27 bounds everything.
        for i in 0..grid.need.len() {
            if grid.need[i] > 0 {
                let p = grid.position(i);
                assert!(p.cmpge(IVec3::splat(13)).all() && p.cmplt(IVec3::splat(27)).all());
                if grid.need[i] > 1 {
                    assert!(p.cmpge(IVec3::splat(16)).all() && p.cmplt(IVec3::splat(24)).all());
                }
            }
        }
    }

    #[test]
    fn axis_parts_give_the_same_slots() {
        // A dependent set over a box that is not a whole number of chunks, with an offset
        // corner, so parts of every axis and of partial chunks are exercised.
        let target = [(IVec3::new(23, 9, 14), IVec3::new(37, 20, 31))];
        let g = dependent_set(
            &Schedule::grid(2, true, 12),
            IVec3::new(70, 50, 60),
            &target,
            4,
        );
        let c = ChunkedNeed::from_grid(&g);
        let mut checked = 0;
        for i in 0..g.need.len() {
            let p = g.position(i);
            let Some(slot) = c.slot(p) else { continue };
            let parts = [0, 1, 2].map(|a| c.axis_part(a, p[a]));
            let table = parts.iter().map(|x| x.0).sum();
            let local = parts.iter().map(|x| x.1).sum();
            assert_eq!(c.slot_of_parts(table, local), slot, "at {p}");
            assert_eq!(c.slot_in_set(p), slot, "at {p}");
            checked += 1;
        }
        assert!(checked > 1000, "only {checked} voxels in kept chunks");
    }
}

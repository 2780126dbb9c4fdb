//! The correction of one voxel (§4.3): its three neighbourhoods gathered along the local
//! frame, projected on the PCA bases (the kernels of `texsyn_core::simd`), the candidates
//! `S(v)` collected and the nearest one kept; with the whole-frame and lattice shortcuts of
//! the trivial field and the per-correction caches.

use super::{NeighbourhoodColour, SolidSynthesis};
use crate::analyse_exemplar::candidate_triples::{SolidAnalysisRef, Triple, wrap};
use crate::simd::{
    Avx2, Kernels, Portable, prefetch_slice, project, project_avx2, project_avx512,
    squared_distance,
};
use crate::synthesize::solid::dependent_set::{CHUNK, CHUNK_BITS, ChunkedNeed, chunk_local};
use crate::synthesize::solid::field_integration::integrated_neighbourhood;
use crate::synthesize::solid::history_window::{HistoryWindow, Step};
use glam::{IVec3, Mat3, Vec3};

/// Per-thread buffers of a correction.
pub(super) struct Scratch {
    vec: Vec<f32>,
    proj: [Vec<f32>; 3],
    cands: Vec<Triple>,
    /// The distinct candidates, in the order of first visits.
    unique: Vec<Triple>,
    /// Sample positions of an integrated neighbourhood (`field_integration`).
    positions: Vec<Vec3>,
    /// Open-addressing set of the triples seen in this correction (entries stamped with
    /// `stamp`): 16 bytes an entry, the triple itself is the key.
    seen: Vec<(Triple, u32)>,
    /// Plane distances of this correction (entries stamped with `stamp`).
    memo: PlaneDistances,
    stamp: u32,
}

/// The distance from a voxel's projected neighbourhood in plane `P` to the feature of one
/// exemplar pixel of that plane, remembered per correction. A candidate's distance is the
/// weighted sum of one such distance per plane, and the candidates share them: the k
/// candidates of one pixel of `P` all have that pixel as their `P` coordinate (and mostly the
/// neighbour's shifted triple too), so each (plane, pixel) is compared once and its
/// feature read once. The sums add the same values in the same order: the same bits.
struct PlaneDistances {
    /// Open addressing: (plane, pixel) key, stamp, distance.
    entries: Vec<(u64, u32, f32)>,
}

impl PlaneDistances {
    /// A table for at most `capacity` distances per correction: always a free entry, and
    /// small enough (8 KiB for k = 4) to stay in the first-level cache beside the rest.
    fn new(capacity: usize) -> PlaneDistances {
        PlaneDistances {
            entries: vec![(0, 0, 0.0); (capacity + 1).next_power_of_two()],
        }
    }

    /// The distance of `plane`'s pixel `px` in correction `stamp`, from `compute` the first
    /// time it is asked for.
    #[inline(always)]
    fn get(
        &mut self,
        stamp: u32,
        plane: usize,
        px: [u16; 2],
        compute: impl FnOnce() -> f32,
    ) -> f32 {
        let key = ((plane as u64) << 32) | ((px[1] as u64) << 16) | px[0] as u64;
        let mask = self.entries.len() - 1;
        let mut i = (key.wrapping_mul(0x9E37_79B9_7F4A_7C15) >> 40) as usize & mask;
        loop {
            let e = &mut self.entries[i];
            if e.1 != stamp {
                let d = compute();
                *e = (key, stamp, d);
                return d;
            }
            if e.0 == key {
                return e.2;
            }
            i = (i + 1) & mask;
        }
    }

    /// Forgets every stamp (when the stamps wrap around).
    fn clear(&mut self) {
        self.entries.iter_mut().for_each(|e| e.1 = 0);
    }
}

/// The colours (`shown` of each voxel state) of a lattice neighbourhood (see
/// `lattice_steps`) into `out`, row-major: the voxel of row part `rows[j]`, column part
/// `cols[i]` and `centre` (each `(table part, local part, inside the latest window)` of one
/// axis) at `out[3(j·side + i)..]`, from `cur` inside the window and from `start` outside, as
/// `read` does. Its own function, not inlined: inside the big correction loop the output
/// cursor lived on the stack, and every cell waited on its store and reload; here the cursor,
/// the tables and both sources stay in registers.
#[inline(never)]
fn gather_lattice(
    st: &States,
    rows: &[(usize, usize, bool)],
    cols: &[(usize, usize, bool)],
    (tc, lc, inc): (usize, usize, bool),
    shown: impl Fn(&VoxelState) -> [f32; 3],
    out: &mut [f32],
) {
    let (cur, start) = (&st.cur[..], &st.start[..]);
    let mut o = 0;
    for &(tb, lb, inb) in rows {
        let (t, l, inside) = (tb + tc, lb + lc, inb && inc);
        for &(ta, la, ina) in cols {
            let slot = st.need.slot_of_parts(ta + t, la + l);
            let src = if ina && inside { cur } else { start };
            out[o..o + 3].copy_from_slice(&shown(&src[slot]));
            o += 3;
        }
    }
}

/// The parts (see [`ChunkedNeed::axis_part`]) of the positions `start + step·t` along `axis`
/// for `t = 0, 1, …` into `out`, each clamped to `[0, dmax]` first, with whether it lies in the
/// latest window `[lo, hi)` on that axis: the lattice gather's per-column and per-row work.
/// Inlined (a closure here was called out of line, 19 times a plane), with the axis's
/// multipliers worked out once.
#[inline(always)]
fn axis_parts(
    need: &ChunkedNeed,
    axis: usize,
    start: i32,
    step: i32,
    dmax: IVec3,
    (lo, hi): (IVec3, IVec3),
    out: &mut [(usize, usize, bool)],
) {
    let (dmax, lo, hi) = (dmax[axis], lo[axis], hi[axis]);
    let (origin, table, local) = need.axis_multipliers(axis);
    let mut x = start;
    for o in out.iter_mut() {
        let c = x.clamp(0, dmax);
        debug_assert!(c >= origin, "a gather coordinate below the need's origin");
        let q = (c - origin) as usize;
        *o = (
            (q >> CHUNK_BITS) * table,
            (q & (CHUNK as usize - 1)) * local,
            c >= lo && c < hi,
        );
        x += step;
    }
}

/// `⌊x + ½⌋`: nearest integer, halves up (no libm call).
#[inline]
fn round_i(x: f32) -> i32 {
    let t = x + 0.5;
    let i = t as i32;
    if (i as f32) > t { i - 1 } else { i }
}

/// A voxel's working value: triple and its colour at the level.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, bytemuck::Pod, bytemuck::Zeroable)]
pub(super) struct VoxelState {
    pub(super) t: Triple,
    pub(super) c: [f32; 3],
}

/// Working values of one batch of a level, slot for slot with the kept chunks of its
/// [`ChunkedNeed`]; `start` is the snapshot at the start of a stage with barriers.
pub(super) struct States<'n> {
    pub(super) need: &'n ChunkedNeed,
    pub(super) cur: Vec<VoxelState>,
    pub(super) start: Vec<VoxelState>,
}

impl<'n> States<'n> {
    pub(super) fn new(need: &'n ChunkedNeed) -> States<'n> {
        States {
            need,
            cur: vec![VoxelState::default(); need.chunk_voxels() as usize],
            start: Vec::new(),
        }
    }

    #[inline]
    pub(super) fn slot(&self, p: IVec3) -> usize {
        self.need.slot_in_set(p)
    }
}

#[inline]
pub(super) fn round_v(v: Vec3) -> IVec3 {
    IVec3::new(round_i(v.x), round_i(v.y), round_i(v.z))
}

/// A hash of a triple's 12 bytes (for the deduplication's table; its bits only choose where
/// probing starts, never what is kept).
#[inline(always)]
fn triple_hash(t: &Triple) -> usize {
    let w: [u32; 3] = bytemuck::cast(*t);
    let lo = w[0] as u64 | (w[1] as u64) << 32;
    ((lo ^ (w[2] as u64).rotate_left(29)).wrapping_mul(0x9E37_79B9_7F4A_7C15) >> 40) as usize
}

/// A frame whose rotation has entries 0 and ±1 only (the trivial field's signed
/// permutations; the argument below needs no more than that), at a whole scale `s`,
/// with a whole number `h/s` of exemplar pixels per voxel step: the trivial field's. Then
/// the candidates' float arithmetic is exact integer arithmetic, done here in integers: the
/// neighbour `[v + s q d]` is `v + s q d` (every coordinate a small integer, exact in `f32`,
/// so the rounding returns it), and its exemplar offset `qᵀ (w − v) h/s` is a sum of
/// products of 0 or ±1 with small whole numbers, each exact, so its roundings return it
/// too. The same values as the float path, bit for bit.
struct WholeFrame {
    /// The rotation's columns.
    axes: [IVec3; 3],
    s: i32,
    /// Exemplar pixels per voxel step, `h/s`.
    hs: i32,
}

impl WholeFrame {
    /// The whole frame of rotation `mat`, scale `s` and step `hs = h/s` (as the float path
    /// computes it), if it is one; magnitudes are bounded so that every intermediate value
    /// of the float path stays an integer below 2²³ (≤ 3 · 2048 · 1024 ≈ 6.3 M), where
    /// `x + 0.5` and its floor are exact too.
    #[inline]
    fn of(mat: &Mat3, s: f32, hs: f32) -> Option<WholeFrame> {
        let unit = mat
            .to_cols_array()
            .iter()
            .all(|&x| x == 0.0 || x == 1.0 || x == -1.0);
        let small = |x: f32| (1.0..=1024.0).contains(&x) && (x as i32) as f32 == x;
        (unit && small(s) && small(hs)).then(|| WholeFrame {
            axes: [0, 1, 2].map(|k| mat.col(k).as_ivec3()),
            s: s as i32,
            hs: hs as i32,
        })
    }

    /// `v + s (d₁ q_p + d₂ q_{p+1})`: the neighbour at in-plane offset `(d₁, d₂)` of plane
    /// `p`, before clamping.
    #[inline(always)]
    fn neighbour(&self, v: IVec3, p: usize, d1: i32, d2: i32) -> IVec3 {
        v + self.axes[p] * (self.s * d1) + self.axes[(p + 1) % 3] * (self.s * d2)
    }

    /// `qᵀ x · h/s`.
    #[inline(always)]
    fn shift(&self, x: IVec3) -> IVec3 {
        IVec3::new(
            self.axes[0].dot(x),
            self.axes[1].dot(x),
            self.axes[2].dot(x),
        ) * self.hs
    }
}

/// Largest neighbourhood side N (the analysis allows 3..=15).
const MAX_SIDE: usize = 15;

/// When the neighbourhood axes `c₁, c₂` are whole voxel steps along one axis each (the
/// columns of a frame whose entries are 0 and ±1, times a whole scale): `(axis, step)` of
/// each. Then every coordinate of `v + i c₁ + j c₂` is a small integer, exact in `f32`, and
/// its nearest voxel is `v + i a + j b` exactly, with no rounding to do.
#[inline(always)]
fn lattice_steps(c1: Vec3, c2: Vec3) -> Option<((usize, i32), (usize, i32))> {
    let single = |c: Vec3| {
        let i = c.as_ivec3();
        let whole = i.as_vec3() == c && i.abs().cmple(IVec3::splat(1024)).all();
        let axes = (0..3).filter(|&a| i[a] != 0).count();
        (whole && axes == 1).then(|| (0..3).find(|&a| i[a] != 0).map(|a| (a, i[a])))?
    };
    let (a, b) = (single(c1)?, single(c2)?);
    (a.0 != b.0).then_some((a, b))
}

/// Asks for the features of candidate `cand` (a hint only).
#[inline(always)]
fn prefetch_candidate(a: &SolidAnalysisRef, li: usize, weights: [f32; 3], cand: &Triple) {
    for p in 0..3 {
        if weights[p] != 0.0 {
            prefetch_slice(a.feature(li, a.image_of(p), cand.c[p]));
        }
    }
}

/// Candidates whose features are requested ahead of their comparison.
const PREFETCH_AHEAD: usize = 4;

impl<'a> SolidSynthesis<'a> {
    pub(super) fn scratch(&self, li: usize) -> Scratch {
        let c = self.analysis.components(li);
        Scratch {
            vec: vec![0.0; self.analysis.dim(li)],
            proj: [vec![0.0; c], vec![0.0; c], vec![0.0; c]],
            cands: Vec::with_capacity(27 * (self.analysis.k() + 1)),
            unique: Vec::with_capacity(27 * (self.analysis.k() + 1)),
            positions: Vec::new(),
            seen: vec![(Triple::default(), 0); (54 * (self.analysis.k() + 1)).next_power_of_two()],
            // At most one distance per plane of each of the 27 (k + 1) candidates.
            memo: PlaneDistances::new(3 * 27 * (self.analysis.k() + 1)),
            stamp: 0,
        }
    }

    /// The corrections of one chunk in one step: every voxel of the chunk whose needed
    /// version reaches `threshold` and that is active in `step`, pushed to `done` (slot in the
    /// chunk, new value) in slot order; returns the comparisons made. On x86-64 CPUs with
    /// AVX2 the same code runs compiled for AVX2: wider vectors for the same operations in the
    /// same order (Rust never fuses a multiply and an add), so the values are the same bits;
    /// where the CPU also has AVX-512F, its projection is [`project_avx512`] (two basis rows
    /// per register, the same products and sums per lane). Checks: CI's emulated Nehalem runs
    /// the portable path against the locks, this machine's runs the widest path its CPU has,
    /// and each vector projection has a bitwise unit test against the portable one (skipped,
    /// and saying so, on a CPU without it).
    #[allow(clippy::too_many_arguments)]
    pub(super) fn correct_chunk(
        &self,
        li: usize,
        st: &States,
        window: &HistoryWindow,
        step: &Step,
        chunk: (u8, IVec3, &[u8]),
        sc: &mut Scratch,
        done: &mut Vec<(u16, VoxelState)>,
    ) -> u64 {
        #[cfg(target_arch = "x86_64")]
        if let Some(avx2) = Avx2::detect() {
            // SAFETY: the token exists, so the CPU supports AVX2.
            return unsafe { self.correct_chunk_avx2(avx2, li, st, window, step, chunk, sc, done) };
        }
        self.correct_chunk_portable(Portable, li, st, window, step, chunk, sc, done)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    #[allow(clippy::too_many_arguments)]
    unsafe fn correct_chunk_avx2(
        &self,
        avx2: Avx2,
        li: usize,
        st: &States,
        window: &HistoryWindow,
        step: &Step,
        chunk: (u8, IVec3, &[u8]),
        sc: &mut Scratch,
        done: &mut Vec<(u16, VoxelState)>,
    ) -> u64 {
        self.correct_chunk_portable(avx2, li, st, window, step, chunk, sc, done)
    }

    /// [`SolidSynthesis::correct_chunk`], compiled for whatever the caller is compiled for;
    /// `kernels` says which projection it may call (a token of [`Avx2`]: the caller has
    /// AVX2, so the projection may use its 8-wide registers).
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    fn correct_chunk_portable<K: Kernels>(
        &self,
        kernels: K,
        li: usize,
        st: &States,
        window: &HistoryWindow,
        step: &Step,
        (threshold, origin, bytes): (u8, IVec3, &[u8]),
        sc: &mut Scratch,
        done: &mut Vec<(u16, VoxelState)>,
    ) -> u64 {
        let mut c = 0u64;
        for (m, &x) in bytes.iter().enumerate() {
            let v = origin + chunk_local(m);
            if x >= threshold && step.active(v) {
                let (s, n) = self.correct(kernels, li, st, window, v, sc);
                done.push((m as u16, s));
                c += n as u64;
            }
        }
        c
    }

    /// The scaled frame (columns `s·q` axes, in voxels of the level) of array level `li` at
    /// `x`, in voxel coordinates of the level.
    fn frame_at(&self, li: usize, x: Vec3) -> Mat3 {
        let pos = self.pyramid.position_f(li as u32 + 1, x);
        let (q, s) = self.rotation_scale(li, pos);
        Mat3::from_quat(q) * s
    }

    /// §4.3: the corrected value of voxel `v` of array level `li`, and the comparisons made.
    #[inline(always)]
    fn correct<K: Kernels>(
        &self,
        kernels: K,
        li: usize,
        st: &States,
        window: &HistoryWindow,
        v: IVec3,
        sc: &mut Scratch,
    ) -> (VoxelState, u32) {
        let a = &self.analysis;
        let level = li as u32 + 1;
        let (w, hh) = self.wh();
        let weights = a.weights();
        let dmax = self.pyramid.level_dims(level) - 1;
        let pos = self.pyramid.position(level, v);
        let (q, s) = self.rotation_scale(li, pos);
        let mat = Mat3::from_quat(q);
        let h = a.spacing(li) as f32;
        let (clo, chi) = window.latest_box(v);
        let read = |p: IVec3| -> &VoxelState {
            let p = p.clamp(IVec3::ZERO, dmax);
            let slot = st.slot(p);
            if p.cmpge(clo).all() && p.cmplt(chi).all() {
                &st.cur[slot]
            } else {
                &st.start[slot]
            }
        };
        // What a voxel shows in plane `p`'s neighbourhood.
        let plane_colour = self.params.neighbourhood_colour == NeighbourhoodColour::Plane;
        let shown = |s: &VoxelState, p: usize| -> [f32; 3] {
            if plane_colour {
                a.match_texel(li, a.image_of(p), s.t.c[p])
            } else {
                s.c
            }
        };
        let trilinear = self.params.levels[li].trilinear;
        let sample = |x: Vec3, p: usize| -> [f32; 3] {
            if !trilinear {
                return shown(read(round_v(x)), p);
            }
            let f = x.floor();
            let t = x - f;
            let b = f.as_ivec3();
            let mut acc = [0.0f32; 3];
            for corner in 0..8 {
                let o = IVec3::new(corner & 1, (corner >> 1) & 1, (corner >> 2) & 1);
                let wt = (if o.x == 1 { t.x } else { 1.0 - t.x })
                    * (if o.y == 1 { t.y } else { 1.0 - t.y })
                    * (if o.z == 1 { t.z } else { 1.0 - t.z });
                if wt == 0.0 {
                    continue;
                }
                let c = shown(read(b + o), p);
                for ch in 0..3 {
                    acc[ch] += wt * c[ch];
                }
            }
            acc
        };
        let nh = (a.n(li) / 2) as i32;
        let vf = v.as_vec3();
        let whole = WholeFrame::of(&mat, s, h / s);
        let comps = a.components(li);
        let dim = a.dim(li);
        sc.cands.clear();
        for p in 0..3 {
            if weights[p] == 0.0 {
                continue;
            }
            let c1 = mat.col(p) * s;
            let c2 = mat.col((p + 1) % 3) * s;
            // Gather, row-major: j along image y (c2), i along image x (c1).
            if let Some(bound) = self.integrate[li] {
                // Coarse levels with `field_integration`: along the field's integral lines.
                let frame = |x: Vec3| self.frame_at(li, x);
                integrated_neighbourhood(frame, vf, p, nh, bound, &mut sc.positions);
                for (o, x) in sc.positions.iter().enumerate() {
                    sc.vec[3 * o..3 * o + 3].copy_from_slice(&sample(*x, p));
                }
            } else {
                let out = &mut sc.vec[..dim];
                match lattice_steps(c1, c2).filter(|_| !trilinear) {
                    // The frame's columns are whole voxel steps along two axes (the trivial
                    // field): every sample position is an integer, exactly, so the nearest voxel
                    // of `v + i c₁ + j c₂` is `v + i a + j b` without rounding, and its clamped
                    // coordinates, slot parts and place in the window (all per axis) are worked
                    // out once per column `i` and row `j`. The same reads as `read`.
                    Some(((ax, sa), (bx, sb))) => {
                        let cx = 3 - ax - bx;
                        let side = (2 * nh + 1) as usize;
                        let latest = (clo, chi);
                        let mut cols = [(0, 0, false); MAX_SIDE];
                        let mut rows = [(0, 0, false); MAX_SIDE];
                        let (cols, rows) = (&mut cols[..side], &mut rows[..side]);
                        axis_parts(st.need, ax, v[ax] - sa * nh, sa, dmax, latest, cols);
                        axis_parts(st.need, bx, v[bx] - sb * nh, sb, dmax, latest, rows);
                        let mut centre = [(0, 0, false)];
                        axis_parts(st.need, cx, v[cx], 0, dmax, latest, &mut centre);
                        let shown = |s: &VoxelState| shown(s, p);
                        gather_lattice(st, rows, cols, centre[0], shown, out);
                    }
                    None => {
                        let mut o = 0;
                        for j in -nh..=nh {
                            let row = vf + c2 * j as f32;
                            for i in -nh..=nh {
                                let col = sample(row + c1 * i as f32, p);
                                out[o..o + 3].copy_from_slice(&col);
                                o += 3;
                            }
                        }
                    }
                }
            }
            let img = a.image_of(p);
            let (_, basis) = a.pca(li, img);
            let mp = &self.mean_proj[li][img];
            let (x, proj) = (&sc.vec[..dim], &mut sc.proj[p][..comps]);
            #[cfg(target_arch = "x86_64")]
            if K::AVX2 {
                match &self.paired {
                    Some((_avx512, rows)) if !rows[li][img].is_empty() => {
                        // SAFETY: the `Avx512` token exists only after `Avx512::detect`
                        // found AVX-512F and AVX2.
                        unsafe { project_avx512(basis, &rows[li][img], x, mp, proj) };
                    }
                    _ => {
                        // SAFETY: only `Avx2` has `AVX2` set, and a value of it (`kernels`)
                        // exists only after `Avx2::detect` found AVX2.
                        let _proof = kernels;
                        unsafe { project_avx2(basis, x, mp, proj) };
                    }
                }
            } else {
                project(basis, x, mp, proj);
            }
            #[cfg(not(target_arch = "x86_64"))]
            {
                let _ = kernels;
                project(basis, x, mp, proj);
            }
            // Candidates S_P(v), reduced form. Where the neighbours are coherent most of
            // the nine shifted pixels are the same pixel, whose k candidates are then all
            // already listed: a repeated pixel adds none (none could be a first visit in the
            // deduplication below), so its list is skipped before any copying or hashing.
            let mut pixels = [[0u16; 2]; 9];
            let mut distinct = 0;
            for d2 in -1..=1 {
                for d1 in -1..=1 {
                    let triple = |wv: IVec3| read(wv).t;
                    // The neighbour `w`'s triple, the pixel it names in `p` shifted back by
                    // `w`'s exemplar offset `e`, and `−e` rounded (eq. 4).
                    let (tw, px, back) = if let Some(f) = &whole {
                        let wv = f.neighbour(v, p, d1, d2).clamp(IVec3::ZERO, dmax);
                        let tw = triple(wv);
                        let e = f.shift(wv - v);
                        let px = [
                            wrap(tw.c[p][0] as i32 - e[p], w),
                            wrap(tw.c[p][1] as i32 - e[(p + 1) % 3], hh),
                        ];
                        (tw, px, -e)
                    } else {
                        let wv =
                            round_v(vf + c1 * d1 as f32 + c2 * d2 as f32).clamp(IVec3::ZERO, dmax);
                        let tw = triple(wv);
                        let e = mat.transpose() * ((wv - v).as_vec3() * (h / s));
                        let (e1, e2) = (e[p], e[(p + 1) % 3]);
                        let px = [
                            wrap(round_i(tw.c[p][0] as f32 - e1), w),
                            wrap(round_i(tw.c[p][1] as f32 - e2), hh),
                        ];
                        (tw, px, -round_v(e))
                    };
                    if !pixels[..distinct].contains(&px) {
                        pixels[distinct] = px;
                        distinct += 1;
                        // One push each: a copy of a few triples is cheaper inline than
                        // through a memcpy call.
                        for t in a.candidates(li, p, px) {
                            sc.cands.push(*t);
                        }
                    }
                    if self.params.coherent_candidates {
                        // The neighbour's whole triple, shifted back (eq. 4).
                        sc.cands.push(tw.offset(back.into(), w, hh));
                    }
                }
            }
        }
        // Coordinates in planes of weight 0 are never read: canonical zeros, so candidates
        // differing only there are compared once.
        for p in 0..3 {
            if weights[p] == 0.0 {
                sc.cands.iter_mut().for_each(|c| c.c[p] = [0, 0]);
            }
        }
        // Deduplicate (a small hash set of the triples themselves), keeping the order of
        // first visits.
        sc.unique.clear();
        sc.stamp = sc.stamp.wrapping_add(1);
        if sc.stamp == 0 {
            sc.seen.iter_mut().for_each(|e| e.1 = 0);
            sc.memo.clear();
            sc.stamp = 1;
        }
        let mask = sc.seen.len() - 1;
        for c in &sc.cands {
            let mut i = triple_hash(c) & mask;
            loop {
                let e = &mut sc.seen[i];
                if e.1 != sc.stamp {
                    *e = (*c, sc.stamp);
                    sc.unique.push(*c);
                    break;
                }
                if e.0 == *c {
                    break;
                }
                i = (i + 1) & mask;
            }
        }
        let mut best = (f32::INFINITY, sc.unique[0]);
        let prefetch = |t: &Triple| prefetch_candidate(a, li, weights, t);
        // The features of the candidates are scattered over the exemplar's stack: ask for
        // them a few candidates ahead (a hint only; the values compared are the same).
        for t in sc.unique.iter().take(PREFETCH_AHEAD) {
            prefetch(t);
        }
        for (ki, cand) in sc.unique.iter().enumerate() {
            if let Some(next) = sc.unique.get(ki + PREFETCH_AHEAD) {
                prefetch(next);
            }
            let mut e = 0.0f32;
            for p in 0..3 {
                if weights[p] == 0.0 {
                    continue;
                }
                let proj = &sc.proj[p];
                let d = sc.memo.get(sc.stamp, p, cand.c[p], || {
                    squared_distance(proj, a.feature(li, a.image_of(p), cand.c[p]))
                });
                e += weights[p] * d;
                if e >= best.0 {
                    break;
                }
            }
            if e < best.0 {
                best = (e, *cand);
            }
        }
        let comparisons = sc.unique.len() as u32;
        let t = best.1;
        (
            VoxelState {
                t,
                c: a.match_colour(li, &t),
            },
            comparisons,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn whole_frames_give_the_float_paths_values() {
        // The float path of the candidates' shifted pixels, as `correct` computes it.
        let float = |mat: Mat3, s: f32, h: f32, v: IVec3, p: usize, d: (i32, i32)| {
            let (c1, c2) = (mat.col(p) * s, mat.col((p + 1) % 3) * s);
            let wv = round_v(v.as_vec3() + c1 * d.0 as f32 + c2 * d.1 as f32);
            let e = mat.transpose() * ((wv - v).as_vec3() * (h / s));
            (wv, e)
        };
        let frames = [
            Mat3::IDENTITY,
            Mat3::from_cols(-Vec3::Y, Vec3::X, Vec3::Z),
            Mat3::from_cols(Vec3::Y, -Vec3::Z, -Vec3::X),
            Mat3::from_cols(-Vec3::X, -Vec3::Y, Vec3::Z),
        ];
        let mut checked = 0;
        for mat in frames {
            for (s, h) in [
                (1.0f32, 1.0f32),
                (1.0, 8.0),
                (2.0, 4.0),
                (2.0, 2.0),
                (4.0, 8.0),
            ] {
                let f = WholeFrame::of(&mat, s, h / s).expect("a whole frame");
                for v in [
                    IVec3::new(0, 0, 0),
                    IVec3::new(17, 3, 250),
                    IVec3::new(5, 900, 41),
                ] {
                    for p in 0..3 {
                        for d2 in -1..=1 {
                            for d1 in -1..=1 {
                                let (wv, e) = float(mat, s, h, v, p, (d1, d2));
                                assert_eq!(f.neighbour(v, p, d1, d2), wv);
                                // Off the unclamped neighbour too (clamping moves `w`).
                                for w in [wv, wv + IVec3::new(1, -2, 0)] {
                                    let e = if w == wv {
                                        e
                                    } else {
                                        mat.transpose() * ((w - v).as_vec3() * (h / s))
                                    };
                                    let i = f.shift(w - v);
                                    assert_eq!(i, round_v(e), "{mat} s {s} h {h}");
                                    for t in [0u16, 7, 300, 32767] {
                                        for k in 0..3 {
                                            assert_eq!(t as i32 - i[k], round_i(t as f32 - e[k]));
                                        }
                                    }
                                    checked += 1;
                                }
                            }
                        }
                    }
                }
            }
        }
        assert!(checked > 1000);
        // Not whole: a fractional pixel step, a fractional scale, a rotation off the axes.
        assert!(WholeFrame::of(&Mat3::IDENTITY, 3.0, 4.0 / 3.0).is_none());
        assert!(WholeFrame::of(&Mat3::IDENTITY, 1.5, 2.0 / 1.5).is_none());
        let tilted = Mat3::from_quat(glam::Quat::from_rotation_z(0.1));
        assert!(WholeFrame::of(&tilted, 1.0, 1.0).is_none());
        assert!(WholeFrame::of(&(Mat3::IDENTITY * 0.5), 2.0, 1.0).is_none());
    }

    #[test]
    fn lattice_steps_are_the_rounded_positions() {
        let frames = [
            Mat3::IDENTITY,
            Mat3::from_cols(-Vec3::Y, Vec3::X, Vec3::Z),
            Mat3::from_cols(Vec3::Y, -Vec3::Z, -Vec3::X),
        ];
        let mut found = 0;
        for mat in frames {
            for s in [1.0f32, 2.0] {
                for p in 0..3 {
                    let (c1, c2) = (mat.col(p) * s, mat.col((p + 1) % 3) * s);
                    let Some(((ax, sa), (bx, sb))) = lattice_steps(c1, c2) else {
                        continue;
                    };
                    found += 1;
                    assert_ne!(ax, bx);
                    for v in [
                        IVec3::new(0, 0, 0),
                        IVec3::new(1023, 627, 333),
                        IVec3::new(5, 9, 2),
                    ] {
                        let vf = v.as_vec3();
                        for j in -7..=7 {
                            let row = vf + c2 * j as f32;
                            for i in -7..=7 {
                                let mut q = v;
                                q[ax] += sa * i;
                                q[bx] += sb * j;
                                assert_eq!(round_v(row + c1 * i as f32), q);
                            }
                        }
                    }
                }
            }
        }
        // Every plane of these signed permutations, at both scales, is a lattice.
        assert_eq!(found, 18, "{found} lattice planes");
        // A frame off the lattice takes the general path.
        let m = Mat3::from_cols(Vec3::new(0.8, 0.6, 0.0), Vec3::new(-0.6, 0.8, 0.0), Vec3::Z);
        assert!(lattice_steps(m.col(0), m.col(1)).is_none());
        assert!(lattice_steps(Vec3::X * 1.5, Vec3::Y).is_none());
        assert!(lattice_steps(Vec3::X, Vec3::X).is_none());
    }
}

//! Parallel synthesis of sample coordinates over a geometry image, in appearance space.
//!
//! Implements S. Lefebvre and H. Hoppe, "Parallel controllable texture synthesis" (SIGGRAPH
//! 2005) §3 (coordinate upsampling, jitter, correction in sub-passes) with the appearance
//! vectors and anisometric synthesis of S. Lefebvre and H. Hoppe, "Appearance-space texture
//! synthesis" (SIGGRAPH 2006) §3 and §6, on the geometry images of Lai et al. (SPM 2005).
//! Every output texel is a coordinate in the sample, so a structure that is connected in the
//! sample stays connected wherever a coherent run copies it; the relief is gathered from the
//! sample at the end.
//!
//! The Jacobian field is [`sample_frame_maps`]: per sample, the map `M` from grid offsets to
//! sample offsets, which holds the field's orientation and scale (Lai et al. §4.3, continuous
//! here instead of their 8 × 3 variants) and the geometry image's surface metric (its
//! anisometry). Coordinates are continuous (texel centres at integers). A grid step at pyramid
//! level `l` (grid side `(n − 1)/2^l + 1`) spans `2^l M` sample texels; the level matches at
//! stack level `l + lift`, spacing `h = 2^(l + lift)`, where `lift` is the stack level nearest
//! the median footprint `√|det M|` of a level-0 step (0 when a step spans about one texel, 2 at
//! four):
//! 1. **Upsampling** (2005 §3.1): texel `(i, j)` takes its parent `(i/2, j/2)`'s coordinate plus
//!    `2^l M (j mod 2, i mod 2)`; the coarsest level starts from whole-texel coordinates drawn
//!    at random.
//! 2. **Jitter** (2005 §3.1): each coordinate moves by `round(h · jitter · ζ)`, `ζ` uniform in
//!    `[−1, 1]²` from a counter-based hash.
//! 3. **Correction** (2005 §3.2, 2006 §6): `appearance_passes` passes (twice as many at the
//!    coarsest level), each of 4 sub-passes over the texels of one parity class `(i mod 2,
//!    j mod 2)`. A texel's neighbourhood is the appearance vectors at the 3×3 sample offsets
//!    `h Δ`: tap `Δ` is predicted from the grid neighbour `g = round(2^lift M⁻¹ Δ)` as its
//!    coordinate `− 2^l M g + h Δ` (anisometric: 2006 §6; where `g` rounds to the texel
//!    itself, the neighbour one step in its direction); the candidates are the k-coherence
//!    sets of the coordinates the neighbours imply for the texel (`− 2^l M g`), each keeping
//!    that coordinate's sub-texel remainder. The nearest candidate neighbourhood wins (the
//!    texel's current coordinate on ties; a candidate that continues no neighbour's run pays
//!    the factor `1 + appearance_coherence`, and one whose `h × h` block of the sample the
//!    level already copies beyond its share the occurrence factor of Kopf et al. 2007 §3.3,
//!    [`crate::synthesize::occurrence`], counted before each sub-pass).
//!
//! Geometry-image cuts (Lai et al. §4.2.2): a neighbour beyond a side sample with a confirmed
//! mate is read across the cut ([`LevelGrid::neighbour`]); coordinates are frame-free, so
//! nothing turns. Every mate group takes one member's coordinate (chosen by hash) after the
//! upsampling and after every sub-pass, so the cut is synthesized as one surface and mated
//! texels end bit-identical. Lai et al.'s separate boundary resynthesis is not needed: the
//! correction passes already see both sides of every cut.
//!
//! Departures: Lefebvre & Hoppe 2006's anisometric synthesis reads every tap from an immediate
//! grid neighbour; here a tap is read from the neighbour `round(2^lift M⁻¹ Δ)`, several steps
//! away where a step spans under a tap spacing, so the query still holds the sample's
//! structure at the tap's distance (reading immediate neighbours only scores relief_cow, seed
//! 1, density offset 0, 1.209 along the surface against 0.913); coordinates are clamped inside
//! the sample (samples are not assumed to tile);
//! a tap beyond an open side or a corner has no neighbour to predict it, so it is left out of
//! the distance (predicted from the texel itself, it would pull border texels towards whatever
//! they hold: at `appearance_k = 4` the crack network of the tests then breaks into 11.2
//! components on average over 5 seeds against 8.4, the extra ones stubs along the sides); the
//! appearance space ([`crate::analyse_exemplar::appearance_space`], its own cached node) is
//! the sample's at the variants' middle scale, and the orientation and scale variants are not
//! read (the map `M` does their work continuously). The occurrence penalty is neither paper's:
//! Kopf et al. 2007 §3.3 re-weight matches in an optimization's averaging; here the same
//! factor multiplies a candidate's distance in the search, as texture optimization's search
//! does too, because a coordinate synthesizer copies and never averages.
//! Thread count does not change the result: each sub-pass reads only the coordinates the
//! previous one left.

use super::ParamField;
use super::controls::{sample_frame_maps, texel_controls};
use super::grid::LevelGrid;
use super::params::{GeometrySynthParams, GeometryTextureError, check_inputs};
use crate::analyse_exemplar::appearance_space::{
    APPEARANCE_DIMS, AppearanceLevel, AppearanceSpaceRef, NEIGHBOURHOOD_DIMS, TAPS_3X3,
    interior_margin,
};
use crate::analyse_exemplar::texel_variants::TexelVariantsRef;
use crate::geom::geometry_image::{GeometryImage, TexelImage};
use crate::image::knn::squared_distance;
use crate::random::{counter_hash, counter_unit};
use crate::synthesize::occurrence::BlockUse;
use rayon::prelude::*;
use texsyn_core::math::PureMath;

const STREAM_START: u64 = 0x6173_0001;
const STREAM_JITTER: u64 = 0x6173_0002;
const STREAM_MATE: u64 = 0x6173_0003;

/// The parity classes of the 4 sub-passes, `(i mod 2, j mod 2)`.
const SUB_PASSES: [(usize, usize); 4] = [(0, 0), (1, 1), (0, 1), (1, 0)];

/// The smallest grid side the coarsest level may have.
const MIN_SIDE: usize = 5;

/// The grid levels a geometry image of side `n` can halve into, down to [`MIN_SIDE`].
fn grid_levels(n: usize) -> usize {
    let mut levels = 1;
    while (n - 1).is_multiple_of(1 << levels) && (n - 1) / (1 << levels) + 1 >= MIN_SIDE {
        levels += 1;
    }
    levels
}

/// The stack level whose spacing is nearest the footprint `√|det M|` of a grid step, in
/// `0..levels`.
fn footprint_level(m: &[f32; 4], levels: usize) -> usize {
    let det = (m[0] as f64 * m[3] as f64 - m[1] as f64 * m[2] as f64).abs();
    if det <= 0.0 {
        return 0;
    }
    (0.5 * det.log2_pure())
        .round()
        .clamp(0.0, (levels - 1) as f64) as usize
}

/// One level's state: its grid, each texel's map `M` (from level-0 grid steps) and its
/// sample coordinate.
struct Level {
    grid: LevelGrid,
    /// Level-0 grid steps per step of this level, `2^l`.
    step: f64,
    /// Stack spacing per grid step of `M`'s scale, `2^lift` (see [`synthesize_appearance`]).
    lift: f64,
    maps: Vec<[f32; 4]>,
    /// Continuous sample coordinates (texel centres at integers).
    coords: Vec<[f32; 2]>,
}

/// The size of the sample the coordinates point into.
struct Sample {
    width: i32,
    height: i32,
}

impl Sample {
    /// `(x, y)` clamped inside the sample.
    #[inline]
    fn clamp(&self, x: f64, y: f64) -> [f32; 2] {
        [
            x.clamp(0.0, (self.width - 1) as f64) as f32,
            y.clamp(0.0, (self.height - 1) as f64) as f32,
        ]
    }

    /// Whether `(x, y)` rounds to a texel at least `margin` inside the sample's borders.
    #[inline]
    fn inside(&self, x: f64, y: f64, margin: f64) -> bool {
        let (x, y) = ((x + 0.5).floor(), (y + 0.5).floor());
        (margin..=(self.width - 1) as f64 - margin).contains(&x)
            && (margin..=(self.height - 1) as f64 - margin).contains(&y)
    }

    /// The texel nearest `u`.
    #[inline]
    fn index(&self, u: [f32; 2]) -> usize {
        let x = ((u[0] + 0.5).floor() as i64).clamp(0, self.width as i64 - 1) as usize;
        let y = ((u[1] + 0.5).floor() as i64).clamp(0, self.height as i64 - 1) as usize;
        y * self.width as usize + x
    }

    /// `u`'s offset from the texel nearest it.
    #[inline]
    fn remainder(&self, u: [f32; 2]) -> [f32; 2] {
        let t = self.index(u);
        let w = self.width as usize;
        [u[0] - (t % w) as f32, u[1] - (t / w) as f32]
    }

    /// Bilinear interpolation of the `c`-channel `texels` at `u`, into `out`.
    fn bilinear(&self, texels: &[f32], c: usize, u: [f32; 2], out: &mut [f32]) {
        let (w, h) = (self.width as usize, self.height as usize);
        let (x0, y0) = (u[0].floor().max(0.0), u[1].floor().max(0.0));
        let (fx, fy) = (u[0] - x0, u[1] - y0);
        let (x0, y0) = ((x0 as usize).min(w - 1), (y0 as usize).min(h - 1));
        let (x1, y1) = ((x0 + 1).min(w - 1), (y0 + 1).min(h - 1));
        for (ch, o) in out.iter_mut().enumerate().take(c) {
            let at = |x: usize, y: usize| texels[(y * w + x) * c + ch];
            let top = at(x0, y0) + (at(x1, y0) - at(x0, y0)) * fx;
            let bot = at(x0, y1) + (at(x1, y1) - at(x0, y1)) * fx;
            *o = top + (bot - top) * fy;
        }
    }
}

#[inline]
fn apply(m: &[f32; 4], x: f64, y: f64) -> (f64, f64) {
    (
        m[0] as f64 * x + m[1] as f64 * y,
        m[2] as f64 * x + m[3] as f64 * y,
    )
}

/// The grid offsets `round(lift · M⁻¹ Δ)` of the 3×3 taps (`(0, 0)` for a singular map). An
/// outer tap that rounds onto the texel itself, where a grid step spans more than two tap
/// spacings, is read from the grid neighbour nearest its direction instead
/// ([`nearest_step`]): predicted from the texel itself it would compare every candidate with
/// the texel's current coordinate there, hold the texel where it is, and leave neighbours
/// across the map's long direction unconstrained by each other.
fn tap_offsets(m: &[f32; 4], lift: f64) -> [(i64, i64); 9] {
    let (a, b, c, d) = (m[0] as f64, m[1] as f64, m[2] as f64, m[3] as f64);
    let det = a * d - b * c;
    let mut out = [(0i64, 0i64); 9];
    if det.abs() < 1e-12 {
        return out;
    }
    for (o, &(dx, dy)) in out.iter_mut().zip(&TAPS_3X3) {
        let (dx, dy) = (lift * dx as f64, lift * dy as f64);
        let gx = (d * dx - b * dy) / det;
        let gy = (-c * dx + a * dy) / det;
        *o = ((gx + 0.5).floor() as i64, (gy + 0.5).floor() as i64);
        if *o == (0, 0) && (dx, dy) != (0.0, 0.0) {
            *o = nearest_step(gx, gy);
        }
    }
    out
}

/// One of the 8 grid steps around a texel, in the direction `(gx, gy)`: `(gx, gy)` divided by
/// its larger component and rounded, so each axis steps by the sign of its component when that
/// component is at least half the larger one (`(0, 0)` for a zero or not finite direction).
/// Lefebvre & Hoppe 2006's anisometric synthesis reads every tap from such an immediate
/// neighbour.
fn nearest_step(gx: f64, gy: f64) -> (i64, i64) {
    let big = gx.abs().max(gy.abs());
    if !(gx.is_finite() && gy.is_finite() && big > 0.0) {
        return (0, 0);
    }
    let unit = |v: f64| {
        if v.abs() * 2.0 >= big {
            v.signum() as i64
        } else {
            0
        }
    };
    (unit(gx), unit(gy))
}

/// The factors a candidate's neighbourhood distance is weighed with.
#[derive(Clone, Copy)]
struct Weights {
    /// `1 + appearance_coherence`, on a candidate that continues no neighbour's run.
    incoherent: f32,
    /// `appearance_occupancy`, per share its block of the sample is copied beyond its own.
    occupancy: f32,
}

/// How often the coordinates of `lv` copy each `spacing`-square block of the sample, against
/// a share proportional to the block's texels: the use of a synthesis that spread over the
/// whole sample evenly. Only the interior can be copied, so at coarse levels, where the
/// interior is a small part of the sample, every block in it is over that share and the
/// penalty spreads the coarse layout hardest, which is where a repeat would show most. (A
/// share of the interior texels alone, so that the penalty is as strong at every level, left
/// the crack network of the tests in a median of 4 pieces at weight 2 or 4 and 3 at 8,
/// against 2 with this share at weight 2 and 3 at 1.)
fn block_use(lv: &Level, s: &Sample, spacing: u32) -> BlockUse {
    let (w, h) = (s.width as usize, s.height as usize);
    BlockUse::new(
        w,
        h,
        spacing as usize,
        lv.coords.iter().map(|&u| {
            let i = s.index(u);
            (i % w, i / w)
        }),
        (0..h).flat_map(|y| (0..w).map(move |x| (x, y))),
    )
}

/// The corrected coordinate of texel `t` of `lv` (see the module docs, step 3).
fn correct(
    lv: &Level,
    s: &Sample,
    al: &AppearanceLevel<'_>,
    k: usize,
    weights: Weights,
    occupancy: &[f32],
    t: usize,
) -> [f32; 2] {
    let (i, j) = lv.grid.coords(t as u32);
    let h = al.spacing as f64;
    let step = lv.step;
    let m = &lv.maps[t];
    let me = lv.coords[t];
    let mut query = [0.0f32; NEIGHBOURHOOD_DIMS];
    let mut bases: [Option<(usize, [f32; 2])>; 9] = [None; 9];
    let mut open = [false; 9];
    let centre = 4 * APPEARANCE_DIMS;
    let margin = interior_margin(s.width as u32, s.height as u32, al.spacing) as f64;
    for (o, (&g, &(dx, dy))) in tap_offsets(m, lv.lift).iter().zip(&TAPS_3X3).enumerate() {
        let at = match lv.grid.neighbour(i + g.1, j + g.0) {
            Some(q) => {
                let (sx, sy) = apply(m, g.0 as f64, g.1 as f64);
                let u = lv.coords[q];
                let (bx, by) = (u[0] as f64 - step * sx, u[1] as f64 - step * sy);
                // A neighbour whose coherent run has left the sample proposes nothing:
                // clamped, its proposal would repeat the sample's border into streaks.
                if s.inside(bx, by, margin) {
                    let base = s.clamp(bx, by);
                    bases[o] = Some((s.index(base), s.remainder(base)));
                }
                s.clamp(
                    u[0] as f64 - step * sx + h * dx as f64,
                    u[1] as f64 - step * sy + h * dy as f64,
                )
            }
            None => {
                open[o] = true;
                s.clamp(me[0] as f64 + h * dx as f64, me[1] as f64 + h * dy as f64)
            }
        };
        let a = s.index(at) * NEIGHBOURHOOD_DIMS + centre;
        query[o * APPEARANCE_DIMS..(o + 1) * APPEARANCE_DIMS]
            .copy_from_slice(&al.neighbourhoods[a..a + APPEARANCE_DIMS]);
    }
    // Taps beyond an open side or a corner compare nothing (see the module docs).
    let any_open = open.iter().any(|&b| b);
    let dist = |u: usize| {
        let cand = &al.neighbourhoods[u * NEIGHBOURHOOD_DIMS..(u + 1) * NEIGHBOURHOOD_DIMS];
        if !any_open {
            return squared_distance(&query, cand);
        }
        let mut d = 0.0;
        for (o, _) in open.iter().enumerate().filter(|(_, b)| !**b) {
            let r = o * APPEARANCE_DIMS..(o + 1) * APPEARANCE_DIMS;
            d += squared_distance(&query[r.clone()], &cand[r]);
        }
        d
    };
    // A candidate keeps the sub-texel remainder of the coordinate it was proposed from, so a
    // coherent run advances by `M g` exactly, not by whole texels (which repeats texels into
    // streaks where a grid step spans less than a sample texel).
    // The texel's own coordinate competes only inside the interior; outside it (a run that
    // left it), the first proposal, or the interior texel nearest, takes its place.
    let own = s.index(me);
    let w = s.width as usize;
    let over = |u: usize| occupancy[u];
    let mut best = if s.inside(me[0] as f64, me[1] as f64, margin) {
        (dist(own) * over(own), own, s.remainder(me))
    } else {
        let m = margin as f32;
        let (wf, hf) = ((s.width - 1) as f32 - m, (s.height - 1) as f32 - m);
        let back = [me[0].clamp(m, wf), me[1].clamp(m, hf)];
        let u = s.index(back);
        (f32::INFINITY, u, s.remainder(back))
    };
    for &(base, rem) in bases.iter().flatten() {
        for (e, &u) in al.candidates[base * k..(base + 1) * k].iter().enumerate() {
            let u = u as usize;
            // The coherent candidate (the base itself) is favoured by `1 + coherence`.
            let d = if e == 0 {
                dist(u)
            } else {
                dist(u) * weights.incoherent
            } * over(u);
            if d < best.0 {
                best = (d, u, rem);
            }
        }
    }
    s.clamp(
        (best.1 % w) as f64 + best.2[0] as f64,
        (best.1 / w) as f64 + best.2[1] as f64,
    )
}

/// Gives every mate group of `lv` one member's coordinate, chosen by hash of `(seed, step)`.
fn unify_mates(lv: &mut Level, seed: u64, step: u64) {
    for g in &lv.grid.groups {
        let pick = counter_hash(seed, STREAM_MATE, step << 32 | g[0] as u64) % g.len() as u64;
        let u = lv.coords[g[pick as usize] as usize];
        for &q in g {
            lv.coords[q as usize] = u;
        }
    }
}

/// Synthesizes a texel image over `gi` by appearance-space synthesis of sample coordinates
/// (see the module docs); the result is as [`super::synthesize_geometry_texture`]'s.
pub fn synthesize_appearance(
    gi: &GeometryImage,
    field: &ParamField,
    variants: &TexelVariantsRef<'_>,
    space: &AppearanceSpaceRef<'_>,
    p: &GeometrySynthParams,
    progress: &dyn Fn(f32),
) -> Result<TexelImage, GeometryTextureError> {
    p.validate()?;
    check_inputs(gi, field, 1)?;
    progress(0.0);
    let vp = variants.params();
    let c = variants.channels();
    let n0 = gi.n as usize;
    let meta = space.meta;
    if meta.channels as usize != c || meta.k != p.appearance_k {
        return Err(GeometryTextureError::AppearanceSpace {
            channels: meta.channels,
            k: meta.k,
        });
    }
    let controls = texel_controls(gi, field, vp, p);
    let maps0 = sample_frame_maps(&controls, variants);
    // Grid level l matches at stack level l + lift, the lift being the footprint level of the
    // median grid step: where a grid step spans 4 sample texels, level 0 matches at spacing 4.
    let total = meta.levels as usize;
    let mut footprints: Vec<usize> = maps0.iter().map(|m| footprint_level(m, total)).collect();
    footprints.sort_unstable();
    let lift = footprints[footprints.len() / 2];
    let nl = grid_levels(n0).min(total - lift).max(1);
    let k = meta.k as usize;
    let weights = Weights {
        incoherent: 1.0 + p.appearance_coherence,
        occupancy: p.appearance_occupancy,
    };
    let s = Sample {
        width: meta.width as i32,
        height: meta.height as i32,
    };

    let mut step = 0u64;
    let mut coarser: Option<Level> = None;
    for l in (0..nl).rev() {
        let grid = LevelGrid::of_level(gi, l, 1);
        let n = grid.n;
        let maps: Vec<[f32; 4]> = (0..n * n)
            .map(|t| maps0[((t / n) << l) * n0 + ((t % n) << l)])
            .collect();
        let h = (1u64 << l) as f64;
        let al = &space.level(l + lift);
        // 1. Upsampling, or the random start.
        let coords: Vec<[f32; 2]> = (0..n * n)
            .into_par_iter()
            .map(|t| match &coarser {
                None => {
                    let r = counter_hash(p.seed, STREAM_START, t as u64);
                    let count = (s.width * s.height) as u64;
                    let u = (r % count) as i32;
                    [(u % s.width) as f32, (u / s.width) as f32]
                }
                Some(cl) => {
                    let (i, j) = (t / n, t % n);
                    let u = cl.coords[(i / 2) * cl.grid.n + j / 2];
                    let (ox, oy) = apply(&maps[t], (j % 2) as f64, (i % 2) as f64);
                    s.clamp(u[0] as f64 + h * ox, u[1] as f64 + h * oy)
                }
            })
            .collect();
        let mut lv = Level {
            grid,
            step: h,
            lift: (1u64 << lift) as f64,
            maps,
            coords,
        };
        // 2. Jitter.
        if p.jitter > 0.0 {
            let amp = al.spacing as f64 * p.jitter as f64;
            lv.coords.par_iter_mut().enumerate().for_each(|(t, u)| {
                let key = (l as u64) << 40 | (t as u64) << 1;
                let zx = counter_unit(p.seed, STREAM_JITTER, key) as f64 * 2.0 - 1.0;
                let zy = counter_unit(p.seed, STREAM_JITTER, key | 1) as f64 * 2.0 - 1.0;
                // Whole texels (the paper's floor(h r ζ + ½)): a sub-texel jitter would blur
                // the gathered relief and shift every tap off the texels the candidates hold.
                let jx = (amp * zx + 0.5).floor();
                let jy = (amp * zy + 0.5).floor();
                *u = s.clamp(u[0] as f64 + jx, u[1] as f64 + jy);
            });
        }
        unify_mates(&mut lv, p.seed, step);
        step += 1;
        // 3. Correction in sub-passes.
        let passes = p.appearance_passes * if coarser.is_none() { 2 } else { 1 };
        for _ in 0..passes {
            for &(pi, pj) in &SUB_PASSES {
                let occupancy = block_use(&lv, &s, al.spacing).factors(weights.occupancy);
                let rows: Vec<usize> = (pi..n).step_by(2).collect();
                let fixed: Vec<Vec<[f32; 2]>> = rows
                    .par_iter()
                    .map(|&i| {
                        (pj..n)
                            .step_by(2)
                            .map(|j| correct(&lv, &s, al, k, weights, &occupancy, i * n + j))
                            .collect()
                    })
                    .collect();
                for (&i, row) in rows.iter().zip(&fixed) {
                    for (j, &u) in (pj..n).step_by(2).zip(row) {
                        lv.coords[i * n + j] = u;
                    }
                }
                unify_mates(&mut lv, p.seed, step);
                step += 1;
            }
        }
        progress((nl - l) as f32 / (nl as f32 + 0.5));
        coarser = Some(lv);
    }

    // Gather the relief: each texel the sample's value at its coordinate, from the stack level
    // of its grid step's footprint (a step spanning 4 sample texels cannot show finer relief),
    // (dx, dy) turned into the grid's axes; a mated texel takes its representative's (in the
    // representative's axes).
    let lv = coarser.expect("at least one level");
    let kk = vp.orientations as f64;
    let mut out = TexelImage::new(gi.n, gi.n, c as u32);
    out.data.par_chunks_mut(c).enumerate().for_each(|(t, o)| {
        let r = lv.grid.rep[t] as usize;
        let level = space.level(footprint_level(&maps0[r], lift + nl));
        s.bilinear(level.texels, c, lv.coords[r], o);
        let theta = std::f64::consts::TAU * controls.orient[r] as f64 / kk;
        let (sin, cos) = (theta.sin_pure(), theta.cos_pure());
        let (dx, dy) = (o[0] as f64, o[1] as f64);
        o[0] = (cos * dx - sin * dy) as f32;
        o[1] = (sin * dx + cos * dy) as f32;
    });
    progress(1.0);
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::analyse_exemplar::appearance_space::AppearanceSpace;
    use crate::analyse_exemplar::texel_variants::{
        TexelVariantParams, TexelVariants, build_texel_variants,
    };
    use glam::{Vec2, Vec3};

    /// Every outer tap reads a grid neighbour, never the texel itself: under a map whose grid
    /// step spans 5 sample texels along x (and 0.25 along y) the x taps round onto the texel
    /// and are moved to the neighbour one step along x, and the y taps keep their far rows.
    #[test]
    fn a_tap_is_never_read_from_the_texel_itself() {
        for m in [
            [5.0, 0.0, 0.0, 0.25],
            [3.0, 2.0, -2.0, 3.0],
            [0.5, 0.0, 0.0, 0.5],
        ] {
            let taps = tap_offsets(&m, 1.0);
            for (&g, &d) in taps.iter().zip(&TAPS_3X3) {
                assert_eq!(g == (0, 0), d == (0, 0), "map {m:?}: tap {d:?} at {g:?}");
            }
        }
        let taps = tap_offsets(&[5.0, 0.0, 0.0, 0.25], 1.0);
        for (&g, &(dx, dy)) in taps.iter().zip(&TAPS_3X3) {
            if dy == 0 {
                assert_eq!(g, (dx, 0), "an x tap at {g:?}");
            } else {
                assert_eq!(g.1, 4 * dy, "a y tap at {g:?}");
            }
        }
        assert_eq!(nearest_step(0.3, -0.1), (1, 0));
        assert_eq!(nearest_step(-0.2, 0.15), (-1, 1));
        assert_eq!(nearest_step(0.0, 0.0), (0, 0));
        assert_eq!(nearest_step(f64::NAN, 1.0), (0, 0));
    }

    /// A 64² sample of round bumps on a jittered lattice, as `(dx, dy, dn)`.
    fn bumps() -> TexelImage {
        let mut s = TexelImage::new(64, 64, 3);
        for y in 0..64u32 {
            for x in 0..64u32 {
                let mut h = 0.0f32;
                for cy in 0..5 {
                    for cx in 0..5 {
                        let j = counter_unit(4, 0, cy * 5 + cx) * 6.0;
                        let (px, py) = (cx as f32 * 16.0 + j, cy as f32 * 16.0 + 6.0 - j);
                        let d2 = (x as f32 - px).powi(2) + (y as f32 - py).powi(2);
                        h = h.max(1.0 - d2 / 30.0);
                    }
                }
                s.texel_mut(x, y)[2] = h.max(0.0);
                s.texel_mut(x, y)[0] = 0.1 * (x as f32 * 0.3).sin_pure();
            }
        }
        s
    }

    /// A 65² cylinder: the right side mated to the left, stretched 2:1 down the rows and
    /// bent, under a turning field.
    fn cylinder() -> (GeometryImage, ParamField) {
        let n = 65u32;
        let nn = (n * n) as usize;
        let mut mate_rep: Vec<u32> = (0..nn as u32).collect();
        for i in 0..n {
            mate_rep[(i * n + n - 1) as usize] = i * n;
        }
        let gi = GeometryImage {
            n,
            positions: (0..nn)
                .map(|k| {
                    let (i, j) = ((k / n as usize) as f32, (k % n as usize) as f32);
                    Vec3::new(j + 0.3 * i, 2.0 * i + 0.01 * j * j, 0.0)
                })
                .collect(),
            normals: vec![Vec3::Z; nn],
            mate_rep,
        };
        let field = ParamField {
            dir: (0..nn)
                .map(|k| Vec2::from_angle(k as f32 * 0.0004).rotate(Vec2::Y))
                .collect(),
            rel_scale: vec![1.0; nn],
        };
        (gi, field)
    }

    #[test]
    fn any_thread_count_gives_the_same_bits_and_the_cut_is_seamless() {
        let owned = variants_of(&bumps());
        let variants = owned.as_ref();
        let (gi, field) = cylinder();
        let p = GeometrySynthParams {
            jitter: 0.5,
            ..Default::default()
        };
        let run = |threads: usize| {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            pool.install(|| {
                let space = space_of(&variants, &p);
                synthesize_appearance(&gi, &field, &variants, &space.view(), &p, &|_| {})
            })
            .unwrap()
        };
        let one = run(1);
        let three = run(3);
        let bits = |t: &TexelImage| t.data.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&one), bits(&three));
        // Across the cut (column 0 is mated with column n − 1): texels two steps apart across
        // it differ no more than texels two steps apart inside, so the cut is synthesized as one
        // surface, not as two borders that meet. Measured on dn.
        let n = gi.n;
        let step = |a: &[f32], b: &[f32]| (a[2] - b[2]).abs();
        let (mut across, mut inside) = (0.0f32, 0.0f32);
        for i in 0..n {
            across += step(one.texel(n - 2, i), one.texel(1, i));
            // Inside: the mean over every pair two columns apart, for a steady yardstick.
            inside += (1..n - 3)
                .map(|j| step(one.texel(j, i), one.texel(j + 2, i)))
                .sum::<f32>()
                / (n - 4) as f32;
        }
        eprintln!("across the cut {across}, inside {inside}");
        assert!(
            across < 2.0 * inside,
            "across the cut {across}, inside {inside}"
        );
        let dn: Vec<f32> = one.data.chunks_exact(3).map(|t| t[2]).collect();
        let (lo, hi) = dn
            .iter()
            .fold((f32::MAX, f32::MIN), |(a, b), &v| (a.min(v), b.max(v)));
        assert!(hi - lo > 0.8, "flat output: {lo} {hi}");
    }

    /// The variants the tests analyse a sample into: 4 orientations, 3 scales.
    fn variants_of(sample: &TexelImage) -> TexelVariants {
        let vp = TexelVariantParams {
            orientations: 4,
            scales: 3,
            ..Default::default()
        };
        build_texel_variants(sample, &vp, &|_| {}).unwrap()
    }

    /// `sample` synthesized at the defaults over an undistorted `n × n` square with a constant
    /// field: one grid step is one sample texel along x.
    fn on_flat_square(sample: &TexelImage, n: u32) -> TexelImage {
        let seed = GeometrySynthParams::default().seed;
        on_flat_square_seeded(sample, n, &[seed]).remove(0)
    }

    /// [`on_flat_square`] once per seed, the sample analysed once.
    fn on_flat_square_seeded(sample: &TexelImage, n: u32, seeds: &[u64]) -> Vec<TexelImage> {
        let owned = variants_of(sample);
        let variants = owned.as_ref();
        let nn = (n * n) as usize;
        let gi = GeometryImage {
            n,
            positions: (0..nn)
                .map(|k| Vec3::new((k % n as usize) as f32, (k / n as usize) as f32, 0.0))
                .collect(),
            normals: vec![Vec3::Z; nn],
            mate_rep: (0..nn as u32).collect(),
        };
        let field = ParamField {
            dir: vec![Vec2::Y; nn],
            rel_scale: vec![1.0; nn],
        };
        let space = space_of(&variants, &GeometrySynthParams::default());
        seeds
            .iter()
            .map(|&seed| {
                let p = GeometrySynthParams {
                    seed,
                    ..Default::default()
                };
                synthesize_appearance(&gi, &field, &variants, &space.view(), &p, &|_| {}).unwrap()
            })
            .collect()
    }

    fn space_of(variants: &TexelVariantsRef<'_>, p: &GeometrySynthParams) -> AppearanceSpace {
        crate::analyse_exemplar::appearance_space::node(variants, p.appearance_k).unwrap()
    }

    #[test]
    fn coherent_runs_follow_the_map_on_a_flat_square() {
        // On an undistorted square with a constant field, most grid neighbours continue each
        // other's coordinates (one grid step = one sample texel along x): the synthesis copies
        // patches, not texels. A synthesizer that rematched every texel on its own, or that
        // rounded the map's steps away, would not.
        let sample = bumps();
        let n = 65u32;
        let out = on_flat_square(&sample, n);
        // A texel continues its left neighbour when it equals the sample one texel right of
        // where the neighbour's value sits: count pairs whose (dn, dx) pair matches the
        // sample's horizontal pairs exactly.
        let pairs: std::collections::HashSet<[u32; 4]> = (0..64u32)
            .flat_map(|y| (0..63u32).map(move |x| (x, y)))
            .map(|(x, y)| {
                let (a, b) = (sample.texel(x, y), sample.texel(x + 1, y));
                [
                    a[0].to_bits(),
                    a[2].to_bits(),
                    b[0].to_bits(),
                    b[2].to_bits(),
                ]
            })
            .collect();
        let mut hits = 0;
        for i in 0..n {
            for j in 0..n - 1 {
                let (a, b) = (out.texel(j, i), out.texel(j + 1, i));
                if pairs.contains(&[
                    a[0].to_bits(),
                    a[2].to_bits(),
                    b[0].to_bits(),
                    b[2].to_bits(),
                ]) {
                    hits += 1;
                }
            }
        }
        let share = hits as f64 / (n * (n - 1)) as f64;
        assert!(share > 0.6, "coherent share {share}");
    }

    /// A 96² crack network: the borders of the Voronoi cells of 16 seeds on a jittered 4 × 4
    /// lattice, 1 on a crack (within 1.5 texels of being equidistant to two seeds), 0 elsewhere.
    fn cracks() -> TexelImage {
        let seeds: Vec<(f32, f32)> = (0..16)
            .map(|k| {
                let (cx, cy) = ((k % 4) as f32 * 24.0 + 12.0, (k / 4) as f32 * 24.0 + 12.0);
                let j = |s| (counter_unit(7, s, k) - 0.5) * 14.0;
                (cx + j(0), cy + j(1))
            })
            .collect();
        let mut s = TexelImage::new(96, 96, 3);
        for y in 0..96u32 {
            for x in 0..96u32 {
                let mut d: Vec<f32> = seeds
                    .iter()
                    .map(|&(sx, sy)| ((x as f32 - sx).powi(2) + (y as f32 - sy).powi(2)).sqrt())
                    .collect();
                d.sort_by(f32::total_cmp);
                s.texel_mut(x, y)[2] = if d[1] - d[0] < 1.5 { 1.0 } else { 0.0 };
            }
        }
        s
    }

    /// Connected components (8-neighbours) of the texels whose `dn` is above one half.
    fn crack_components(img: &TexelImage) -> usize {
        crack_component_sizes(img).len()
    }

    /// The sizes of [`crack_components`]'s components.
    fn crack_component_sizes(img: &TexelImage) -> Vec<usize> {
        let (w, h) = (img.width as usize, img.height as usize);
        let on = |x: usize, y: usize| img.texel(x as u32, y as u32)[2] > 0.5;
        let mut seen = vec![false; w * h];
        let mut sizes = Vec::new();
        for start in 0..w * h {
            if seen[start] || !on(start % w, start / w) {
                continue;
            }
            let mut size = 0;
            let mut stack = vec![start];
            seen[start] = true;
            while let Some(t) = stack.pop() {
                size += 1;
                let (x, y) = ((t % w) as i64, (t / w) as i64);
                for dy in -1..=1i64 {
                    for dx in -1..=1i64 {
                        let (nx, ny) = (x + dx, y + dy);
                        if nx < 0 || ny < 0 || nx >= w as i64 || ny >= h as i64 {
                            continue;
                        }
                        let u = ny as usize * w + nx as usize;
                        if !seen[u] && on(nx as usize, ny as usize) {
                            seen[u] = true;
                            stack.push(u);
                        }
                    }
                }
            }
            sizes.push(size);
        }
        sizes
    }

    /// The seeds the crack tests synthesize with: enough that a median says how the
    /// synthesizer does, not how one seed fell.
    const CRACK_SEEDS: [u64; 12] = [0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11];

    /// The crack sample and its syntheses over a flat 129² square at the defaults, one per
    /// seed of [`CRACK_SEEDS`], made once for both crack tests.
    fn cracks_synthesized() -> &'static (TexelImage, Vec<TexelImage>) {
        static CRACKS: std::sync::OnceLock<(TexelImage, Vec<TexelImage>)> =
            std::sync::OnceLock::new();
        CRACKS.get_or_init(|| {
            let sample = cracks();
            let outs = on_flat_square_seeded(&sample, 129, &CRACK_SEEDS);
            (sample, outs)
        })
    }

    #[test]
    fn a_crack_network_stays_mostly_one_network() {
        // Coordinates copy runs of the sample, so a crack continues across a patch instead of
        // breaking into fragments: at every seed the largest crack component holds at least
        // 80 % of the crack texels (measured 0.94–1.00 over the 12 seeds; BENCHMARKS.md has
        // the weaker settings that fail it; a texel-by-texel synthesizer leaves specks), and
        // the crack share is the sample's within 1.5×.
        let (sample, outs) = cracks_synthesized();
        let share = |img: &TexelImage| {
            img.data.chunks_exact(3).filter(|t| t[2] > 0.5).count() as f64
                / (img.width * img.height) as f64
        };
        for (seed, out) in CRACK_SEEDS.iter().zip(outs) {
            let sizes = crack_component_sizes(out);
            let total: usize = sizes.iter().sum();
            let largest = sizes.iter().copied().max().unwrap_or(0);
            assert!(
                5 * largest >= 4 * total,
                "seed {seed}: components {sizes:?}"
            );
            let (a, b) = (share(sample), share(out));
            assert!(
                b > a / 1.5 && b < a * 1.5,
                "seed {seed}: crack share {b} against {a}"
            );
        }
    }

    #[test]
    fn crack_components_per_area_are_within_twice_the_samples() {
        // The bar, for the median run, not a lucky seed: about 3.6 components over the
        // 129² square. Measured over the 12 seeds: 1–6, median 3; without the occurrence
        // penalty 3–10, median 5 (the sample is one component).
        let (sample, outs) = cracks_synthesized();
        let density = |img: &TexelImage| {
            crack_components(img) as f64 / (img.width as f64 * img.height as f64)
        };
        let want = density(sample);
        let mut got: Vec<f64> = outs.iter().map(density).collect();
        got.sort_by(f64::total_cmp);
        let counts: Vec<usize> = outs.iter().map(crack_components).collect();
        eprintln!("crack components per seed: {counts:?}");
        assert!(
            got[got.len() / 2] <= 2.0 * want,
            "median {:.2e} per texel against the sample's {want:.2e} ({} components; per seed {counts:?})",
            got[got.len() / 2],
            crack_components(sample)
        );
    }
}

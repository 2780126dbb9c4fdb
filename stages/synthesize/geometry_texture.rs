//! Geometric texture synthesis over a geometry image, consistent across its cuts.
//!
//! Implements Y.-K. Lai, S.-M. Hu, D. X. Gu and R. R. Martin, "Geometric Texture Synthesis and
//! Transfer via Geometry Images" (SPM 2005): §4.2.1 (initial synthesis), §4.2.2 (boundary
//! resynthesis) and the synthesis side of §4.3 (discretized orientation and scaling). The
//! oriented and scaled sample set, its pyramids, features and kd-trees come from
//! [`crate::analyse_exemplar::texel_variants`].
//!
//! A geometry image of side `n = 2^k + 1` has `(n − 1) / 2^l + 1` samples per side at pyramid
//! level `l`; sample `i` of level `l` is sample `i · 2^l` of level 0, and its field values are
//! that sample's. Coarse to fine, each level is
//! 1. started: the coarsest level with texels drawn at random from the sample (the variant each
//!    texel would be matched in, so the start has the sample's statistics), each finer level
//!    with the finished coarser level, interpolated;
//! 2. synthesized in scanline order with the causal Γ template, plus the full neighbourhood one
//!    level coarser above the coarsest level. Each texel is matched in one variant (§4.3): of
//!    the two discretized orientations next to the field angle, each with probability by
//!    closeness, and of the two scales next to `level = log2 R + 2` (clamped to the range of
//!    scales), `T_s` with probability `s + 1 − level`. The nearest candidate in that variant
//!    (PCA-reduced features, kd-tree search within `1 + search_eps`) gives the texel: the
//!    variant's texel, whose `(dx, dy)` the analysis already turned into the variant's axes,
//!    which are the grid's;
//! 3. resynthesized near the cuts (§4.2.2), `boundary_passes` times: texels within
//!    `boundary_strip` texels of a side sample that has a mate, in scanline order, with the full
//!    template, which reads both sides of the cut (below). After each pass (and after step 2)
//!    each mate group takes the value of one member, chosen by a counter-based hash, so mated
//!    texels end bit-identical.
//!
//! Reading across a cut: the square's sides are taken in perimeter order (top `i = 0` with
//! `j` increasing, right, bottom, left), each with a tangent `t` along that order and an
//! inward normal `m`. A tap `b` texels outside side sample `p` is read at `q + b · m_q`, where
//! `q` is a mate of `p` whose side runs the opposite way along the cut: the pairing `(p, side)`
//! ↔ `(q, side)` is accepted when the border neighbours agree (`p ± t_p` is mated with
//! `q ∓ t_q`), which also tells which side of a corner sample is meant. The value is turned by
//! the quarter turn between the two sides' grid axes.
//!
//! Frames: while synthesizing, every texel's `(dx, dy)` are in its own side's grid axes
//! (`x` = column `j`, `y` = row `i`, as the local frames of
//! [`crate::geom::geometry_image::local_frames`] are away from the cuts). Those frames give a
//! mated sample its group representative's frame, so in the output every member of a mate group
//! holds the representative-frame value, turned by the quarter turn between the member's and
//! the representative's sides; all members' output texels are bit-identical.
//!
//! Surface metric (`anisotropic`, the default): the paper's templates are laid out
//! in grid texels and its scale `R` is one number per sample, so where the geometry image
//! stretches the surface more one way than the other (long thin parts) the relief came out as
//! streaks. Each texel instead reads template tap `s` (in sample texels) at grid offset
//! `round(A⁻¹ s)` and shifts a coherent candidate by `A o` for a neighbour `o` grid steps away,
//! with `A` the unimodular square root of the grid's metric ([`SurfaceMetric`]); a finer level's
//! start takes its parent's source shifted by `A` times the child's offset; `R` uses the
//! metric's isotropic spacing; and the field's direction goes through `A` into sample axes. The
//! variants stay isotropic. In the scanline pass a tap so placed can fall outside the causal
//! half: taps not finished in both the scanline and the wave order are read from the level's
//! starting values, which keeps the wave order exact.
//!
//! Heuristics (the paper: "for other problem cases, e.g. texels in the corner of geometry images,
//! or where two cuts meet, we use a heuristic approach"):
//! - A tap outside the square across a corner (outside in both `i` and `j`) is first mirrored
//!   back along the axis it overshoots less (rows on ties), then read across the other side.
//! - A tap across a side sample without a mate, or whose pairing cannot be confirmed, is
//!   mirrored into the square. A tap mapped across a cut that falls outside the square again is
//!   mirrored.
//! - A mate whose pairing with its group representative cannot be confirmed directly (e.g. the
//!   third member where cuts meet) is taken to share the representative's axes.
//! - Mate groups at a coarse level are those of the level-0 samples `(i · 2^l, j · 2^l)`
//!   restricted to that lattice (the parameterization puts cut nodes on the coarsest grid).
//!
//! Departures and choices the paper leaves open:
//! - The boundary template's size is a parameter of the variant set
//!   (`TexelVariantParams::boundary_template`), whose analysis builds its features and trees,
//!   not of this stage.
//! - The scanline pass reads taps outside the square (across cuts, or mirrored) from the level's
//!   starting values, not from texels synthesized in this pass. The paper "ignores the
//!   boundary" there; reading the synthesized texels instead (mirrored) fed each border
//!   texel's choice back into its neighbours' templates and grew repeating diagonal streaks from
//!   the left border on the test bumps. Starting finer levels from the coarser result (rather
//!   than from the pyramid of the random start, whose blurred noise has almost no contrast)
//!   gives those taps a sensible prediction, across cuts too.
//! - Scanline order is kept exactly, but texels on one anti-diagonal wave (`j + (r + 1) i`
//!   constant, `r` the template radius) do not depend on one another, so each wave is computed
//!   in parallel: the result is the sequential one (a unit test compares them), for any number
//!   of threads. Boundary passes are sequential.
//! - The random number that picks the scale is shared by the texels of a cell of a jittered
//!   grid of template spacing (each texel takes the cell whose jittered centre is nearest); the
//!   probabilities per texel are the paper's. Drawn per texel, neighbouring texels matched at
//!   different scales and the texture turned into grain where `R` falls between two scales.
//!   Orientations are still drawn per texel: per cell, stripes broke into straight pieces at the
//!   cell borders.
use crate::analyse_exemplar::texel_variants::{
    SampleMap, Template, TexelVariantParams, TexelVariantsRef, coarse_taps, coarse_window,
    template_taps,
};
use crate::check::{ParamError, check_range};
use crate::field::param_field::local_spacing;
use crate::geom::geometry_image::{GeometryImage, TexelImage};
use crate::image::neighbourhood::mirror;
use crate::random::{counter_hash, counter_unit};
use crate::synthesize::surface_metric::{MAX_STRETCH, SurfaceMetric, surface_metrics_clamped};
use glam::Vec2;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use texsyn_core::math::PureMath;

/// The `geometry_texture` node's algorithm and version (part of its key; bump on any change of output).
pub const NODE: texsyn_core::algorithm::Algorithm =
    texsyn_core::algorithm::Algorithm::new("geometry_texture", 4);

/// The per-sample controls of synthesis (§4.3), computed by the field stage.
pub use crate::field::param_field::ParamField;

/// Parameters of the synthesis.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct GeometrySynthParams {
    /// Seed of every random choice (start texels, variant choices, mate propagation).
    /// Default: 0.
    pub seed: u64,
    /// Boundary resynthesis passes per level, 0..=16 (§4.2.2: "can be repeatedly performed
    /// several times"). Default: 2.
    pub boundary_passes: u32,
    /// Width in texels (of each level) of the strip along mated sides that boundary
    /// resynthesis redoes, 1..=64. Default: 4.
    pub boundary_strip: u32,
    /// Approximate nearest-neighbour factor, 0..=10: a match may be up to `1 + search_eps`
    /// times farther than the best one; 0 = exact. Default: 0.25 (on the tests' bumps, 0.5 and
    /// 1 left flat triangular plateaus that exact search does not; 0.25 looked like exact
    /// search, and at 257² exact search costs about 0.25 s on 2 cores anyway). Used by
    /// `search = "per_texel"` only.
    pub search_eps: f32,
    /// How a texel's match is found: `"k_coherence"` (default) or `"per_texel"` (the paper's
    /// kd-tree search over every texel of the variant, §4.2.1).
    pub search: Search,
    /// How much better (as a factor `1 + coherence` on the template distance) a k-coherent
    /// candidate must match than the best shifted one to be taken (`k_coherence` only),
    /// 0..=10. Default: see [`GeometrySynthParams::default`].
    pub coherence: f32,
    /// Correction passes per level after the scanline pass (`k_coherence` only; Lefebvre &
    /// Hoppe 2005), 0..=8: every texel rematched with the full boundary template against the
    /// level as the previous pass left it, all at once. Default: 1.
    pub correction_passes: u32,
    /// Factor on the coarser level's taps in the template distance of `k_coherence`, 0..=4
    /// (`per_texel` uses `analyse_exemplar.coarse_weight`, which its features are built with).
    /// Default: 1 (relief_cow at `analyse_exemplar.scales = 1`, density offset 0, coherence 1,
    /// one correction pass: nearest-patch ratio 0.650, against 0.815 for `per_texel`; measured
    /// with `examples/gi_quality.rs`).
    pub coarse_weight: f32,
    /// Whether the templates are laid out in the surface's metric (see [`SurfaceMetric`]):
    /// each texel's taps and coherent shifts go through the geometry image's Jacobian, so
    /// relief keeps its shape where the grid stretches the surface more one way than the other
    /// (long thin parts: legs, necks, trunks). `false` is the paper's template in grid texels,
    /// which draws the relief out into streaks there. Default: true.
    pub anisotropic: bool,
    /// With the surface metric, how a template tap that falls between grid points is read:
    /// `"bilinear"` (default) or `"nearest"` (the grid point nearest to it, as the coherent
    /// shifts round).
    pub taps: Taps,
    /// How a texel's scale is picked between the two variants' scales next to its
    /// `log2 R + middle`: `"random"` (default; the paper's, `T_s` with probability by
    /// closeness, shared over jittered cells) or `"nearest"` (the closer one everywhere).
    pub scale_choice: ScaleChoice,
    /// With the surface metric, whether a texel takes the value at its source's sub-texel
    /// position (bilinear between the four variant texels around it) rather than the nearest
    /// texel's. Coherent runs then follow the fractional shifts `A o` in value too, instead of
    /// repeating a texel where a grid step is less than one sample texel. Default: false.
    pub subtexel: bool,
    /// With the surface metric, the largest stretch `λ` undone, 1..=4 (see [`SurfaceMetric`]):
    /// where a grid step one way spans more than `λ²` times the surface length of a step the
    /// other way, the rest
    /// is left to the grid. A grid step along the stretched direction covers `λ` times the
    /// isotropic spacing, and relief finer than that is lost there. Default: 4.
    pub max_stretch: f32,
}

/// How template taps between grid points are read (see [`GeometrySynthParams::taps`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Taps {
    #[default]
    Bilinear,
    Nearest,
}

/// How each texel's scale is picked (see [`GeometrySynthParams::scale_choice`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ScaleChoice {
    #[default]
    Random,
    Nearest,
}

/// The candidate search of each texel's match.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Search {
    /// Coherent candidates (Ashikhmin 2001) and their k-coherent sets (Tong et al. 2002),
    /// compared by the full template distance.
    #[default]
    KCoherence,
    /// The paper's approximate nearest neighbour over all texels of the variant.
    PerTexel,
}

impl Default for GeometrySynthParams {
    fn default() -> Self {
        GeometrySynthParams {
            seed: 0,
            boundary_passes: 2,
            boundary_strip: 4,
            search_eps: 0.25,
            search: Search::KCoherence,
            coherence: 1.0,
            correction_passes: 1,
            coarse_weight: 1.0,
            anisotropic: true,
            taps: Taps::Bilinear,
            scale_choice: ScaleChoice::Random,
            subtexel: false,
            max_stretch: MAX_STRETCH as f32,
        }
    }
}

impl GeometrySynthParams {
    /// Checks every field; the error names the field, its range and the value.
    pub fn validate(&self) -> Result<(), ParamError> {
        let within = |e: ParamError| e.within("geometry texture");
        check_range("boundary_passes", self.boundary_passes, 0, 16).map_err(within)?;
        check_range("boundary_strip", self.boundary_strip, 1, 64).map_err(within)?;
        check_range("search_eps", self.search_eps, 0.0, 10.0).map_err(within)?;
        check_range("coherence", self.coherence, 0.0, 10.0).map_err(within)?;
        check_range("correction_passes", self.correction_passes, 0, 8).map_err(within)?;
        check_range("coarse_weight", self.coarse_weight, 0.0, 4.0).map_err(within)?;
        check_range("max_stretch", self.max_stretch, 1.0, MAX_STRETCH as f32).map_err(within)
    }
}

const STREAM_INIT: u64 = 0x6774_0001;
const STREAM_ORIENT: u64 = 0x6774_0002;
const STREAM_SCALE: u64 = 0x6774_0003;
const STREAM_MATE: u64 = 0x6774_0004;
const STREAM_BLOCK: u64 = 0x6774_0005;
const STREAM_FALLBACK: u64 = 0x6774_0006;

/// A texel's source: variant `v` and texel index `k` of the variant's level, `v << 32 | k`.
#[inline]
fn pack_src(v: usize, k: usize) -> u64 {
    ((v as u64) << 32) | k as u64
}

/// Where a texel's value was copied from: [`pack_src`] of the variant and texel, and, with the
/// surface metric, the sub-texel remainder of the continuous source position (in that
/// variant's texels, within ±0.5), so that shifts by `A o` that are not whole texels add up
/// along a run of coherent texels instead of being rounded away at each step.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct Src {
    packed: u64,
    frac: [f32; 2],
}

impl Src {
    fn whole(v: usize, k: usize) -> Src {
        Src {
            packed: pack_src(v, k),
            frac: [0.0; 2],
        }
    }
}

/// Most channels a texel has.
const MAX_CHANNELS: usize = 6;

/// Pass number of the choices made for the starting values.
const INIT_PASS: u32 = 0xFFFF;

/// Counter of a random choice at `texel` of `level` in pass `pass` (0 the scanline pass).
#[inline]
fn choice_index(level: usize, pass: u32, texel: usize) -> u64 {
    ((level as u64) << 56) | ((pass as u64) << 40) | texel as u64
}

/// Quarter turns of the tangent of each side (top, right, bottom, left) in `(x, y)` axes.
const SIDE_TOP: u8 = 0;
const SIDE_RIGHT: u8 = 1;
const SIDE_BOTTOM: u8 = 2;
const SIDE_LEFT: u8 = 3;

/// `(di, dj)` of the tangent and of the inward normal of each side.
const TANGENT: [(i64, i64); 4] = [(0, 1), (1, 0), (0, -1), (-1, 0)];
const NORMAL: [(i64, i64); 4] = [(1, 0), (0, -1), (-1, 0), (0, 1)];

/// Turns `(dx, dy)` by `r` quarter turns (`(x, y) → (−y, x)` each). Exact.
#[inline]
fn quarter_turn(r: u8, v: &mut [f32]) {
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
struct LevelGrid {
    n: usize,
    rep: Vec<u32>,
    /// Mate groups with more than one member, members by increasing index.
    groups: Vec<Vec<u32>>,
    /// Per sample, quarter turns from its grid axes to its representative's.
    to_rep: Vec<u8>,
    /// Per `(side, position along the side as i or j)`, the sample and side across the cut.
    across: Vec<Option<(u32, u8)>>,
    /// Texels of the boundary strip in scanline order.
    strip: Vec<u32>,
}

impl LevelGrid {
    fn sides_of(&self, i: i64, j: i64) -> impl Iterator<Item = u8> {
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
    fn inside(&self, i: i64, j: i64) -> bool {
        let n = self.n as i64;
        (0..n).contains(&i) && (0..n).contains(&j)
    }

    #[inline]
    fn idx(&self, i: i64, j: i64) -> usize {
        i as usize * self.n + j as usize
    }

    fn coords(&self, k: u32) -> (i64, i64) {
        ((k as usize / self.n) as i64, (k as usize % self.n) as i64)
    }

    /// Whether side `sp` at `p` and side `sq` at `q` are the two sides of one cut, running in
    /// opposite directions: the border neighbours of `p` and `q` are mated.
    fn paired(&self, p: u32, sp: u8, q: u32, sq: u8) -> bool {
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

    fn build(n: usize, rep: Vec<u32>, strip_width: u32) -> LevelGrid {
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
    fn locate(&self, i: i64, j: i64) -> (usize, u8, bool) {
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

/// One level's working state: texels (own grid axes) and the per-texel variant controls.
struct Level {
    grid: LevelGrid,
    data: Vec<f32>,
    /// The level's values before its scanline pass, which reads taps outside the square here.
    init: Vec<f32>,
    /// Fractional orientation index in `[0, orientations)`.
    orient: Vec<f32>,
    /// Fractional scale index in `[0, scales − 1]` (0 = most enlarged).
    scale: Vec<f32>,
    /// Per texel, where its value was copied from ([`pack_src`]), and the same for `init`.
    src: Vec<Src>,
    init_src: Vec<Src>,
    /// Per texel, the map from grid offsets to sample offsets ([`SurfaceMetric`]); empty
    /// without `anisotropic` (template taps are grid offsets).
    metric: Vec<SurfaceMetric>,
}

impl Level {
    /// The grid offset `(dx, dy)` at which texel `t` reads template tap `tap`.
    #[inline]
    fn tap_offset(&self, t: usize, tap: (i32, i32)) -> (i32, i32) {
        match self.metric.get(t) {
            Some(m) => m.to_grid(tap),
            None => tap,
        }
    }

    /// The shift, in sample texels, of a neighbour `o` grid steps away from texel `t`.
    #[inline]
    fn sample_shift(&self, t: usize, o: (i32, i32)) -> [f64; 2] {
        match self.metric.get(t) {
            Some(m) => {
                let s = m.to_sample(Vec2::new(o.0 as f32, o.1 as f32));
                [s.x as f64, s.y as f64]
            }
            None => [o.0 as f64, o.1 as f64],
        }
    }
}

/// Everything a texel's match needs, shared by the passes.
struct Ctx<'a, 'v> {
    variants: &'a TexelVariantsRef<'v>,
    channels: usize,
    weights: &'a [f32],
    coarse_weight: f32,
    seed: u64,
    eps: f32,
    orientations: usize,
    scales: usize,
    /// Side of the blocks of texels that share their random variant choice.
    block: usize,
    search: Search,
    /// `coherence` of the parameters.
    coherence: f32,
    /// `taps = "nearest"`.
    nearest_taps: bool,
    /// `subtexel` (with the surface metric).
    subtexel: bool,
    /// Per (variant, level), `v * levels + l`: the map to the sample's level 0.
    maps: Vec<SampleMap>,
    /// Anti-diagonal step of the scanline pass's waves (`template / 2 + 1`): a texel `(i', j')`
    /// is finished before texel `(i, j)` in both the scanline and the wave order when it is
    /// left of it on its row, or on a row above and on an earlier wave.
    wave: i64,
}

impl Ctx<'_, '_> {
    /// Whether the scanline pass reads tap `(ti, tj)` of texel `(i, j)` from the starting
    /// values: outside the square, or not yet finished in both orders (taps laid out by the
    /// surface metric can reach past the causal half).
    #[inline]
    fn reads_init(&self, i: i64, j: i64, ti: i64, tj: i64, outside: bool) -> bool {
        let done = (ti == i && tj < j) || (ti < i && tj + self.wave * ti < j + self.wave * i);
        outside || !done
    }
}

/// Scratch buffers of one matcher.
#[derive(Default)]
struct Scratch {
    raw: Vec<f32>,
    reduced: Vec<f32>,
    search: Vec<f32>,
    /// Candidate texel index `<< 1`, plus 1 for a k-coherent (not shifted) one, and its
    /// sub-texel remainder ([`Src::frac`]).
    candidates: Vec<(u64, [f32; 2])>,
}

/// The texels of a `w × h` variant level (with a `cw × ch` coarser level, if any) whose whole
/// template lies inside, as inclusive ranges `[x_lo, x_hi, y_lo, y_hi]` (as the analysis'
/// candidates).
fn valid_range(kind: Template, side: u32, w: u32, h: u32, coarse: Option<(u32, u32)>) -> [i64; 4] {
    let r = (side / 2) as i64;
    let (w, h) = (w as i64, h as i64);
    let mut b = [
        r,
        w - 1 - r,
        r,
        match kind {
            Template::Causal => h - 1,
            Template::Full => h - 1 - r,
        },
    ];
    if let Some((cw, ch)) = coarse {
        let rc = (coarse_window(side) / 2) as i64;
        b[0] = b[0].max(2 * rc);
        b[1] = b[1].min(2 * (cw as i64 - 1 - rc) + 1);
        b[2] = b[2].max(2 * rc);
        b[3] = b[3].min(2 * (ch as i64 - 1 - rc) + 1);
    }
    b
}

/// The value at grid offset `g` (fractional, `x` = columns) from `(i, j)`, interpolated
/// bilinearly between the four grid points around it, each read by `at(i, j)`.
#[inline]
fn bilinear(
    g: Vec2,
    i: i64,
    j: i64,
    at: &impl Fn(i64, i64) -> [f32; MAX_CHANNELS],
) -> [f32; MAX_CHANNELS] {
    let (x0, y0) = (g.x.floor(), g.y.floor());
    let (fx, fy) = (g.x - x0, g.y - y0);
    let (bi, bj) = (i + y0 as i64, j + x0 as i64);
    let mut out = [0.0f32; MAX_CHANNELS];
    for (di, dj, w) in [
        (0, 0, (1.0 - fx) * (1.0 - fy)),
        (0, 1, fx * (1.0 - fy)),
        (1, 0, (1.0 - fx) * fy),
        (1, 1, fx * fy),
    ] {
        if w > 0.0 {
            let px = at(bi + di, bj + dj);
            for (o, p) in out.iter_mut().zip(px) {
                *o += w * p;
            }
        }
    }
    out
}

impl Ctx<'_, '_> {
    /// Variant for texel `t` of `level` in `pass` (§4.3).
    #[inline]
    fn choose(&self, lv: &Level, level: usize, pass: u32, t: usize) -> usize {
        // Orientation: one random number per texel. Scale: one per cell of a jittered grid of
        // spacing `block` (each texel takes the cell whose jittered centre is nearest), so
        // neighbouring texels mostly match at the same scale.
        let n = lv.grid.n as i64;
        let b = self.block.max(1) as i64;
        let (i, j) = (t as i64 / n, t as i64 % n);
        let (ci, cj) = (i.div_euclid(b), j.div_euclid(b));
        let cells = n / b + 3;
        let mut best = (i64::MAX, 0u64);
        for di in -1..=1 {
            for dj in -1..=1 {
                let (gi, gj) = (ci + di, cj + dj);
                let cell = ((gi + 1) * cells + gj + 1) as u64;
                let h = counter_hash(
                    self.seed,
                    STREAM_BLOCK,
                    choice_index(level, pass, cell as usize),
                );
                let pi = gi * b + (h % b as u64) as i64;
                let pj = gj * b + ((h >> 32) % b as u64) as i64;
                let d = (pi - i).pow(2) + (pj - j).pow(2);
                if d < best.0 {
                    best = (d, cell);
                }
            }
        }
        let key = choice_index(level, pass, best.1 as usize);
        let f = lv.orient[t];
        let k0 = f.floor();
        let u = counter_unit(self.seed, STREAM_ORIENT, choice_index(level, pass, t));
        let k = (if u < 1.0 - (f - k0) {
            k0 as usize
        } else {
            k0 as usize + 1
        }) % self.orientations;
        let s = lv.scale[t];
        let s0 = s.floor();
        let u = counter_unit(self.seed, STREAM_SCALE, key);
        let sc = if u < 1.0 - (s - s0) {
            s0 as usize
        } else {
            (s0 as usize + 1).min(self.scales - 1)
        };
        self.variants.variant(sc, k)
    }

    /// The raw feature vector of texel `(i, j)` of `levels[l]` (taps `taps`, and `ctaps` one
    /// level coarser if there is one), as the variants' features are built, into `raw`.
    #[allow(clippy::too_many_arguments)]
    fn gather(
        &self,
        levels: &[Level],
        l: usize,
        taps: &[(i32, i32)],
        ctaps: &[(i32, i32)],
        i: i64,
        j: i64,
        outside_from_init: bool,
        raw: &mut Vec<f32>,
    ) {
        let c = self.channels;
        raw.clear();
        let read = |data: &[f32], k: usize, r: u8| {
            let mut px = [0.0f32; MAX_CHANNELS];
            px[..c].copy_from_slice(&data[k * c..(k + 1) * c]);
            if r != 0 {
                quarter_turn(r, &mut px);
            }
            px
        };
        let push = |px: [f32; MAX_CHANNELS], raw: &mut Vec<f32>| {
            for ch in 0..c {
                raw.push(px[ch] * self.weights[ch]);
            }
        };
        let lv = &levels[l];
        let t = lv.grid.idx(i, j);
        let metric = lv.metric.get(t);
        // The value at grid point (ti, tj) of the level being synthesized.
        let at = |ti: i64, tj: i64| {
            let (k, r, outside) = lv.grid.locate(ti, tj);
            let src = if outside_from_init && self.reads_init(i, j, ti, tj, outside) {
                &lv.init
            } else {
                &lv.data
            };
            read(src, k, r)
        };
        for &tap in taps {
            match metric {
                // With the surface metric a tap falls between grid points: bilinear, or the
                // nearest grid point.
                Some(m) if self.nearest_taps => {
                    let (dx, dy) = m.to_grid(tap);
                    push(at(i + dy as i64, j + dx as i64), raw)
                }
                Some(m) => push(bilinear(m.to_grid_f(tap), i, j, &at), raw),
                None => push(at(i + tap.1 as i64, j + tap.0 as i64), raw),
            }
        }
        if let Some(cl) = levels.get(l + 1) {
            // The coarser level is finished: read it as it is, across cuts too.
            let (ci, cj) = (i >> 1, j >> 1);
            let start = raw.len();
            let at = |ti: i64, tj: i64| {
                let (k, r, _) = cl.grid.locate(ti, tj);
                read(&cl.data, k, r)
            };
            for &tap in ctaps {
                match metric {
                    Some(m) if self.nearest_taps => {
                        let (dx, dy) = m.to_grid(tap);
                        push(at(ci + dy as i64, cj + dx as i64), raw)
                    }
                    Some(m) => push(bilinear(m.to_grid_f(tap), ci, cj, &at), raw),
                    None => push(at(ci + tap.1 as i64, cj + tap.0 as i64), raw),
                }
            }
            for v in &mut raw[start..] {
                *v *= self.coarse_weight;
            }
        }
    }

    /// The synthesized value of texel `(i, j)` of `levels[l]` with template `kind`, written to
    /// `out` (in the texel's grid axes); returns where it was copied from ([`pack_src`]).
    #[allow(clippy::too_many_arguments)]
    fn synthesize_texel(
        &self,
        levels: &[Level],
        l: usize,
        pass: u32,
        kind: Template,
        taps: &[(i32, i32)],
        ctaps: &[(i32, i32)],
        i: i64,
        j: i64,
        scratch: &mut Scratch,
        out: &mut [f32],
    ) -> Src {
        let c = self.channels;
        let lv = &levels[l];
        let t = lv.grid.idx(i, j);
        let v = self.choose(lv, l, pass, t);
        // The scanline pass reads outside taps from the level's starting values, so no texel
        // depends on one synthesized later (and the wavefront order stays exact); boundary
        // resynthesis reads the current values across the cuts.
        let from_init = kind == Template::Causal;
        self.gather(levels, l, taps, ctaps, i, j, from_init, &mut scratch.raw);
        let level_img = self.variants.level(v, l);
        let (k, frac) = match self.search {
            Search::PerTexel => {
                let set = self.variants.set(v, l, kind);
                debug_assert_eq!(scratch.raw.len(), set.dim_in);
                scratch.reduced.resize(set.dims, 0.0);
                set.project(&scratch.raw, &mut scratch.reduced);
                let (id, _) = set
                    .tree
                    .nearest1_approx(&scratch.reduced, self.eps, &mut scratch.search)
                    .expect("feature sets are never empty");
                (set.centres[id as usize] as usize, [0.0; 2])
            }
            Search::KCoherence => {
                self.coherent_match(levels, l, pass, kind, taps, ctaps, i, j, v, scratch)
            }
        };
        out[..c].copy_from_slice(&level_img.texels[k * c..(k + 1) * c]);
        if self.subtexel && frac != [0.0; 2] {
            // The value at the continuous source position, bilinear between the four texels
            // around it (clamped inside the level).
            let (w, h) = (level_img.width as i64, level_img.height as i64);
            let (x, y) = (
                (k as i64 % w) as f32 + frac[0],
                (k as i64 / w) as f32 + frac[1],
            );
            let (x0, y0) = (x.floor(), y.floor());
            let (fx, fy) = (x - x0, y - y0);
            let mut acc = [0.0f32; MAX_CHANNELS];
            for (dx, dy, wt) in [
                (0, 0, (1.0 - fx) * (1.0 - fy)),
                (1, 0, fx * (1.0 - fy)),
                (0, 1, (1.0 - fx) * fy),
                (1, 1, fx * fy),
            ] {
                let xi = (x0 as i64 + dx).clamp(0, w - 1);
                let yi = (y0 as i64 + dy).clamp(0, h - 1);
                let q = (yi * w + xi) as usize * c;
                for ch in 0..c {
                    acc[ch] += wt * level_img.texels[q + ch];
                }
            }
            out[..c].copy_from_slice(&acc[..c]);
        }
        Src {
            packed: pack_src(v, k),
            frac,
        }
    }

    /// Rounds a point of level `l` of variant `v` to a texel index inside `range`.
    #[inline]
    fn texel_in(range: &[i64; 4], w: u32, q: [f64; 2]) -> Option<u32> {
        let (x, y) = ((q[0] + 0.5).floor() as i64, (q[1] + 0.5).floor() as i64);
        (x >= range[0] && x <= range[1] && y >= range[2] && y <= range[3])
            .then(|| (y * w as i64 + x) as u32)
    }

    /// The k-coherence match of texel `(i, j)` of `levels[l]` in variant `v` (see the module
    /// docs): the candidate of least template distance to the gathered `scratch.raw`, as a
    /// texel index of the variant's level.
    #[allow(clippy::too_many_arguments)]
    fn coherent_match(
        &self,
        levels: &[Level],
        l: usize,
        pass: u32,
        kind: Template,
        taps: &[(i32, i32)],
        ctaps: &[(i32, i32)],
        i: i64,
        j: i64,
        v: usize,
        scratch: &mut Scratch,
    ) -> (usize, [f32; 2]) {
        let vars = self.variants;
        let nl = vars.levels();
        let lv = &levels[l];
        let img = vars.level(v, l);
        let coarser = (l + 1 < nl).then(|| vars.level(v, l + 1));
        let side = match kind {
            Template::Causal => vars.params().template,
            Template::Full => vars.params().boundary_template,
        };
        let range = valid_range(
            kind,
            side,
            img.width,
            img.height,
            coarser.map(|cl| (cl.width, cl.height)),
        );
        let nlv = nl;
        let map_v = &self.maps[v * nlv + l];
        let kl = vars.kset_level_of(v, l);
        let ks = vars.kset(kl);
        let kscale = (1u64 << kl) as f64;
        let kk = vars.coherent_k();
        // Hertzmann et al.'s level scaling of κ: coarser levels jump more freely, so the
        // coarse layout keeps the sample's statistics rather than the first texels' copies.
        let jump_factor = (1.0 + self.coherence / (1u32 << l) as f32).powi(2);
        let cands = &mut scratch.candidates;
        cands.clear();
        let keep_frac = !lv.metric.is_empty();
        // The texel itself (its prediction from the coarser level, or its value before this
        // pass) and each synthesized neighbour inside the square: their source, shifted back by
        // the neighbour's offset.
        let own = std::iter::once((0i32, 0i32));
        let t = lv.grid.idx(i, j);
        for tap in own.chain(taps.iter().copied()) {
            let (dx, dy) = lv.tap_offset(t, tap);
            // Across a cut whose sides share their axes (a quarter turn of 0) the shift holds
            // too; across a turning cut it would need the turned variant, so those taps bring
            // none. Outside taps of the scanline pass are read from the starting values (see
            // `gather`), and so are their sources.
            let (ti, tj) = (i + dy as i64, j + dx as i64);
            let (k, r, outside) = lv.grid.locate(ti, tj);
            if r != 0 {
                continue;
            }
            let src = if kind == Template::Causal && self.reads_init(i, j, ti, tj, outside) {
                lv.init_src[k]
            } else {
                lv.src[k]
            };
            let (sv, sk) = (
                (src.packed >> 32) as usize,
                (src.packed & 0xFFFF_FFFF) as u32,
            );
            let sw = vars.level(sv, l).width;
            let shift = lv.sample_shift(t, (dx, dy));
            let q = [
                (sk % sw) as f64 + src.frac[0] as f64 - shift[0],
                (sk / sw) as f64 + src.frac[1] as f64 - shift[1],
            ];
            let q = if sv == v {
                q
            } else {
                // Another variant: the same point of the sample, in this variant's texels.
                map_v.from_sample(self.maps[sv * nlv + l].to_sample(q))
            };
            if let Some(id) = Self::texel_in(&range, img.width, q) {
                // The remainder is kept with the surface metric only: without it every shift
                // is whole texels within a variant, and the paper's rounding across variants
                // stays as it was.
                let frac = if keep_frac {
                    [q[0] - (q[0] + 0.5).floor(), q[1] - (q[1] + 0.5).floor()].map(|f| f as f32)
                } else {
                    [0.0; 2]
                };
                cands.push(((id as u64) << 1, frac));
            }
            // Its k-coherent set, through the sample level matching this variant's level.
            let x0 = map_v.to_sample(q);
            let (kx, ky) = (
                ((x0[0] / kscale + 0.5).floor() as i64).clamp(0, ks.width as i64 - 1),
                ((x0[1] / kscale + 0.5).floor() as i64).clamp(0, ks.height as i64 - 1),
            );
            let at = (ky * ks.width as i64 + kx) as usize * kk;
            for &e in &ks.entries[at..at + kk] {
                if e == u32::MAX {
                    continue;
                }
                let ex = [
                    (e % ks.width) as f64 * kscale,
                    (e / ks.width) as f64 * kscale,
                ];
                if let Some(id) = Self::texel_in(&range, img.width, map_v.from_sample(ex)) {
                    cands.push((((id as u64) << 1) | 1, [0.0; 2]));
                }
            }
        }
        // By texel, a shifted candidate before a k-coherent one of the same texel, which then
        // goes.
        cands.sort_unstable_by(|a, b| {
            a.0.cmp(&b.0)
                .then(a.1[0].total_cmp(&b.1[0]))
                .then(a.1[1].total_cmp(&b.1[1]))
        });
        cands.dedup_by(|b, a| a.0 >> 1 == b.0 >> 1);
        if cands.is_empty() && !(l + 1 == nl && kind == Template::Causal) {
            // Nothing coherent lies inside the variant: a random texel whose template does.
            let h = counter_hash(
                self.seed,
                STREAM_FALLBACK,
                choice_index(l, pass, lv.grid.idx(i, j)),
            );
            let nx = (range[1] - range[0] + 1) as u64;
            let ny = (range[3] - range[2] + 1) as u64;
            let x = range[0] + (h % nx) as i64;
            let y = range[2] + ((h >> 32) % ny) as i64;
            return ((y * img.width as i64 + x) as usize, [0.0; 2]);
        }
        let c = self.channels;
        let query = &scratch.raw;
        let w = img.width as i64;
        // Squared template distance of the texel at (x, y), or a value ≥ `bound` once the
        // partial sum reaches it.
        let dist = |x: i64, y: i64, bound: f32| -> f32 {
            let mut d = 0.0f32;
            let mut o = 0;
            for &(dx, dy) in taps {
                let k = ((y + dy as i64) * w + x + dx as i64) as usize * c;
                for ch in 0..c {
                    let e = img.texels[k + ch] * self.weights[ch] - query[o + ch];
                    d += e * e;
                }
                o += c;
                if d >= bound {
                    return d;
                }
            }
            if let Some(cl) = coarser {
                let (cx, cy) = (x / 2, y / 2);
                for &(dx, dy) in ctaps {
                    let k = ((cy + dy as i64) * cl.width as i64 + cx + dx as i64) as usize * c;
                    for ch in 0..c {
                        let e = cl.texels[k + ch] * self.weights[ch] * self.coarse_weight
                            - query[o + ch];
                        d += e * e;
                    }
                    o += c;
                }
            }
            d
        };
        if l + 1 == nl && kind == Template::Causal {
            // The coarsest level's scanline pass lays out the whole texture, and coherent
            // candidates there only propagate the random start: every texel of the variant is
            // a candidate (the coarsest levels are small).
            let mut best = (f32::INFINITY, 0i64);
            for y in range[2]..=range[3] {
                for x in range[0]..=range[1] {
                    let d = dist(x, y, best.0);
                    if d < best.0 {
                        best = (d, y * w + x);
                    }
                }
            }
            return (best.1 as usize, [0.0; 2]);
        }
        let mut best = (f32::INFINITY, (cands[0].0 >> 1) as u32, cands[0].1);
        for &(cand, frac) in cands.iter() {
            // Jumps to a k-coherent texel must be (1 + coherence) times better than a shifted
            // candidate (Hertzmann et al. 2001's κ), as squared distances.
            let scale = if cand & 1 == 1 { jump_factor } else { 1.0 };
            let cand = (cand >> 1) as u32;
            let (x, y) = ((cand % img.width) as i64, (cand / img.width) as i64);
            let d = dist(x, y, best.0 / scale) * scale;
            if d < best.0 {
                best = (d, cand, frac);
            }
        }
        (best.1 as usize, best.2)
    }
}

/// Gives every mate group of `lv` one member's value (chosen by hash), turned into each
/// member's axes.
fn unify_mates(lv: &mut Level, c: usize, seed: u64, level: usize, pass: u32) {
    for g in &lv.grid.groups {
        let pick = counter_hash(seed, STREAM_MATE, choice_index(level, pass, g[0] as usize))
            % g.len() as u64;
        let m = g[pick as usize] as usize;
        let mut v = [0.0f32; MAX_CHANNELS];
        v[..c].copy_from_slice(&lv.data[m * c..(m + 1) * c]);
        let rm = lv.grid.to_rep[m];
        for &q in g {
            let q = q as usize;
            let mut w = v;
            // Into the representative's axes, then into q's.
            quarter_turn((rm + 4 - lv.grid.to_rep[q]) % 4, &mut w);
            lv.data[q * c..(q + 1) * c].copy_from_slice(&w[..c]);
        }
    }
}

/// The sources of a finer level's starting values: texel `(i, j)` takes its parent
/// `(i / 2, j / 2)`'s source texel `q` (in the coarser level of the parent's variant) as
/// `2 q + (j mod 2, i mod 2)` in that variant's finer level (`size` gives its width and
/// height), clamped inside; with the surface metric, the child's offset `(j mod 2, i mod 2)`
/// goes through `fine`'s map to sample offsets, rounded.
fn upsample_sources(coarse: &Level, fine: &Level, size: impl Fn(usize) -> (u32, u32)) -> Vec<Src> {
    let nc = coarse.grid.n;
    let nf = fine.grid.n;
    let mut out = vec![Src::default(); nf * nf];
    for i in 0..nf {
        for j in 0..nf {
            let src = coarse.src[(i / 2) * nc + j / 2];
            let (v, k) = (
                (src.packed >> 32) as usize,
                (src.packed & 0xFFFF_FFFF) as u32,
            );
            let (w, h) = size(v);
            let cw = w.div_ceil(2);
            let o = fine.sample_shift(i * nf + j, ((j % 2) as i32, (i % 2) as i32));
            // The continuous position 2 (q + frac) + o, rounded to a texel inside; the
            // remainder is kept (zero without the surface metric).
            let at = |base: u32, frac: f32, d: f64, len: u32| {
                let x = 2.0 * frac as f64 + d;
                let r = (x + 0.5).floor();
                let t = ((2 * base) as i64 + r as i64).clamp(0, len as i64 - 1) as u32;
                (t, (x - r) as f32)
            };
            let (x, fx) = at(k % cw, src.frac[0], o[0], w);
            let (y, fy) = at(k / cw, src.frac[1], o[1], h);
            out[i * nf + j] = Src {
                packed: pack_src(v, (y * w + x) as usize),
                frac: [fx, fy],
            };
        }
    }
    out
}

/// Bilinear interpolation of the coarser level `coarse` onto a grid of side `nf` (sample `i` of
/// `coarse` is sample `2 i` of the result).
fn upsample(coarse: &Level, nf: usize, c: usize) -> Vec<f32> {
    let nc = coarse.grid.n;
    debug_assert_eq!((nc - 1) * 2 + 1, nf);
    let mut fine = vec![0.0f32; nf * nf * c];
    fine.par_chunks_mut(nf * c)
        .enumerate()
        .for_each(|(i, row)| {
            let (i0, i1) = (i / 2, i.div_ceil(2));
            for (j, out) in row.chunks_exact_mut(c).enumerate() {
                let (j0, j1) = (j / 2, j.div_ceil(2));
                for ch in 0..c {
                    let at = |a: usize, b: usize| coarse.data[(a * nc + b) * c + ch];
                    out[ch] = 0.25 * (at(i0, j0) + at(i0, j1) + at(i1, j0) + at(i1, j1));
                }
            }
        });
    fine
}

/// Why a geometry texture could not be synthesized: bad parameters, or inputs that disagree
/// with each other.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum GeometryTextureError {
    #[error(transparent)]
    Params(#[from] ParamError),
    #[error(
        "geometry texture: a geometry image of side {n} cannot have {levels} pyramid levels: \
         the side must be 2^{} · k + 1 with k ≥ 2 (e.g. {}, {} or {})",
        .levels - 1,
        2 * (1usize << (.levels - 1)) + 1,
        4 * (1usize << (.levels - 1)) + 1,
        8 * (1usize << (.levels - 1)) + 1
    )]
    Levels { n: usize, levels: usize },
    #[error(
        "geometry texture: search = \"per_texel\" needs the variants' per-texel search \
         structures, which this variant set was built without"
    )]
    NoPerTexelSets,
    #[error("geometry texture: the geometry image has {entries} mate entries for {n}×{n} samples")]
    MateCount { entries: usize, n: usize },
    #[error(
        "geometry texture: sample {sample}'s mate representative {rep} is not a representative"
    )]
    MateRep { sample: usize, rep: u32 },
    #[error(
        "geometry texture: the field has {dirs} directions and {scales} scales for {samples} samples"
    )]
    FieldSize {
        dirs: usize,
        scales: usize,
        samples: usize,
    },
    #[error("geometry texture: field direction at sample ({i}, {j}) is not finite: {dir}")]
    FieldDirection { i: usize, j: usize, dir: Vec2 },
    #[error(
        "geometry texture: relative scale at sample ({i}, {j}) must be a positive number, got {scale}"
    )]
    FieldScale { i: usize, j: usize, scale: f32 },
}

fn check_inputs(
    gi: &GeometryImage,
    field: &ParamField,
    levels: usize,
) -> Result<(), GeometryTextureError> {
    use GeometryTextureError as E;
    let n = gi.n as usize;
    let nn = n * n;
    let step = 1usize << (levels - 1);
    if n < 3 || !(n - 1).is_multiple_of(step) || (n - 1) / step < 2 {
        return Err(E::Levels { n, levels });
    }
    if gi.mate_rep.len() != nn {
        return Err(E::MateCount {
            entries: gi.mate_rep.len(),
            n,
        });
    }
    for (k, &r) in gi.mate_rep.iter().enumerate() {
        if r as usize >= nn || gi.mate_rep[r as usize] != r {
            return Err(E::MateRep { sample: k, rep: r });
        }
    }
    if field.dir.len() != nn || field.rel_scale.len() != nn {
        return Err(E::FieldSize {
            dirs: field.dir.len(),
            scales: field.rel_scale.len(),
            samples: nn,
        });
    }
    if let Some(k) = field.dir.iter().position(|d| !d.is_finite()) {
        return Err(E::FieldDirection {
            i: k / n,
            j: k % n,
            dir: field.dir[k],
        });
    }
    if let Some(k) = field
        .rel_scale
        .iter()
        .position(|r| !(r.is_finite() && *r > 0.0))
    {
        return Err(E::FieldScale {
            i: k / n,
            j: k % n,
            scale: field.rel_scale[k],
        });
    }
    Ok(())
}

/// `(cos θ, sin θ)` of the rotation taking the sample's up `(0, 1)` to `dir`.
#[inline]
fn dir_rotation(dir: Vec2) -> (f32, f32) {
    let d = dir.normalize_or_zero();
    if d == Vec2::ZERO {
        (1.0, 0.0)
    } else {
        (d.y, -d.x)
    }
}

/// The level-0 controls of each sample (`i * n + j`), as synthesis reads them.
pub struct TexelControls {
    /// The surface metric ([`SurfaceMetric`]); empty without `anisotropic`.
    pub metric: Vec<SurfaceMetric>,
    /// Fractional orientation index in `[0, orientations)`: the variant angle is
    /// `orient · 360° / orientations`.
    pub orient: Vec<f32>,
    /// Fractional scale index in `[0, scales − 1]` (0 = most enlarged).
    pub scale: Vec<f32>,
}

/// The per-sample orientation, scale and metric that [`synthesize_geometry_texture`] matches
/// each texel with (§4.3; with the surface metric, see the module docs).
pub fn texel_controls(
    gi: &GeometryImage,
    field: &ParamField,
    vp: &TexelVariantParams,
    p: &GeometrySynthParams,
) -> TexelControls {
    let anisotropic = p.anisotropic;
    let kk = vp.orientations as usize;
    let ss = vp.scales as usize;
    let mid = vp.middle_scale();
    // Per-sample controls at level 0. With the surface metric, the field's direction (grid
    // axes) is turned into the sample axes by A, and R takes the metric's isotropic spacing in
    // place of the mean neighbour distance (which the longer grid direction dominates).
    let metric0 = if anisotropic {
        surface_metrics_clamped(gi, p.max_stretch as f64)
    } else {
        Vec::new()
    };
    let spacing = if anisotropic {
        local_spacing(gi)
    } else {
        Vec::new()
    };
    let tau = std::f64::consts::TAU;
    let orient0: Vec<f32> = field
        .dir
        .iter()
        .enumerate()
        .map(|(k, &d)| {
            let d = match metric0.get(k) {
                Some(m) if d != Vec2::ZERO => m.to_sample(d),
                _ => d,
            };
            let (cos, sin) = dir_rotation(d);
            let theta = (sin as f64).atan2_pure(cos as f64);
            let f = (theta / (tau / kk as f64)).rem_euclid(kk as f64);
            if f >= kk as f64 { 0.0 } else { f as f32 }
        })
        .collect();
    // R = S / S̄ · 2^offset becomes g / ḡ · 2^offset (means over the samples where both are
    // known), so the texture's density over the whole image stays where the field put it.
    let (sum_s, sum_g) = metric0
        .iter()
        .zip(&spacing)
        .filter(|(m, s)| m.spacing > 0.0 && **s > 0.0)
        .fold((0.0f64, 0.0f64), |(a, b), (m, s)| {
            (a + *s as f64, b + m.spacing as f64)
        });
    let mean_ratio = if sum_g > 0.0 {
        (sum_s / sum_g) as f32
    } else {
        1.0
    };
    let scale0: Vec<f32> = field
        .rel_scale
        .iter()
        .enumerate()
        .map(|(k, &r)| {
            let r = match (metric0.get(k), spacing.get(k)) {
                (Some(m), Some(&s)) if m.spacing > 0.0 && s > 0.0 => r * m.spacing / s * mean_ratio,
                _ => r,
            };
            let s = (r.log2_pure() + mid as f32).clamp(0.0, (ss - 1) as f32);
            match p.scale_choice {
                ScaleChoice::Random => s,
                // A whole index: the choice then takes that scale with probability 1.
                ScaleChoice::Nearest => (s + 0.5).floor(),
            }
        })
        .collect();

    TexelControls {
        metric: metric0,
        orient: orient0,
        scale: scale0,
    }
}

/// Per level-0 sample, the linear map `M` (row-major, acting on `(x = column, y = row)`) from
/// grid offsets to offsets in the sample's own texels (level 0, unrotated) that synthesis lays
/// the texture out with there: `M = f · R(−θ) · A`, with `A` the surface metric (the identity
/// without it), `θ` the field's angle as a continuous orientation index and `f` the variants'
/// texel size in sample texels at the continuous scale index (geometric between the two scales
/// the synthesis mixes). A synthesized neighbour `o` grid steps away copies, in coherent runs,
/// the sample point `M o` away from the texel's; this is what the surface-space score reads
/// the relief along.
pub fn sample_frame_maps(
    controls: &TexelControls,
    variants: &TexelVariantsRef<'_>,
) -> Vec<[f32; 4]> {
    let vp = variants.params();
    let kk = vp.orientations as f64;
    let ss = vp.scales as usize;
    // Texel size of scale s's variants in sample texels (orientation 0: a pure scaling).
    let log_size: Vec<f64> = (0..ss)
        .map(|s| variants.sample_map(variants.variant(s, 0), 0).a[0][0].log2_pure())
        .collect();
    controls
        .orient
        .iter()
        .zip(&controls.scale)
        .enumerate()
        .map(|(k, (&o, &s))| {
            let s = s as f64;
            let s0 = (s.floor() as usize).min(ss - 1);
            let t = s - s0 as f64;
            let ls = if s0 + 1 < ss {
                (1.0 - t) * log_size[s0] + t * log_size[s0 + 1]
            } else {
                log_size[s0]
            };
            let f = ls.exp2_pure();
            let theta = std::f64::consts::TAU * o as f64 / kk;
            let (sin, cos) = (theta.sin_pure(), theta.cos_pure());
            // f R(−θ) = f [[cos, sin], [−sin, cos]], as the variants' sample maps.
            let r = [f * cos, f * sin, -f * sin, f * cos];
            let a = controls
                .metric
                .get(k)
                .map_or([1.0f64, 0.0, 0.0, 1.0], |m| m.a.map(|v| v as f64));
            [
                r[0] * a[0] + r[1] * a[2],
                r[0] * a[1] + r[1] * a[3],
                r[2] * a[0] + r[3] * a[2],
                r[2] * a[1] + r[3] * a[3],
            ]
            .map(|v| v as f32)
        })
        .collect()
}

/// Synthesizes a texel image over `gi` (see the module docs). The result has `gi.n × gi.n`
/// texels with the variants' channels; `(dx, dy, dn)` are in the local frames of
/// [`crate::geom::geometry_image::local_frames`]. `progress` gets the fraction done, 0 to 1,
/// from the calling thread.
pub fn synthesize_geometry_texture(
    gi: &GeometryImage,
    field: &ParamField,
    variants: &TexelVariantsRef<'_>,
    p: &GeometrySynthParams,
    progress: &dyn Fn(f32),
) -> Result<TexelImage, GeometryTextureError> {
    synthesize_impl(gi, field, variants, p, progress, true)
}

/// [`synthesize_geometry_texture`]; `wavefront` false runs the scanline pass texel by texel
/// (the reference the wavefront order must reproduce).
fn synthesize_impl(
    gi: &GeometryImage,
    field: &ParamField,
    variants: &TexelVariantsRef<'_>,
    p: &GeometrySynthParams,
    progress: &dyn Fn(f32),
    wavefront: bool,
) -> Result<TexelImage, GeometryTextureError> {
    p.validate()?;
    let vp = variants.params().clone();
    let nl = vp.levels as usize;
    check_inputs(gi, field, nl)?;
    progress(0.0);
    let n0 = gi.n as usize;
    let c = variants.channels();
    let kk = vp.orientations as usize;
    let ss = vp.scales as usize;

    let TexelControls {
        metric: metric0,
        orient: orient0,
        scale: scale0,
    } = texel_controls(gi, field, &vp, p);

    // Level grids: mates from the level-0 samples on each level's lattice.
    let mut levels: Vec<Level> = Vec::with_capacity(nl);
    for l in 0..nl {
        let n = (n0 - 1) / (1 << l) + 1;
        let fine = |i: usize, j: usize| (i << l) * n0 + (j << l);
        let mut first: Vec<u32> = vec![u32::MAX; n0 * n0];
        let mut rep = vec![0u32; n * n];
        for i in 0..n {
            for j in 0..n {
                let k = i * n + j;
                let key = gi.mate_rep[fine(i, j)] as usize;
                if first[key] == u32::MAX {
                    first[key] = k as u32;
                }
                rep[k] = first[key];
            }
        }
        let mut orient = vec![0.0f32; n * n];
        let mut scale = vec![0.0f32; n * n];
        for i in 0..n {
            for j in 0..n {
                orient[i * n + j] = orient0[fine(i, j)];
                scale[i * n + j] = scale0[fine(i, j)];
            }
        }
        // The metric is scale-free: a level's texel takes its level-0 sample's.
        let metric = if metric0.is_empty() {
            Vec::new()
        } else {
            (0..n * n).map(|k| metric0[fine(k / n, k % n)]).collect()
        };
        levels.push(Level {
            grid: LevelGrid::build(n, rep, p.boundary_strip),
            data: Vec::new(),
            init: Vec::new(),
            orient,
            scale,
            src: Vec::new(),
            init_src: Vec::new(),
            metric,
        });
    }
    if p.search == Search::PerTexel && !variants.meta.per_texel {
        return Err(GeometryTextureError::NoPerTexelSets);
    }
    let maps: Vec<_> = (0..variants.variant_count() * nl)
        .map(|vl| variants.sample_map(vl / nl, vl % nl))
        .collect();

    let ctx = Ctx {
        variants,
        channels: c,
        weights: &variants.meta.channel_weights,
        coarse_weight: match p.search {
            Search::KCoherence => p.coarse_weight,
            Search::PerTexel => vp.coarse_weight,
        },
        seed: p.seed,
        eps: p.search_eps,
        orientations: kk,
        scales: ss,
        block: vp.template as usize,
        search: p.search,
        coherence: p.coherence,
        nearest_taps: p.taps == Taps::Nearest,
        subtexel: p.subtexel && p.anisotropic,
        maps,
        wave: (vp.template / 2) as i64 + 1,
    };
    let causal_taps = template_taps(Template::Causal, vp.template);
    let causal_ctaps = coarse_taps(vp.template);
    let full_taps = template_taps(Template::Full, vp.boundary_template);
    let full_ctaps = coarse_taps(vp.boundary_template);

    // Work units for progress: texels per level, times (1 + a share for the boundary).
    let total: f64 = levels
        .iter()
        .map(|lv| (lv.grid.n * lv.grid.n) as f64)
        .sum::<f64>()
        + levels
            .iter()
            .map(|lv| lv.grid.strip.len() as f64 * p.boundary_passes as f64)
            .sum::<f64>();
    let mut done = 0.0f64;

    for l in (0..nl).rev() {
        let n = levels[l].grid.n as i64;
        // 1. Starting values: at the coarsest level texels drawn at random from the variant
        // each texel would be matched in (the sample's statistics at that level and scale),
        // above it the coarser result, interpolated.
        let init = if l + 1 == nl {
            let lv = &levels[l];
            let mut init = vec![0.0f32; lv.grid.n * lv.grid.n * c];
            let mut src = vec![Src::default(); lv.grid.n * lv.grid.n];
            init.par_chunks_mut(c)
                .zip(src.par_iter_mut())
                .enumerate()
                .for_each(|(t, (out, src))| {
                    let v = ctx.choose(lv, l, INIT_PASS, t);
                    let img = variants.level(v, l);
                    let count = (img.width * img.height) as u64;
                    let key = choice_index(l, INIT_PASS, t);
                    let k = (counter_hash(p.seed, STREAM_INIT, key) % count) as usize;
                    out.copy_from_slice(&img.texels[k * c..(k + 1) * c]);
                    *src = Src::whole(v, k);
                });
            (init, src)
        } else {
            let src = upsample_sources(&levels[l + 1], &levels[l], |v| {
                let img = variants.level(v, l);
                (img.width, img.height)
            });
            (upsample(&levels[l + 1], levels[l].grid.n, c), src)
        };
        let (init, init_src) = init;
        levels[l].data = init.clone();
        levels[l].init = init;
        levels[l].src = init_src.clone();
        levels[l].init_src = init_src;
        // 2. Scanline synthesis, one anti-diagonal wave at a time (or in plain scanline order).
        let f = if wavefront {
            (vp.template / 2) as i64 + 1
        } else {
            n
        };
        let last_wave = (n - 1) + f * (n - 1);
        let mut results: Vec<([f32; MAX_CHANNELS], Src)> = Vec::new();
        for w in 0..=last_wave {
            let i_lo = if w > n - 1 {
                (w - (n - 1) + f - 1) / f
            } else {
                0
            };
            let i_hi = (w / f).min(n - 1);
            if i_lo > i_hi {
                continue;
            }
            let compute = |scratch: &mut Scratch, i: i64| {
                let mut out = [0.0f32; MAX_CHANNELS];
                let src = ctx.synthesize_texel(
                    &levels,
                    l,
                    0,
                    Template::Causal,
                    &causal_taps,
                    &causal_ctaps,
                    i,
                    w - f * i,
                    scratch,
                    &mut out,
                );
                (out, src)
            };
            results.clear();
            if i_hi - i_lo < 8 || !wavefront {
                let mut scratch = Scratch::default();
                results.extend((i_lo..=i_hi).map(|i| compute(&mut scratch, i)));
            } else {
                (i_lo as usize..i_hi as usize + 1)
                    .into_par_iter()
                    .map_init(Scratch::default, |s, i| compute(s, i as i64))
                    .collect_into_vec(&mut results);
            }
            let lv = &mut levels[l];
            for (i, (px, src)) in (i_lo..=i_hi).zip(&results) {
                let t = lv.grid.idx(i, w - f * i);
                lv.data[t * c..(t + 1) * c].copy_from_slice(&px[..c]);
                lv.src[t] = *src;
            }
        }
        // 2b. Correction passes (k-coherence only): each texel rematched in the variant of its
        // scanline match, from the level as the previous pass left it, so the texels do not
        // depend on one another and any thread count gives the same result.
        let corrections = if p.search == Search::KCoherence {
            p.correction_passes
        } else {
            0
        };
        for _ in 0..corrections {
            let nn = levels[l].grid.n * levels[l].grid.n;
            let res: Vec<([f32; MAX_CHANNELS], Src)> = (0..nn)
                .into_par_iter()
                .map_init(Scratch::default, |scratch, t| {
                    let (i, j) = levels[l].grid.coords(t as u32);
                    let mut out = [0.0f32; MAX_CHANNELS];
                    let src = ctx.synthesize_texel(
                        &levels,
                        l,
                        0,
                        Template::Full,
                        &full_taps,
                        &full_ctaps,
                        i,
                        j,
                        scratch,
                        &mut out,
                    );
                    (out, src)
                })
                .collect();
            let lv = &mut levels[l];
            for (t, (px, src)) in res.iter().enumerate() {
                lv.data[t * c..(t + 1) * c].copy_from_slice(&px[..c]);
                lv.src[t] = *src;
            }
        }
        unify_mates(&mut levels[l], c, p.seed, l, 0);
        done += (n * n) as f64;
        progress((done / total) as f32);

        // 3. Boundary resynthesis.
        let mut scratch = Scratch::default();
        for pass in 1..=p.boundary_passes {
            let strip = std::mem::take(&mut levels[l].grid.strip);
            for &t in &strip {
                let (i, j) = levels[l].grid.coords(t);
                let mut out = [0.0f32; MAX_CHANNELS];
                let src = ctx.synthesize_texel(
                    &levels,
                    l,
                    pass,
                    Template::Full,
                    &full_taps,
                    &full_ctaps,
                    i,
                    j,
                    &mut scratch,
                    &mut out,
                );
                let t = t as usize;
                levels[l].data[t * c..(t + 1) * c].copy_from_slice(&out[..c]);
                levels[l].src[t] = src;
            }
            done += strip.len() as f64;
            levels[l].grid.strip = strip;
            unify_mates(&mut levels[l], c, p.seed, l, pass);
            progress((done / total) as f32);
        }
    }

    // Output: mated samples in their representative's axes.
    let lv = levels.swap_remove(0);
    let mut out = TexelImage {
        width: gi.n,
        height: gi.n,
        channels: c as u32,
        data: lv.data,
    };
    for g in &lv.grid.groups {
        for &q in g {
            let q = q as usize;
            quarter_turn(lv.grid.to_rep[q], &mut out.data[q * c..q * c + 2]);
        }
    }
    progress(1.0);
    Ok(out)
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

    #[test]
    fn params_validate_names_the_field() {
        assert!(GeometrySynthParams::default().validate().is_ok());
        for (p, name) in [
            (
                GeometrySynthParams {
                    boundary_strip: 0,
                    ..Default::default()
                },
                "boundary_strip",
            ),
            (
                GeometrySynthParams {
                    search_eps: -1.0,
                    ..Default::default()
                },
                "search_eps",
            ),
            (
                GeometrySynthParams {
                    boundary_passes: 17,
                    ..Default::default()
                },
                "boundary_passes",
            ),
        ] {
            let e = p.validate().unwrap_err().to_string();
            assert!(e.contains(name), "{e}");
        }
        let e: Result<GeometrySynthParams, _> = toml::from_str("boundary_pass = 2");
        assert!(e.is_err());
    }

    #[test]
    fn wavefront_order_reproduces_the_scanline_order() {
        use crate::analyse_exemplar::texel_variants::{TexelVariantParams, build_texel_variants};
        use glam::Vec3;
        let mut sample = TexelImage::new(40, 40, 3);
        for y in 0..40u32 {
            for x in 0..40u32 {
                let h = counter_unit(9, 0, (y * 40 + x) as u64);
                let t = sample.texel_mut(x, y);
                t[0] = (x as f32 * 0.7).sin_pure() * 0.2;
                t[1] = h - 0.5;
                t[2] = (x as f32 * 0.9 + y as f32 * 0.3).sin_pure() + 0.3 * h;
            }
        }
        let vp = TexelVariantParams {
            orientations: 4,
            ..Default::default()
        };
        let n = 33u32;
        let nn = (n * n) as usize;
        let mut mate_rep: Vec<u32> = (0..nn as u32).collect();
        for i in 0..n {
            mate_rep[(i * n + n - 1) as usize] = i * n;
        }
        // Stretched 3:1 down the rows, sheared and bent: the surface metric spreads the
        // causal taps past the causal half, where both orders must read the starting values.
        let gi = GeometryImage {
            n,
            positions: (0..nn)
                .map(|k| {
                    let (i, j) = ((k / n as usize) as f32, (k % n as usize) as f32);
                    Vec3::new(j + 0.5 * i, 3.0 * i + 0.02 * j * j, 0.0)
                })
                .collect(),
            normals: vec![Vec3::Z; nn],
            mate_rep,
        };
        let field = ParamField {
            dir: (0..nn)
                .map(|k| Vec2::from_angle(k as f32 * 0.01).rotate(Vec2::Y))
                .collect(),
            rel_scale: (0..nn).map(|k| 0.6 + (k % 7) as f32 * 0.25).collect(),
        };
        for template in [3u32, 5] {
            let p = GeometrySynthParams::default();
            // The causal template radius decides the waves.
            let owned = build_texel_variants(
                &sample,
                &TexelVariantParams {
                    template,
                    ..vp.clone()
                },
                &|_| {},
            )
            .unwrap();
            let vr = owned.as_ref();
            for (search, anisotropic, options) in [
                (Search::KCoherence, true, false),
                (Search::KCoherence, true, true),
                (Search::KCoherence, false, false),
                (Search::PerTexel, true, false),
            ] {
                let p = GeometrySynthParams {
                    search,
                    anisotropic,
                    ..p.clone()
                };
                // The experiments' options keep the order exact too.
                let p = if options {
                    GeometrySynthParams {
                        taps: Taps::Nearest,
                        scale_choice: ScaleChoice::Nearest,
                        subtexel: true,
                        max_stretch: 2.0,
                        ..p
                    }
                } else {
                    p
                };
                let a = synthesize_impl(&gi, &field, &vr, &p, &|_| {}, true).unwrap();
                let b = synthesize_impl(&gi, &field, &vr, &p, &|_| {}, false).unwrap();
                let bits = |t: &TexelImage| t.data.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
                assert_eq!(
                    bits(&a),
                    bits(&b),
                    "template {template} {search:?} anisotropic {anisotropic} {options}"
                );
            }
        }
    }

    #[test]
    fn sample_frame_maps_are_the_variants_maps_times_the_metric() {
        use crate::analyse_exemplar::texel_variants::{TexelVariantParams, build_texel_variants};
        let mut sample = TexelImage::new(40, 40, 3);
        for (k, v) in sample.data.iter_mut().enumerate() {
            *v = counter_unit(3, 0, k as u64);
        }
        let vp = TexelVariantParams {
            orientations: 4,
            ..Default::default()
        };
        let owned = build_texel_variants(&sample, &vp, &|_| {}).unwrap();
        let vr = owned.as_ref();
        let stretched = SurfaceMetric::from_metric(9.0, 0.0, 1.0);
        let controls = TexelControls {
            metric: vec![SurfaceMetric::IDENTITY, SurfaceMetric::IDENTITY, stretched],
            orient: vec![0.0, 1.0, 0.0],
            scale: vec![1.0, 2.0, 1.5],
        };
        let maps = sample_frame_maps(&controls, &vr);
        let close =
            |a: [f32; 4], b: [f64; 4]| a.iter().zip(b).all(|(&x, y)| (x as f64 - y).abs() < 1e-5);
        // The middle scale unrotated: the sample's own texels.
        assert!(close(maps[0], [1.0, 0.0, 0.0, 1.0]), "{:?}", maps[0]);
        // Orientation 1 of 4 at the coarser scale: the variant's own sample map.
        let a = vr.sample_map(vr.variant(2, 1), 0).a;
        assert!(
            close(maps[1], [a[0][0], a[0][1], a[1][0], a[1][1]]),
            "{:?} against {a:?}",
            maps[1]
        );
        assert!(close(maps[1], [0.0, 2.0, -2.0, 0.0]), "{:?}", maps[1]);
        // Halfway between two scales a factor √2, times the metric's A: a grid step along x
        // covers 3 times the surface of one along y, so A = diag(√3, 1/√3).
        let (r2, r3) = (std::f64::consts::SQRT_2, 3f64.sqrt());
        assert!(
            close(maps[2], [r2 * r3, 0.0, 0.0, r2 / r3]),
            "{:?}",
            maps[2]
        );
    }

    #[test]
    fn destination_features_equal_the_sample_features_where_the_images_agree() {
        use crate::analyse_exemplar::texel_variants::{TexelVariantParams, build_texel_variants};
        // A 33×33 sample is itself a valid 2-level destination: the pyramids coincide, so each
        // candidate's gathered feature must be found at distance 0, at itself.
        let n = 33usize;
        let mut sample = TexelImage::new(n as u32, n as u32, 3);
        for (k, v) in sample.data.iter_mut().enumerate() {
            *v = counter_unit(3, 0, k as u64);
        }
        for template in [3u32, 5, 7] {
            let vp = TexelVariantParams {
                orientations: 1,
                scales: 1,
                levels: 2,
                template,
                boundary_template: template,
                ..Default::default()
            };
            let owned = build_texel_variants(&sample, &vp, &|_| {}).unwrap();
            let vr = owned.as_ref();
            let levels: Vec<Level> = (0..2)
                .map(|l| {
                    let lev = vr.level(0, l);
                    let m = lev.width as usize;
                    Level {
                        grid: LevelGrid::build(m, (0..(m * m) as u32).collect(), 2),
                        data: lev.texels.to_vec(),
                        init: lev.texels.to_vec(),
                        orient: vec![0.0; m * m],
                        scale: vec![0.0; m * m],
                        src: vec![Src::default(); m * m],
                        init_src: vec![Src::default(); m * m],
                        metric: Vec::new(),
                    }
                })
                .collect();
            let ctx = Ctx {
                variants: &vr,
                channels: 3,
                weights: &vr.meta.channel_weights,
                coarse_weight: vr.params().coarse_weight,
                seed: 0,
                eps: 0.0,
                orientations: 1,
                scales: 1,
                block: 5,
                search: Search::PerTexel,
                coherence: 0.0,
                nearest_taps: false,
                subtexel: false,
                wave: (template / 2) as i64 + 1,
                maps: vec![vr.sample_map(0, 0), vr.sample_map(0, 1)],
            };
            for kind in [Template::Causal, Template::Full] {
                let taps = template_taps(kind, template);
                let ctaps = coarse_taps(template);
                for l in 0..2 {
                    let set = vr.set(0, l, kind);
                    let m = levels[l].grid.n;
                    let mut raw = Vec::new();
                    let mut red = vec![0.0; set.dims];
                    let mut scratch = Vec::new();
                    for (id, &centre) in set.centres.iter().enumerate() {
                        let (i, j) = ((centre as usize / m) as i64, (centre as usize % m) as i64);
                        ctx.gather(&levels, l, &taps, &ctaps, i, j, true, &mut raw);
                        set.project(&raw, &mut red);
                        let (got, d) = set.tree.nearest1_approx(&red, 0.0, &mut scratch).unwrap();
                        assert_eq!(d, 0.0, "template {template} {kind:?} level {l} ({i}, {j})");
                        assert_eq!(got as usize, id);
                    }
                }
            }
        }
    }
}

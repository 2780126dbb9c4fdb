//! The working state the passes share: one level's texels, their variant controls and sources
//! ([`Level`], [`Src`]), the matching context ([`Ctx`]) and scratch buffers, and the random
//! streams and counters of the synthesis' choices.

use super::grid::LevelGrid;
use super::params::Search;
use crate::analyse_exemplar::texel_variants::{SampleMap, TexelVariantsRef};
use crate::synthesize::surface_metric::SurfaceMetric;
use glam::Vec2;

pub(super) const STREAM_INIT: u64 = 0x6774_0001;
pub(super) const STREAM_ORIENT: u64 = 0x6774_0002;
pub(super) const STREAM_SCALE: u64 = 0x6774_0003;
pub(super) const STREAM_MATE: u64 = 0x6774_0004;
pub(super) const STREAM_BLOCK: u64 = 0x6774_0005;
pub(super) const STREAM_FALLBACK: u64 = 0x6774_0006;

/// A texel's source: variant `v` and texel index `k` of the variant's level, `v << 32 | k`.
#[inline]
pub(super) fn pack_src(v: usize, k: usize) -> u64 {
    ((v as u64) << 32) | k as u64
}

/// Where a texel's value was copied from: [`pack_src`] of the variant and texel, and, with the
/// surface metric, the sub-texel remainder of the continuous source position (in that
/// variant's texels, within ±0.5), so that shifts by `A o` that are not whole texels add up
/// along a run of coherent texels instead of being rounded away at each step.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(super) struct Src {
    pub(super) packed: u64,
    pub(super) frac: [f32; 2],
}

impl Src {
    pub(super) fn whole(v: usize, k: usize) -> Src {
        Src {
            packed: pack_src(v, k),
            frac: [0.0; 2],
        }
    }
}

/// Most channels a texel has.
pub(super) const MAX_CHANNELS: usize = 6;

/// Pass number of the choices made for the starting values.
pub(super) const INIT_PASS: u32 = 0xFFFF;

/// Counter of a random choice at `texel` of `level` in pass `pass` (0 the scanline pass).
#[inline]
pub(super) fn choice_index(level: usize, pass: u32, texel: usize) -> u64 {
    ((level as u64) << 56) | ((pass as u64) << 40) | texel as u64
}

/// One level's working state: texels (own grid axes) and the per-texel variant controls.
pub(super) struct Level {
    pub(super) grid: LevelGrid,
    pub(super) data: Vec<f32>,
    /// The level's values before its scanline pass, which reads taps outside the square here.
    pub(super) init: Vec<f32>,
    /// Fractional orientation index in `[0, orientations)`.
    pub(super) orient: Vec<f32>,
    /// Fractional scale index in `[0, scales − 1]` (0 = most enlarged).
    pub(super) scale: Vec<f32>,
    /// Per texel, where its value was copied from ([`pack_src`]), and the same for `init`.
    pub(super) src: Vec<Src>,
    pub(super) init_src: Vec<Src>,
    /// Per texel, the map from grid offsets to sample offsets ([`SurfaceMetric`]); empty
    /// without `anisotropic` (template taps are grid offsets).
    pub(super) metric: Vec<SurfaceMetric>,
}

impl Level {
    /// The grid offset `(dx, dy)` at which texel `t` reads template tap `tap`.
    #[inline]
    pub(super) fn tap_offset(&self, t: usize, tap: (i32, i32)) -> (i32, i32) {
        match self.metric.get(t) {
            Some(m) => m.to_grid(tap),
            None => tap,
        }
    }

    /// The shift, in sample texels, of a neighbour `o` grid steps away from texel `t`.
    #[inline]
    pub(super) fn sample_shift(&self, t: usize, o: (i32, i32)) -> [f64; 2] {
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
pub(super) struct Ctx<'a, 'v> {
    pub(super) variants: &'a TexelVariantsRef<'v>,
    pub(super) channels: usize,
    pub(super) weights: &'a [f32],
    pub(super) coarse_weight: f32,
    pub(super) seed: u64,
    pub(super) eps: f32,
    pub(super) orientations: usize,
    pub(super) scales: usize,
    /// Side of the blocks of texels that share their random variant choice.
    pub(super) block: usize,
    pub(super) search: Search,
    /// `coherence` of the parameters.
    pub(super) coherence: f32,
    /// `taps = "nearest"`.
    pub(super) nearest_taps: bool,
    /// `subtexel` (with the surface metric).
    pub(super) subtexel: bool,
    /// Per (variant, level), `v * levels + l`: the map to the sample's level 0.
    pub(super) maps: Vec<SampleMap>,
    /// Anti-diagonal step of the scanline pass's waves (`template / 2 + 1`): a texel `(i', j')`
    /// is finished before texel `(i, j)` in both the scanline and the wave order when it is
    /// left of it on its row, or on a row above and on an earlier wave.
    pub(super) wave: i64,
}

impl Ctx<'_, '_> {
    /// Whether the scanline pass reads tap `(ti, tj)` of texel `(i, j)` from the starting
    /// values: outside the square, or not yet finished in both orders (taps laid out by the
    /// surface metric can reach past the causal half).
    #[inline]
    pub(super) fn reads_init(&self, i: i64, j: i64, ti: i64, tj: i64, outside: bool) -> bool {
        let done = (ti == i && tj < j) || (ti < i && tj + self.wave * ti < j + self.wave * i);
        outside || !done
    }
}

/// Scratch buffers of one matcher.
#[derive(Default)]
pub(super) struct Scratch {
    pub(super) raw: Vec<f32>,
    pub(super) reduced: Vec<f32>,
    pub(super) search: Vec<f32>,
    /// Candidate texel index `<< 1`, plus 1 for a k-coherent (not shifted) one, and its
    /// sub-texel remainder ([`Src::frac`]).
    pub(super) candidates: Vec<(u64, [f32; 2])>,
}

//! Image synthesis with a jump map: every output pixel gets an exemplar address.
//!
//! Implements the synthesis phase of S. Zelinka and M. Garland, "Towards real-time texture
//! synthesis with the jump map", Eurographics Workshop on Rendering 2002, as reviewed in §4.2.1
//! (weights as in §4.2.5) of Zelinka and Garland, "Interactive texture synthesis on surfaces
//! using jump maps" (2003). Output pixels are visited along a Hilbert path; each picks a random
//! already-synthesized 4-neighbour as its source; the source's effective address is a weighted
//! random choice between its actual address (weight `continuation`, tapered linearly to zero
//! within `boundary_fraction` of an exemplar edge) and the jumps listed there; the new address is
//! the effective address plus the offset from the source to the new pixel.
//!
//! Departures and choices the papers leave open:
//! - The path is a generalized Hilbert curve ("gilbert", J. Červený 2018), so any rectangle
//!   works, not only powers of two. Its rare diagonal steps can leave a pixel with no
//!   synthesized 4-neighbour; that pixel then continues from the previous pixel on the path.
//! - Choices whose new address would leave the exemplar are dropped before the random draw (as
//!   §4.2.4 does on surfaces); if none is left, the continuation is clamped into the exemplar.
//! - The first pixel gets a random address away from the edges.
//! - By default (`combine_neighbours`) a pixel does not pick one source neighbour: the
//!   continuations and jumps of all its synthesized 4-neighbours enter one weighted draw, the
//!   "probabilistically good matching" of §4.2.5, which §6 proposes for images as well. With
//!   one random source, every pixel along the front of a patch that reaches an exemplar edge
//!   jumps on its own, and the patch dissolves into fragments; with the combined draw the
//!   first jump is followed by its neighbours. `combine_neighbours = false` is the 2002
//!   algorithm exactly.
//! - The default continuation weight (300) is far above the paper's "relatively rare" jumps
//!   of one in a dozen pixels or so: with exemplars of 64–128 pixels, small weights gave
//!   visibly noisy, fragmented output.
//! - Randomness comes from [`crate::random::counter_hash`] of (seed, draw, output pixel index), never from a
//!   shared stream, so any output pixel's choices can be recomputed independently.

use crate::analyse_exemplar::jump_map::JumpMapRef;
use crate::check::{ParamError, check_range};
use crate::random::counter_unit;

/// The `jump_walk_2d` node's algorithm and version (part of its key; bump on any change of output).
pub const NODE: texsyn_core::algorithm::Algorithm =
    texsyn_core::algorithm::Algorithm::new("jump_walk_2d", 1);

/// Parameters of the 2D jump-map synthesis (`[synthesize]` of `synth2d`).
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct Synth2dParams {
    /// Output size in pixels, 1..=16384 each (the node's; [`synthesize_2d`] takes its own).
    /// Default: 256 × 256.
    pub width: u32,
    pub height: u32,
    /// The node's seed ([`synthesize_2d`] takes its own). Default: 1.
    pub seed: u64,
    /// Weight of "do not jump" per source neighbour, i.e. roughly the mean number of pixels
    /// between jumps (a pixel's jump weights sum to at most 1), 0..=1e9. Default: 300 (with the
    /// small exemplars used here, 10–50 gives patches of a few pixels and a noisy result; jumps
    /// forced by the exemplar's edges still start new patches often).
    pub continuation: f32,
    /// Fraction of the exemplar size, 0..=0.5, over which the continuation weight falls
    /// linearly to zero towards an exemplar edge, to encourage jumps away from it. Default: 0.1.
    pub boundary_fraction: f32,
    /// false: each pixel continues from one already-synthesized 4-neighbour picked at random
    /// (the image algorithm, §4.2.1). true: the continuations and jumps of *all* its
    /// synthesized 4-neighbours go into one weighted draw ("probabilistically good matching",
    /// §4.2.5, which §6 suggests for images too): a neighbour that has just jumped is then
    /// usually followed by the next pixels instead of each of them jumping somewhere else, which
    /// fragments patches much less. Default: true.
    pub combine_neighbours: bool,
}

impl Default for Synth2dParams {
    fn default() -> Self {
        Synth2dParams {
            width: 256,
            height: 256,
            seed: 1,
            continuation: 300.0,
            boundary_fraction: 0.1,
            combine_neighbours: true,
        }
    }
}

impl Synth2dParams {
    /// Checks every field's range; the error names the field, its range and the value.
    pub fn validate(&self) -> Result<(), ParamError> {
        check_range("synthesize.width", self.width, 1, 16384)?;
        check_range("synthesize.height", self.height, 1, 16384)?;
        let c = self.continuation;
        if !(c.is_finite() && (0.0..=1e9).contains(&c)) {
            // The bound reads 1e9, not the 1000000000 check_range would print.
            return Err(ParamError::out_of_range(
                "synth2d: continuation",
                "0",
                "1e9",
                c,
            ));
        }
        check_range("boundary_fraction", self.boundary_fraction, 0.0, 0.5)
            .map_err(|e| e.within("synth2d"))
    }
}

/// Draw numbers (hash streams) used per output pixel.
const DRAW_SOURCE: u64 = 0;
const DRAW_CHOICE: u64 = 1;
const DRAW_START_X: u64 = 2;
const DRAW_START_Y: u64 = 3;

/// The pixels of a `width × height` rectangle along a generalized Hilbert curve (Červený's
/// "gilbert"): each pixel exactly once, consecutive pixels 4-adjacent except for at most a few
/// diagonal steps when a side is odd.
pub fn gilbert_curve(width: u32, height: u32) -> Vec<[u32; 2]> {
    let mut out = Vec::with_capacity(width as usize * height as usize);
    if width == 0 || height == 0 {
        return out;
    }
    let (w, h) = (width as i64, height as i64);
    if w >= h {
        gilbert(&mut out, 0, 0, w, 0, 0, h);
    } else {
        gilbert(&mut out, 0, 0, 0, h, w, 0);
    }
    out
}

/// Fills the rectangle spanned from `(x, y)` by the major axis `(ax, ay)` and the minor axis
/// `(bx, by)`.
fn gilbert(out: &mut Vec<[u32; 2]>, x: i64, y: i64, ax: i64, ay: i64, bx: i64, by: i64) {
    let w = (ax + ay).abs();
    let h = (bx + by).abs();
    let (dax, day) = (ax.signum(), ay.signum());
    let (dbx, dby) = (bx.signum(), by.signum());
    if h == 1 {
        for i in 0..w {
            out.push([(x + i * dax) as u32, (y + i * day) as u32]);
        }
        return;
    }
    if w == 1 {
        for i in 0..h {
            out.push([(x + i * dbx) as u32, (y + i * dby) as u32]);
        }
        return;
    }
    let (mut ax2, mut ay2) = (ax.div_euclid(2), ay.div_euclid(2));
    let (mut bx2, mut by2) = (bx.div_euclid(2), by.div_euclid(2));
    let w2 = (ax2 + ay2).abs();
    let h2 = (bx2 + by2).abs();
    if 2 * w > 3 * h {
        // Long rectangle: split along the major axis only, keeping halves even if possible.
        if w2 % 2 == 1 && w > 2 {
            ax2 += dax;
            ay2 += day;
        }
        gilbert(out, x, y, ax2, ay2, bx, by);
        gilbert(out, x + ax2, y + ay2, ax - ax2, ay - ay2, bx, by);
    } else {
        if h2 % 2 == 1 && h > 2 {
            bx2 += dbx;
            by2 += dby;
        }
        // Up, across, down.
        gilbert(out, x, y, bx2, by2, ax2, ay2);
        gilbert(out, x + bx2, y + by2, ax, ay, bx - bx2, by - by2);
        gilbert(
            out,
            x + (ax - dax) + (bx2 - dbx),
            y + (ay - day) + (by2 - dby),
            -bx2,
            -by2,
            -(ax - ax2),
            -(ay - ay2),
        );
    }
}

/// Estimated peak memory, in bytes, of a `width` × `height` synthesis and its blend: about 52
/// bytes per output pixel (addresses, the blended image, its PNG), measured: 216 MB at 2048²,
/// 853 MB at 4096².
pub fn memory_estimate(width: u64, height: u64) -> u64 {
    52 * width * height + (32 << 20)
}

/// Synthesizes a `width × height` image as exemplar addresses (row-major, `[x, y]`), from the
/// jump map `jm` of the exemplar. The same inputs and seed always give the same addresses.
///
/// Panics if `params` do not pass [`Synth2dParams::validate`].
pub fn synthesize_2d(
    jm: JumpMapRef,
    width: u32,
    height: u32,
    params: &Synth2dParams,
    seed: u64,
) -> Vec<[u16; 2]> {
    if let Err(e) = params.validate() {
        panic!("{e}");
    }
    let n = width as usize * height as usize;
    let mut addr = vec![[0u16; 2]; n];
    if n == 0 || jm.width == 0 || jm.height == 0 {
        return addr;
    }
    let (ew, eh) = (jm.width as i64, jm.height as i64);
    let margin_x = params.boundary_fraction * jm.width as f32;
    let margin_y = params.boundary_fraction * jm.height as f32;
    // Continuation weight at an exemplar address, tapered towards the edges.
    let taper = |d: i64, margin: f32| {
        if margin > 0.0 {
            (d as f32 / margin).min(1.0)
        } else {
            1.0
        }
    };
    let continuation_at = |a: [i64; 2]| {
        let fx = taper(a[0].min(ew - 1 - a[0]), margin_x);
        let fy = taper(a[1].min(eh - 1 - a[1]), margin_y);
        params.continuation * fx.min(fy)
    };
    let inside = |a: [i64; 2]| a[0] >= 0 && a[0] < ew && a[1] >= 0 && a[1] < eh;

    let mut done = vec![false; n];
    let mut prev: Option<[u32; 2]> = None;
    let mut options: Vec<(f32, [i64; 2])> = Vec::with_capacity(jm.k as usize + 1);
    for p in gilbert_curve(width, height) {
        let pi = p[1] as usize * width as usize + p[0] as usize;
        let (px, py) = (p[0] as i64, p[1] as i64);
        let mut sources = [[0i64; 2]; 4];
        let mut count = 0;
        for (dx, dy) in [(-1i64, 0i64), (1, 0), (0, -1), (0, 1)] {
            let (qx, qy) = (px + dx, py + dy);
            if qx >= 0
                && qx < width as i64
                && qy >= 0
                && qy < height as i64
                && done[qy as usize * width as usize + qx as usize]
            {
                sources[count] = [qx, qy];
                count += 1;
            }
        }
        if count == 0
            && let Some(q) = prev
        {
            sources[0] = [q[0] as i64, q[1] as i64];
            count = 1;
        }
        let new = if count == 0 {
            // First pixel: anywhere not tapered, if there is such a place.
            let pick = |stream: u64, size: i64, margin: f32| {
                let lo = (margin.ceil() as i64).min((size - 1) / 2);
                let span = size - 2 * lo;
                let u = counter_unit(seed, stream, pi as u64);
                lo + ((u * span as f32) as i64).min(span - 1)
            };
            [
                pick(DRAW_START_X, ew, margin_x),
                pick(DRAW_START_Y, eh, margin_y),
            ]
        } else {
            // The neighbours whose suggestions are considered: one at random (§4.2.1), or all
            // of them (§4.2.5).
            let chosen = if params.combine_neighbours {
                0..count
            } else {
                let u = counter_unit(seed, DRAW_SOURCE, pi as u64);
                let i = ((u * count as f32) as usize).min(count - 1);
                i..i + 1
            };
            options.clear();
            let mut fallback = None;
            for s in &sources[chosen] {
                let si = s[1] as usize * width as usize + s[0] as usize;
                let a = [addr[si][0] as i64, addr[si][1] as i64];
                let off = [px - s[0], py - s[1]];
                let cont = [a[0] + off[0], a[1] + off[1]];
                fallback.get_or_insert(cont);
                if inside(cont) {
                    options.push((continuation_at(a), cont));
                }
                for j in jm.jumps_at(a[0] as u32, a[1] as u32) {
                    let t = [j.x as i64 + off[0], j.y as i64 + off[1]];
                    if inside(t) {
                        options.push((j.weight, t));
                    }
                }
            }
            let total: f32 = options.iter().map(|o| o.0).sum();
            if total > 0.0 {
                let mut r = counter_unit(seed, DRAW_CHOICE, pi as u64) * total;
                let mut pick = options[options.len() - 1].1;
                for &(wgt, t) in &options {
                    if r < wgt {
                        pick = t;
                        break;
                    }
                    r -= wgt;
                }
                pick
            } else if let Some(&(_, t)) = options.first() {
                t
            } else {
                let c = fallback.expect("at least one source");
                [c[0].clamp(0, ew - 1), c[1].clamp(0, eh - 1)]
            }
        };
        addr[pi] = [new[0] as u16, new[1] as u16];
        done[pi] = true;
        prev = Some(p);
    }
    addr
}

/// The synthesize node: `params.width × params.height` exemplar addresses from the jump map,
/// drawn with `params.seed`.
pub fn node(jm: JumpMapRef, params: &Synth2dParams) -> Vec<[u16; 2]> {
    synthesize_2d(jm, params.width, params.height, params, params.seed)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::assert_validation;

    #[test]
    fn gilbert_visits_every_pixel_once_with_local_steps() {
        for (w, h) in [
            (1, 1),
            (1, 7),
            (7, 1),
            (2, 2),
            (8, 8),
            (5, 3),
            (3, 5),
            (17, 9),
            (64, 62),
            (31, 100),
        ] {
            let c = gilbert_curve(w, h);
            assert_eq!(c.len(), (w * h) as usize);
            let mut seen = vec![false; (w * h) as usize];
            for p in &c {
                assert!(p[0] < w && p[1] < h);
                let i = (p[1] * w + p[0]) as usize;
                assert!(!seen[i], "{w}x{h}: {p:?} twice");
                seen[i] = true;
            }
            let mut diagonal = 0;
            for s in c.windows(2) {
                let dx = (s[0][0] as i64 - s[1][0] as i64).abs();
                let dy = (s[0][1] as i64 - s[1][1] as i64).abs();
                assert!(dx <= 1 && dy <= 1, "{w}x{h}: jump {s:?}");
                if dx + dy == 2 {
                    diagonal += 1;
                }
            }
            assert!(
                diagonal <= 2 + (w.max(h) / 16) as usize,
                "{w}x{h}: {diagonal} diagonal steps"
            );
        }
        assert!(gilbert_curve(0, 5).is_empty());
        // Powers of two give the classic Hilbert curve: no diagonal steps at all.
        let c = gilbert_curve(16, 16);
        assert!(
            c.windows(2)
                .all(|s| s[0][0].abs_diff(s[1][0]) + s[0][1].abs_diff(s[1][1]) == 1)
        );
    }

    #[test]
    fn params_validate_names_the_field() {
        assert_validation!(Synth2dParams {
            boundary_fraction: 0.7 => "synth2d: boundary_fraction must be in 0..=0.5, got 0.7",
            continuation: -1.0 => "synth2d: continuation must be in 0..=1e9, got -1",
        });
    }
}

//! Reading a geometry image's synthesized relief in the sample's frame, along the surface,
//! for the surface-space score of [`super::geometry`].
//!
//! The grid-space score compares the relief image's `p × p` grid patches with the sample's.
//! But synthesis lays the texture out per texel: with the surface metric a tap `s` of the
//! template (sample texels) is read `A⁻¹ s` grid steps away, the scale `R` varies per texel
//! (two scales mixed by probability) and the field turns the sample. In the grid the relief is
//! squeezed and turned on purpose, so grid patches say little about how it looks on the
//! surface.
//!
//! Here each scored patch centre `c` (a level-0 grid texel) has a linear map `M_c` from grid
//! offsets to offsets in the sample's own texels (for synthesis:
//! [`crate::stages::synthesize::geometry_texture::sample_frame_maps`]). The patch's tap
//! `(u, v)`, `u` and `v` in `−p/2..=p/2`, is read at grid position `c + M_c⁻¹ (u, v)`,
//! interpolated bilinearly, so the patch comes out in the sample's frame at the sample's scale
//! and is matched against the sample's own patches by [`patch_score_resampled`]. Patches with
//! a tap outside the square (across a cut) are skipped and counted. The gradient energy reads
//! each texel's neighbour one sample texel away, `c + M_c⁻¹ e_x` and `c + M_c⁻¹ e_y`. For
//! `largest_offset`, each patch is placed at its centre's position in the sample's frame,
//! `M` integrated along the grid (trapezoids along row 0, then down each column): a verbatim
//! copy laid out by a map that is the Jacobian of a flattening has one offset. Synthesis's `M`
//! need not be such a Jacobian (the metric's square root has curl), so there a verbatim copy
//! drifts across neighbouring offsets and `largest_offset` reads lower than in the grid.
//!
//! With `M_c` the identity everywhere every number equals the grid score's.

use crate::image::patch_score::{
    GradientEnergy, PatchScore, ResampledPatches, ScoreError, ScoreParams, patch_score_resampled,
    query_subset,
};
use crate::image::{Image, ImageView};

/// The surface-space measures and how many patches could be read.
#[derive(Clone, Debug)]
pub struct FrameScore {
    pub score: PatchScore,
    /// Patch centres (level-0 texels) whose patch stays inside the square: the pool the
    /// queries are drawn from.
    pub readable: usize,
    /// Patch centres skipped: a tap leaves the square (crosses a cut) or the map is singular.
    pub skipped: usize,
}

/// `M⁻¹` of a row-major 2×2 map, `None` when singular or not finite.
fn inverse(m: &[f32; 4]) -> Option<[f64; 4]> {
    let m = m.map(|v| v as f64);
    let det = m[0] * m[3] - m[1] * m[2];
    (det.is_finite() && det.abs() > 1e-12 && m.iter().all(|v| v.is_finite()))
        .then(|| [m[3] / det, -m[1] / det, -m[2] / det, m[0] / det])
}

/// The grid `image`'s RGB at fractional `(x, y)` (columns, rows), bilinear between the four
/// texels around it (a weight of 0 reads nothing, so whole positions read one texel exactly).
fn bilinear(image: ImageView<'_>, x: f64, y: f64) -> [f32; 3] {
    let (w, h) = (image.width as i64, image.height as i64);
    bilinear_by(x, y, |xi, yi| {
        let px = image.pixels[(yi.clamp(0, h - 1) * w + xi.clamp(0, w - 1)) as usize];
        [px[0], px[1], px[2]]
    })
}

/// The value at fractional `(x, y)`, bilinear between the four whole points around it, each
/// read by `at(x, y)` (a point of weight 0 is not read).
fn bilinear_by(x: f64, y: f64, at: impl Fn(i64, i64) -> [f32; 3]) -> [f32; 3] {
    let (x0, y0) = (x.floor(), y.floor());
    let (fx, fy) = ((x - x0) as f32, (y - y0) as f32);
    let (x0, y0) = (x0 as i64, y0 as i64);
    let mut out = [0.0f32; 3];
    for (dx, dy, wt) in [
        (0, 0, (1.0 - fx) * (1.0 - fy)),
        (1, 0, fx * (1.0 - fy)),
        (0, 1, (1.0 - fx) * fy),
        (1, 1, fx * fy),
    ] {
        if wt > 0.0 {
            let px = at(x0 + dx, y0 + dy);
            for c in 0..3 {
                out[c] += wt * px[c];
            }
        }
    }
    out
}

/// Windows of `side × side` sample texels around `count` centres spread over the grid, each
/// read through its centre's map (taps outside the square black), side by side with a
/// 2-texel gap: what the surface row scores, large enough to look at (`TEXSYN_SCORE_DUMP`).
pub fn windows_along_maps(grid: ImageView<'_>, maps: &[[f32; 4]], side: u32, count: u32) -> Image {
    let (w, h) = (grid.width as usize, grid.height as usize);
    let stride = side + 2;
    let mut out = Image::new(stride * count, side);
    let r = side as f64 / 2.0;
    for k in 0..count {
        // Centres on the diagonal band, clear of the square's sides.
        let t = (k as f64 + 1.0) / (count as f64 + 1.0);
        let (cx, cy) = (
            (t * (w - 1) as f64).round() as usize,
            ((0.5 + 0.3 * (t - 0.5)) * (h - 1) as f64).round() as usize,
        );
        let Some(m) = maps.get(cy * w + cx).and_then(inverse) else {
            continue;
        };
        for v in 0..side {
            for u in 0..side {
                let (a, b) = (u as f64 - r, v as f64 - r);
                let (x, y) = (
                    cx as f64 + m[0] * a + m[1] * b,
                    cy as f64 + m[2] * a + m[3] * b,
                );
                if x >= 0.0 && y >= 0.0 && x <= (w - 1) as f64 && y <= (h - 1) as f64 {
                    let g = bilinear(grid, x, y);
                    out.pixels[(v * stride * count + k * stride + u) as usize] =
                        [g[0], g[1], g[2], 1.0];
                }
            }
        }
    }
    out
}

/// How a perfect synthesis would copy the sample's texels into the grid, for
/// [`floor_along_maps`]: as synthesis copies them (`subtexel` off: the nearest texel) or
/// bilinearly (`subtexel` on).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LayoutCopy {
    Nearest,
    Bilinear,
}

/// The patch centres [`score_along_maps`] scores: the pool (centres whose patch lies inside
/// the square and whose map has an inverse), the seeded picks into it, whether they are a
/// subset, and each texel's inverse map.
struct Pool {
    pool: Vec<usize>,
    picked: Vec<usize>,
    subsampled: bool,
    inv: Vec<Option<[f64; 4]>>,
}

fn pool(w: usize, h: usize, maps: &[[f32; 4]], p: &ScoreParams) -> Result<Pool, ScoreError> {
    let r = (p.patch / 2) as f64;
    let inv: Vec<Option<[f64; 4]>> = maps.iter().map(inverse).collect();
    let inside =
        |x: f64, y: f64| x >= 0.0 && y >= 0.0 && x <= (w - 1) as f64 && y <= (h - 1) as f64;
    // The patch's four corners (and so, the map being linear, all its taps) lie in the square.
    let pool: Vec<usize> = (0..w * h)
        .filter(|&k| {
            inv[k].is_some_and(|m| {
                [(-r, -r), (r, -r), (-r, r), (r, r)].iter().all(|&(u, v)| {
                    let (x, y) = (
                        (k % w) as f64 + m[0] * u + m[1] * v,
                        (k / w) as f64 + m[2] * u + m[3] * v,
                    );
                    inside(x, y)
                })
            })
        })
        .collect();
    if pool.is_empty() {
        return Err(ScoreError::NoPatchInMask { patch: p.patch });
    }
    let (picked, subsampled) = query_subset(pool.len(), p);
    Ok(Pool {
        pool,
        picked,
        subsampled,
        inv,
    })
}

/// Counter stream of the floor's sample positions.
const STREAM_FLOOR: u64 = 0x7366_0001;

/// The floor of [`score_along_maps`] for these maps: the same patches scored on a
/// verbatim layout instead of `grid`. Around each scored centre `c` the grid holds the
/// sample laid out under `c`'s map, grid point `c + g` showing sample point `x_c + M_c g`,
/// and the patch is read back through `M_c⁻¹` bilinearly, as the row reads the output.
///
/// How the layout is copied follows synthesis: it copies texels of a variant, the sample
/// turned and scaled by the variant's frame `F_c` (`frames`, per texel, grid-free: variant
/// texels to sample texels; empty for the sample's own texels). With [`LayoutCopy::Nearest`]
/// grid point `g` takes the variant texel nearest to `F_c⁻¹ (x_c + M_c g)`, read from the
/// sample at that texel's position (bilinearly, as the variants are made); with
/// [`LayoutCopy::Bilinear`] the sample at `x_c + M_c g` itself. `x_c` is a seeded position,
/// between variant texels as a layout's positions are, unless `F_c⁻¹ M_c` has whole steps
/// (then every grid point sits on a texel, as synthesis without the surface metric copies).
///
/// With `M_c = F_c` whole (the identity) that is an exact crop (ratio 0); a turned or scaled
/// frame still costs its resampling. A stretch resamples twice, and the floor
/// says what that costs a flawless layout; it is no lower bound: a blurrier result can score
/// a lower ratio (with a lower gradient ratio). The ratio and gradient ratio are the floor's
/// meaningful numbers; coverage and largest offset describe scattered crops. The gradient is
/// taken at the scored centres only (the row's own over every texel with a map). Patches whose
/// layout would reach past the sample's border are left out rather than clamped.
pub fn floor_along_maps(
    width: u32,
    height: u32,
    maps: &[[f32; 4]],
    frames: &[[f32; 4]],
    exemplar: ImageView<'_>,
    copy: LayoutCopy,
    p: &ScoreParams,
) -> Result<PatchScore, ScoreError> {
    let (w, h) = (width as usize, height as usize);
    for (which, len) in [
        ("maps of the output", maps.len()),
        ("frames of the output", frames.len()),
    ] {
        if len != w * h && !(which.starts_with("frames") && len == 0) {
            return Err(ScoreError::PixelCount {
                which,
                width,
                height,
                pixels: len,
            });
        }
    }
    crate::image::patch_score::validate_exemplar(exemplar, p)?;
    let Pool {
        pool,
        picked,
        subsampled,
        inv,
    } = pool(w, h, maps, p)?;
    let (ew, eh) = (exemplar.width as i64, exemplar.height as i64);
    let r = (p.patch / 2) as f64;
    let side = p.patch as usize;
    let apply = |m: &[f64; 4], v: (f64, f64)| (m[0] * v.0 + m[1] * v.1, m[2] * v.0 + m[3] * v.1);
    let inverse64 = |m: &[f64; 4]| inverse(&m.map(|v| v as f32));
    const IDENTITY: [f64; 4] = [1.0, 0.0, 0.0, 1.0];
    // One centre's layout: its map `m` (grid to sample), frame `f` and `f⁻¹`, and position.
    struct Layout {
        m: [f64; 4],
        f: [f64; 4],
        f_inv: [f64; 4],
        x0: (f64, f64),
    }
    let layout = |l: &Layout, gx: f64, gy: f64| -> [f32; 3] {
        let (dx, dy) = apply(&l.m, (gx, gy));
        let (x, y) = (l.x0.0 + dx, l.x0.1 + dy);
        match copy {
            LayoutCopy::Bilinear => bilinear(exemplar, x, y),
            LayoutCopy::Nearest if l.f == IDENTITY => {
                let xi = ((x + 0.5).floor() as i64).clamp(0, ew - 1);
                let yi = ((y + 0.5).floor() as i64).clamp(0, eh - 1);
                let px = exemplar.pixels[(yi * ew + xi) as usize];
                [px[0], px[1], px[2]]
            }
            LayoutCopy::Nearest => {
                let (zx, zy) = apply(&l.f_inv, (x, y));
                let z = ((zx + 0.5).floor(), (zy + 0.5).floor());
                let (sx, sy) = apply(&l.f, z);
                bilinear(exemplar, sx, sy)
            }
        }
    };
    // The grid read at fractional offset `d` (grid steps) from the centre, bilinear between
    // grid points.
    let read = |l: &Layout, d: (f64, f64)| -> [f32; 3] {
        bilinear_by(d.0, d.1, |gx, gy| layout(l, gx as f64, gy as f64))
    };
    let mut patches = ResampledPatches {
        patch: p.patch,
        rgb: Vec::with_capacity(picked.len() * side * side),
        at: Vec::with_capacity(picked.len()),
    };
    let mut g = GradientEnergy::default();
    for &i in &picked {
        let k = pool[i];
        let m_inv = inv[k].expect("pooled centres have an inverse");
        let m = maps[k].map(|v| v as f64);
        let (f, f_inv) = match frames.get(k).map(|f| f.map(|v| v as f64)) {
            Some(f) => match inverse64(&f) {
                Some(f_inv) => (f, f_inv),
                None => continue,
            },
            None => (IDENTITY, IDENTITY),
        };
        // How far the layout reaches from its position along x and along y: the patch, a
        // grid step of interpolation either way, half a variant texel of rounding and a texel
        // of the sample's bilinear read.
        let row = |a: &[f64; 4], i: usize| a[2 * i].abs() + a[2 * i + 1].abs();
        let reach = [0, 1].map(|i| r + row(&m, i) + 0.5 * row(&f, i) + 1.0);
        if 2.0 * reach[0] + 1.0 > ew as f64 || 2.0 * reach[1] + 1.0 > eh as f64 {
            continue;
        }
        // In variant texels, the layout's steps are `F⁻¹ M`.
        let steps = [
            f_inv[0] * m[0] + f_inv[1] * m[2],
            f_inv[0] * m[1] + f_inv[1] * m[3],
            f_inv[2] * m[0] + f_inv[3] * m[2],
            f_inv[2] * m[1] + f_inv[3] * m[3],
        ];
        let whole = steps.iter().all(|v| (v - v.round()).abs() < 1e-4);
        let pick = |stream_index: u64, len: i64, reach: f64| {
            let u = crate::random::counter_unit(p.seed, STREAM_FLOOR, stream_index) as f64;
            reach + u * (len as f64 - 1.0 - 2.0 * reach)
        };
        let mut x0 = (
            pick(2 * k as u64, ew, reach[0]),
            pick(2 * k as u64 + 1, eh, reach[1]),
        );
        if whole {
            // Every grid point on a variant texel: the position on one too.
            let (zx, zy) = apply(&f_inv, x0);
            x0 = apply(&f, ((zx + 0.5).floor(), (zy + 0.5).floor()));
        }
        let l = Layout { m, f, f_inv, x0 };
        for v in 0..side {
            for u in 0..side {
                patches
                    .rgb
                    .push(read(&l, apply(&m_inv, (u as f64 - r, v as f64 - r))));
            }
        }
        let round = |t: f64| (t + 0.5).floor() as i64;
        patches
            .at
            .push((round(x0.0) - r as i64, round(x0.1) - r as i64));
        let here = read(&l, (0.0, 0.0));
        g.add_x(&read(&l, (m_inv[0], m_inv[2])), &here);
        g.add_y(&read(&l, (m_inv[1], m_inv[3])), &here);
    }
    if patches.at.is_empty() {
        return Err(ScoreError::FloorReach {
            width: exemplar.width,
            height: exemplar.height,
        });
    }
    patch_score_resampled(&patches, subsampled, g.value(), exemplar, p)
}

/// Scores the grid image `grid` read along `maps` (one per texel, row-major; see the module
/// docs) against `exemplar` with `p`'s patches, query count and seed.
pub fn score_along_maps(
    grid: ImageView<'_>,
    maps: &[[f32; 4]],
    exemplar: ImageView<'_>,
    p: &ScoreParams,
) -> Result<FrameScore, ScoreError> {
    let (w, h) = (grid.width as usize, grid.height as usize);
    if maps.len() != w * h || grid.pixels.len() != w * h {
        return Err(ScoreError::PixelCount {
            which: "maps of the output",
            width: grid.width,
            height: grid.height,
            pixels: maps.len(),
        });
    }
    let r = (p.patch / 2) as f64;
    let inside =
        |x: f64, y: f64| x >= 0.0 && y >= 0.0 && x <= (w - 1) as f64 && y <= (h - 1) as f64;
    let at = |k: usize, m: &[f64; 4], u: f64, v: f64| {
        let (x, y) = ((k % w) as f64, (k / w) as f64);
        (x + m[0] * u + m[1] * v, y + m[2] * u + m[3] * v)
    };
    let Pool {
        pool,
        picked,
        subsampled,
        inv,
    } = pool(w, h, maps, p)?;

    // Each centre's position in the sample's frame: M integrated along row 0, then down.
    let mut pos = vec![(0.0f64, 0.0f64); w * h];
    let m64 = |k: usize| maps[k].map(|v| v as f64);
    for y in 0..h {
        for x in 0..w {
            let k = y * w + x;
            pos[k] = if x == 0 && y == 0 {
                (0.0, 0.0)
            } else if y == 0 {
                let (a, b) = (m64(k - 1), m64(k));
                let p0 = pos[k - 1];
                (p0.0 + 0.5 * (a[0] + b[0]), p0.1 + 0.5 * (a[2] + b[2]))
            } else {
                let (a, b) = (m64(k - w), m64(k));
                let p0 = pos[k - w];
                (p0.0 + 0.5 * (a[1] + b[1]), p0.1 + 0.5 * (a[3] + b[3]))
            };
        }
    }

    let side = p.patch as usize;
    let mut patches = ResampledPatches {
        patch: p.patch,
        rgb: Vec::with_capacity(picked.len() * side * side),
        at: Vec::with_capacity(picked.len()),
    };
    for &i in &picked {
        let k = pool[i];
        let m = inv[k].expect("pooled centres have an inverse");
        for v in 0..side {
            for u in 0..side {
                let (x, y) = at(k, &m, u as f64 - r, v as f64 - r);
                patches.rgb.push(bilinear(grid, x, y));
            }
        }
        let round = |t: f64| (t + 0.5).floor() as i64;
        patches
            .at
            .push((round(pos[k].0) - r as i64, round(pos[k].1) - r as i64));
    }

    // Gradient energy: each texel against its neighbour one sample texel along x and y.
    let mut g = GradientEnergy::default();
    for k in 0..w * h {
        let Some(m) = inv[k] else { continue };
        let here = bilinear(grid, (k % w) as f64, (k / w) as f64);
        let (x, y) = at(k, &m, 1.0, 0.0);
        if inside(x, y) {
            g.add_x(&bilinear(grid, x, y), &here);
        }
        let (x, y) = at(k, &m, 0.0, 1.0);
        if inside(x, y) {
            g.add_y(&bilinear(grid, x, y), &here);
        }
    }

    let score = patch_score_resampled(&patches, subsampled, g.value(), exemplar, p)?;
    Ok(FrameScore {
        score,
        readable: pool.len(),
        skipped: w * h - pool.len(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::image::Image;
    use crate::image::patch_score::patch_score;
    use crate::random::counter_unit;
    use texsyn_core::math::PureMath;

    /// A smooth random grey texture: value noise on 7- and 3-texel lattices, bilinear
    /// with a smoothstep (features of a few texels, so that resampling it is nearly exact).
    fn sample(side: u32, seed: u64) -> Image {
        let noise = |cell: u32, stream: u64, x: f64, y: f64| {
            let (cx, cy) = ((x / cell as f64).floor(), (y / cell as f64).floor());
            let (fx, fy) = (x / cell as f64 - cx, y / cell as f64 - cy);
            let s = |t: f64| t * t * (3.0 - 2.0 * t);
            let at = |i: f64, j: f64| {
                counter_unit(
                    seed,
                    stream,
                    ((i as i64 + 1000) * 4096 + j as i64 + 1000) as u64,
                ) as f64
            };
            let (sx, sy) = (s(fx), s(fy));
            let top = at(cx, cy) * (1.0 - sx) + at(cx + 1.0, cy) * sx;
            let bottom = at(cx, cy + 1.0) * (1.0 - sx) + at(cx + 1.0, cy + 1.0) * sx;
            top * (1.0 - sy) + bottom * sy
        };
        Image::from_fn(side, side, |x, y| {
            let (x, y) = (x as f64, y as f64);
            let g = (0.5 * noise(7, 1, x, y) + 0.5 * noise(3, 2, x, y)) as f32;
            [g, g, g, 1.0]
        })
    }

    /// The planted warp: grid point `(x, y)` shows sample point `φ(x, y)`, a non-uniform,
    /// sheared, anisotropic map (grid steps cover 0.33 to 0.68 sample texels along x, 0.3
    /// along y), and its Jacobian per grid point.
    fn phi(x: f64, y: f64) -> (f64, f64) {
        (8.0 + 0.33 * x + 0.0014 * x * x, 8.0 + 0.3 * y + 0.12 * x)
    }

    fn jacobian(x: f64, _y: f64) -> [f32; 4] {
        [(0.33 + 0.0028 * x) as f32, 0.0, 0.12, 0.3]
    }

    /// The sample warped into an `n × n` grid by [`phi`] (bilinear), and the grid's maps.
    fn warped(ex: &Image, n: u32) -> (Image, Vec<[f32; 4]>) {
        let grid = Image::from_fn(n, n, |x, y| {
            let (u, v) = phi(x as f64, y as f64);
            let g = bilinear(ex.view(), u, v);
            [g[0], g[1], g[2], 1.0]
        });
        let maps = (0..n * n)
            .map(|k| jacobian((k % n) as f64, (k / n) as f64))
            .collect();
        (grid, maps)
    }

    fn params() -> ScoreParams {
        ScoreParams {
            patch: 7,
            max_queries: 3000,
            seed: 0,
        }
    }

    #[test]
    fn a_planted_warp_read_along_its_map_is_a_copy_of_the_sample() {
        let ex = sample(128, 7);
        let (grid, maps) = warped(&ex, 129);
        let p = params();
        let frame = score_along_maps(grid.view(), &maps, ex.view(), &p).unwrap();
        let grid_score = patch_score(grid.view(), ex.view(), &p).unwrap();
        let s = &frame.score;
        eprintln!(
            "surface {s:?} readable {} skipped {}",
            frame.readable, frame.skipped
        );
        eprintln!("grid {grid_score:?}");
        // The best a resampled copy can do: the same centres' patches read straight from the
        // sample at φ(c) + (u, v). Not 0, because φ(c) falls between the sample's texels and
        // the nearest sample patch sits at a whole texel.
        let (picked, _) = query_subset(129 * 129, &p);
        let mut ideal = ResampledPatches {
            patch: 7,
            ..Default::default()
        };
        for &k in &picked {
            let (u0, v0) = phi((k % 129) as f64, (k / 129) as f64);
            for v in -3..=3 {
                for u in -3..=3 {
                    ideal
                        .rgb
                        .push(bilinear(ex.view(), u0 + u as f64, v0 + v as f64));
                }
            }
            ideal.at.push((0, 0));
        }
        let ideal = patch_score_resampled(&ideal, true, 1.0, ex.view(), &p).unwrap();
        eprintln!("ideal {ideal:?}");
        // Read along the map, every patch is that copy up to the grid's interpolation, and
        // they sit at the one offset the integrated map predicts.
        assert!(
            s.ratio < ideal.ratio + 0.05,
            "surface ratio {} against {}",
            s.ratio,
            ideal.ratio
        );
        assert!(
            s.largest_offset > 0.5,
            "largest offset {}",
            s.largest_offset
        );
        assert!(
            (s.gradient_ratio - 1.0).abs() < 0.25,
            "{}",
            s.gradient_ratio
        );
        // In the grid the same relief is stretched 1.5 to 3 times: far from any sample patch.
        assert!(
            grid_score.ratio > 1.5 * s.ratio,
            "grid {}",
            grid_score.ratio
        );
        assert!(grid_score.gradient_ratio < 0.5 * s.gradient_ratio);
        // Patches near the far corner, where the map reads beyond the grid, are skipped.
        assert!(frame.skipped > 0 && frame.readable > 3000);
        // The map's inverse is what is read along: the transposed map is no copy.
        let transposed: Vec<[f32; 4]> = maps.iter().map(|m| [m[0], m[2], m[1], m[3]]).collect();
        let t = score_along_maps(grid.view(), &transposed, ex.view(), &p).unwrap();
        assert!(
            t.score.ratio > 1.5 * s.ratio,
            "transposed {}",
            t.score.ratio
        );
    }

    #[test]
    fn windows_read_the_planted_warp_back_into_the_sample() {
        let ex = sample(128, 7);
        let (grid, maps) = warped(&ex, 129);
        let win = windows_along_maps(grid.view(), &maps, 16, 3);
        assert_eq!((win.width, win.height), (54, 16));
        // The middle window's centre is the grid's texel (64, 64), which shows φ(64, 64).
        let (u, v) = phi(64.0, 64.0);
        let want = bilinear(ex.view(), u, v)[0];
        let got = win.pixels[(8 * 54 + 18 + 8) as usize][0];
        assert!((got - want).abs() < 0.02, "{got} against {want}");
    }

    #[test]
    fn a_shuffled_grid_is_far_from_the_sample_in_surface_space_too() {
        let ex = sample(128, 7);
        let (grid, maps) = warped(&ex, 129);
        let mut shuffled = grid.clone();
        // Fisher–Yates with the crate's counter hash.
        let n = shuffled.pixels.len();
        for i in (1..n).rev() {
            let j = (crate::random::counter_hash(3, 9, i as u64) % (i as u64 + 1)) as usize;
            shuffled.pixels.swap(i, j);
        }
        let s = score_along_maps(shuffled.view(), &maps, ex.view(), &params())
            .unwrap()
            .score;
        // Bilinear taps between shuffled texels average some of the noise away, but the
        // patches stay far from any sample patch and much rougher.
        assert!(s.ratio > 1.3, "shuffled surface ratio {}", s.ratio);
        assert!(s.gradient_ratio > 2.0, "{}", s.gradient_ratio);
        assert!(s.largest_offset < 0.05, "{}", s.largest_offset);
    }

    #[test]
    fn identity_maps_give_the_grid_score() {
        let ex = sample(96, 3);
        let out = sample(80, 11);
        let maps = vec![[1.0f32, 0.0, 0.0, 1.0]; 80 * 80];
        for max_queries in [1000, 100_000] {
            let p = ScoreParams {
                max_queries,
                ..params()
            };
            let a = score_along_maps(out.view(), &maps, ex.view(), &p).unwrap();
            let b = patch_score(out.view(), ex.view(), &p).unwrap();
            assert_eq!(a.readable, 74 * 74);
            assert_eq!(
                format!("{:?}", a.score),
                format!("{b:?}"),
                "max_queries {max_queries}"
            );
        }
    }

    /// `R(θ) diag(a, 1/a) R(θ)ᵀ` after a turn by `φ`: a stretch and a rotation, row-major.
    fn stretched(a: f64, theta: f64, phi: f64) -> [f32; 4] {
        let (s, c) = (theta.sin_pure(), theta.cos_pure());
        let b = 1.0 / a;
        let sym = [
            a * c * c + b * s * s,
            (a - b) * c * s,
            (a - b) * c * s,
            a * s * s + b * c * c,
        ];
        let (s, c) = (phi.sin_pure(), phi.cos_pure());
        [
            c * sym[0] - s * sym[2],
            c * sym[1] - s * sym[3],
            s * sym[0] + c * sym[2],
            s * sym[1] + c * sym[3],
        ]
        .map(|v| v as f32)
    }

    /// The sample laid out verbatim in an `n × n` grid under one constant map `m` (grid
    /// point `c` shows sample point `x0 + m (c − centre)`, the nearest texel).
    fn verbatim_layout(ex: &Image, n: u32, m: [f32; 4]) -> Image {
        let m = m.map(|v| v as f64);
        let (x0, y0) = (ex.width as f64 / 2.0, ex.height as f64 / 2.0);
        let centre = (n / 2) as f64;
        Image::from_fn(n, n, |x, y| {
            let (gx, gy) = (x as f64 - centre, y as f64 - centre);
            let sx =
                ((x0 + m[0] * gx + m[1] * gy + 0.5).floor() as i64).clamp(0, ex.width as i64 - 1);
            let sy =
                ((y0 + m[2] * gx + m[3] * gy + 0.5).floor() as i64).clamp(0, ex.height as i64 - 1);
            ex.pixels[(sy * ex.width as i64 + sx) as usize]
        })
    }

    /// The floor of one constant map `m` over an `n × n` grid, and the row's score of a whole
    /// grid laid out verbatim under `m`; asserts that they agree.
    fn floor_and_whole_layout(ex: &Image, n: u32, m: [f32; 4]) -> (PatchScore, PatchScore) {
        let p = params();
        let maps = vec![m; (n * n) as usize];
        let floor = floor_along_maps(n, n, &maps, &[], ex.view(), LayoutCopy::Nearest, &p).unwrap();
        let grid = verbatim_layout(ex, n, m);
        let whole = score_along_maps(grid.view(), &maps, ex.view(), &p)
            .unwrap()
            .score;
        eprintln!("{m:?}: floor {floor:?}, whole layout {whole:?}");
        assert!(
            (floor.ratio - whole.ratio).abs() < 0.1 * whole.ratio.max(0.1),
            "{m:?}: floor {} against a whole layout's {}",
            floor.ratio,
            whole.ratio
        );
        assert!(
            (floor.gradient_ratio - whole.gradient_ratio).abs() < 0.1,
            "{m:?}: floor gradient {} against {}",
            floor.gradient_ratio,
            whole.gradient_ratio
        );
        (floor, whole)
    }

    #[test]
    fn the_floor_of_identity_maps_is_an_exact_crop() {
        let ex = sample(96, 3);
        let maps = vec![[1.0f32, 0.0, 0.0, 1.0]; 80 * 80];
        for copy in [LayoutCopy::Nearest, LayoutCopy::Bilinear] {
            let f = floor_along_maps(80, 80, &maps, &[], ex.view(), copy, &params()).unwrap();
            assert!(f.ratio < 1e-6, "{copy:?}: {}", f.ratio);
            assert!(
                (f.gradient_ratio - 1.0).abs() < 0.15,
                "{copy:?}: {}",
                f.gradient_ratio
            );
        }
    }

    #[test]
    fn the_floor_is_what_a_verbatim_layout_scores_under_the_same_map() {
        // Per patch, the floor lays the sample out around that patch alone; a whole grid laid
        // out verbatim under the same constant map and scored along it must agree, for
        // stretches, shears and turns, and both must cost something once the map stretches.
        let ex = sample(160, 5);
        let n = 97;
        let p = params();
        let identity = floor_along_maps(
            n,
            n,
            &vec![[1.0, 0.0, 0.0, 1.0]; 97 * 97],
            &[],
            ex.view(),
            LayoutCopy::Nearest,
            &p,
        )
        .unwrap()
        .ratio;
        for m in [
            stretched(1.3, 0.0, 0.0),
            stretched(1.316, std::f64::consts::FRAC_PI_4, 0.0),
            stretched(1.2, 0.3, 0.5),
        ] {
            let (floor, _) = floor_and_whole_layout(&ex, n, m);
            let maps = vec![m; (n * n) as usize];
            assert!(floor.ratio > identity + 0.05, "{m:?}: {}", floor.ratio);
            // A bilinear copy is smoother than the nearest texel's, so it scores lower.
            let bilinear =
                floor_along_maps(n, n, &maps, &[], ex.view(), LayoutCopy::Bilinear, &p).unwrap();
            assert!(
                bilinear.ratio < floor.ratio,
                "{m:?}: bilinear {} against {}",
                bilinear.ratio,
                floor.ratio
            );
        }
    }

    #[test]
    fn the_floor_names_a_map_count_that_does_not_fit() {
        let ex = sample(64, 1);
        let e = floor_along_maps(
            40,
            40,
            &[[1.0, 0.0, 0.0, 1.0]; 10],
            &[],
            ex.view(),
            LayoutCopy::Nearest,
            &params(),
        )
        .unwrap_err();
        assert!(e.to_string().contains("maps of the output"), "{e}");
        // Maps so coarse that no patch's layout fits in the sample: said so, not clamped.
        let e = floor_along_maps(
            40,
            40,
            &[[40.0, 0.0, 0.0, 40.0]; 1600],
            &[],
            ex.view(),
            LayoutCopy::Nearest,
            &params(),
        )
        .unwrap_err();
        assert!(e.to_string().contains("verbatim layout"), "{e}");
    }

    /// Columns that alternate dark and light, each of its own contrast in each band of 8
    /// rows: a texture that a map and its inverse lay out very differently.
    fn stripes(side: u32) -> Image {
        Image::from_fn(side, side, |x, y| {
            let r = 0.3 + 0.7 * counter_unit(4, 4, ((y / 8) * side + x) as u64);
            let g = 0.5 + if x % 2 == 0 { 0.45 } else { -0.45 } * r;
            [g, g, g, 1.0]
        })
    }

    #[test]
    fn the_floor_lays_the_sample_out_under_the_map_not_its_inverse() {
        // Grid steps of 2 sample texels along x land every grid point of a row on the same
        // parity of stripe: read back, a patch has lost its alternation, far from every
        // sample patch (measured 5.75, and 5.68 for a whole layout). Laid out under the
        // inverse (steps of ½) it would read back exact.
        let (floor, _) = floor_and_whole_layout(&stripes(128), 97, [2.0, 0.0, 0.0, 0.5]);
        assert!(floor.ratio > 1.0, "floor {}", floor.ratio);
    }

    #[test]
    fn the_floor_copies_texels_of_the_turned_variant() {
        // Synthesis copies whole texels of the variant turned by the field: under a map that
        // is only that turn, the layout has no rounding jaggies, only the turn's resampling
        // (which costs the most here), so it scores below a layout rounded in the sample's
        // own texels (measured 0.480 against 0.526).
        let ex = sample(160, 5);
        let n = 97;
        let p = params();
        let turn = stretched(1.0, 0.0, 0.5);
        let maps = vec![turn; (n * n) as usize];
        let frames = maps.clone();
        let variant =
            floor_along_maps(n, n, &maps, &frames, ex.view(), LayoutCopy::Nearest, &p).unwrap();
        let own = floor_along_maps(n, n, &maps, &[], ex.view(), LayoutCopy::Nearest, &p).unwrap();
        eprintln!("turned: variant {} own {}", variant.ratio, own.ratio);
        assert!(
            variant.ratio < own.ratio - 0.02,
            "turned variant {} against the sample's texels {}",
            variant.ratio,
            own.ratio
        );
        // A bilinear copy takes no texels of either (the positions drawn differ a little).
        let a =
            floor_along_maps(n, n, &maps, &frames, ex.view(), LayoutCopy::Bilinear, &p).unwrap();
        let b = floor_along_maps(n, n, &maps, &[], ex.view(), LayoutCopy::Bilinear, &p).unwrap();
        assert!(
            (a.ratio - b.ratio).abs() < 0.02,
            "{} against {}",
            a.ratio,
            b.ratio
        );
        // Frames that do not fit the grid are named.
        let e = floor_along_maps(
            n,
            n,
            &maps,
            &frames[..5],
            ex.view(),
            LayoutCopy::Nearest,
            &p,
        )
        .unwrap_err();
        assert!(e.to_string().contains("frames of the output"), "{e}");
    }
}

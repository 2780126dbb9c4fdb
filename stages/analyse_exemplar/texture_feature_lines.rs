//! The exemplar's own feature lines — mortar of a brick wall, gaps of parquet, grain of wood —
//! and every texel's distance to them, for feature-to-feature texture optimization (Xu et al.,
//! "Feature-Aligned Shape Texturing", §5.2: "we extract the prominent features in the exemplar
//! as piecewise linear segments using a heuristic approach [Wu and Yu 2004], optionally
//! allowing user sketching. When more than one feature lines are detected, we select one as
//! the principal feature line"). The matching constraint of §5.2 compares a surface point's
//! geodesic distance to the shape's salient curves with an exemplar pixel's distance to the
//! nearest texture feature: that is [`TextureFeatures::distance`].
//!
//! Detection ([`detect_texture_features`]), a curvilinear-structure detector in the spirit of
//! Wu & Yu (2004), who leave the detector a heuristic:
//! 1. Luminance `Y = 0.2126 R + 0.7152 G + 0.0722 B` (Rec. 709 weights) of the values as
//!    decoded (sRGB-encoded: lines are judged by how they look, not by linear light).
//! 2. The Hessian of `Y` smoothed by a Gaussian of σ = `scale` texels, by sampled Gaussian
//!    derivative kernels (mirrored borders: exemplars are not assumed to tile). Its larger
//!    eigenvalue `λ₁` is large and positive across a dark line (a valley), its smaller one
//!    `λ₂` large and negative across a bright line (a ridge). Strength is `σ²·λ₁⁺` (dark),
//!    `σ²·(−λ₂)⁺` (bright) or the larger of the two (both); the σ² makes it a contrast, so
//!    one absolute floor ([`MIN_STRENGTH`]) can tell a flat exemplar from a textured one.
//! 3. Non-maximum suppression across the line: a texel stays if its strength is at least that
//!    at ±1 texel along its eigenvector (bilinearly interpolated). Ties keep both texels; the
//!    thinning of step 5 makes them one.
//! 4. Hysteresis (Canny): texels at or above `threshold × (strongest response)` seed lines,
//!    texels at or above half that extend them (8-connected). The ratio ½ is Canny's usual
//!    choice; it closes the gaps a single threshold leaves in faint stretches of mortar.
//! 5. Zhang–Suen thinning to a one-texel skeleton, then tracing as in
//!    [`crate::extract::crease_lines`]: texels are graph nodes joined to their 8 neighbours
//!    (a diagonal link is dropped when the two texels also meet through a common 4-neighbour,
//!    so a staircase is a chain, not a chain of triangles); lines run from an end or a
//!    junction (a node of other than two links) to the next; what is left are closed loops.
//!    Spurs (a free end reaching a junction in fewer than `max(3, 2·scale)` texels: a bump of
//!    the skeleton, not a line) are removed once and the skeleton traced again, so a mortar row
//!    is not cut at every bump. Lines are also cut at sharp corners (a turn of more than
//!    [`CORNER_DEG`]° between chords `max(3, 2·scale)` texels long): Wu & Yu's features are
//!    piecewise linear, and the corner of a brick is where one mortar line ends and the next
//!    begins. Lines shorter than `min_length` texels are dropped.
//!
//! A mask drawn by the user ([`features_from_mask`]) replaces steps 1–4: it is thinned and
//! traced the same way.
//!
//! The principal line. The paper does not say how it is chosen; the longest line (the paper's
//! choice of the first curve to orient in §4.1) fails on a brick wall, where junctions cut the
//! long mortar rows at every vertical joint and an irregular joint can come out longer than a
//! piece of row. Instead each line is straightened into piecewise-linear segments (Wu & Yu's
//! representation; Douglas–Peucker with a tolerance of [`SEGMENT_TOLERANCE`] texel), the
//! dominant direction is the segment direction shared by the most segment length within
//! ±[`DIRECTION_WINDOW_DEG`]° (then moved to the length-weighted mean direction of the segments
//! in its window), and the principal line is the line holding the most length of
//! segments in that direction (first in trace order on ties). On a brick wall the horizontal
//! rows hold most of the mortar's length, so a horizontal row wins. `principal_angle` is a
//! length-weighted PCA of the principal line's texels on those aligned segments only: a PCA
//! of all of a bent line's texels (a loop around a parquet board, an L of mortar) gives a
//! diagonal that no part of the line follows.
//!
//! Conventions: pixel coordinates with x right, y down and texel centres at integers (as
//! [`crate::image`]); `principal_angle = atan2(dy, dx)` in those coordinates, so a line that
//! descends to the right on screen has a positive angle; lines are unoriented, so it is folded
//! into (−π/2, π/2]. A closed line repeats its first texel at its end.
//!
//! The distance map is the exact Euclidean distance transform of the kept lines' texels
//! (Felzenszwalb & Huttenlocher, "Distance Transforms of Sampled Functions", 2012: the lower
//! envelope of parabolas, rows then columns), in texels.
//!
//! Departures and choices where the paper leaves values open: the detector above (Wu & Yu's
//! own heuristic is not specified beyond "piecewise linear segments"); the principal-line rule
//! and angle fit (above); cutting at corners (above). Defaults, tuned by looking at overlays of
//! the shipped exemplars (the ignored test `shipped_exemplars`): `scale = 1` texel (the board
//! gaps of parque1 are one texel wide and σ = 1.5 merged them with the grain into curves; the
//! brick mortar, 3–4 texels, is found at 1 and 1.5 alike), `threshold = 0.5` (at 0.2–0.35 the
//! speckle inside the bricks and the pores of the wood came out as lines; at 0.5 brick keeps
//! its mortar rows and joints, wood its grain), `min_length = 8` texels (an absolute length,
//! not a fraction of the exemplar: features have a size in texels whatever the exemplar's).
//! Lines are texel chains, not sub-texel curves: the distance map is in whole-texel steps of
//! the line, finer than §5.2's matching threshold needs. Within about 2σ of the exemplar's
//! border the mirrored borders bend oblique lines by up to two texels.
//!
//! Known limits: the threshold is relative to the strongest response, so one very dark spot
//! raises it and fainter lines are lost; exemplars whose features are bright (the light mortar of
//! brick_wall_512.png) need `polarity = "bright"` — with the default the dark brick edges
//! beside the mortar are found instead.

use crate::check::{ParamError, check_range};
use crate::image::Image;
use serde::{Deserialize, Serialize};
use texsyn_core::algorithm::Failure;
use texsyn_core::math::PureMath;

/// The `texture_feature_lines` node's algorithm and version (part of its key; bump on any change of output).
pub const NODE: texsyn_core::algorithm::Algorithm =
    texsyn_core::algorithm::Algorithm::new("texture_feature_lines", 1);

/// Below this scale-normalised strength (σ²·λ, in luminance units: about the Hessian answer to
/// a line of 1.5/255 contrast) nothing is a line, whatever `threshold` says: 8-bit
/// quantization noise of a flat exemplar is not its structure.
pub const MIN_STRENGTH: f64 = 0.002;
/// Douglas–Peucker tolerance, in texels, of the segments the principal line is chosen by.
pub const SEGMENT_TOLERANCE: f32 = 1.0;
/// Half-width, in degrees, of the direction window that decides which segments share a
/// direction. Wide enough for the wobble of hand-laid mortar, narrow enough to keep a brick
/// wall's rows and joints (90° apart) or a herringbone's two directions apart.
pub const DIRECTION_WINDOW_DEG: f32 = 15.0;
/// Turn, in degrees, past which a line is cut in two: a corner of mortar or of a board is the
/// end of one straight feature and the start of another.
pub const CORNER_DEG: f32 = 60.0;

/// Which lines are features.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Polarity {
    /// Dark lines on a lighter ground (valleys of luminance): mortar, gaps, grain.
    #[default]
    Dark,
    /// Bright lines on a darker ground (ridges of luminance).
    Bright,
    /// Either.
    Both,
}

/// `[analyse_exemplar]` of the feature-aligned method: how the exemplar's lines are found.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TextureFeatureParams {
    /// `"dark"` (default), `"bright"` or `"both"`: which lines are features.
    pub polarity: Polarity,
    /// Gaussian σ, in texels, of the smoothing the line detector works at, 0.5..=16: about half
    /// the width of the lines sought. Default: 1. A mask uses it only for the spur and corner
    /// lengths.
    pub scale: f32,
    /// Fraction of the strongest line response that starts a line, 0..=1 (half of it extends
    /// one). Default: 0.5. Ignored by a mask.
    pub threshold: f32,
    /// Shortest line kept, in texels of arc length, 0..=65536. Default: 8.
    pub min_length: f32,
    /// The feature lines to lay along the field: those running nearest this direction, in
    /// degrees in the image (x right, y down: 0 horizontal, 90 vertical, so brick's head
    /// joints are 90), instead of the dominant direction; -180..=180. Default: none.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub direction: Option<f32>,
}

impl Default for TextureFeatureParams {
    fn default() -> Self {
        TextureFeatureParams {
            polarity: Polarity::Dark,
            scale: 1.0,
            threshold: 0.5,
            min_length: 8.0,
            direction: None,
        }
    }
}

impl TextureFeatureParams {
    pub fn validate(&self) -> Result<(), ParamError> {
        check_range("analyse_exemplar.scale", self.scale, 0.5, 16.0)?;
        check_range("analyse_exemplar.threshold", self.threshold, 0.0, 1.0)?;
        check_range("analyse_exemplar.min_length", self.min_length, 0.0, 65536.0)?;
        if let Some(d) = self.direction {
            check_range("analyse_exemplar.direction", d, -180.0, 180.0)?;
        }
        Ok(())
    }
}

/// The exemplar's feature lines and the distance of every texel to them.
#[derive(Clone, Debug, PartialEq)]
pub struct TextureFeatures {
    pub width: u32,
    pub height: u32,
    /// The lines as traced, texel centres in pixel coordinates (x, y), neighbours 8-adjacent;
    /// a closed line repeats its first texel at its end.
    pub lines: Vec<Vec<[f32; 2]>>,
    /// Index into `lines` of the principal line (see the module doc).
    pub principal: u32,
    /// Direction of the principal line, radians in (−π/2, π/2], `atan2(dy, dx)` with y down.
    pub principal_angle: f32,
    /// Per texel, row-major: distance in texels to the nearest line texel.
    pub distance: Vec<f32>,
}

impl TextureFeatures {
    /// The lines straightened into piecewise-linear segments (Douglas–Peucker, `tolerance`
    /// texels), as Wu & Yu and the paper represent them.
    pub fn segments(&self, tolerance: f32) -> Vec<Vec<[f32; 2]>> {
        self.lines
            .iter()
            .map(|l| simplify_line(l, tolerance))
            .collect()
    }
}

/// Why no features could be given.
#[derive(Debug, thiserror::Error)]
pub enum TextureFeatureError {
    #[error(
        "no feature lines in the exemplar: {reason}; lower analyse_exemplar.threshold (now {threshold}) or analyse_exemplar.min_length (now {min_length} texels), or draw the lines in a mask image given as inputs.feature_mask"
    )]
    NoLines {
        reason: String,
        threshold: f32,
        min_length: f32,
    },
    #[error(
        "inputs.feature_mask: the mask is {mask_width}×{mask_height} but the exemplar is {width}×{height}; draw the mask at the exemplar's size"
    )]
    MaskSize {
        mask_width: u32,
        mask_height: u32,
        width: u32,
        height: u32,
    },
    #[error(
        "analyse_exemplar.direction = {direction}°: too few feature lines run within ±{window}° of it (under a tenth of the dominant direction's length); the lines found run mostly at {dominant:.0}°"
    )]
    NoLineInDirection {
        direction: f32,
        window: f32,
        dominant: f32,
    },
    #[error(transparent)]
    Param(#[from] ParamError),
}

/// Finds the exemplar's feature lines (module doc, steps 1–5).
pub fn detect_texture_features(
    exemplar: &Image,
    p: &TextureFeatureParams,
) -> Result<TextureFeatures, TextureFeatureError> {
    p.validate()?;
    let (w, h) = (exemplar.width as usize, exemplar.height as usize);
    let no_lines = |reason: String| TextureFeatureError::NoLines {
        reason,
        threshold: p.threshold,
        min_length: p.min_length,
    };
    if w == 0 || h == 0 || exemplar.pixels.len() != w * h {
        return Err(no_lines("the exemplar has no pixels".into()));
    }
    let lum: Vec<f64> = exemplar.pixels.iter().map(|&c| luminance(c)).collect();
    let (strength, normal) = line_response(&lum, w, h, p.scale as f64, p.polarity);
    let strongest = strength.iter().copied().fold(0.0f64, f64::max);
    if strongest < MIN_STRENGTH {
        return Err(no_lines(format!(
            "the strongest {} line response is {strongest:.5}, below the contrast of a line ({MIN_STRENGTH})",
            polarity_name(p.polarity)
        )));
    }
    let high = (p.threshold as f64 * strongest).max(MIN_STRENGTH);
    let low = (0.5 * high).max(MIN_STRENGTH);

    // Non-maximum suppression across the line.
    let sample = |x: f64, y: f64| bilinear(&strength, w, h, x, y);
    let mut candidate = vec![false; w * h];
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            let s = strength[i];
            if s < low {
                continue;
            }
            let [nx, ny] = normal[i];
            let (fx, fy) = (x as f64, y as f64);
            candidate[i] = s >= sample(fx + nx, fy + ny) && s >= sample(fx - nx, fy - ny);
        }
    }
    // Hysteresis: keep the candidates 8-connected to a strong one.
    let mut kept = vec![false; w * h];
    let mut stack = Vec::new();
    for i in 0..w * h {
        if candidate[i] && strength[i] >= high && !kept[i] {
            kept[i] = true;
            stack.push(i);
            while let Some(j) = stack.pop() {
                for k in neighbours8(j, w, h) {
                    if candidate[k] && !kept[k] {
                        kept[k] = true;
                        stack.push(k);
                    }
                }
            }
        }
    }
    finish(kept, w, h, p, |n| {
        no_lines(format!(
            "{n} texels answer as {} lines (strongest response {strongest:.4}) but none forms a line of at least {} texels",
            polarity_name(p.polarity),
            p.min_length
        ))
    })
}

/// The lines drawn by the user: a mask image the size of the exemplar. Line texels are those
/// of alpha > 0.5 when the mask has any alpha below 1 (strokes on a transparent layer), else
/// those of luminance > 0.5 (white strokes on black). They are thinned and traced as detected
/// lines are; `min_length` applies.
pub fn features_from_mask(
    exemplar: &Image,
    mask: &Image,
    p: &TextureFeatureParams,
) -> Result<TextureFeatures, TextureFeatureError> {
    p.validate()?;
    if mask.width != exemplar.width || mask.height != exemplar.height {
        return Err(TextureFeatureError::MaskSize {
            mask_width: mask.width,
            mask_height: mask.height,
            width: exemplar.width,
            height: exemplar.height,
        });
    }
    let (w, h) = (mask.width as usize, mask.height as usize);
    let no_lines = |reason: String| TextureFeatureError::NoLines {
        reason,
        threshold: p.threshold,
        min_length: p.min_length,
    };
    if w == 0 || h == 0 || mask.pixels.len() != w * h {
        return Err(no_lines(
            "the mask inputs.feature_mask has no pixels".into(),
        ));
    }
    let use_alpha = mask.pixels.iter().any(|c| c[3] < 1.0);
    let on: Vec<bool> = mask
        .pixels
        .iter()
        .map(|&c| {
            if use_alpha {
                c[3] > 0.5
            } else {
                luminance(c) > 0.5
            }
        })
        .collect();
    let what = if use_alpha {
        "alpha > 0.5"
    } else {
        "luminance > 0.5"
    };
    finish(on, w, h, p, |n| {
        no_lines(format!(
            "the mask inputs.feature_mask has {n} line texels ({what}) but no line of at least {} texels",
            p.min_length
        ))
    })
}

/// The exemplar, dimmed, with the principal line drawn in red and the others in cyan.
pub fn feature_overlay(exemplar: &Image, f: &TextureFeatures) -> image::RgbaImage {
    let mut out = exemplar.to_rgba8();
    for px in out.pixels_mut() {
        for k in 0..3 {
            px.0[k] = (px.0[k] as f32 * 0.6) as u8;
        }
        px.0[3] = 255;
    }
    let mut draw = |line: &[[f32; 2]], colour: [u8; 4]| {
        for q in line {
            let (x, y) = (q[0].round(), q[1].round());
            if x >= 0.0 && y >= 0.0 && (x as u32) < out.width() && (y as u32) < out.height() {
                out.put_pixel(x as u32, y as u32, image::Rgba(colour));
            }
        }
    };
    for (i, l) in f.lines.iter().enumerate() {
        if i != f.principal as usize {
            draw(l, [0, 230, 255, 255]);
        }
    }
    if let Some(l) = f.lines.get(f.principal as usize) {
        draw(l, [255, 30, 30, 255]);
    }
    out
}

/// Exact Euclidean distance transform: for every texel, the distance in texels to the nearest
/// texel where `mask` is true (Felzenszwalb & Huttenlocher 2012). Infinite everywhere when the
/// mask is empty.
pub fn distance_transform(mask: &[bool], width: u32, height: u32) -> Vec<f32> {
    let (w, h) = (width as usize, height as usize);
    assert_eq!(
        mask.len(),
        w * h,
        "mask of {} texels for {w}×{h}",
        mask.len()
    );
    let mut f: Vec<f64> = mask
        .iter()
        .map(|&m| if m { 0.0 } else { f64::INFINITY })
        .collect();
    let n = w.max(h);
    let (mut d, mut v, mut z, mut col) = (
        vec![0.0; n],
        vec![0usize; n],
        vec![0.0; n + 1],
        vec![0.0; n],
    );
    for y in 0..h {
        let row = &mut f[y * w..(y + 1) * w];
        edt_1d(row, &mut d[..w], &mut v, &mut z);
        row.copy_from_slice(&d[..w]);
    }
    for x in 0..w {
        for y in 0..h {
            col[y] = f[y * w + x];
        }
        edt_1d(&col[..h], &mut d[..h], &mut v, &mut z);
        for y in 0..h {
            f[y * w + x] = d[y];
        }
    }
    f.iter().map(|&s| s.sqrt() as f32).collect()
}

/// Squared distance transform of one row of sampled costs `f` (0 on a site, ∞ elsewhere after
/// the first pass): the lower envelope of the parabolas `(q − p)² + f(p)` over finite `f(p)`.
fn edt_1d(f: &[f64], d: &mut [f64], v: &mut [usize], z: &mut [f64]) {
    let n = f.len();
    let mut k: usize = 0;
    let mut any = false;
    for q in 0..n {
        if !f[q].is_finite() {
            continue;
        }
        if !any {
            any = true;
            v[0] = q;
            z[0] = f64::NEG_INFINITY;
            z[1] = f64::INFINITY;
            continue;
        }
        let fq = f[q] + (q * q) as f64;
        loop {
            let p = v[k];
            let s = (fq - (f[p] + (p * p) as f64)) / (2.0 * (q as f64 - p as f64));
            // z[0] = −∞, so the search always stops at k = 0.
            if k > 0 && s <= z[k] {
                k -= 1;
            } else {
                k += 1;
                v[k] = q;
                z[k] = s;
                z[k + 1] = f64::INFINITY;
                break;
            }
        }
    }
    if !any {
        d.fill(f64::INFINITY);
        return;
    }
    let mut k = 0;
    for q in 0..n {
        while z[k + 1] < q as f64 {
            k += 1;
        }
        let dq = q as f64 - v[k] as f64;
        d[q] = dq * dq + f[v[k]];
    }
}

/// Douglas–Peucker: the polyline's points kept within `tolerance` texels of the original.
pub fn simplify_line(points: &[[f32; 2]], tolerance: f32) -> Vec<[f32; 2]> {
    simplify_indices(points, tolerance)
        .into_iter()
        .map(|i| points[i])
        .collect()
}

/// Arc length of a polyline, in texels.
pub fn line_length(points: &[[f32; 2]]) -> f32 {
    points
        .windows(2)
        .map(|s| ((s[1][0] - s[0][0]).powi(2) + (s[1][1] - s[0][1]).powi(2)).sqrt())
        .sum()
}

// ---------------------------------------------------------------------------------------------

fn luminance(c: [f32; 4]) -> f64 {
    0.2126 * c[0] as f64 + 0.7152 * c[1] as f64 + 0.0722 * c[2] as f64
}

fn polarity_name(p: Polarity) -> &'static str {
    match p {
        Polarity::Dark => "dark",
        Polarity::Bright => "bright",
        Polarity::Both => "dark or bright",
    }
}

/// Index `i` reflected into `0..n` (half-sample symmetric, repeated for kernels wider than the
/// image).
fn mirror(i: i64, n: usize) -> usize {
    let n = n as i64;
    let m = i.rem_euclid(2 * n);
    (if m < n { m } else { 2 * n - 1 - m }) as usize
}

/// Sampled Gaussian, first and second derivative kernels (correlation weights, index `k + r`),
/// corrected so that they answer exactly 1 to a constant, `x`, and `x²/2` respectively.
fn kernels(sigma: f64) -> (i64, Vec<f64>, Vec<f64>, Vec<f64>) {
    let r = (4.0 * sigma).ceil().max(2.0) as i64;
    let ks: Vec<f64> = (-r..=r).map(|k| k as f64).collect();
    let s2 = sigma * sigma;
    let mut g: Vec<f64> = ks
        .iter()
        .map(|k| (-k * k / (2.0 * s2)).exp_pure())
        .collect();
    let sum: f64 = g.iter().sum();
    g.iter_mut().for_each(|x| *x /= sum);
    let mut d1: Vec<f64> = ks.iter().zip(&g).map(|(k, g)| k / s2 * g).collect();
    let m1: f64 = ks.iter().zip(&d1).map(|(k, d)| k * d).sum();
    d1.iter_mut().for_each(|x| *x /= m1);
    let mut d2: Vec<f64> = ks
        .iter()
        .zip(&g)
        .map(|(k, g)| (k * k / (s2 * s2) - 1.0 / s2) * g)
        .collect();
    let m0: f64 = d2.iter().sum();
    d2.iter_mut().zip(&g).for_each(|(d, g)| *d -= m0 * g);
    let m2: f64 = ks.iter().zip(&d2).map(|(k, d)| k * k * d).sum();
    d2.iter_mut().for_each(|x| *x *= 2.0 / m2);
    (r, g, d1, d2)
}

fn correlate_rows(src: &[f64], w: usize, h: usize, r: i64, ker: &[f64]) -> Vec<f64> {
    let mut out = vec![0.0; w * h];
    for y in 0..h {
        let row = &src[y * w..(y + 1) * w];
        for x in 0..w {
            let mut s = 0.0;
            for (j, wk) in ker.iter().enumerate() {
                s += wk * row[mirror(x as i64 + j as i64 - r, w)];
            }
            out[y * w + x] = s;
        }
    }
    out
}

fn correlate_cols(src: &[f64], w: usize, h: usize, r: i64, ker: &[f64]) -> Vec<f64> {
    let mut out = vec![0.0; w * h];
    for y in 0..h {
        for x in 0..w {
            let mut s = 0.0;
            for (j, wk) in ker.iter().enumerate() {
                s += wk * src[mirror(y as i64 + j as i64 - r, h) * w + x];
            }
            out[y * w + x] = s;
        }
    }
    out
}

/// Line strength (σ²-normalised Hessian eigenvalue of the chosen polarity, ≥ 0) and the unit
/// direction across the line, per texel.
fn line_response(
    lum: &[f64],
    w: usize,
    h: usize,
    sigma: f64,
    polarity: Polarity,
) -> (Vec<f64>, Vec<[f64; 2]>) {
    let (r, g, d1, d2) = kernels(sigma);
    let rg = correlate_rows(lum, w, h, r, &g);
    let r1 = correlate_rows(lum, w, h, r, &d1);
    let r2 = correlate_rows(lum, w, h, r, &d2);
    let lxx = correlate_cols(&r2, w, h, r, &g);
    let lyy = correlate_cols(&rg, w, h, r, &d2);
    let lxy = correlate_cols(&r1, w, h, r, &d1);
    let s2 = sigma * sigma;
    let mut strength = vec![0.0; w * h];
    let mut normal = vec![[0.0; 2]; w * h];
    for i in 0..w * h {
        let (a, b, c) = (lxx[i], lxy[i], lyy[i]);
        let mean = 0.5 * (a + c);
        let dev = (0.25 * (a - c) * (a - c) + b * b).sqrt();
        let (l1, l2) = (mean + dev, mean - dev);
        // Eigenvector of λ₁; λ₂'s is perpendicular to it.
        let phi = 0.5 * (2.0 * b).atan2_pure(a - c);
        let e1 = [phi.cos_pure(), phi.sin_pure()];
        let e2 = [-phi.sin_pure(), phi.cos_pure()];
        let dark = (s2 * l1).max(0.0);
        let bright = (-s2 * l2).max(0.0);
        let (s, n) = match polarity {
            Polarity::Dark => (dark, e1),
            Polarity::Bright => (bright, e2),
            Polarity::Both => {
                if dark >= bright {
                    (dark, e1)
                } else {
                    (bright, e2)
                }
            }
        };
        strength[i] = s;
        normal[i] = n;
    }
    (strength, normal)
}

fn bilinear(f: &[f64], w: usize, h: usize, x: f64, y: f64) -> f64 {
    let x = x.clamp(0.0, (w - 1) as f64);
    let y = y.clamp(0.0, (h - 1) as f64);
    let (x0, y0) = (x.floor() as usize, y.floor() as usize);
    let (x1, y1) = ((x0 + 1).min(w - 1), (y0 + 1).min(h - 1));
    let (fx, fy) = (x - x0 as f64, y - y0 as f64);
    let top = f[y0 * w + x0] * (1.0 - fx) + f[y0 * w + x1] * fx;
    let bot = f[y1 * w + x0] * (1.0 - fx) + f[y1 * w + x1] * fx;
    top * (1.0 - fy) + bot * fy
}

/// The 8 neighbours of texel `i` inside the image, in a fixed order.
fn neighbours8(i: usize, w: usize, h: usize) -> impl Iterator<Item = usize> {
    let (x, y) = ((i % w) as i64, (i / w) as i64);
    OFFSETS.iter().filter_map(move |&(dx, dy)| {
        let (nx, ny) = (x + dx, y + dy);
        (nx >= 0 && ny >= 0 && nx < w as i64 && ny < h as i64)
            .then(|| ny as usize * w + nx as usize)
    })
}

/// E, SE, S, SW, W, NW, N, NE.
const OFFSETS: [(i64, i64); 8] = [
    (1, 0),
    (1, 1),
    (0, 1),
    (-1, 1),
    (-1, 0),
    (-1, -1),
    (0, -1),
    (1, -1),
];

/// Zhang & Suen, "A fast parallel algorithm for thinning digital patterns" (1984).
fn thin(m: &mut [bool], w: usize, h: usize) {
    let at = |m: &[bool], x: i64, y: i64| -> bool {
        x >= 0 && y >= 0 && x < w as i64 && y < h as i64 && m[y as usize * w + x as usize]
    };
    let mut del = Vec::new();
    loop {
        let mut changed = false;
        for step in 0..2 {
            del.clear();
            for y in 0..h as i64 {
                for x in 0..w as i64 {
                    if !m[y as usize * w + x as usize] {
                        continue;
                    }
                    // P2..P9: N, NE, E, SE, S, SW, W, NW.
                    let p = [
                        at(m, x, y - 1),
                        at(m, x + 1, y - 1),
                        at(m, x + 1, y),
                        at(m, x + 1, y + 1),
                        at(m, x, y + 1),
                        at(m, x - 1, y + 1),
                        at(m, x - 1, y),
                        at(m, x - 1, y - 1),
                    ];
                    let b = p.iter().filter(|&&q| q).count();
                    if !(2..=6).contains(&b) {
                        continue;
                    }
                    let a = (0..8).filter(|&k| !p[k] && p[(k + 1) % 8]).count();
                    if a != 1 {
                        continue;
                    }
                    let (p2, p4, p6, p8) = (p[0], p[2], p[4], p[6]);
                    let ok = if step == 0 {
                        // P2·P4·P6 = 0 and P4·P6·P8 = 0.
                        !(p4 && p6 && (p2 || p8))
                    } else {
                        // P2·P4·P8 = 0 and P2·P6·P8 = 0.
                        !(p2 && p8 && (p4 || p6))
                    };
                    if ok {
                        del.push(y as usize * w + x as usize);
                    }
                }
            }
            for &i in &del {
                m[i] = false;
            }
            changed |= !del.is_empty();
        }
        if !changed {
            break;
        }
    }
}

/// Graph neighbours of a skeleton texel: 8-neighbours, minus diagonals that a common
/// 4-neighbour already joins.
fn links(m: &[bool], w: usize, h: usize, i: usize) -> Vec<usize> {
    let (x, y) = ((i % w) as i64, (i / w) as i64);
    let on = |x: i64, y: i64| {
        x >= 0 && y >= 0 && x < w as i64 && y < h as i64 && m[y as usize * w + x as usize]
    };
    let mut out = Vec::with_capacity(4);
    for &(dx, dy) in &OFFSETS {
        if !on(x + dx, y + dy) {
            continue;
        }
        if dx != 0 && dy != 0 && (on(x + dx, y) || on(x, y + dy)) {
            continue;
        }
        out.push((y + dy) as usize * w + (x + dx) as usize);
    }
    out
}

/// Texel chains from ends and junctions to the next, then closed loops (module doc, step 5).
fn trace(m: &[bool], w: usize, h: usize) -> Vec<Vec<usize>> {
    let graph: std::collections::BTreeMap<u32, Vec<u32>> = (0..w * h)
        .filter(|&i| m[i])
        .map(|i| {
            (
                i as u32,
                links(m, w, h, i).into_iter().map(|n| n as u32).collect(),
            )
        })
        .collect();
    crate::geom::chains::trace_chains(&graph)
        .into_iter()
        .map(|(chain, closed)| {
            let mut c: Vec<usize> = chain.into_iter().map(|i| i as usize).collect();
            // A loop repeats its first texel (module doc: lines as traced).
            if closed {
                c.push(c[0]);
            }
            c
        })
        .collect()
}

fn chain_length(c: &[usize], w: usize) -> f32 {
    c.windows(2)
        .map(|s| {
            let (dx, dy) = ((s[0] % w).abs_diff(s[1] % w), (s[0] / w).abs_diff(s[1] / w));
            if dx + dy == 2 {
                std::f32::consts::SQRT_2
            } else {
                1.0
            }
        })
        .sum()
}

/// Thinning, spur removal, tracing, length filter, principal line and distance map.
fn finish(
    mut m: Vec<bool>,
    w: usize,
    h: usize,
    p: &TextureFeatureParams,
    no_lines: impl Fn(usize) -> TextureFeatureError,
) -> Result<TextureFeatures, TextureFeatureError> {
    let texels = m.iter().filter(|&&b| b).count();
    thin(&mut m, w, h);
    // Spurs: chains from a free end to a junction, shorter than the detector's scale.
    let spur = (2.0 * p.scale).max(3.0);
    let degree = |m: &[bool], i: usize| links(m, w, h, i).len();
    let chains = trace(&m, w, h);
    let mut removed = Vec::new();
    for c in &chains {
        let (a, b) = (c[0], *c.last().expect("chains have two texels"));
        let (da, db) = (degree(&m, a), degree(&m, b));
        if chain_length(c, w) < spur {
            if da == 1 && db >= 3 {
                removed.extend_from_slice(&c[..c.len() - 1]);
            } else if db == 1 && da >= 3 {
                removed.extend_from_slice(&c[1..]);
            }
        }
    }
    for i in removed {
        m[i] = false;
    }
    // Isolated texels are no lines.
    for i in 0..w * h {
        if m[i] && degree(&m, i) == 0 {
            m[i] = false;
        }
    }
    let chains: Vec<Vec<usize>> = trace(&m, w, h)
        .into_iter()
        .flat_map(|c| split_at_corners(c, w, spur))
        .filter(|c| c.len() >= 2 && chain_length(c, w) >= p.min_length)
        .collect();
    if chains.is_empty() {
        return Err(no_lines(texels));
    }
    let lines: Vec<Vec<[f32; 2]>> = chains
        .iter()
        .map(|c| {
            c.iter()
                .map(|&i| [(i % w) as f32, (i / w) as f32])
                .collect()
        })
        .collect();
    let (principal, principal_angle) = match principal_line(&lines, p.direction) {
        Ok(found) => found,
        Err(dominant) => {
            return Err(TextureFeatureError::NoLineInDirection {
                direction: p.direction.unwrap_or_default(),
                window: DIRECTION_WINDOW_DEG,
                dominant: dominant.to_degrees(),
            });
        }
    };
    let mut on = vec![false; w * h];
    for c in &chains {
        for &i in c {
            on[i] = true;
        }
    }
    Ok(TextureFeatures {
        width: w as u32,
        height: h as u32,
        lines,
        principal: principal as u32,
        principal_angle,
        distance: distance_transform(&on, w as u32, h as u32),
    })
}

/// The chain cut at its sharp corners: texels where the direction turns by more than
/// [`CORNER_DEG`] between chords `arm` texels long on either side (so a one-texel jog of the
/// skeleton is no corner, and a corner the thinning rounded still is one), the sharpest texel
/// of each corner. Both pieces keep the corner texel.
fn split_at_corners(c: Vec<usize>, w: usize, arm: f32) -> Vec<Vec<usize>> {
    let pts: Vec<[f32; 2]> = c
        .iter()
        .map(|&i| [(i % w) as f32, (i / w) as f32])
        .collect();
    let n = pts.len();
    let k = arm.ceil() as usize;
    if n < 2 * k + 1 {
        return vec![c];
    }
    // Cosine of the turn at each texel (1 = straight); ends count as straight.
    let mut cos_turn = vec![1.0f32; n];
    for i in k..n - k {
        let (a, v, b) = (pts[i - k], pts[i], pts[i + k]);
        let (ux, uy) = (v[0] - a[0], v[1] - a[1]);
        let (wx, wy) = (b[0] - v[0], b[1] - v[1]);
        let norm = (ux.hypot_pure(uy) * wx.hypot_pure(wy)).max(f32::MIN_POSITIVE);
        cos_turn[i] = (ux * wx + uy * wy) / norm;
    }
    let cos_limit = CORNER_DEG.to_radians().cos_pure();
    let mut cuts = Vec::new();
    for i in k..n - k {
        if cos_turn[i] >= cos_limit {
            continue;
        }
        // The sharpest within ±k (the first of equals).
        let lo = i.saturating_sub(k);
        let hi = (i + k).min(n - 1);
        let sharpest = (lo..i).all(|j| cos_turn[j] > cos_turn[i])
            && (i + 1..=hi).all(|j| cos_turn[j] >= cos_turn[i]);
        if sharpest {
            cuts.push(i);
        }
    }
    if cuts.is_empty() {
        return vec![c];
    }
    let mut out = Vec::with_capacity(cuts.len() + 1);
    let mut start = 0;
    for i in cuts {
        out.push(c[start..=i].to_vec());
        start = i;
    }
    out.push(c[start..].to_vec());
    out
}

fn simplify_indices(points: &[[f32; 2]], tolerance: f32) -> Vec<usize> {
    let n = points.len();
    if n <= 2 {
        return (0..n).collect();
    }
    let mut keep = vec![false; n];
    keep[0] = true;
    keep[n - 1] = true;
    let mut stack = vec![(0usize, n - 1)];
    while let Some((a, b)) = stack.pop() {
        if b <= a + 1 {
            continue;
        }
        let (pa, pb) = (points[a], points[b]);
        let (dx, dy) = (pb[0] - pa[0], pb[1] - pa[1]);
        let len = (dx * dx + dy * dy).sqrt();
        let mut worst = (0.0f32, a);
        for i in a + 1..b {
            let (qx, qy) = (points[i][0] - pa[0], points[i][1] - pa[1]);
            let d = if len > 0.0 {
                (qx * dy - qy * dx).abs() / len
            } else {
                (qx * qx + qy * qy).sqrt()
            };
            if d > worst.0 {
                worst = (d, i);
            }
        }
        if worst.0 > tolerance {
            keep[worst.1] = true;
            stack.push((a, worst.1));
            stack.push((worst.1, b));
        }
    }
    (0..n).filter(|&i| keep[i]).collect()
}

/// Unoriented angle folded into (−π/2, π/2].
fn fold_angle(a: f32) -> f32 {
    use std::f32::consts::PI;
    let mut a = a.rem_euclid(PI);
    if a > PI / 2.0 {
        a -= PI;
    }
    a
}

/// Smallest angle between two unoriented directions, in [0, π/2].
fn angle_between(a: f32, b: f32) -> f32 {
    let d = (a - b).rem_euclid(std::f32::consts::PI);
    d.min(std::f32::consts::PI - d)
}

/// A chosen direction needs segments within the window of it holding at least this share of
/// the dominant direction's length.
const MIN_CHOSEN_SUPPORT: f32 = 0.1;

/// The principal line and its angle (module doc); with a preferred `direction` (degrees), the
/// lines around it instead of the dominant direction, or `Err(dominant angle)` when the
/// segments within the window of it hold less than [`MIN_CHOSEN_SUPPORT`] of the dominant
/// direction's length.
fn principal_line(lines: &[Vec<[f32; 2]>], direction: Option<f32>) -> Result<(usize, f32), f32> {
    struct Seg {
        line: usize,
        from: usize,
        to: usize,
        angle: f32,
        length: f32,
    }
    let mut segs = Vec::new();
    for (li, l) in lines.iter().enumerate() {
        let idx = simplify_indices(l, SEGMENT_TOLERANCE);
        for s in idx.windows(2) {
            let (a, b) = (l[s[0]], l[s[1]]);
            let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
            let length = (dx * dx + dy * dy).sqrt();
            if length > 0.0 {
                segs.push(Seg {
                    line: li,
                    from: s[0],
                    to: s[1],
                    angle: fold_angle(dy.atan2_pure(dx)),
                    length,
                });
            }
        }
    }
    let window = DIRECTION_WINDOW_DEG.to_radians();
    let mut best = (f32::NEG_INFINITY, 0.0f32);
    for s in &segs {
        let support: f32 = segs
            .iter()
            .filter(|t| angle_between(s.angle, t.angle) <= window)
            .map(|t| t.length)
            .sum();
        if support > best.0 {
            best = (support, s.angle);
        }
    }
    // Mean shift: the length-weighted mean (of doubled angles) of the segments in the window,
    // so the direction is the cluster's, not that of the one segment that found it; from the
    // preferred direction when one is given.
    let mut dominant = best.1;
    if let Some(d) = direction {
        let d = fold_angle(d.to_radians());
        let support: f32 = segs
            .iter()
            .filter(|t| angle_between(d, t.angle) <= window)
            .map(|t| t.length)
            .sum();
        // A few bends at junctions are no lines in that direction.
        if support < MIN_CHOSEN_SUPPORT * best.0 {
            return Err(best.1);
        }
        dominant = d;
    }
    for _ in 0..5 {
        let (mut c2, mut s2) = (0.0f64, 0.0f64);
        for t in segs
            .iter()
            .filter(|t| angle_between(dominant, t.angle) <= window)
        {
            c2 += t.length as f64 * (2.0 * t.angle as f64).cos_pure();
            s2 += t.length as f64 * (2.0 * t.angle as f64).sin_pure();
        }
        if c2 == 0.0 && s2 == 0.0 {
            break;
        }
        dominant = fold_angle((0.5 * s2.atan2_pure(c2)) as f32);
    }
    let mut aligned = vec![0.0f32; lines.len()];
    for s in &segs {
        if angle_between(s.angle, dominant) <= window {
            aligned[s.line] += s.length;
        }
    }
    let mut principal = 0;
    for (i, &a) in aligned.iter().enumerate() {
        if a > aligned[principal] {
            principal = i;
        }
    }
    // Length-weighted PCA of the principal line's steps on aligned segments: each step's
    // midpoint weighted by the step's length.
    let l = &lines[principal];
    let (mut sw, mut sx, mut sy) = (0.0f64, 0.0f64, 0.0f64);
    let mut steps = Vec::new();
    for s in segs
        .iter()
        .filter(|s| s.line == principal && angle_between(s.angle, dominant) <= window)
    {
        for i in s.from..s.to {
            let (a, b) = (l[i], l[i + 1]);
            let wgt = (((b[0] - a[0]).powi(2) + (b[1] - a[1]).powi(2)) as f64).sqrt();
            let mx = 0.5 * (a[0] + b[0]) as f64;
            let my = 0.5 * (a[1] + b[1]) as f64;
            steps.push((mx, my, wgt));
            sw += wgt;
            sx += wgt * mx;
            sy += wgt * my;
        }
    }
    if sw <= 0.0 {
        return Ok((principal, fold_angle(dominant)));
    }
    let (cx, cy) = (sx / sw, sy / sw);
    let (mut cxx, mut cxy, mut cyy) = (0.0f64, 0.0f64, 0.0f64);
    for &(x, y, wgt) in &steps {
        cxx += wgt * (x - cx) * (x - cx);
        cxy += wgt * (x - cx) * (y - cy);
        cyy += wgt * (y - cy) * (y - cy);
    }
    let angle = 0.5 * (2.0 * cxy).atan2_pure(cxx - cyy);
    Ok((principal, fold_angle(angle as f32)))
}

/// The analyse-exemplar node: the exemplar's feature lines, drawn by hand in `mask` or
/// detected.
pub fn node(
    exemplar: &Image,
    mask: Option<&Image>,
    p: &TextureFeatureParams,
) -> Result<TextureFeatures, Failure> {
    let f = match mask {
        Some(m) => features_from_mask(exemplar, m, p),
        None => detect_texture_features(exemplar, p),
    }
    .map_err(Failure::input)?;
    tracing::info!(
        "analyse_exemplar: {} texture feature lines, principal at {:.1}°",
        f.lines.len(),
        f.principal_angle.to_degrees()
    );
    Ok(f)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::random::counter_unit;
    use crate::testing::assert_validation;

    const PERIOD: f32 = 32.0;

    /// Light ground (0.8 ± 0.03 noise) with dark stripes 2 texels wide running along the
    /// direction `angle` (radians, y down), antialiased, one every `PERIOD` texels; returns the
    /// image and the stripes' signed distance function (0 on a stripe's centre line).
    fn stripes(w: u32, h: u32, angle: f32, seed: u64) -> (Image, impl Fn(f32, f32) -> f32) {
        let (c, s) = (angle.cos_pure(), angle.sin_pure());
        let (cx, cy) = (w as f32 / 2.0 + 0.5, h as f32 / 2.0 + 0.5);
        let offset = move |x: f32, y: f32| {
            let t = -s * (x - cx) + c * (y - cy);
            t - (t / PERIOD).round() * PERIOD
        };
        let img = Image::from_fn(w, h, |x, y| {
            let cover = (1.5 - offset(x as f32, y as f32).abs()).clamp(0.0, 1.0);
            let n = 0.06 * (counter_unit(seed, 0, (y * w + x) as u64) - 0.5);
            let v = 0.8 - 0.6 * cover + n;
            [v, v, v, 1.0]
        });
        (img, offset)
    }

    fn all_texels(f: &TextureFeatures) -> Vec<[f32; 2]> {
        f.lines.iter().flatten().copied().collect()
    }

    /// Every detected texel lies on a stripe, and every stripe (its part at least 4 texels
    /// inside the image) is covered over ≥ 80% of its length.
    fn check_stripes(
        f: &TextureFeatures,
        w: u32,
        h: u32,
        angle: f32,
        offset: impl Fn(f32, f32) -> f32,
    ) {
        let texels = all_texels(f);
        // Within 3 texels of the border the mirrored exemplar bends oblique lines.
        for q in texels.iter().filter(|q| {
            q[0] >= 3.0 && q[1] >= 3.0 && q[0] <= w as f32 - 4.0 && q[1] <= h as f32 - 4.0
        }) {
            let d = offset(q[0], q[1]).abs();
            assert!(
                d <= 1.5,
                "texel {q:?} is {d} texels from the nearest stripe"
            );
        }
        // Walk each stripe's centre line at unit steps.
        let (c, s) = (angle.cos_pure(), angle.sin_pure());
        let (cx, cy) = (w as f32 / 2.0 + 0.5, h as f32 / 2.0 + 0.5);
        let reach = (w + h) as i32;
        let mut stripes_checked = 0;
        for k in -10..=10 {
            let t = k as f32 * PERIOD;
            let (ox, oy) = (cx - s * t, cy + c * t);
            let (mut inside, mut covered) = (0, 0);
            for u in -reach..=reach {
                let (x, y) = (ox + c * u as f32, oy + s * u as f32);
                if x < 4.0 || y < 4.0 || x > w as f32 - 5.0 || y > h as f32 - 5.0 {
                    continue;
                }
                inside += 1;
                if texels
                    .iter()
                    .any(|q| (q[0] - x).powi(2) + (q[1] - y).powi(2) <= 1.5 * 1.5)
                {
                    covered += 1;
                }
            }
            if inside >= 20 {
                stripes_checked += 1;
                assert!(
                    covered as f32 >= 0.8 * inside as f32,
                    "stripe {k}: {covered} of {inside} texels covered"
                );
            }
        }
        assert!(
            stripes_checked >= 3,
            "only {stripes_checked} stripes checked"
        );
    }

    fn degrees(a: f32) -> f32 {
        a.to_degrees()
    }

    #[test]
    fn horizontal_stripes_are_found_and_horizontal() {
        let (w, h) = (128, 128);
        let (img, offset) = stripes(w, h, 0.0, 1);
        let f = detect_texture_features(&img, &TextureFeatureParams::default()).unwrap();
        check_stripes(&f, w, h, 0.0, offset);
        assert!(
            degrees(f.principal_angle).abs() < 2.0,
            "principal angle {}°",
            degrees(f.principal_angle)
        );
    }

    #[test]
    fn stripes_at_plus_and_minus_30_degrees_give_the_signed_angle() {
        // +30° in pixel coordinates (y down): the stripes descend to the right on screen.
        let (w, h) = (128, 128);
        for deg in [30.0f32, -30.0] {
            let a = deg.to_radians();
            let (img, offset) = stripes(w, h, a, 2);
            let f = detect_texture_features(&img, &TextureFeatureParams::default()).unwrap();
            check_stripes(&f, w, h, a, offset);
            let got = degrees(f.principal_angle);
            assert!(
                (got - deg).abs() < 3.0,
                "stripes at {deg}°: principal at {got}°"
            );
            // The principal line itself descends (or rises) as the sign says.
            let l = &f.lines[f.principal as usize];
            let (first, last) = (l[0], l[l.len() - 1]);
            let slope = (last[1] - first[1]) / (last[0] - first[0]);
            assert!(slope * deg.signum() > 0.0, "slope {slope} for {deg}°");
        }
    }

    /// Bricks of 40 × 30 texels (mortar 2 texels, rows at y ≡ 15 mod 30), odd rows shifted by
    /// half a brick. Junctions cut the rows every 20 texels, so a vertical joint (28 texels)
    /// is longer than any piece of row: the longest line is a joint.
    fn bricks(w: u32, h: u32) -> Image {
        Image::from_fn(w, h, |x, y| {
            let (mortar, _) = brick_mortar(x, y);
            let n = 0.08 * (counter_unit(7, 0, (y * w + x) as u64) - 0.5);
            let v = if mortar { 0.3 } else { 0.7 } + n;
            [v * 1.1, v, v * 0.8, 1.0]
        })
    }

    /// Whether texel (x, y) is mortar, and whether it is a row's.
    fn brick_mortar(x: u32, y: u32) -> (bool, bool) {
        let row = (y + 15) / 30;
        let shift = if row % 2 == 1 { 20 } else { 0 };
        let in_row = (y + 15) % 30 < 2;
        (in_row || (x + shift) % 40 < 2, in_row)
    }

    #[test]
    fn a_chosen_direction_lays_the_head_joints_instead_of_the_rows() {
        let (w, h) = (160, 120);
        let img = bricks(w, h);
        let p = TextureFeatureParams {
            direction: Some(80.0),
            ..Default::default()
        };
        let f = detect_texture_features(&img, &p).unwrap();
        let a = degrees(f.principal_angle);
        assert!((a.abs() - 90.0).abs() < 2.0, "principal at {a}°");
        // The principal line is a head joint: its texels on a joint column.
        let l = &f.lines[f.principal as usize];
        let on_joint = l
            .iter()
            .filter(|q| brick_mortar(q[0] as u32, q[1] as u32).0)
            .count();
        assert!(
            on_joint * 10 >= l.len() * 9,
            "{on_joint} of {} on mortar",
            l.len()
        );
        let (y0, y1) = (l[0][1], l[l.len() - 1][1]);
        assert!((y1 - y0).abs() >= 20.0, "a joint from y {y0} to {y1}");
        // The same lines and distances as without a direction: only the choice differs.
        let plain = detect_texture_features(&img, &TextureFeatureParams::default()).unwrap();
        assert_eq!(plain.lines, f.lines);
        assert!(plain.distance == f.distance);
        assert_ne!(plain.principal, f.principal);
        // No line runs at 45°: an error naming the key and what the lines do run at.
        let diagonal = TextureFeatureParams {
            direction: Some(45.0),
            ..Default::default()
        };
        let e = match detect_texture_features(&img, &diagonal) {
            Ok(f) => panic!(
                "45° chose line {} at {}°",
                f.principal,
                degrees(f.principal_angle)
            ),
            Err(e) => e.to_string(),
        };
        assert!(
            e.contains("analyse_exemplar.direction = 45°") && e.contains("mostly at"),
            "{e}"
        );
    }

    #[test]
    fn brick_principal_is_a_horizontal_mortar_row() {
        let (w, h) = (160, 120);
        let f = detect_texture_features(&bricks(w, h), &TextureFeatureParams::default()).unwrap();
        let a = degrees(f.principal_angle);
        assert!(a.abs() < 2.0, "principal at {a}°");
        // The principal line is a row, but for where it bends into a junction at its ends.
        let l = &f.lines[f.principal as usize];
        assert!(
            line_length(l) >= 18.0,
            "a principal of {} texels",
            line_length(l)
        );
        for (i, q) in l.iter().enumerate() {
            let d = (q[1] - 15.5) - ((q[1] - 15.5) / 30.0).round() * 30.0;
            let tolerance = if i < 3 || i + 3 >= l.len() { 3.0 } else { 1.5 };
            assert!(
                d.abs() <= tolerance,
                "principal texel {q:?} is off the mortar rows"
            );
        }
        // The joints are found too: some line runs vertically.
        let vertical = f.lines.iter().any(|l| {
            let (a, b) = (l[0], l[l.len() - 1]);
            (b[1] - a[1]).abs() >= 20.0 && (b[0] - a[0]).abs() <= 2.0
        });
        assert!(vertical, "no vertical joint among {} lines", f.lines.len());
        // Every line texel is on mortar or next to it.
        for q in all_texels(&f) {
            let (x, y) = (q[0] as i64, q[1] as i64);
            let near = (-1..=1).any(|dy: i64| {
                (-1..=1).any(|dx: i64| {
                    let (u, v) = (x + dx, y + dy);
                    u >= 0 && v >= 0 && brick_mortar(u as u32, v as u32).0
                })
            });
            assert!(near, "texel {q:?} is inside a brick");
        }
    }

    #[test]
    fn principal_follows_the_direction_with_the_most_length() {
        // Twelve horizontal dashes of 20 texels (240 in all) and three vertical lines of 40
        // (120 in all): the longest line is vertical, the texture's direction horizontal.
        let img = Image::from_fn(128, 128, |x, y| {
            let dash = (70..=118).contains(&y)
                && (y - 70) % 16 < 2
                && [8, 48, 88].iter().any(|&x0| (x0..x0 + 20).contains(&x));
            let bar =
                (5..45).contains(&y) && [20, 60, 100].iter().any(|&x0| (x0..x0 + 2).contains(&x));
            let v = if dash || bar { 0.2 } else { 0.8 };
            [v, v, v, 1.0]
        });
        let f = detect_texture_features(&img, &TextureFeatureParams::default()).unwrap();
        let longest = (0..f.lines.len())
            .max_by(|&a, &b| line_length(&f.lines[a]).total_cmp(&line_length(&f.lines[b])))
            .unwrap();
        let l = &f.lines[longest];
        assert!(
            (l[0][0] - l[l.len() - 1][0]).abs() <= 1.0,
            "the longest line is not a bar"
        );
        let a = degrees(f.principal_angle);
        assert!(a.abs() < 2.0, "principal at {a}°");
        assert!(f.lines[f.principal as usize].iter().all(|q| q[1] >= 68.0));
    }

    #[test]
    fn a_corner_ends_a_line() {
        // A dark L: 40 texels right, then 40 down.
        let img = Image::from_fn(64, 64, |x, y| {
            let on = ((10..52).contains(&x) && (10..12).contains(&y))
                || ((50..52).contains(&x) && (10..52).contains(&y));
            let v = if on { 0.2 } else { 0.8 };
            [v, v, v, 1.0]
        });
        let f = detect_texture_features(&img, &TextureFeatureParams::default()).unwrap();
        assert_eq!(f.lines.len(), 2, "{:?}", f.lines);
        let mut dirs: Vec<i32> = f
            .lines
            .iter()
            .map(|l| {
                let (a, b) = (l[0], l[l.len() - 1]);
                assert!(line_length(l) >= 30.0, "a piece of {}", line_length(l));
                (b[1] - a[1])
                    .atan2_pure(b[0] - a[0])
                    .to_degrees()
                    .abs()
                    .round() as i32
                    % 180
            })
            .collect();
        dirs.sort();
        assert!(
            dirs[0] <= 3 && (87..=93).contains(&dirs[1]),
            "directions {dirs:?}"
        );
    }

    #[test]
    fn bright_polarity_does_not_find_the_dark_stripes() {
        let (img, offset) = stripes(128, 128, 0.0, 3);
        let p = TextureFeatureParams {
            polarity: Polarity::Bright,
            ..Default::default()
        };
        match detect_texture_features(&img, &p) {
            Err(TextureFeatureError::NoLines { .. }) => {}
            Err(e) => panic!("{e}"),
            Ok(f) => {
                for q in all_texels(&f) {
                    let d = offset(q[0], q[1]).abs();
                    // Dark texels are those within 0.5 of a stripe's centre line; the
                    // ridges found lie in the light ground beside or between the stripes.
                    assert!(d > 1.0, "bright line texel {q:?} on a dark stripe ({d})");
                }
            }
        }
        // Both finds the dark stripes again.
        let p = TextureFeatureParams {
            polarity: Polarity::Both,
            ..Default::default()
        };
        let f = detect_texture_features(&img, &p).unwrap();
        let on_dark = all_texels(&f)
            .iter()
            .filter(|q| offset(q[0], q[1]).abs() <= 1.5)
            .count();
        assert!(on_dark >= 4 * 100, "{on_dark} texels on the dark stripes");
    }

    #[test]
    fn flat_grey_has_no_lines_and_says_what_to_lower() {
        let flat = Image::from_fn(64, 48, |_, _| [0.5, 0.5, 0.5, 1.0]);
        // 8-bit quantization noise is no structure either.
        let dithered = Image::from_fn(64, 48, |x, y| {
            let v = 0.5 + (counter_unit(5, 0, (y * 64 + x) as u64) - 0.5) / 255.0;
            [v, v, v, 1.0]
        });
        for img in [flat, dithered] {
            let e = detect_texture_features(&img, &TextureFeatureParams::default()).unwrap_err();
            assert!(matches!(e, TextureFeatureError::NoLines { .. }), "{e}");
            let msg = e.to_string();
            for key in [
                "analyse_exemplar.threshold",
                "analyse_exemplar.min_length",
                "inputs.feature_mask",
            ] {
                assert!(msg.contains(key), "{msg}");
            }
        }
    }

    #[test]
    fn min_length_drops_short_lines() {
        // One dark bar 20 texels long: kept at min_length 8, dropped at 40.
        let img = Image::from_fn(64, 64, |x, y| {
            let v = if (20..40).contains(&x) && (31..33).contains(&y) {
                0.2
            } else {
                0.8
            };
            [v, v, v, 1.0]
        });
        let f = detect_texture_features(&img, &TextureFeatureParams::default()).unwrap();
        assert_eq!(f.lines.len(), 1, "{:?}", f.lines);
        let len = line_length(&f.lines[0]);
        assert!((15.0..=24.0).contains(&len), "length {len}");
        let p = TextureFeatureParams {
            min_length: 40.0,
            ..Default::default()
        };
        let e = detect_texture_features(&img, &p).unwrap_err();
        assert!(e.to_string().contains("40 texels"), "{e}");
    }

    fn diagonal_mask(w: u32, h: u32, alpha: bool) -> Image {
        // A stroke 3 texels wide from (10, 70) to (90, 20).
        let (a, b) = ([10.0f32, 70.0], [90.0f32, 20.0]);
        Image::from_fn(w, h, |x, y| {
            let (px, py) = (x as f32 - a[0], y as f32 - a[1]);
            let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
            let t = ((px * dx + py * dy) / (dx * dx + dy * dy)).clamp(0.0, 1.0);
            let d = ((px - t * dx).powi(2) + (py - t * dy).powi(2)).sqrt();
            let on = d <= 1.5;
            match (alpha, on) {
                (false, true) => [1.0, 1.0, 1.0, 1.0],
                (false, false) => [0.0, 0.0, 0.0, 1.0],
                // Drawn in black on a transparent layer: alpha decides, not luminance.
                (true, true) => [0.0, 0.0, 0.0, 1.0],
                (true, false) => [1.0, 1.0, 1.0, 0.0],
            }
        })
    }

    #[test]
    fn mask_diagonal_gives_its_angle() {
        let (w, h) = (100, 80);
        let exemplar = Image::from_fn(w, h, |_, _| [0.5, 0.5, 0.5, 1.0]);
        let expected = (-50.0f32).atan2_pure(80.0).to_degrees(); // rises to the right: negative
        for alpha in [false, true] {
            let f = features_from_mask(&exemplar, &diagonal_mask(w, h, alpha), &Default::default())
                .unwrap();
            let got = degrees(f.principal_angle);
            assert!(
                (got - expected).abs() < 1.5,
                "alpha {alpha}: {got}° for {expected}°"
            );
            assert_eq!(f.lines.len(), 1, "{} lines", f.lines.len());
            // Thinned: one texel per step, near the stroke's centre line.
            let l = &f.lines[0];
            assert!(line_length(l) >= 0.9 * (80.0f32.hypot_pure(50.0) - 4.0));
            for q in l {
                let d =
                    ((q[0] - 10.0) * -50.0 - (q[1] - 70.0) * 80.0).abs() / 80.0f32.hypot_pure(50.0);
                assert!(
                    d <= 1.0,
                    "skeleton texel {q:?} is {d} off the stroke's axis"
                );
            }
        }
    }

    #[test]
    fn mask_of_another_size_is_refused() {
        let exemplar = Image::from_fn(100, 80, |_, _| [0.5; 4]);
        let e = features_from_mask(
            &exemplar,
            &diagonal_mask(90, 80, false),
            &Default::default(),
        )
        .unwrap_err();
        assert!(matches!(e, TextureFeatureError::MaskSize { .. }));
        assert_eq!(
            e.to_string(),
            "inputs.feature_mask: the mask is 90×80 but the exemplar is 100×80; draw the mask at the exemplar's size"
        );
        // An empty mask: nothing to trace.
        let empty = Image::from_fn(100, 80, |_, _| [0.0, 0.0, 0.0, 1.0]);
        let e = features_from_mask(&exemplar, &empty, &Default::default()).unwrap_err();
        assert!(matches!(e, TextureFeatureError::NoLines { .. }), "{e}");
    }

    fn brute_force(mask: &[bool], w: usize, h: usize) -> Vec<f32> {
        let sites: Vec<(i64, i64)> = (0..w * h)
            .filter(|&i| mask[i])
            .map(|i| ((i % w) as i64, (i / w) as i64))
            .collect();
        (0..w * h)
            .map(|i| {
                let (x, y) = ((i % w) as i64, (i / w) as i64);
                sites
                    .iter()
                    .map(|&(sx, sy)| (((sx - x).pow(2) + (sy - y).pow(2)) as f64).sqrt() as f32)
                    .fold(f32::INFINITY, f32::min)
            })
            .collect()
    }

    #[test]
    fn distance_transform_is_exact() {
        let mut case = 0;
        for (w, h) in [(1, 1), (1, 9), (9, 1), (37, 23), (64, 64), (5, 70)] {
            for density in [0.002f32, 0.03, 0.3, 0.9] {
                case += 1;
                let mask: Vec<bool> = (0..w * h)
                    .map(|i| counter_unit(11, case, i as u64) < density)
                    .collect();
                let got = distance_transform(&mask, w as u32, h as u32);
                let want = brute_force(&mask, w, h);
                for i in 0..w * h {
                    let ok = if want[i].is_infinite() {
                        got[i].is_infinite()
                    } else {
                        (got[i] - want[i]).abs() <= 1e-4
                    };
                    assert!(
                        ok,
                        "{w}×{h} density {density}, texel {i}: {} vs {}",
                        got[i], want[i]
                    );
                }
            }
        }
        // One site in a corner: the far corner is the diagonal away.
        let mut m = vec![false; 30 * 20];
        m[0] = true;
        let d = distance_transform(&m, 30, 20);
        assert!((d[30 * 20 - 1] - (29.0f32).hypot_pure(19.0)).abs() < 1e-4);
    }

    #[test]
    fn distance_map_is_zero_exactly_on_the_lines_and_detection_is_deterministic() {
        let img = bricks(120, 80);
        let p = TextureFeatureParams::default();
        let f = detect_texture_features(&img, &p).unwrap();
        let g = detect_texture_features(&img, &p).unwrap();
        assert_eq!(f, g);
        assert_eq!(f.principal_angle.to_bits(), g.principal_angle.to_bits());
        let mut on = vec![false; 120 * 80];
        for q in all_texels(&f) {
            on[q[1] as usize * 120 + q[0] as usize] = true;
        }
        for i in 0..on.len() {
            assert_eq!(f.distance[i] == 0.0, on[i], "texel {i}");
            assert!(
                f.distance[i] <= 20.0,
                "texel {i} is {} from mortar",
                f.distance[i]
            );
        }
        // Overlay: principal in red, others in cyan, elsewhere the dimmed exemplar.
        let o = feature_overlay(&img, &f);
        let pq = f.lines[f.principal as usize][0];
        assert_eq!(
            o.get_pixel(pq[0] as u32, pq[1] as u32).0,
            [255, 30, 30, 255]
        );
        let other = (0..f.lines.len())
            .find(|&i| i != f.principal as usize)
            .unwrap();
        let oq = f.lines[other][f.lines[other].len() / 2];
        assert_eq!(
            o.get_pixel(oq[0] as u32, oq[1] as u32).0,
            [0, 230, 255, 255]
        );
    }

    #[test]
    fn segments_straighten_lines() {
        let l: Vec<[f32; 2]> = (0..=20)
            .map(|i| [i as f32, if i <= 10 { 0.0 } else { (i - 10) as f32 }])
            .collect();
        assert_eq!(
            simplify_line(&l, 0.5),
            vec![[0.0, 0.0], [10.0, 0.0], [20.0, 10.0]]
        );
        assert_eq!(simplify_line(&l, 20.0), vec![[0.0, 0.0], [20.0, 10.0]]);
    }

    #[test]
    fn params_validate_and_parse() {
        assert_validation!(TextureFeatureParams {
            scale: 0.2 => "analyse_exemplar.scale must be in 0.5..=16, got 0.2",
            threshold: 1.5 => "analyse_exemplar.threshold must be in 0..=1, got 1.5",
            min_length: -1.0 => "analyse_exemplar.min_length must be in 0..=65536, got -1",
        });
        let p: TextureFeatureParams = toml::from_str("polarity = \"both\"\nscale = 2.0").unwrap();
        assert_eq!(p.polarity, Polarity::Both);
        assert_eq!(p.threshold, TextureFeatureParams::default().threshold);
        assert!(toml::from_str::<TextureFeatureParams>("colour = 1").is_err());
        let bad = TextureFeatureParams {
            scale: f32::NAN,
            ..Default::default()
        };
        let img = Image::from_fn(8, 8, |_, _| [0.5; 4]);
        assert!(matches!(
            detect_texture_features(&img, &bad),
            Err(TextureFeatureError::Param(_))
        ));
    }

    /// The shipped exemplars, when ../shared/data is there (not for CI): writes overlays
    /// (4× enlarged) to /tmp/texfeat-<name>.png for a person to look at.
    #[test]
    #[ignore]
    fn shipped_exemplars() {
        let dir =
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/data/exemplars");
        for name in ["brick", "brick_wall_512", "parque1", "wood1", "wood2"] {
            let path = dir.join(format!("{name}.png"));
            let bytes = std::fs::read(&path).unwrap();
            let img = crate::image::decode_image(&path, &bytes).unwrap();
            let t = std::time::Instant::now();
            let env = |k: &str, d: f32| {
                std::env::var(k)
                    .ok()
                    .and_then(|v| v.parse().ok())
                    .unwrap_or(d)
            };
            let d = TextureFeatureParams::default();
            let p = TextureFeatureParams {
                scale: env("TEXFEAT_SCALE", d.scale),
                threshold: env("TEXFEAT_THRESHOLD", d.threshold),
                min_length: env("TEXFEAT_MIN_LENGTH", d.min_length),
                ..d
            };
            let f = detect_texture_features(&img, &p).unwrap();
            let ms = t.elapsed().as_secs_f64() * 1e3;
            let total: f32 = f.lines.iter().map(|l| line_length(l)).sum();
            let principal = &f.lines[f.principal as usize];
            eprintln!(
                "{name} {}×{}: {} lines, total {total:.0} texels, principal #{} of {:.0} texels at {:.1}° from {:?} to {:?}, {ms:.1} ms",
                img.width,
                img.height,
                f.lines.len(),
                f.principal,
                line_length(principal),
                f.principal_angle.to_degrees(),
                principal[0],
                principal[principal.len() - 1],
            );
            let o = feature_overlay(&img, &f);
            let k = (400 / img.width.max(img.height)).max(1);
            let big = image::imageops::resize(
                &o,
                o.width() * k,
                o.height() * k,
                image::imageops::FilterType::Nearest,
            );
            big.save(format!("/tmp/texfeat-{name}.png")).unwrap();
            let src = img.to_rgba8();
            let big = image::imageops::resize(
                &src,
                o.width() * k,
                o.height() * k,
                image::imageops::FilterType::Nearest,
            );
            big.save(format!("/tmp/texfeat-src-{name}.png")).unwrap();
        }
    }
}

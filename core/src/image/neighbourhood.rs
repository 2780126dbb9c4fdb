//! Per-pixel neighbourhood feature vectors: Gaussian-weighted square windows of RGB values at
//! several levels of a Gaussian pyramid, concatenated, finest level first.
//!
//! At level `l` the window is centred on the pixel's position scaled to that level (`p / 2^l`,
//! see [`super::pyramid`]) and sampled bilinearly, with offsets in that level's pixels, so coarse
//! levels see a wider area. Borders are mirrored (reflected about the edge pixel centres).
//!
//! Each component is multiplied by the square root of its Gaussian weight, so the squared
//! Euclidean distance between two vectors is the Gaussian-weighted sum of squared differences.
//! Level `l`'s weights sum to `coarse_weight^l`: by default each coarser level counts half as
//! much as the one below it, so fine detail (which blurs away on coarse levels) is not outvoted.

use super::ImageView;
use super::pyramid::Pyramid;
use crate::math::PureMath;
use rayon::prelude::*;

/// Neighbourhood shape. Defaults: 3 levels, a 5×5 window at the finest level.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct NeighbourhoodParams {
    /// Pyramid levels used (fewer if the image is too small, see [`Pyramid::build`]).
    /// Default: 3.
    pub levels: u32,
    /// Window side at the finest level, odd. Coarser levels use `window - 2 l`, but at least 3
    /// (or `window` itself if that is smaller). Default: 5.
    pub window: u32,
    /// Total weight of each level relative to the next finer one (level 0 has weight 1).
    /// Default: 0.5.
    pub coarse_weight: f32,
}

impl Default for NeighbourhoodParams {
    fn default() -> Self {
        NeighbourhoodParams {
            levels: 3,
            window: 5,
            coarse_weight: 0.5,
        }
    }
}

/// Window side used at pyramid level `level` for a finest window `window`.
pub fn level_window(window: u32, level: usize) -> u32 {
    let shrunk = window.saturating_sub(2 * level as u32);
    shrunk.max(window.min(3))
}

/// Mirrors an integer index into `[0, n)` (reflecting about the centres of the edge pixels).
#[inline]
pub fn mirror(i: i64, n: i64) -> i64 {
    if n <= 1 {
        return 0;
    }
    let period = 2 * (n - 1);
    let m = i.rem_euclid(period);
    if m < n { m } else { period - m }
}

/// The pyramid and weights needed to produce neighbourhood vectors of one image.
#[derive(Debug, Clone)]
pub struct Neighbourhoods {
    pyramid: Pyramid,
    /// Window side per level.
    windows: Vec<u32>,
    /// Square roots of the Gaussian weights per level, row-major over the window.
    sqrt_weights: Vec<Vec<f32>>,
    dim: usize,
}

impl Neighbourhoods {
    /// Builds the pyramid of `img`. `params.window` is rounded up to odd and to at least 1, and
    /// `params.levels` to at least 1.
    pub fn new(img: ImageView, params: &NeighbourhoodParams) -> Self {
        let window = params.window.max(1) | 1;
        let pyramid = Pyramid::build(img, params.levels.max(1) as usize);
        let mut windows = Vec::new();
        let mut sqrt_weights = Vec::new();
        let mut dim = 0;
        for l in 0..pyramid.len() {
            let n = level_window(window, l);
            let r = (n / 2) as i32;
            let sigma = n as f32 / 3.0;
            let mut ws = Vec::with_capacity((n * n) as usize);
            for dy in -r..=r {
                for dx in -r..=r {
                    let d2 = (dx * dx + dy * dy) as f32;
                    ws.push((-d2 / (2.0 * sigma * sigma)).exp_pure());
                }
            }
            let total: f32 = ws.iter().sum();
            let level_weight = params.coarse_weight.max(0.0).powi(l as i32);
            for w in &mut ws {
                *w = (*w * level_weight / total).sqrt();
            }
            dim += 3 * ws.len();
            windows.push(n);
            sqrt_weights.push(ws);
        }
        Neighbourhoods {
            pyramid,
            windows,
            sqrt_weights,
            dim,
        }
    }

    /// Length of one feature vector.
    pub fn dim(&self) -> usize {
        self.dim
    }

    /// Pyramid levels actually used.
    pub fn levels(&self) -> usize {
        self.pyramid.len()
    }

    pub fn pyramid(&self) -> &Pyramid {
        &self.pyramid
    }

    /// Width and height of the finest level.
    pub fn size(&self) -> (u32, u32) {
        let l0 = self.pyramid.level(0);
        (l0.width, l0.height)
    }

    /// Writes the feature vector of pixel `(x, y)` into `out` (length [`Self::dim`]).
    pub fn write(&self, x: u32, y: u32, out: &mut [f32]) {
        assert_eq!(out.len(), self.dim, "feature buffer length");
        let mut o = 0;
        for (l, (&n, ws)) in self.windows.iter().zip(&self.sqrt_weights).enumerate() {
            let img = self.pyramid.level(l);
            let (w, h) = (img.width as i64, img.height as i64);
            let scale = 1.0 / (1u32 << l) as f32;
            let cx = x as f32 * scale;
            let cy = y as f32 * scale;
            let r = (n / 2) as i64;
            // Bilinear footprint: the fractional part is the same for every tap of the window.
            let (bx, by) = (cx.floor(), cy.floor());
            let (fx, fy) = (cx - bx, cy - by);
            let (bx, by) = (bx as i64, by as i64);
            let mut t = 0;
            for dy in -r..=r {
                let y0 = mirror(by + dy, h);
                let y1 = mirror(by + dy + 1, h);
                for dx in -r..=r {
                    let x0 = mirror(bx + dx, w);
                    let x1 = mirror(bx + dx + 1, w);
                    let a = img.pixels[(y0 * w + x0) as usize];
                    let sw = ws[t];
                    t += 1;
                    if fx == 0.0 && fy == 0.0 {
                        for c in 0..3 {
                            out[o + c] = a[c] * sw;
                        }
                    } else {
                        let b = img.pixels[(y0 * w + x1) as usize];
                        let c_ = img.pixels[(y1 * w + x0) as usize];
                        let d = img.pixels[(y1 * w + x1) as usize];
                        for c in 0..3 {
                            let top = a[c] + (b[c] - a[c]) * fx;
                            let bot = c_[c] + (d[c] - c_[c]) * fx;
                            out[o + c] = (top + (bot - top) * fy) * sw;
                        }
                    }
                    o += 3;
                }
            }
        }
    }

    /// All feature vectors, row-major over pixels, flat (`width * height * dim` values).
    pub fn all(&self) -> Vec<f32> {
        let (w, h) = self.size();
        let dim = self.dim;
        let mut out = vec![0.0f32; w as usize * h as usize * dim];
        if dim == 0 || out.is_empty() {
            return out;
        }
        out.par_chunks_mut(w as usize * dim)
            .enumerate()
            .for_each(|(y, row)| {
                for (x, v) in row.chunks_mut(dim).enumerate() {
                    self.write(x as u32, y as u32, v);
                }
            });
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::image::Image;

    fn noise(w: u32, h: u32, seed: u32) -> Image {
        let mut img = Image::new(w, h);
        let mut s = seed.wrapping_mul(2654435761).wrapping_add(12345);
        for p in &mut img.pixels {
            for v in p.iter_mut().take(3) {
                s ^= s << 13;
                s ^= s >> 17;
                s ^= s << 5;
                *v = (s % 1000) as f32 / 1000.0;
            }
        }
        img
    }

    /// The neighbourhoods of `img` over `levels` levels with a `window` wide finest window,
    /// other parameters default.
    fn neighbourhoods(img: &Image, levels: u32, window: u32) -> Neighbourhoods {
        let params = NeighbourhoodParams {
            levels,
            window,
            ..Default::default()
        };
        Neighbourhoods::new(img.view(), &params)
    }

    #[test]
    fn mirror_reflects_about_edge_centres() {
        let v: Vec<i64> = (-3..8).map(|i| mirror(i, 5)).collect();
        assert_eq!(v, vec![3, 2, 1, 0, 1, 2, 3, 4, 3, 2, 1]);
        assert_eq!(mirror(7, 1), 0);
    }

    #[test]
    fn dims_and_windows() {
        assert_eq!(level_window(5, 0), 5);
        assert_eq!(level_window(5, 1), 3);
        assert_eq!(level_window(5, 2), 3);
        assert_eq!(level_window(1, 2), 1);
        assert_eq!(level_window(9, 1), 7);
        let img = noise(64, 64, 1);
        let n = Neighbourhoods::new(img.view(), &NeighbourhoodParams::default());
        assert_eq!(n.levels(), 3);
        assert_eq!(n.dim(), 3 * (25 + 9 + 9));
        assert_eq!(neighbourhoods(&img, 1, 3).dim(), 27);
    }

    #[test]
    fn squared_distance_is_gaussian_weighted_ssd() {
        // Two pixels of a single-level neighbourhood: the squared distance of their vectors must
        // equal the Gaussian-weighted SSD computed directly, weights summing to one.
        let img = noise(20, 20, 7);
        let n = neighbourhoods(&img, 1, 5);
        let mut a = vec![0.0; n.dim()];
        let mut b = vec![0.0; n.dim()];
        n.write(6, 7, &mut a);
        n.write(12, 9, &mut b);
        let d2: f32 = a.iter().zip(&b).map(|(p, q)| (p - q) * (p - q)).sum();
        let sigma = 5.0f32 / 3.0;
        let mut direct = 0.0f32;
        let mut wsum = 0.0f32;
        for dy in -2i64..=2 {
            for dx in -2i64..=2 {
                let w = (-((dx * dx + dy * dy) as f32) / (2.0 * sigma * sigma)).exp_pure();
                let p = img.view().get((6 + dx) as u32, (7 + dy) as u32);
                let q = img.view().get((12 + dx) as u32, (9 + dy) as u32);
                for c in 0..3 {
                    direct += w * (p[c] - q[c]) * (p[c] - q[c]);
                }
                wsum += w;
            }
        }
        assert!(
            (d2 - direct / wsum).abs() < 1e-4 * direct.max(1e-3),
            "{d2} {}",
            direct / wsum
        );
    }

    #[test]
    fn borders_are_mirrored_and_coarse_levels_bilinear() {
        let img = noise(32, 32, 3);
        let n = neighbourhoods(&img, 2, 3);
        let mut v = vec![0.0; n.dim()];
        n.write(0, 0, &mut v);
        let sw = &n.sqrt_weights[0];
        // Tap (dx, dy) = (-1, -1) mirrors to pixel (1, 1).
        let p = img.view().get(1, 1);
        for c in 0..3 {
            assert!((v[c] / sw[0] - p[c]).abs() < 1e-6);
        }
        // Level 1 centre tap of pixel (3, 5) is the bilinear sample at (1.5, 2.5) of level 1.
        n.write(3, 5, &mut v);
        let l1 = n.pyramid().level(1);
        let centre = 27 + 3 * 4;
        let s = l1.sample(glam::Vec2::new(1.5, 2.5));
        let sw1 = n.sqrt_weights[1][4];
        for c in 0..3 {
            assert!((v[centre + c] / sw1 - s[c]).abs() < 1e-5);
        }
        // all() agrees with write().
        let all = n.all();
        let d = n.dim();
        let i = 5 * 32 + 3;
        assert_eq!(&all[i * d..(i + 1) * d], &v[..]);
    }
}

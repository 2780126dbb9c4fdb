//! Gaussian pyramids: a 5-tap binomial blur `[1, 4, 6, 4, 1] / 16` (separable, borders clamped)
//! followed by keeping every second pixel.
//!
//! Addressing across levels: pixel `i` of level `l + 1` sits where pixel `2 i` of level `l` does
//! (the blur is centred on the kept pixel), so a level-0 texel address `p` is at `p / 2^l` on
//! level `l`. A level of size `w × h` gives `⌈w/2⌉ × ⌈h/2⌉`.

use super::{Image, ImageView};
use rayon::prelude::*;

/// Levels are added while both sides of the next level are at least this many pixels.
pub const MIN_LEVEL_SIDE: u32 = 8;

const BINOMIAL5: [f32; 5] = [1.0 / 16.0, 4.0 / 16.0, 6.0 / 16.0, 4.0 / 16.0, 1.0 / 16.0];

/// A Gaussian pyramid; level 0 is the input image.
#[derive(Debug, Clone, PartialEq)]
pub struct Pyramid {
    pub levels: Vec<Image>,
}

impl Pyramid {
    /// Builds up to `max_levels` levels (at least one: the input itself), stopping before a level
    /// whose smaller side would be under [`MIN_LEVEL_SIDE`].
    pub fn build(img: ImageView, max_levels: usize) -> Pyramid {
        let mut levels = vec![img.to_owned()];
        while levels.len() < max_levels {
            let last = levels.last().expect("at least one level");
            let (w, h) = (last.width.div_ceil(2), last.height.div_ceil(2));
            if w.min(h) < MIN_LEVEL_SIDE || last.width < 2 || last.height < 2 {
                break;
            }
            let next = downsample(last.view());
            levels.push(next);
        }
        Pyramid { levels }
    }

    /// Number of levels (≥ 1).
    pub fn len(&self) -> usize {
        self.levels.len()
    }

    /// Always false: a pyramid has at least its input level. Present for clippy's sake.
    pub fn is_empty(&self) -> bool {
        self.levels.is_empty()
    }

    pub fn level(&self, l: usize) -> ImageView<'_> {
        self.levels[l].view()
    }
}

/// Separable 5-tap binomial blur with clamped borders, all four channels.
pub fn blur_binomial5(img: ImageView) -> Image {
    blur_binomial5_dilated(img, 1)
}

/// The same blur with its taps `step` texels apart (à trous): applied with steps 1, 2, 4, …
/// it gives a Gaussian stack's levels at full size.
pub fn blur_binomial5_dilated(img: ImageView, step: i64) -> Image {
    let (w, h) = (img.width as usize, img.height as usize);
    if w == 0 || h == 0 {
        return img.to_owned();
    }
    // Horizontal pass.
    let mut tmp = vec![[0.0f32; 4]; w * h];
    tmp.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
        for (x, out) in row.iter_mut().enumerate() {
            let mut acc = [0.0f32; 4];
            for (t, &k) in BINOMIAL5.iter().enumerate() {
                let p = img.get_clamped(x as i64 + (t as i64 - 2) * step, y as i64);
                for c in 0..4 {
                    acc[c] += k * p[c];
                }
            }
            *out = acc;
        }
    });
    // Vertical pass.
    let tmp_view = ImageView {
        width: img.width,
        height: img.height,
        pixels: &tmp,
    };
    let mut out = vec![[0.0f32; 4]; w * h];
    out.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
        for (x, o) in row.iter_mut().enumerate() {
            let mut acc = [0.0f32; 4];
            for (t, &k) in BINOMIAL5.iter().enumerate() {
                let p = tmp_view.get_clamped(x as i64, y as i64 + (t as i64 - 2) * step);
                for c in 0..4 {
                    acc[c] += k * p[c];
                }
            }
            *o = acc;
        }
    });
    Image {
        width: img.width,
        height: img.height,
        pixels: out,
    }
}

/// Blurs, then keeps pixels with even coordinates: `⌈w/2⌉ × ⌈h/2⌉`.
pub fn downsample(img: ImageView) -> Image {
    let blurred = blur_binomial5(img);
    let (w2, h2) = (img.width.div_ceil(2), img.height.div_ceil(2));
    let b = blurred.view();
    Image::from_fn(w2, h2, |x, y| b.get(2 * x, 2 * y))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ramp(w: u32, h: u32) -> Image {
        Image::from_fn(w, h, |x, y| [x as f32, y as f32, 0.5, 1.0])
    }

    #[test]
    fn level_count_and_sizes() {
        let img = ramp(100, 40);
        let p = Pyramid::build(img.view(), 10);
        // 100x40 -> 50x20 -> 25x10 -> (13x5 stops: 5 < 8)
        let sizes: Vec<_> = p.levels.iter().map(|l| (l.width, l.height)).collect();
        assert_eq!(sizes, vec![(100, 40), (50, 20), (25, 10)]);
        let p2 = Pyramid::build(img.view(), 2);
        assert_eq!(p2.len(), 2);
        let tiny = ramp(5, 5);
        assert_eq!(Pyramid::build(tiny.view(), 4).len(), 1);
    }

    #[test]
    fn blur_preserves_constants_and_linear_ramps_inside() {
        let img = ramp(16, 16);
        let b = blur_binomial5(img.view());
        // The binomial kernel is symmetric, so away from borders a linear ramp is unchanged.
        for y in 2..14 {
            for x in 2..14 {
                let p = b.view().get(x, y);
                assert!((p[0] - x as f32).abs() < 1e-5 && (p[1] - y as f32).abs() < 1e-5);
                assert!((p[2] - 0.5).abs() < 1e-6 && (p[3] - 1.0).abs() < 1e-6);
            }
        }
        // Downsampled pixel i sits at 2i of the finer level.
        let d = downsample(img.view());
        assert_eq!((d.width, d.height), (8, 8));
        let p = d.view().get(3, 4);
        assert!((p[0] - 6.0).abs() < 1e-5 && (p[1] - 8.0).abs() < 1e-5);
    }

    #[test]
    fn blur_removes_checkerboard() {
        let img = Image::from_fn(16, 16, |x, y| {
            let v = ((x + y) % 2) as f32;
            [v, v, v, 1.0]
        });
        let b = blur_binomial5(img.view());
        // [1,4,6,4,1] has zero response at the Nyquist frequency.
        for y in 2..14 {
            for x in 2..14 {
                assert!((b.view().get(x, y)[0] - 0.5).abs() < 1e-6);
            }
        }
    }
}

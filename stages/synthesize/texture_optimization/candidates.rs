//! The exemplar side: its colours per pyramid level, the rotations a patch is read at, and the
//! candidate patches (full and PCA-reduced, in a kd-tree) the search picks from.

use super::pca::fit_pca;
use crate::image::knn::KdTree;
use crate::image::pca::Pca;
use glam::Vec2;
use rayon::prelude::*;

/// Exemplar RGB with bilinear lookups.
pub(super) struct Rgb {
    pub(super) w: usize,
    pub(super) h: usize,
    pub(super) px: Vec<[f32; 3]>,
}

impl Rgb {
    #[inline]
    pub(super) fn sample(&self, p: Vec2) -> [f32; 3] {
        let x = p.x.clamp(0.0, (self.w - 1) as f32);
        let y = p.y.clamp(0.0, (self.h - 1) as f32);
        let x0 = (x as usize).min(self.w - 1);
        let y0 = (y as usize).min(self.h - 1);
        let x1 = (x0 + 1).min(self.w - 1);
        let y1 = (y0 + 1).min(self.h - 1);
        let fx = x - x0 as f32;
        let fy = y - y0 as f32;
        let a = self.px[y0 * self.w + x0];
        let b = self.px[y0 * self.w + x1];
        let c = self.px[y1 * self.w + x0];
        let d = self.px[y1 * self.w + x1];
        let mut out = [0.0; 3];
        for k in 0..3 {
            let top = a[k] + (b[k] - a[k]) * fx;
            let bot = c[k] + (d[k] - c[k]) * fx;
            out[k] = top + (bot - top) * fy;
        }
        out
    }
}

impl Rgb {
    /// The exemplar filtered with a tent of half-width `width` texels at `p` (`width` 1 is
    /// the bilinear lookup): what a grid of that step sees without aliasing.
    pub(super) fn tent(&self, p: Vec2, width: f32) -> [f32; 3] {
        if width <= 1.0 {
            return self.sample(p);
        }
        let mut acc = [0.0f32; 3];
        let mut wsum = 0.0f32;
        let (x0, x1) = ((p.x - width).ceil() as i64, (p.x + width).floor() as i64);
        let (y0, y1) = ((p.y - width).ceil() as i64, (p.y + width).floor() as i64);
        for y in y0..=y1 {
            let wy = 1.0 - (y as f32 - p.y).abs() / width;
            if wy <= 0.0 {
                continue;
            }
            let yy = y.clamp(0, self.h as i64 - 1) as usize;
            for x in x0..=x1 {
                let wx = 1.0 - (x as f32 - p.x).abs() / width;
                if wx <= 0.0 {
                    continue;
                }
                let xx = x.clamp(0, self.w as i64 - 1) as usize;
                let c = self.px[yy * self.w + xx];
                let wgt = wx * wy;
                for k in 0..3 {
                    acc[k] += wgt * c[k];
                }
                wsum += wgt;
            }
        }
        acc.map(|a| a / wsum)
    }
}

/// Rotation of local `(s, t)` onto exemplar pixel axes.
#[derive(Clone, Copy)]
pub(super) struct Rot {
    pub(super) c: f32,
    pub(super) s: f32,
}

impl Rot {
    #[inline]
    pub(super) fn apply(&self, o: [f32; 2]) -> Vec2 {
        Vec2::new(o[0] * self.c - o[1] * self.s, o[0] * self.s + o[1] * self.c)
    }
}

/// One resolution level.
#[derive(Clone, Copy)]
pub(super) struct Level {
    /// Grid cells per side.
    pub(super) w: usize,
    /// Texels per grid cell.
    pub(super) step: f32,
}

impl Level {
    /// Patch side in texels.
    pub(super) fn extent(&self) -> f32 {
        self.w as f32 * self.step
    }
    pub(super) fn dim(&self) -> usize {
        self.w * self.w * 3
    }
    /// Offset in texels of grid cell `a` along one axis.
    #[inline]
    pub(super) fn cell_offset(&self, a: usize) -> f32 {
        (a as f32 - (self.w as f32 - 1.0) * 0.5) * self.step
    }
}

/// The exemplar patches of one level: every candidate centre's grid vector, its PCA
/// projection in a kd-tree, and its feature distance.
pub(super) struct Candidates {
    /// First candidate centre's x and y (the margin).
    pub(super) margin: usize,
    pub(super) nx: usize,
    pub(super) full: Vec<f32>,
    pub(super) pca: Pca,
    pub(super) tree: KdTree,
    /// Feature distance at each candidate centre; sorted copy for existence checks.
    pub(super) distance: Option<(Vec<f32>, Vec<f32>)>,
}

impl Candidates {
    pub(super) fn len(&self) -> usize {
        self.full.len() / self.pca.dim
    }
    #[inline]
    pub(super) fn centre(&self, i: u32) -> Vec2 {
        let i = i as usize;
        Vec2::new(
            (self.margin + i % self.nx) as f32,
            (self.margin + i / self.nx) as f32,
        )
    }
    /// The candidate nearest to exemplar address `p`, clamped into the candidate rectangle.
    pub(super) fn nearest_to(&self, p: [f32; 2]) -> u32 {
        let ny = self.len() / self.nx;
        let clamp = |v: f32, n: usize| {
            let v = (v.round() - self.margin as f32).clamp(0.0, (n - 1) as f32);
            if v.is_nan() { 0 } else { v as usize }
        };
        (clamp(p[1], ny) * self.nx + clamp(p[0], self.nx)) as u32
    }
    /// The candidate centred at exemplar address `p` (rounded to a pixel), if `p` is inside the
    /// candidate rectangle: no clamping, so a patch continued past the exemplar's border is not
    /// replaced by an unrelated one at the border.
    pub(super) fn at(&self, p: Vec2) -> Option<u32> {
        let ny = self.len() / self.nx;
        let (x, y) = (
            p.x.round() - self.margin as f32,
            p.y.round() - self.margin as f32,
        );
        if !(x >= 0.0 && y >= 0.0 && x < self.nx as f32 && y < ny as f32) {
            return None;
        }
        Some((y as usize * self.nx + x as usize) as u32)
    }
    /// Whether some candidate's feature distance is within `tol` of `d`.
    pub(super) fn any_within(&self, d: f32, tol: f32) -> bool {
        let Some((_, sorted)) = &self.distance else {
            return true;
        };
        let i = sorted.partition_point(|&x| x < d - tol);
        i < sorted.len() && sorted[i] <= d + tol
    }
}

/// Half-width in texels the rotated patch square reaches along the exemplar axes, rounded up to
/// whole pixels.
pub(super) fn margin(level: Level, rot: Rot) -> usize {
    let half = level.extent() * 0.5 * (rot.c.abs() + rot.s.abs());
    (half - 1e-3).ceil().max(0.0) as usize
}

pub(super) fn build_candidates(
    ex: &Rgb,
    texture_distance: Option<&[f32]>,
    level: Level,
    rot: Rot,
    components: usize,
) -> Option<Candidates> {
    let m = margin(level, rot);
    if ex.w < 2 * m + 1 || ex.h < 2 * m + 1 {
        return None;
    }
    let nx = ex.w - 2 * m;
    let ny = ex.h - 2 * m;
    // A coarse level with candidates over less than half of each side has too few to choose
    // from (a 60-texel patch in a 64-texel exemplar has 16) and only scrambles the layout.
    if level.step > 1.0 && (2 * nx < ex.w || 2 * ny < ex.h) {
        return None;
    }
    let dim = level.dim();
    let offsets: Vec<Vec2> = (0..level.w * level.w)
        .map(|c| {
            rot.apply([
                level.cell_offset(c % level.w),
                level.cell_offset(c / level.w),
            ])
        })
        .collect();
    let mut full = vec![0.0f32; nx * ny * dim];
    full.par_chunks_mut(dim).enumerate().for_each(|(i, out)| {
        let centre = Vec2::new((m + i % nx) as f32, (m + i / nx) as f32);
        for (c, o) in offsets.iter().enumerate() {
            out[c * 3..c * 3 + 3].copy_from_slice(&ex.tent(centre + *o, level.step));
        }
    });
    let pca = fit_pca(&full, dim, components);
    let proj = pca.project_all(&full);
    let tree = KdTree::build(&proj, pca.components());
    let distance = texture_distance.map(|td| {
        let d: Vec<f32> = (0..nx * ny)
            .map(|i| td[(m + i / nx) * ex.w + m + i % nx])
            .collect();
        let mut sorted: Vec<f32> = d.iter().copied().filter(|x| !x.is_nan()).collect();
        sorted.sort_by(f32::total_cmp);
        (d, sorted)
    });
    Some(Candidates {
        margin: m,
        nx,
        full,
        pca,
        tree,
        distance,
    })
}

//! The surface's metric over a geometry image, as the per-texel anisotropic map that lets
//! geometric texture synthesis lay its templates out in surface units.
//!
//! Lai et al. (§4.3) scale the texture by one number per sample, `R(v)`, the mean distance to
//! the grid neighbours. A geometry image of a long thin part (a leg, a neck, a trunk) stretches
//! the surface much more one way than the other: one grid step along the part can cover
//! several times the surface that a step across it covers. A template laid out in grid texels
//! then copies the sample's texels one per grid step in both directions, and on the surface the
//! relief is drawn out into streaks along the part.
//!
//! With `J = [X_u X_v]` the Jacobian of the map from the grid to the surface (central
//! differences, one-sided at the border), `G = JᵀJ` is the metric: a grid offset `o` covers
//! `√(oᵀ G o)` on the surface. Its unimodular square root `A = (G / √det G)^{1/2}` maps grid
//! offsets to sample offsets so that equal surface lengths are equal sample lengths, with the
//! area (and so the isotropic scale `R`) left to the variants: `A` is symmetric with
//! eigenvalues `λ` and `1/λ`, `λ⁴` the ratio of the metric's eigenvalues (so `λ²` is the
//! ratio of the surface lengths of grid steps along its two axes). Synthesis reads
//! template tap `s` (sample texels) at grid offset `round(A⁻¹ s)` and shifts a coherent
//! candidate by `A o` for a neighbour at grid offset `o`.
//!
//! `λ` is clamped to [`MAX_STRETCH`]: near cut-nodes and the square's corners the grid can be
//! nearly degenerate, and a template spread over dozens of texels there reads unrelated parts
//! of the surface.

use crate::geom::geometry_image::GeometryImage;
use glam::{DVec3, Vec2};

/// Largest `λ` (fourth root of the metric's eigenvalue ratio) that is undone; beyond it the
/// map keeps `λ = MAX_STRETCH` along the same axes.
pub const MAX_STRETCH: f64 = 4.0;

/// Per texel, the map `A` from grid offsets `(x = column, y = row)` to sample offsets, and its
/// inverse; and `g = (det G)^{1/4}`, the geometric mean of the grid's surface spacings along
/// the metric's axes (the isotropic spacing that `A` leaves to the scale `R`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfaceMetric {
    /// `A` row-major: `[a00, a01, a10, a11]`.
    pub a: [f32; 4],
    /// `A⁻¹` row-major.
    pub inv: [f32; 4],
    /// `(det G)^{1/4}`; 0 where the grid is degenerate (then `A` is the identity).
    pub spacing: f32,
}

impl SurfaceMetric {
    pub const IDENTITY: SurfaceMetric = SurfaceMetric {
        a: [1.0, 0.0, 0.0, 1.0],
        inv: [1.0, 0.0, 0.0, 1.0],
        spacing: 0.0,
    };

    /// The metric of the symmetric 2×2 matrix `[[g11, g12], [g12, g22]]` (`G = JᵀJ`).
    pub fn from_metric(g11: f64, g12: f64, g22: f64) -> SurfaceMetric {
        Self::from_metric_clamped(g11, g12, g22, MAX_STRETCH)
    }

    /// [`Self::from_metric`] with `λ` clamped to `max_stretch` (≥ 1) instead of
    /// [`MAX_STRETCH`].
    pub fn from_metric_clamped(g11: f64, g12: f64, g22: f64, max_stretch: f64) -> SurfaceMetric {
        let det = g11 * g22 - g12 * g12;
        if !(det.is_finite() && det > 0.0 && g11 > 0.0 && g22 > 0.0) {
            return SurfaceMetric::IDENTITY;
        }
        let s = det.sqrt();
        // Ĝ = G / √det G has eigenvalues μ ≥ 1 and 1/μ.
        let (a, b, c) = (g11 / s, g12 / s, g22 / s);
        let half = 0.5 * (a + c);
        let mu = half + (half * half - 1.0).max(0.0).sqrt();
        // Unit eigenvector of μ.
        let e = if b.abs() > 1e-12 {
            let v = (b, mu - a);
            let l = (v.0 * v.0 + v.1 * v.1).sqrt();
            (v.0 / l, v.1 / l)
        } else if a >= c {
            (1.0, 0.0)
        } else {
            (0.0, 1.0)
        };
        let lambda = mu.sqrt().min(max_stretch.max(1.0));
        // A = λ e eᵀ + λ⁻¹ (I − e eᵀ); A⁻¹ swaps λ and λ⁻¹.
        let m = |l: f64| {
            let (p, q) = (l, 1.0 / l);
            [
                (q + (p - q) * e.0 * e.0) as f32,
                ((p - q) * e.0 * e.1) as f32,
                ((p - q) * e.0 * e.1) as f32,
                (q + (p - q) * e.1 * e.1) as f32,
            ]
        };
        SurfaceMetric {
            a: m(lambda),
            inv: m(1.0 / lambda),
            spacing: s.sqrt() as f32,
        }
    }

    /// `λ`, the larger eigenvalue of `A` (clamped as `A` is): a grid step along the stretched
    /// direction spans `λ²` times the length on the surface of a step across it. 1 where
    /// isotropic.
    pub fn stretch(&self) -> f32 {
        let (a, b, c) = (self.a[0], self.a[1], self.a[3]);
        let half = 0.5 * (a + c);
        half + (half * half - (a * c - b * b)).max(0.0).sqrt()
    }

    /// `A v`: a grid offset in sample texels.
    #[inline]
    pub fn to_sample(&self, v: Vec2) -> Vec2 {
        Vec2::new(
            self.a[0] * v.x + self.a[1] * v.y,
            self.a[2] * v.x + self.a[3] * v.y,
        )
    }

    /// `A⁻¹ s`: the (fractional) grid offset `(dx, dy)` where sample offset `s` lies.
    #[inline]
    pub fn to_grid_f(&self, s: (i32, i32)) -> Vec2 {
        let (x, y) = (s.0 as f32, s.1 as f32);
        Vec2::new(
            self.inv[0] * x + self.inv[1] * y,
            self.inv[2] * x + self.inv[3] * y,
        )
    }

    /// `round(A⁻¹ s)`: the grid point nearest to where sample offset `s` lies.
    #[inline]
    pub fn to_grid(&self, s: (i32, i32)) -> (i32, i32) {
        let (x, y) = (s.0 as f32, s.1 as f32);
        let gx = self.inv[0] * x + self.inv[1] * y;
        let gy = self.inv[2] * x + self.inv[3] * y;
        ((gx + 0.5).floor() as i32, (gy + 0.5).floor() as i32)
    }
}

/// The metric of every sample of `gi` (`i * n + j`), from the grid derivatives of its
/// positions.
pub fn surface_metrics(gi: &GeometryImage) -> Vec<SurfaceMetric> {
    surface_metrics_clamped(gi, MAX_STRETCH)
}

/// The share of `metrics` stretched to [`MAX_STRETCH`] (within 10⁻³): where a geometry image
/// samples the surface so unevenly that the metric no longer undoes it, and a sample's fine
/// lines fall between texels along the long direction.
pub fn share_at_max_stretch(metrics: &[SurfaceMetric]) -> f64 {
    if metrics.is_empty() {
        return 0.0;
    }
    let at_max = metrics
        .iter()
        .filter(|m| m.stretch() as f64 >= MAX_STRETCH - 1e-3)
        .count();
    at_max as f64 / metrics.len() as f64
}

/// [`surface_metrics`] with the stretch clamped to `max_stretch` (see
/// [`SurfaceMetric::from_metric_clamped`]).
pub fn surface_metrics_clamped(gi: &GeometryImage, max_stretch: f64) -> Vec<SurfaceMetric> {
    let n = gi.n as usize;
    if n < 2 {
        return vec![SurfaceMetric::IDENTITY; n * n];
    }
    let p = |i: usize, j: usize| gi.positions[i * n + j].as_dvec3();
    let deriv = |a: DVec3, b: DVec3, steps: f64| (b - a) / steps;
    (0..n * n)
        .map(|k| {
            let (i, j) = (k / n, k % n);
            let xu = match j {
                0 => deriv(p(i, 0), p(i, 1), 1.0),
                _ if j == n - 1 => deriv(p(i, n - 2), p(i, n - 1), 1.0),
                _ => deriv(p(i, j - 1), p(i, j + 1), 2.0),
            };
            let xv = match i {
                0 => deriv(p(0, j), p(1, j), 1.0),
                _ if i == n - 1 => deriv(p(n - 2, j), p(n - 1, j), 1.0),
                _ => deriv(p(i - 1, j), p(i + 1, j), 2.0),
            };
            SurfaceMetric::from_metric_clamped(xu.dot(xu), xu.dot(xv), xv.dot(xv), max_stretch)
        })
        .collect()
}

/// The angle-preserving check of [`SurfaceMetric`]: `|J A⁻¹ s|` is the same for every unit
/// `s` (up to the clamp), which is what makes the relief isotropic on the surface.
#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_share_at_max_stretch_counts_the_clamped_texels() {
        // λ⁴ is the ratio of the metric's eigenvalues: 10⁴ is λ = 10, clamped; 16 is λ = 2.
        let clamped = SurfaceMetric::from_metric(1.0, 0.0, 1e4);
        let mild = SurfaceMetric::from_metric(16.0, 0.0, 1.0);
        let flat = SurfaceMetric::from_metric(1.0, 0.0, 1.0);
        assert_eq!(share_at_max_stretch(&[]), 0.0);
        assert_eq!(share_at_max_stretch(&[clamped, clamped]), 1.0);
        assert_eq!(share_at_max_stretch(&[clamped, mild, flat, mild]), 0.25);
        assert_eq!(share_at_max_stretch(&[mild, flat]), 0.0);
    }

    fn apply(m: &[f32; 4], v: Vec2) -> Vec2 {
        Vec2::new(m[0] * v.x + m[1] * v.y, m[2] * v.x + m[3] * v.y)
    }

    #[test]
    fn a_sheared_stretched_grid_becomes_a_similarity() {
        // J maps the grid's x to (3, 0, 0) and y to (1, 0.5, 0): stretched and sheared.
        let (xu, xv) = (DVec3::new(3.0, 0.0, 0.0), DVec3::new(1.0, 0.5, 0.0));
        let m = SurfaceMetric::from_metric(xu.dot(xu), xu.dot(xv), xv.dot(xv));
        let j = |g: Vec2| xu * g.x as f64 + xv * g.y as f64;
        let lens: Vec<f64> = (0..16)
            .map(|k| {
                let s = Vec2::from_angle(k as f32 * 0.39).rotate(Vec2::X);
                j(apply(&m.inv, s)).length()
            })
            .collect();
        for l in &lens {
            assert!((l / lens[0] - 1.0).abs() < 1e-5, "{lens:?}");
        }
        // λ² is the square root of the metric's eigenvalue ratio: G = [[9, 3], [3, 1.25]].
        let (ev_hi, ev_lo) = {
            let (a, b, c) = (9.0f64, 3.0, 1.25);
            let h = 0.5 * (a + c);
            let d = (h * h - (a * c - b * b)).sqrt();
            (h + d, h - d)
        };
        let want = (ev_hi / ev_lo).sqrt().sqrt();
        assert!(
            (m.stretch() as f64 - want).abs() < 1e-4,
            "{} against {want}",
            m.stretch()
        );
        assert_eq!(SurfaceMetric::IDENTITY.stretch(), 1.0);
        // The common length is the isotropic spacing: √|det J| = √1.5.
        assert!((lens[0] - 1.5f64.sqrt()).abs() < 1e-5, "{}", lens[0]);
        assert!((m.spacing as f64 - 1.5f64.sqrt()).abs() < 1e-5);
        // A and A⁻¹ are inverse, and A is unimodular.
        let a = m.a;
        assert!((a[0] * a[3] - a[1] * a[2] - 1.0).abs() < 1e-5);
        let v = apply(&m.a, apply(&m.inv, Vec2::new(0.3, -0.7)));
        assert!((v - Vec2::new(0.3, -0.7)).length() < 1e-5);
    }

    #[test]
    fn the_identity_where_isotropic_or_degenerate_and_the_stretch_clamped() {
        let m = SurfaceMetric::from_metric(4.0, 0.0, 4.0);
        assert_eq!(m.a, [1.0, 0.0, 0.0, 1.0]);
        assert_eq!(m.to_grid((2, -1)), (2, -1));
        assert_eq!(
            SurfaceMetric::from_metric(1.0, 1.0, 1.0),
            SurfaceMetric::IDENTITY
        );
        assert_eq!(
            SurfaceMetric::from_metric(f64::NAN, 0.0, 1.0),
            SurfaceMetric::IDENTITY
        );
        // A ratio of 10⁴ in the metric (λ = 10) is clamped to MAX_STRETCH along y.
        let m = SurfaceMetric::from_metric(1.0, 0.0, 1e4);
        assert!((m.a[3] as f64 - MAX_STRETCH).abs() < 1e-5 && m.a[1] == 0.0);
        assert!((m.a[0] as f64 - 1.0 / MAX_STRETCH).abs() < 1e-6);
        assert!(
            (m.stretch() as f64 - MAX_STRETCH).abs() < 1e-5,
            "{}",
            m.stretch()
        );
        // Along the stretched axis a grid step is several sample texels; across, a sample
        // texel is several grid steps.
        assert_eq!(m.to_grid((0, 4)), (0, 1));
        assert_eq!(m.to_grid((1, 0)), (4, 0));
    }
}

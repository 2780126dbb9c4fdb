//! Reading the exemplar inside copied patches, for atlases baked from per-vertex synthesis.
//!
//! Feature-aligned texturing's final discrete pass (Xu et al., "Feature-Aligned Shape
//! Texturing", §5, with the discrete solver of Han et al. 2006) and graph matching's
//! transfers (Bangay & Morkel, §3.4) give every vertex the exemplar address its colour was
//! copied from. Inside a triangle whose corners copied one patch, the addresses interpolated
//! across it are that patch's own texels, so an atlas can hold the exemplar's detail at its
//! own texel density instead of the vertex spacing's (as jump maps give each triangle
//! exemplar coordinates). Across a seam between patches there is no one address to
//! interpolate: each corner's patch is continued to the point through that corner's frame
//! (the synthesis's, or one fitted to the addresses) and the reads are blended, so a seam is
//! a short blend of textures that keep their detail, not a jagged edge of flat colours.

use crate::geom::Mesh;
use glam::Vec3;
use serde::{Deserialize, Serialize};

/// How an address between exemplar texels is read.
///
/// Addresses inside a patch fall between texels wherever the patch is shifted or turned
/// against the exemplar's grid (almost everywhere on a surface), and a bilinear read there
/// averages up to four texels: at a half-texel offset it is a 2×2 box filter. Measured along
/// the surface (`texsyn score`, gradient ratio / nearest-patch ratio): on a flat sheet with
/// one straight curve and wood2 (the score test's sheet), bilinear keeps 0.53 of the
/// exemplar's gradient energy, bicubic 0.64 and nearest 1.00 (ratios not measured there);
/// on fandisk with brick bilinear keeps 0.53 at a ratio of
/// 0.75 and nearest 1.02 at 0.81, where nearest reads show the exemplar's texel staircase
/// wherever the field turns a patch against its grid. Nearest copies the exemplar's texels
/// themselves, as the discrete pass gives each vertex one; bilinear is the smoother
/// resampling. Bicubic lies between: fandisk 0.70 at a ratio of 0.77, the cow's
/// graph-matching atlas 0.82 at 0.92 (bilinear 0.69 at 0.88, nearest 1.01 at 0.98).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ExemplarSampling {
    /// The four texels around the address, weighted by distance.
    Bilinear,
    /// The texel nearest the address.
    Nearest,
    /// The sixteen texels around the address, weighted by the Catmull–Rom cubic (Keys'
    /// a = −½), kept within those texels' range: a half-texel offset is not a box filter.
    /// The default: the sharpness nearest gives without its staircase, at a few hundredths of
    /// nearest-patch ratio over bilinear.
    #[default]
    Bicubic,
}

impl ExemplarSampling {
    pub fn is_bicubic(&self) -> bool {
        *self == ExemplarSampling::Bicubic
    }

    /// The exemplar's colour at `at` (texel centres at whole numbers, clamped at the border).
    pub fn read(self, exemplar: crate::image::ImageView, at: glam::Vec2) -> [f32; 4] {
        match self {
            ExemplarSampling::Bilinear => exemplar.sample(at),
            ExemplarSampling::Nearest => {
                exemplar.get_clamped(at.x.round() as i64, at.y.round() as i64)
            }
            ExemplarSampling::Bicubic => bicubic(exemplar, at),
        }
    }
}

/// Catmull–Rom weights of the four texels at −1, 0, 1, 2 for a read `t` ∈ [0, 1) past texel
/// 0: they sum to 1, give texel 0 alone at `t = 0`, and reproduce linear ramps.
fn catmull_rom(t: f32) -> [f32; 4] {
    [
        ((-0.5 * t + 1.0) * t - 0.5) * t,
        (1.5 * t - 2.5) * t * t + 1.0,
        ((-1.5 * t + 2.0) * t + 0.5) * t,
        (0.5 * t - 0.5) * t * t,
    ]
}

/// [`ExemplarSampling::Bicubic`]: border texels repeat outward, as the other reads clamp.
fn bicubic(exemplar: crate::image::ImageView, at: glam::Vec2) -> [f32; 4] {
    let (x0, y0) = (at.x.floor(), at.y.floor());
    let (wx, wy) = (catmull_rom(at.x - x0), catmull_rom(at.y - y0));
    // `as` saturates a huge or infinite address; the steps from it saturate too.
    let (x0, y0) = ((x0 as i64).saturating_sub(1), (y0 as i64).saturating_sub(1));
    let mut sum = [0.0f32; 4];
    let (mut lo, mut hi) = ([f32::INFINITY; 4], [f32::NEG_INFINITY; 4]);
    for (j, wy) in wy.iter().enumerate() {
        for (i, wx) in wx.iter().enumerate() {
            let c = exemplar.get_clamped(x0.saturating_add(i as i64), y0.saturating_add(j as i64));
            for k in 0..4 {
                sum[k] += wx * wy * c[k];
                lo[k] = lo[k].min(c[k]);
                hi[k] = hi[k].max(c[k]);
            }
        }
    }
    std::array::from_fn(|k| sum[k].clamp(lo[k], hi[k]))
}

/// Where an atlas looks the exemplar up instead of interpolating vertex colours: the
/// triangles whose three corners copied their colours from one exemplar patch. Such corners'
/// addresses are one similarity map of their positions (the patch's frame), so the
/// addresses interpolated across the triangle are the patch's own texels, finer than the
/// vertex spacing. A triangle counts as one patch's when each of its edges is as long in the
/// exemplar as on the surface, at the run's texel scale (the median ratio over all edges,
/// which lie inside patches far more often than across seams), within 25 % and 0.1 texel:
/// two patches' addresses differ by whole texels, while one patch's frame only foreshortens
/// edges a little where the surface bends away from the patch's tangent plane.
pub struct ExemplarLookup<'a> {
    source: &'a [[f32; 2]],
    exemplar: Option<crate::image::ImageView<'a>>,
    sampling: ExemplarSampling,
    /// Per triangle: its corners copied one patch.
    one_patch: Vec<bool>,
    /// How each vertex's patch continues around it, for reads across seams.
    frames: Option<PatchFrames<'a>>,
    /// Texels per unit length: the median over the edges between vertices with addresses.
    scale: f32,
}

/// Per vertex, the linear map from a surface offset to an exemplar offset that the vertex's
/// patch was copied with: `d ↦ (d · axes[v][0], d · axes[v][1])` texels.
pub struct PatchFrames<'a> {
    pub positions: &'a [Vec3],
    pub axes: Vec<[Vec3; 2]>,
}

impl<'a> PatchFrames<'a> {
    /// Each vertex's frame fitted to the patch it copied: the linear map of the tangent
    /// plane that best carries the edges of its one-patch triangles (`one_patch`) onto their
    /// address differences (least squares). Where the vertex lies in no such triangle, or
    /// they span no plane, its axes are NaN and [`ExemplarLookup::across_seam`] does not
    /// continue its patch. The fit needs no convention of how the synthesis laid its
    /// patches (field, handedness, principal angle, scale): it reads them off the addresses.
    pub fn fitted(mesh: &'a Mesh, source: &[[f32; 2]], one_patch: &[bool]) -> Self {
        let n = mesh.positions.len();
        let normals = mesh.vertex_normals();
        let basis: Vec<(Vec3, Vec3)> = (normals.iter())
            .map(|&nrm| {
                let nrm = nrm.try_normalize().unwrap_or(Vec3::Z);
                let t1 = nrm.any_orthonormal_vector();
                (t1, nrm.cross(t1))
            })
            .collect();
        // Per vertex: Σ p pᵀ (symmetric: xx, xy, yy) and Σ s pᵀ (2×2), p the edge in the
        // tangent basis, s its address difference.
        let mut m = vec![[0.0f64; 3]; n];
        let mut b = vec![[0.0f64; 4]; n];
        for (t, tri) in mesh.triangles.iter().enumerate() {
            if !one_patch.get(t).copied().unwrap_or(false) {
                continue;
            }
            for k in 0..3 {
                let v = tri[k] as usize;
                let (t1, t2) = basis[v];
                for u in [tri[(k + 1) % 3] as usize, tri[(k + 2) % 3] as usize] {
                    let d = mesh.positions[u] - mesh.positions[v];
                    let (px, py) = (d.dot(t1) as f64, d.dot(t2) as f64);
                    let sx = (source[u][0] - source[v][0]) as f64;
                    let sy = (source[u][1] - source[v][1]) as f64;
                    m[v][0] += px * px;
                    m[v][1] += px * py;
                    m[v][2] += py * py;
                    b[v][0] += sx * px;
                    b[v][1] += sx * py;
                    b[v][2] += sy * px;
                    b[v][3] += sy * py;
                }
            }
        }
        let axes = (0..n)
            .map(|v| {
                let [xx, xy, yy] = m[v];
                let det = xx * yy - xy * xy;
                // Edges along one line (or none, or only slivers) fix no map of the plane, and
                // address noise would blow up across them; NaN sums fail too.
                let spans_plane = det > 1e-3 * (xx + yy) * (xx + yy);
                if !spans_plane {
                    return [Vec3::NAN; 2];
                }
                // A = B M⁻¹, M⁻¹ = [yy −xy; −xy xx] / det.
                let row = |bx: f64, by: f64| {
                    let (a0, a1) = ((bx * yy - by * xy) / det, (by * xx - bx * xy) / det);
                    let (t1, t2) = basis[v];
                    t1 * a0 as f32 + t2 * a1 as f32
                };
                [row(b[v][0], b[v][1]), row(b[v][2], b[v][3])]
            })
            .collect();
        PatchFrames {
            positions: &mesh.positions,
            axes,
        }
    }
}

impl<'a> ExemplarLookup<'a> {
    /// Reads across seams continue each corner's patch with frames fitted to the addresses
    /// themselves ([`PatchFrames::fitted`]).
    /// A fitted axis more than 4 times longer or shorter than the lookup's texel scale (the
    /// median over all edges) is not a patch's frame but a poor fit, and is left out.
    pub fn with_fitted_frames(self, mesh: &'a Mesh) -> Self {
        let mut frames = PatchFrames::fitted(mesh, self.source, &self.one_patch);
        let (lo, hi) = (0.25 * self.scale, 4.0 * self.scale);
        for axes in &mut frames.axes {
            if axes.iter().any(|a| !(lo..=hi).contains(&a.length())) {
                *axes = [Vec3::NAN; 2];
            }
        }
        self.with_frames(frames)
    }

    /// `source`: per vertex of `mesh`, the exemplar address its colour was copied from
    /// (negative or NaN where it has none).
    pub fn new(
        mesh: &Mesh,
        source: &'a [[f32; 2]],
        exemplar: crate::image::ImageView<'a>,
        sampling: ExemplarSampling,
    ) -> Self {
        let m = mesh;
        let none = ExemplarLookup {
            source,
            exemplar: None,
            sampling,
            one_patch: Vec::new(),
            frames: None,
            scale: 0.0,
        };
        if source.len() != m.positions.len() {
            return none;
        }
        let valid = |v: u32| has_address(source[v as usize]);
        let edge = |a: u32, b: u32| {
            let (sa, sb) = (source[a as usize], source[b as usize]);
            let texels = glam::Vec2::new(sa[0] - sb[0], sa[1] - sb[1]).length();
            (
                texels,
                m.positions[a as usize].distance(m.positions[b as usize]),
            )
        };
        let mut ratios: Vec<f32> = m
            .triangles
            .iter()
            .filter(|t| t.iter().all(|&v| valid(v)))
            .flat_map(|t| [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])])
            .map(|(a, b)| edge(a, b))
            .filter(|&(_, len)| len > 0.0)
            .map(|(texels, len)| texels / len)
            .collect();
        if ratios.is_empty() {
            return none;
        }
        let mid = ratios.len() / 2;
        let scale = *ratios.select_nth_unstable_by(mid, f32::total_cmp).1;
        let fits =
            |(texels, len): (f32, f32)| (texels - len * scale).abs() <= 0.1 + 0.25 * len * scale;
        let one_patch = m
            .triangles
            .iter()
            .map(|t| {
                t.iter().all(|&v| valid(v))
                    && [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])]
                        .into_iter()
                        .all(|(a, b)| fits(edge(a, b)))
            })
            .collect::<Vec<bool>>();
        ExemplarLookup {
            source,
            exemplar: Some(exemplar),
            sampling,
            one_patch,
            frames: None,
            scale,
        }
    }

    /// Reads across seams continue each corner's patch with `frames` ([`Self::across_seam`]).
    pub fn with_frames(mut self, frames: PatchFrames<'a>) -> Self {
        if frames.positions.len() == self.source.len() && frames.axes.len() == self.source.len() {
            self.frames = Some(frames);
        }
        self
    }

    /// Whether the lookup reads the exemplar at all (addresses of the mesh's size, and some
    /// triangle with three).
    pub fn is_active(&self) -> bool {
        self.exemplar.is_some()
    }

    /// Whether triangle `t`'s corners copied one patch (false when nothing is looked up).
    pub fn one_patch(&self, t: usize) -> bool {
        self.one_patch.get(t).copied().unwrap_or(false)
    }

    /// The share of triangles looked up in the exemplar.
    pub fn looked_up_share(&self) -> f64 {
        let n = self.one_patch.iter().filter(|&&b| b).count();
        n as f64 / self.one_patch.len().max(1) as f64
    }

    /// The colour at barycentrics `l` (summing to 1) of triangle `t` (corners `tri`)
    /// when its corners copied one patch; `None` across a seam.
    pub fn colour(&self, t: usize, tri: [u32; 3], l: [f32; 3]) -> Option<Vec3> {
        let exemplar = self.exemplar?;
        if !self.one_patch[t] {
            return None;
        }
        let mut at = glam::Vec2::ZERO;
        for k in 0..3 {
            at += glam::Vec2::from(self.source[tri[k] as usize]) * l[k];
        }
        let c = self.sampling.read(exemplar, at);
        Some(Vec3::new(c[0], c[1], c[2]))
    }
}

impl ExemplarLookup<'_> {
    /// What an atlas holds at barycentrics `l` of triangle `t` (corners `tri`): the exemplar
    /// at the interpolated address inside one patch ([`Self::colour`]), the corners' patches
    /// continued and blended across a seam ([`Self::across_seam`]), else the colour of the
    /// nearest corner (`vertex_colour`), so a seam without addresses stays a line.
    pub fn texture_colour(
        &self,
        t: usize,
        tri: [u32; 3],
        l: [f32; 3],
        vertex_colour: impl Fn(u32) -> Vec3,
    ) -> Vec3 {
        (self.colour(t, tri, l))
            .or_else(|| self.across_seam(tri, l))
            .unwrap_or_else(|| vertex_colour(tri[nearest_corner(l)]))
    }

    /// The colour at barycentrics `l` of a triangle whose corners copied different patches,
    /// when the lookup has [`PatchFrames`]: each corner's patch continued to the point (its
    /// address plus the point's offset from it through its frame), read, and weighted by
    /// `l`, so the seam is a short blend of textures that each keep their detail, with no
    /// step and no flat vertex colour. A corner without an address or a frame is left out
    /// and the others' weights renormalized; `None` without frames or when no corner is left.
    pub fn across_seam(&self, tri: [u32; 3], l: [f32; 3]) -> Option<Vec3> {
        let (exemplar, frames) = (self.exemplar?, self.frames.as_ref()?);
        let p: Vec3 = (0..3)
            .map(|k| frames.positions[tri[k] as usize] * l[k])
            .sum();
        let mut sum = Vec3::ZERO;
        let mut weight = 0.0;
        for k in 0..3 {
            let v = tri[k] as usize;
            let (s, [ax, ay]) = (self.source[v], frames.axes[v]);
            if !has_address(s) || !ax.is_finite() || !ay.is_finite() {
                continue;
            }
            let d = p - frames.positions[v];
            let at = glam::Vec2::new(s[0] + d.dot(ax), s[1] + d.dot(ay));
            let c = self.sampling.read(exemplar, at);
            sum += Vec3::new(c[0], c[1], c[2]) * l[k];
            weight += l[k];
        }
        (weight > 1e-6).then(|| sum / weight)
    }
}

/// Whether a vertex copied its colour from an address (negative or NaN: it did not).
fn has_address(s: [f32; 2]) -> bool {
    s[0] > -0.5
}

/// The corner of largest barycentric weight (the first of equals).
pub fn nearest_corner(l: [f32; 3]) -> usize {
    (0..3)
        .max_by(|&a, &b| l[a].total_cmp(&l[b]).then(b.cmp(&a)))
        .unwrap_or(0)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An exemplar whose red and green are its texel address / 64, so a read tells where it
    /// was made, and whose blue is a one-texel checkerboard, which tells a blend of reads
    /// from a read of blended addresses.
    fn ramp() -> crate::image::Image {
        crate::image::Image::from_fn(64, 64, |x, y| {
            [x as f32 / 64.0, y as f32 / 64.0, ((x + y) % 2) as f32, 1.0]
        })
    }

    /// Two triangles of a unit square.
    fn square() -> Mesh {
        let p = vec![
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(1.0, 0.0, 0.0),
            Vec3::new(1.0, 1.0, 0.0),
            Vec3::new(0.0, 1.0, 0.0),
        ];
        Mesh::new(p, vec![[0, 1, 2], [0, 2, 3]])
    }

    #[test]
    fn across_a_seam_each_corner_s_patch_is_continued_to_the_point_and_blended() {
        let (m, ex) = (square(), ramp());
        // Corners 0, 1 and 3 copied one patch at 16 texels per unit; corner 2 another,
        // turned a quarter and 8 texels per unit.
        let source = [[10.0, 10.0], [26.0, 10.0], [46.0, 30.0], [10.0, 26.0]];
        let mut axes = vec![[Vec3::X * 16.0, Vec3::Y * 16.0]; 4];
        axes[2] = [Vec3::Y * 8.0, -Vec3::X * 8.0];
        let frames = PatchFrames {
            positions: &m.positions,
            axes,
        };
        let lookup = ExemplarLookup::new(&m, &source, ex.view(), ExemplarSampling::Nearest)
            .with_frames(frames);
        assert!(
            !lookup.one_patch(0) && !lookup.one_patch(1),
            "both touch corner 2"
        );
        assert_eq!(lookup.colour(0, m.triangles[0], [0.2, 0.3, 0.5]), None);
        let read = |x: f32, y: f32| {
            let (x, y) = (x.round(), y.round());
            Vec3::new(x / 64.0, y / 64.0, (x + y).rem_euclid(2.0))
        };
        // At a corner: that corner's own address.
        let at_corner = lookup.across_seam(m.triangles[0], [0.0, 0.0, 1.0]).unwrap();
        assert!((at_corner - read(46.0, 30.0)).abs().max_element() < 1e-6);
        // At (0.75, 0.5): corners 0 and 1 continue to (22, 18), corner 2 through its own
        // frame by (−0.25, −0.5) to (42, 32); the reads are blended by the barycentrics (a
        // read of the blended address, (32, 25), would have blue 1, not 0).
        let l = [0.25, 0.25, 0.5];
        let got = lookup.across_seam(m.triangles[0], l).unwrap();
        let want = read(22.0, 18.0) * 0.5 + read(42.0, 32.0) * 0.5;
        assert!(
            (got - want).abs().max_element() < 1e-6,
            "{got} against {want}"
        );
        // Without frames there is nothing to continue. A corner without an address is left
        // out and the others renormalized.
        let plain = ExemplarLookup::new(&m, &source, ex.view(), ExemplarSampling::Nearest);
        assert_eq!(plain.across_seam(m.triangles[0], l), None);
        // (A third triangle without corner 2 keeps the lookup in use.)
        let m = Mesh::new(m.positions.clone(), vec![[0, 1, 2], [0, 2, 3], [0, 1, 3]]);
        let missing = [
            [10.0, 10.0],
            [26.0, 10.0],
            [f32::NAN, f32::NAN],
            [10.0, 26.0],
        ];
        let frames = PatchFrames {
            positions: &m.positions,
            axes: vec![[Vec3::X * 16.0, Vec3::Y * 16.0]; 4],
        };
        let lookup = ExemplarLookup::new(&m, &missing, ex.view(), ExemplarSampling::Nearest)
            .with_frames(frames);
        assert!(lookup.is_active());
        let got = lookup.across_seam(m.triangles[0], l).unwrap();
        assert!((got - read(22.0, 18.0)).abs().max_element() < 1e-6, "{got}");
    }

    #[test]
    fn fitted_frames_recover_a_sheared_mirrored_map_and_leave_lone_vertices_out() {
        // An irregular mesh on a tilted plane copied through one sheared, mirrored, unequally
        // scaled map: every vertex in a triangle must get that map back; a vertex in no
        // triangle gets none.
        let (u, v) = (Vec3::new(1.0, 0.0, 0.5).normalize(), Vec3::Y);
        let plane = [
            [0.0, 0.0],
            [1.0, 0.1],
            [0.3, 0.9],
            [1.2, 1.1],
            [0.6, 0.4],
            [2.0, 2.0],
        ];
        let positions: Vec<Vec3> = plane.iter().map(|p| u * p[0] + v * p[1]).collect();
        let map = |p: Vec3| {
            let (a, b) = (p.dot(u), p.dot(v));
            [5.0 + 12.0 * a + 3.0 * b, 40.0 + 2.0 * a - 7.0 * b]
        };
        let source: Vec<[f32; 2]> = positions.iter().map(|&p| map(p)).collect();
        let m = Mesh::new(positions, vec![[0, 1, 4], [1, 3, 4], [3, 2, 4], [2, 0, 4]]);
        let frames = PatchFrames::fitted(&m, &source, &[true; 4]);
        for k in 0..5 {
            let [ax, ay] = frames.axes[k];
            for d in [u, v, u - v * 0.3] {
                let want = map(m.positions[k] + d);
                let got = [source[k][0] + d.dot(ax), source[k][1] + d.dot(ay)];
                assert!(
                    (got[0] - want[0]).abs() < 1e-3 && (got[1] - want[1]).abs() < 1e-3,
                    "vertex {k}: {got:?} against {want:?}"
                );
            }
        }
        assert!(frames.axes[5][0].is_nan(), "vertex 5 lies in no triangle");
        let none = PatchFrames::fitted(&m, &source, &[false; 4]);
        assert!(none.axes.iter().all(|a| a[0].is_nan()));
    }

    #[test]
    fn inside_one_patch_the_interpolated_address_is_read() {
        let (m, ex) = (square(), ramp());
        let source = [[10.0, 10.0], [26.0, 10.0], [26.0, 26.0], [10.0, 26.0]];
        let lookup = ExemplarLookup::new(&m, &source, ex.view(), ExemplarSampling::Nearest);
        assert!(lookup.one_patch(0) && lookup.one_patch(1));
        assert_eq!(lookup.looked_up_share(), 1.0);
        // (0.75, 0.5) is address (22, 18), read at its nearest texel.
        let c = lookup.colour(0, m.triangles[0], [0.25, 0.25, 0.5]).unwrap();
        assert!(
            (c - Vec3::new(22.0 / 64.0, 18.0 / 64.0, 0.0))
                .abs()
                .max_element()
                < 1e-6
        );
    }

    /// Bicubic reads give a texel itself at its centre, reproduce a linear ramp, and are
    /// sharper than bilinear across a step: a quarter texel past the last dark texel they
    /// stay nearer the dark side, without leaving the texels' range.
    #[test]
    fn bicubic_reads_keep_texels_ramps_and_sharper_steps() {
        for t in [0.0f32, 0.1, 0.25, 0.5, 0.9] {
            let w = catmull_rom(t);
            assert!((w.iter().sum::<f32>() - 1.0).abs() < 1e-6, "{t}: {w:?}");
        }
        let grey = |v: f32| [v, v, v, 1.0];
        // Each profile runs along x and, transposed, along y, read off the other axis's
        // texel centres: a read that mixes up the axes, or the rows, fails one of the two.
        let along = |f: fn(u32) -> f32| {
            [
                crate::image::Image::from_fn(8, 4, move |x, _| grey(f(x))),
                crate::image::Image::from_fn(4, 8, move |_, y| grey(f(y))),
            ]
        };
        let reads = |imgs: &[crate::image::Image; 2], s: ExemplarSampling, t: f32| {
            [
                s.read(imgs[0].view(), glam::Vec2::new(t, 1.37))[0],
                s.read(imgs[1].view(), glam::Vec2::new(1.37, t))[0],
            ]
        };
        let ramp = along(|x| x as f32 / 8.0);
        let step = along(|x| if x < 4 { 0.0 } else { 1.0 });
        for x in [2.0f32, 2.3, 3.5, 4.75] {
            for got in reads(&ramp, ExemplarSampling::Bicubic, x) {
                assert!((got - x / 8.0).abs() < 1e-5, "ramp at {x}: {got}");
            }
        }
        let bicubic = |t| reads(&step, ExemplarSampling::Bicubic, t);
        assert_eq!(bicubic(3.0), [0.0, 0.0]);
        assert_eq!(bicubic(4.0), [1.0, 1.0]);
        for (bilinear, bicubic) in reads(&step, ExemplarSampling::Bilinear, 3.25)
            .into_iter()
            .zip(bicubic(3.25))
        {
            assert!((bilinear - 0.25).abs() < 1e-6, "{bilinear}");
            assert!((0.0..0.23).contains(&bicubic), "{bicubic}");
        }
        // Past the step the cubic overshoots below 0 and is kept at the texels' range.
        assert_eq!(bicubic(2.5), [0.0, 0.0]);
        // The range is the sixteen texels', not the nearest four's: with the four outer
        // corners lit, a read at the centre is (w₋₁ + w₂)² = 1/64, where the middle 2×2 is
        // all zero.
        let corners = crate::image::Image::from_fn(4, 4, |x, y| {
            grey(if x % 3 == 0 && y % 3 == 0 { 1.0 } else { 0.0 })
        });
        let centre = ExemplarSampling::Bicubic.read(corners.view(), glam::Vec2::new(1.5, 1.5));
        assert!((centre[0] - 1.0 / 64.0).abs() < 1e-6, "{centre:?}");
    }
}

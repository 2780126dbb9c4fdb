//! Preview images: three perspective views of a shaded mesh side by side.
//!
//! Per view: vertices are projected once, triangles are binned into bands of rows, and the
//! bands are rendered in parallel (each band owns its rows of the z-buffer and of the image, and
//! walks its triangles in index order, so ties and results never depend on the thread count).
//! Visibility is resolved first (depth = interpolated 1/w, the nearest wins, the lower triangle
//! index on exact ties), then each supersample is shaded once. Shading happens in linear light:
//! the albedo is decoded from sRGB, lit, supersamples are averaged and the result re-encoded.

use super::raster::raster_triangle;
use super::shader::SurfaceShader;
use super::srgb;
use crate::geom::Mesh;
use glam::{Vec2, Vec3};
use rayon::prelude::*;

/// Supersampling factor per axis.
const SUPERSAMPLE: u32 = 2;
/// Rows per parallel band.
const BAND: u32 = 16;
/// tan(fov / 2) for a vertical (and horizontal) field of view of 30 degrees.
const TAN_HALF_FOV: f32 = 0.267_949_2;
/// Fraction of the half-width the fitted bounding box may use (a margin around the object).
const FILL: f32 = 0.92;
/// Elevation of the three-quarter view above the horizon: 30 degrees (cos, sin).
const ELEVATION: (f32, f32) = (0.866_025_4, 0.5);
const AMBIENT: f32 = 0.28;
const KEY: f32 = 0.72;

/// Options of [`render_views`].
#[derive(Debug, Clone, PartialEq)]
pub struct ViewOptions {
    /// Side of each (square) view in pixels; the image is `3 * size` wide and `size` high.
    /// Range: 1 to 8192. Default: 512.
    pub size: u32,
    /// The world direction that points up in the views (need not be unit length; a zero
    /// vector means +Y). Default: +Y.
    pub up: Vec3,
    /// Light the surface (Lambert with a key light from the camera's upper left plus ambient);
    /// `false` shows the plain albedo. Default: true.
    pub lit: bool,
    /// Background colour, 8-bit sRGB. Default: light grey (235, 236, 240).
    pub background: [u8; 3],
}

impl Default for ViewOptions {
    fn default() -> Self {
        ViewOptions {
            size: 512,
            up: Vec3::Y,
            lit: true,
            background: [235, 236, 240],
        }
    }
}

impl ViewOptions {
    /// Largest accepted [`ViewOptions::size`].
    pub const MAX_SIZE: u32 = 8192;
}

/// A perspective camera with a square viewport of `pixels` × `pixels`.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Camera {
    pub eye: Vec3,
    pub right: Vec3,
    pub up: Vec3,
    /// Viewing direction (unit).
    pub forward: Vec3,
    pub pixels: u32,
    /// Points closer than this along `forward` are not drawn.
    pub near: f32,
}

impl Camera {
    /// Looks at the centre of the box `[lo, hi]` from direction `dir` (from the centre towards
    /// the camera), with `up` pointing up, at the nearest distance at which every one of
    /// `points` (which the box should contain) projects inside the central `FILL` part of the
    /// view.
    pub fn fit(points: &[Vec3], lo: Vec3, hi: Vec3, dir: Vec3, up: Vec3, pixels: u32) -> Camera {
        let dir = dir.normalize();
        let forward = -dir;
        let right = forward.cross(up).normalize();
        let up = right.cross(forward);
        let centre = (lo + hi) * 0.5;
        let radius = ((hi - lo) * 0.5).length();
        let t = TAN_HALF_FOV * FILL;
        let mut dist = 0.0f32;
        let mut max_depth = 0.0f32;
        for &p in points {
            let d = p - centre;
            let (x, y, z) = (d.dot(right), d.dot(up), d.dot(dir));
            // |x| / (dist - z) <= t  <=>  dist >= z + |x| / t.
            dist = dist.max(z + x.abs().max(y.abs()) / t);
            max_depth = max_depth.max(z);
        }
        let scale = if radius > 0.0 { radius } else { 1.0 };
        dist = dist.max(max_depth + 0.05 * scale).max(0.05 * scale);
        Camera {
            eye: centre + dir * dist,
            right,
            up,
            forward,
            pixels,
            near: (dist - max_depth) * 0.01,
        }
    }

    /// Screen position (pixels, x right, y down, pixel centres at +0.5) and depth along the
    /// viewing direction.
    #[inline]
    pub fn project(&self, p: Vec3) -> (Vec2, f32) {
        let d = p - self.eye;
        let w = d.dot(self.forward);
        let half = self.pixels as f32 * 0.5;
        let k = half / (w * TAN_HALF_FOV);
        (
            Vec2::new(half + d.dot(self.right) * k, half - d.dot(self.up) * k),
            w,
        )
    }

    /// Direction towards the key light: from the camera's upper left, somewhat behind it.
    fn light(&self) -> Vec3 {
        (-self.right * 0.45 + self.up * 0.55 - self.forward * 0.7).normalize()
    }
}

/// The unit vector `up` (or +Y when zero or not finite), and the directions towards the three
/// cameras: front, side, three-quarter from above.
fn view_directions(up: Vec3) -> (Vec3, [Vec3; 3]) {
    let up = if up.is_finite() && up.length_squared() > 0.0 {
        up.normalize()
    } else {
        Vec3::Y
    };
    // Front: +Z for Y-up (and most axes); -Y for Z-up, the usual front of Z-up models.
    let seed = if up.z.abs() < 0.9 { Vec3::Z } else { -Vec3::Y };
    let front = (seed - up * seed.dot(up)).normalize();
    let side = up.cross(front);
    let diag = (front + side).normalize();
    let three_quarter = (diag * ELEVATION.0 + up * ELEVATION.1).normalize();
    (up, [front, side, three_quarter])
}

/// Winner of the depth test at one supersample.
#[derive(Clone, Copy)]
struct Hit {
    depth: f32,
    face: u32,
    lambda: Vec3,
}

const NO_FACE: u32 = u32::MAX;

/// A triangle ready to rasterize.
struct ScreenTri {
    xy: [Vec2; 3],
    inv_w: [f32; 3],
    back_facing: bool,
}

/// Renders one view into linear-light RGB supersamples (`cam.pixels`² of them, row-major),
/// once per shader: the triangles are binned and rasterized once, and each shader shades the
/// same visible points (a preview and `patches.png` of a million-triangle mesh share the work).
fn render_linear(
    mesh: &Mesh,
    shaders: &[&dyn SurfaceShader],
    cam: &Camera,
    lit: bool,
    background: Vec3,
) -> Vec<Vec<Vec3>> {
    let n = cam.pixels;
    let projected: Vec<(Vec2, f32)> = mesh.positions.par_iter().map(|&p| cam.project(p)).collect();
    let normals = mesh.vertex_normals();
    let light = cam.light();

    // Triangles in front of the near plane and overlapping the image rows.
    let tris: Vec<Option<ScreenTri>> = mesh
        .triangles
        .par_iter()
        .enumerate()
        .map(|(f, t)| {
            let c = t.map(|v| projected.get(v as usize).copied());
            let (Some(a), Some(b), Some(c)) = (c[0], c[1], c[2]) else {
                return None;
            };
            let pts = [a, b, c];
            if pts
                .iter()
                .any(|(xy, w)| w.is_nan() || *w <= cam.near || !xy.is_finite())
            {
                return None;
            }
            let min_y = a.0.y.min(b.0.y).min(c.0.y);
            let max_y = a.0.y.max(b.0.y).max(c.0.y);
            if max_y < 0.0 || min_y > n as f32 {
                return None;
            }
            let p0 = mesh.positions[t[0] as usize];
            let back_facing = mesh.face_normal_unnormalized(f).dot(cam.eye - p0) < 0.0;
            Some(ScreenTri {
                xy: pts.map(|p| p.0),
                inv_w: pts.map(|p| 1.0 / p.1),
                back_facing,
            })
        })
        .collect();
    // Binned into bands of rows, in index order.
    let bands = n.div_ceil(BAND) as usize;
    let mut bins: Vec<Vec<u32>> = vec![Vec::new(); bands];
    let band_of = |y: f32| ((y.clamp(0.0, n as f32 - 1.0) as u32 / BAND) as usize).min(bands - 1);
    for (f, tri) in tris.iter().enumerate() {
        if let Some(tri) = tri {
            let min_y = tri.xy[0].y.min(tri.xy[1].y).min(tri.xy[2].y);
            let max_y = tri.xy[0].y.max(tri.xy[1].y).max(tri.xy[2].y);
            for bin in &mut bins[band_of(min_y)..=band_of(max_y)] {
                bin.push(f as u32);
            }
        }
    }

    // Each band is rasterized once and shaded by every shader before the next, so only a
    // band's hits are held (as when one shader was rendered at a time).
    let mut outs: Vec<Vec<Vec3>> = vec![vec![Vec3::ZERO; (n * n) as usize]; shaders.len()];
    let mut band_slices: Vec<Vec<&mut [Vec3]>> = (0..bands).map(|_| Vec::new()).collect();
    for out in &mut outs {
        for (b, chunk) in out.chunks_mut((n * BAND) as usize).enumerate() {
            band_slices[b].push(chunk);
        }
    }
    band_slices
        .into_par_iter()
        .enumerate()
        .for_each(|(band, mut rows_outs)| {
            let y0 = band as u32 * BAND;
            let y1 = (y0 + BAND).min(n);
            let mut hits = vec![
                Hit {
                    depth: 0.0,
                    face: NO_FACE,
                    lambda: Vec3::ZERO,
                };
                ((y1 - y0) * n) as usize
            ];
            for &f in &bins[band] {
                let Some(tri) = &tris[f as usize] else {
                    continue;
                };
                raster_triangle(tri.xy, n, y0..y1, |x, y, lambda| {
                    let depth =
                        lambda.x * tri.inv_w[0] + lambda.y * tri.inv_w[1] + lambda.z * tri.inv_w[2];
                    let h = &mut hits[((y - y0) * n + x) as usize];
                    if depth > h.depth {
                        *h = Hit {
                            depth,
                            face: f,
                            lambda,
                        };
                    }
                });
            }
            for (&shader, rows_out) in shaders.iter().zip(rows_outs.iter_mut()) {
                for (px, h) in rows_out.iter_mut().zip(&hits) {
                    *px = if h.face == NO_FACE {
                        background
                    } else {
                        shade(
                            mesh,
                            normals,
                            shader,
                            tris[h.face as usize].as_ref(),
                            h,
                            lit,
                            light,
                        )
                    };
                }
            }
        });
    outs
}

/// Perspective-correct barycentrics from screen-space ones: `lambda_i / w_i`, renormalized.
#[inline]
pub(crate) fn perspective_correct(lambda: Vec3, inv_w: [f32; 3]) -> Vec3 {
    let q = Vec3::new(
        lambda.x * inv_w[0],
        lambda.y * inv_w[1],
        lambda.z * inv_w[2],
    );
    q / (q.x + q.y + q.z)
}

/// Linear-light colour of one supersample.
fn shade(
    mesh: &Mesh,
    normals: &[Vec3],
    shader: &dyn SurfaceShader,
    tri: Option<&ScreenTri>,
    h: &Hit,
    lit: bool,
    light: Vec3,
) -> Vec3 {
    let Some(tri) = tri else {
        return Vec3::ZERO;
    };
    let f = h.face as usize;
    let bary = perspective_correct(h.lambda, tri.inv_w);
    let albedo = shader.albedo(f, bary);
    let albedo = Vec3::new(
        srgb::to_linear(albedo.x),
        srgb::to_linear(albedo.y),
        srgb::to_linear(albedo.z),
    );
    if !lit {
        return albedo;
    }
    let t = mesh.triangles[f];
    let mut n = normals[t[0] as usize] * bary.x
        + normals[t[1] as usize] * bary.y
        + normals[t[2] as usize] * bary.z;
    n = n.normalize_or_zero();
    if n == Vec3::ZERO {
        n = mesh.face_normal_unnormalized(f).normalize_or_zero();
    }
    // Two-sided: the back of a face is lit like a front facing the other way.
    if tri.back_facing {
        n = -n;
    }
    albedo * (AMBIENT + KEY * n.dot(light).max(0.0))
}

/// Peak memory of a preview of `size` pixels per view, in bytes: 120 per pixel of one view
/// (the three views' supersampled depth winners and linear colours, the shaded image and its
/// encoding). Measured with `configs/demo.toml`: 460 MB at 2048, 1.94 GB at 4096 above the
/// run's 53 MB without a preview (110 and 115 bytes per pixel).
pub fn preview_memory_estimate(size: u64) -> u64 {
    120 * size * size
}

/// Renders three views of `mesh` side by side, each `opts.size` pixels square: front, side and
/// three-quarter from above, with a perspective camera fitted to the bounding box and `opts.up`
/// pointing up. The result is the same, byte for byte, for any number of threads.
/// `opts.size` is clamped to `1..=ViewOptions::MAX_SIZE`.
pub fn render_views(
    mesh: &Mesh,
    shader: &dyn SurfaceShader,
    opts: &ViewOptions,
) -> image::RgbaImage {
    let mut images = render_views_of_each(mesh, &[shader], opts);
    images.pop().expect("one image per shader")
}

/// [`render_views`] for each of `shaders`, from one rasterization of each view: the images
/// are the same, byte for byte, as separate calls give.
pub fn render_views_of_each(
    mesh: &Mesh,
    shaders: &[&dyn SurfaceShader],
    opts: &ViewOptions,
) -> Vec<image::RgbaImage> {
    let s = opts.size.clamp(1, ViewOptions::MAX_SIZE);
    let bg = opts.background;
    let mut outs =
        vec![
            image::RgbaImage::from_pixel(3 * s, s, image::Rgba([bg[0], bg[1], bg[2], 255]));
            shaders.len()
        ];
    if mesh.triangles.is_empty() {
        return outs;
    }
    let bg_lin = Vec3::new(
        srgb::to_linear(bg[0] as f32 / 255.0),
        srgb::to_linear(bg[1] as f32 / 255.0),
        srgb::to_linear(bg[2] as f32 / 255.0),
    );
    let (lo, hi) = mesh.bounds();
    // The referenced vertices (others are ignored, see `Mesh`), for a tight camera fit.
    let mut used = vec![false; mesh.positions.len()];
    for t in &mesh.triangles {
        for &v in t {
            if let Some(u) = used.get_mut(v as usize) {
                *u = true;
            }
        }
    }
    let points: Vec<Vec3> = mesh
        .positions
        .iter()
        .zip(&used)
        .filter(|&(p, &u)| u && p.is_finite())
        .map(|(p, _)| *p)
        .collect();
    let (up, dirs) = view_directions(opts.up);
    let ss = s * SUPERSAMPLE;
    let row_bytes = (3 * s * 4) as usize;
    for (v, dir) in dirs.into_iter().enumerate() {
        let cam = Camera::fit(&points, lo, hi, dir, up, ss);
        let lins = render_linear(mesh, shaders, &cam, opts.lit, bg_lin);
        for (out, lin) in outs.iter_mut().zip(&lins) {
            out.par_chunks_mut(row_bytes)
                .enumerate()
                .for_each(|(y, row)| {
                    for x in 0..s as usize {
                        let mut sum = Vec3::ZERO;
                        for sy in 0..SUPERSAMPLE as usize {
                            for sx in 0..SUPERSAMPLE as usize {
                                let i = (y * SUPERSAMPLE as usize + sy) * ss as usize
                                    + x * SUPERSAMPLE as usize
                                    + sx;
                                sum += lin[i];
                            }
                        }
                        let c = sum / (SUPERSAMPLE * SUPERSAMPLE) as f32;
                        let o = (v * s as usize + x) * 4;
                        row[o] = srgb::to_u8(c.x);
                        row[o + 1] = srgb::to_u8(c.y);
                        row[o + 2] = srgb::to_u8(c.z);
                        row[o + 3] = 255;
                    }
                });
        }
    }
    outs
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::geom::primitives::uv_quad;
    use crate::image::Image;
    use crate::math::PureMath;
    use crate::render::shader::{ConstantShader, CornerUvShader};

    /// A UV sphere (OBJ-convention corner uvs per face), `rings` × `segments`.
    pub(crate) fn uv_sphere(rings: u32, segments: u32) -> (Mesh, Vec<[Vec2; 3]>) {
        let mut pos = vec![];
        let mut uv = vec![];
        for r in 0..=rings {
            let v = r as f32 / rings as f32;
            let theta = v * std::f32::consts::PI;
            for s in 0..=segments {
                let u = s as f32 / segments as f32;
                let phi = u * std::f32::consts::TAU;
                pos.push(Vec3::new(
                    theta.sin_pure() * phi.sin_pure(),
                    theta.cos_pure(),
                    theta.sin_pure() * phi.cos_pure(),
                ));
                uv.push(Vec2::new(u, 1.0 - v));
            }
        }
        let idx = |r: u32, s: u32| r * (segments + 1) + s;
        let mut tris = vec![];
        let mut corner_uv = vec![];
        for r in 0..rings {
            for s in 0..segments {
                let (a, b, c, d) = (idx(r, s), idx(r + 1, s), idx(r + 1, s + 1), idx(r, s + 1));
                for t in [[a, b, c], [a, c, d]] {
                    if pos[t[0] as usize] == pos[t[1] as usize]
                        || pos[t[1] as usize] == pos[t[2] as usize]
                        || pos[t[0] as usize] == pos[t[2] as usize]
                    {
                        continue;
                    }
                    tris.push(t);
                    corner_uv.push(t.map(|i| uv[i as usize]));
                }
            }
        }
        (Mesh::new(pos, tris), corner_uv)
    }

    /// An 8×8 texture with four flat quadrants: red top left, green top right, blue bottom
    /// left, yellow bottom right (texel rows go down).
    pub(crate) fn quadrant_texture() -> Image {
        Image::from_fn(8, 8, |x, y| quadrant_color(x < 4, y < 4))
    }

    /// Asserts that the red, green and blue of `got` are each within 1 of `want` (8-bit
    /// values); `place` names the pixel in the message.
    pub(crate) fn assert_rgb_near(got: [u8; 4], want: [i32; 3], place: std::fmt::Arguments) {
        for k in 0..3 {
            assert!(
                (got[k] as i32 - want[k]).abs() <= 1,
                "{place}: {got:?} vs {want:?}"
            );
        }
    }

    pub(crate) fn quadrant_color(left: bool, top: bool) -> [f32; 4] {
        match (left, top) {
            (true, true) => [0.8, 0.1, 0.1, 1.0],
            (false, true) => [0.1, 0.7, 0.2, 1.0],
            (true, false) => [0.15, 0.2, 0.9, 1.0],
            (false, false) => [0.9, 0.85, 0.1, 1.0],
        }
    }

    /// Bounding box (x0, y0, x1, y1 inclusive) of the pixels of view `v` that differ from the
    /// background.
    pub(crate) fn foreground_box(
        img: &image::RgbaImage,
        v: u32,
        bg: [u8; 3],
    ) -> (u32, u32, u32, u32) {
        let s = img.height();
        let (mut x0, mut y0, mut x1, mut y1) = (u32::MAX, u32::MAX, 0, 0);
        for y in 0..s {
            for x in 0..s {
                let p = img.get_pixel(v * s + x, y).0;
                if p[..3] != bg {
                    x0 = x0.min(x);
                    y0 = y0.min(y);
                    x1 = x1.max(x);
                    y1 = y1.max(y);
                }
            }
        }
        (x0, y0, x1, y1)
    }

    #[test]
    fn textured_quad_head_on_shows_the_texture_upright() {
        let (mesh, corner_uv) = uv_quad();
        let tex = quadrant_texture();
        let shader = CornerUvShader::new(&corner_uv, tex.view());
        let opts = ViewOptions {
            size: 96,
            lit: false,
            ..ViewOptions::default()
        };
        let img = render_views(&mesh, &shader, &opts);
        assert_eq!(img.dimensions(), (288, 96));
        let (x0, y0, x1, y1) = foreground_box(&img, 0, opts.background);
        // Head-on, the quad's image is a square centred in the view.
        let (w, h) = (x1 - x0 + 1, y1 - y0 + 1);
        assert!(w > 60 && w.abs_diff(h) <= 1, "{w}x{h}");
        assert!((x0 + x1).abs_diff(95) <= 1 && (y0 + y1).abs_diff(95) <= 1);
        for (fx, fy) in [(0.25, 0.25), (0.75, 0.25), (0.25, 0.75), (0.75, 0.75)] {
            for (dx, dy) in [(-0.1, -0.1), (0.1, 0.1), (0.0, 0.0), (0.1, -0.1)] {
                let x = x0 + ((fx + dx) * w as f32) as u32;
                let y = y0 + ((fy + dy) * h as f32) as u32;
                let want = quadrant_color(fx < 0.5, fy < 0.5);
                assert_rgb_near(
                    img.get_pixel(x, y).0,
                    std::array::from_fn(|k| (want[k] * 255.0).round() as i32),
                    format_args!("pixel ({x}, {y}) of quadrant ({fx}, {fy})"),
                );
            }
        }
    }

    #[test]
    fn perspective_correct_barycentrics_land_on_the_pixel_ray() {
        // Render a slanted triangle and check every covered pixel: the 3D point given by the
        // perspective-correct barycentrics projects back onto the pixel centre. Affine
        // interpolation would miss by several pixels for this depth range.
        let tri = [
            Vec3::new(-1.0, -1.0, 0.0),
            Vec3::new(1.0, -0.5, -6.0),
            Vec3::new(0.0, 1.0, 0.5),
        ];
        let (lo, hi) = (
            tri[0].min(tri[1]).min(tri[2]),
            tri[0].max(tri[1]).max(tri[2]),
        );
        let cam = Camera::fit(&tri, lo, hi, Vec3::new(0.3, 0.2, 1.0), Vec3::Y, 128);
        let pts = tri.map(|p| cam.project(p));
        let mut n = 0;
        let mut worst_affine = 0.0f32;
        raster_triangle(pts.map(|p| p.0), 128, 0..128, |x, y, l| {
            let b = perspective_correct(l, pts.map(|p| 1.0 / p.1));
            let p3 = tri[0] * b.x + tri[1] * b.y + tri[2] * b.z;
            let centre = Vec2::new(x as f32 + 0.5, y as f32 + 0.5);
            assert!((cam.project(p3).0 - centre).length() < 0.01);
            let affine = tri[0] * l.x + tri[1] * l.y + tri[2] * l.z;
            worst_affine = worst_affine.max((cam.project(affine).0 - centre).length());
            n += 1;
        });
        assert!(n > 1000);
        assert!(
            worst_affine > 2.0,
            "the test triangle is not slanted enough"
        );
    }

    #[test]
    fn camera_fit_keeps_every_point_in_view() {
        let (lo, hi) = (Vec3::new(-3.0, 0.0, -1.0), Vec3::new(5.0, 2.0, 0.5));
        let corners = crate::geom::box_corners(lo, hi);
        let (up, dirs) = view_directions(Vec3::Y);
        for dir in dirs {
            let cam = Camera::fit(&corners, lo, hi, dir, up, 100);
            let mut touches = false;
            for &c in &corners {
                let (p, w) = cam.project(c);
                assert!(w > cam.near);
                assert!(
                    p.x >= 3.9 && p.x <= 96.1 && p.y >= 3.9 && p.y <= 96.1,
                    "{p}"
                );
                touches |= p.x < 4.1 || p.x > 95.9 || p.y < 4.1 || p.y > 95.9;
            }
            assert!(touches, "fit is not tight");
            // Up is up: a point above the centre appears above it on screen.
            let c = (lo + hi) * 0.5;
            assert!(cam.project(c + up * 0.1).0.y < cam.project(c).0.y);
        }
    }

    #[test]
    fn views_are_identical_for_one_and_two_threads() {
        let (mesh, corner_uv) = uv_sphere(24, 48);
        let tex = quadrant_texture();
        let shader = CornerUvShader::new(&corner_uv, tex.view());
        let opts = ViewOptions {
            size: 120,
            ..ViewOptions::default()
        };
        let run = |n: usize| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(n)
                .build()
                .unwrap()
                .install(|| render_views(&mesh, &shader, &opts))
        };
        let a = run(1);
        let b = run(2);
        let c = run(3);
        assert!(a.as_raw() == b.as_raw() && a.as_raw() == c.as_raw());
    }

    #[test]
    fn views_of_several_shaders_equal_separate_renders() {
        // One rasterization shaded twice must give each shader its own image, as if rendered
        // alone (a mix-up of shaders or of hit buffers between bands breaks this).
        let (mesh, corner_uv) = uv_sphere(24, 48);
        let tex = quadrant_texture();
        let textured = CornerUvShader::new(&corner_uv, tex.view());
        let red = ConstantShader(Vec3::new(0.9, 0.1, 0.1));
        let opts = ViewOptions {
            size: 100,
            ..ViewOptions::default()
        };
        let both = render_views_of_each(&mesh, &[&textured, &red], &opts);
        assert_eq!(both.len(), 2);
        assert!(both[0].as_raw() == render_views(&mesh, &textured, &opts).as_raw());
        assert!(both[1].as_raw() == render_views(&mesh, &red, &opts).as_raw());
        assert!(both[0].as_raw() != both[1].as_raw());
    }

    /// Lit views `size` pixels high of a fine sphere with a uniform `grey` albedo, and the
    /// background colour around it.
    fn grey_sphere_views(size: u32, grey: f32) -> (image::RgbaImage, [u8; 3]) {
        let (mesh, _) = uv_sphere(40, 80);
        let opts = ViewOptions {
            size,
            ..ViewOptions::default()
        };
        let img = render_views(&mesh, &ConstantShader(Vec3::splat(grey)), &opts);
        (img, opts.background)
    }

    #[test]
    fn a_closed_sphere_has_no_background_pixels_inside_its_outline() {
        // Cracks between triangles would let the background through.
        let (img, background) = grey_sphere_views(200, 0.6);
        for v in 0..3 {
            let (x0, y0, x1, y1) = foreground_box(&img, v, background);
            let (cx, cy) = ((x0 + x1) as f32 / 2.0, (y0 + y1) as f32 / 2.0);
            let r = (x1 - x0) as f32 / 2.0;
            assert!((y1 - y0).abs_diff(x1 - x0) <= 2);
            for y in y0..=y1 {
                for x in x0..=x1 {
                    let d = ((x as f32 - cx).powi(2) + (y as f32 - cy).powi(2)).sqrt();
                    if d < r - 2.0 {
                        let p = img.get_pixel(v * 200 + x, y).0;
                        assert_ne!(p[..3], background, "hole at ({x}, {y}) of view {v}");
                    }
                }
            }
        }
    }

    #[test]
    fn lighting_comes_from_the_upper_left() {
        let (img, background) = grey_sphere_views(100, 0.7);
        let (x0, y0, x1, y1) = foreground_box(&img, 0, background);
        let at = |fx: f32, fy: f32| {
            let x = x0 + ((x1 - x0) as f32 * fx) as u32;
            let y = y0 + ((y1 - y0) as f32 * fy) as u32;
            img.get_pixel(x, y).0[0]
        };
        assert!(at(0.3, 0.3) > at(0.7, 0.7) + 40);
        assert!(at(0.3, 0.5) > at(0.7, 0.5));
        assert!(at(0.5, 0.3) > at(0.5, 0.7));
    }
}

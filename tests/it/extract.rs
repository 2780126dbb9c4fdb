//! Geometric texture extraction (Lai et al. 2005, §4.1 and §5): stages/extract/.
//!
//! The sample meshes are planes with a known analytic relief h(x, y), tilted and moved in 3D,
//! so every expected value comes from h and the transform, never from the code under test.

use glam::{Mat3, Vec3};
use std::path::Path;
use texsyn::geom::Mesh;
use texsyn::geom::geometry_image::{GeometryImage, TexelImage};
use texsyn::image::Image;
use texsyn::stages::extract::bilateral_difference::{BilateralParams, bilateral_difference};
use texsyn::stages::extract::height_field::{height_field_image, mesh_height_field};
use texsyn::stages::extract::planar_ransac::{
    PlanarExtraction, RansacParams, fit_plane_ransac, pca_plane, planar_extract, surface_samples,
};
use texsyn::stages::extract::sample_region::{Region, select_region};
use texsyn::stages::extract::{ExtractError, ExtractMethod, ExtractParams, extract_mesh_texture};
use texsyn_core::math::PureMath;

/// A rigid placement of the sample in space: world = rot · local + shift.
struct Placement {
    rot: Mat3,
    shift: Vec3,
}

impl Placement {
    fn tilted() -> Self {
        Placement {
            rot: Mat3::from_axis_angle(Vec3::new(0.3, -0.5, 0.8).normalize(), 0.9),
            shift: Vec3::new(3.0, -1.5, 0.7),
        }
    }
    fn to_world(&self, p: Vec3) -> Vec3 {
        self.rot * p + self.shift
    }
    fn to_local(&self, p: Vec3) -> Vec3 {
        self.rot.transpose() * (p - self.shift)
    }
}

/// Four Gaussian bumps, a dimple and a ripple on [-1, 1]², amplitude ≈ 0.05, symmetric so
/// that the relief has no first moments: its least-squares plane is z = const.
fn bumps(x: f32, y: f32) -> f32 {
    let g = |cx: f32, cy: f32, s: f32, a: f32| {
        a * (-((x - cx).powi(2) + (y - cy).powi(2)) / (2.0 * s * s)).exp_pure()
    };
    let pi = std::f32::consts::PI;
    g(0.5, 0.5, 0.15, 0.05)
        + g(-0.5, 0.5, 0.15, 0.05)
        + g(0.5, -0.5, 0.15, 0.05)
        + g(-0.5, -0.5, 0.15, 0.05)
        + g(0.0, 0.0, 0.12, -0.03)
        + 0.01 * (5.0 * pi * x).sin_pure() * (4.0 * pi * y).sin_pure()
}

/// An (n+1)×(n+1)-vertex grid over [-1, 1]² with z = h(x, y), placed in space, optionally
/// coloured by a function of the local position.
fn relief_mesh(
    n: u32,
    h: &dyn Fn(f32, f32) -> f32,
    place: &Placement,
    color: Option<&dyn Fn(f32, f32) -> [f32; 4]>,
) -> Mesh {
    let mut positions = Vec::new();
    let mut colors = Vec::new();
    for i in 0..=n {
        for j in 0..=n {
            let x = -1.0 + 2.0 * j as f32 / n as f32;
            let y = -1.0 + 2.0 * i as f32 / n as f32;
            positions.push(place.to_world(Vec3::new(x, y, h(x, y))));
            if let Some(c) = color {
                colors.push(c(x, y));
            }
        }
    }
    let mut triangles = Vec::new();
    let w = n + 1;
    for i in 0..n {
        for j in 0..n {
            let a = i * w + j;
            triangles.push([a, a + 1, a + w + 1]);
            triangles.push([a, a + w + 1, a + w]);
        }
    }
    Mesh::with_colors(positions, triangles, color.map(|_| colors))
}

/// Vertex colours linear in the local position: red along x, green along y.
fn gradient(x: f32, y: f32) -> [f32; 4] {
    [0.5 + 0.5 * x, 0.5 + 0.5 * y, 0.25, 1.0]
}

fn mean(v: impl Iterator<Item = f32>) -> f32 {
    let (s, n) = v.fold((0.0f64, 0usize), |(s, n), x| (s + x as f64, n + 1));
    (s / n as f64) as f32
}

fn no_progress(_: f32) {}

/// For every texel: (local position of the sample's plane point, texel).
fn samples<'a>(
    e: &'a PlanarExtraction,
    place: &'a Placement,
) -> impl Iterator<Item = (Vec3, &'a [f32])> + 'a {
    let n = e.texels.width;
    (0..n).flat_map(move |i| {
        (0..n).map(move |j| (place.to_local(e.sample_point(i, j)), e.texels.texel(j, i)))
    })
}

/// The [`bumps`] relief on a 120×120-quad grid, [`Placement::tilted`].
fn tilted_bumps() -> (Placement, Mesh) {
    let place = Placement::tilted();
    let mesh = relief_mesh(120, &bumps, &place, None);
    (place, mesh)
}

/// Asserts that the extraction's plane is the sample's base plane: normals within 1°.
fn assert_base_plane(e: &PlanarExtraction, place: &Placement) {
    let angle = e
        .plane
        .normal
        .angle_between(place.rot * Vec3::Z)
        .to_degrees();
    assert!(angle < 1.0, "plane normal off by {angle}°");
}

#[test]
fn planar_extraction_recovers_the_relief_of_a_tilted_plane() {
    let (place, mesh) = tilted_bumps();
    let e = planar_extract(&mesh, 64, &RansacParams::default(), &no_progress).unwrap();
    assert_eq!(
        (e.texels.width, e.texels.height, e.texels.channels),
        (64, 64, 3)
    );
    // The plane is the sample's base plane.
    assert_base_plane(&e, &place);
    // The square covers most of the 2×2 patch (whatever its orientation).
    assert!(e.square.side > 1.6, "square side {}", e.square.side);

    let dn_mean = mean(e.texels.data.chunks(3).map(|t| t[2]));
    let h_mean = mean(samples(&e, &place).map(|(q, _)| bumps(q.x, q.y)));
    let (mut worst, mut worst_t) = (0.0f32, 0.0f32);
    for (q, t) in samples(&e, &place) {
        assert!(
            q.x.abs() <= 1.0 && q.y.abs() <= 1.0,
            "sample outside the patch: {q}"
        );
        worst = worst.max(((t[2] - dn_mean) - (bumps(q.x, q.y) - h_mean)).abs());
        worst_t = worst_t.max(t[0].abs()).max(t[1].abs());
    }
    eprintln!("planar: worst dn error {worst}, worst |dx|,|dy| {worst_t}");
    assert!(
        worst < 0.002,
        "dn differs from the relief by {worst} (relief 0.05)"
    );
    assert!(worst_t < 0.005, "tangential offsets up to {worst_t}");
}

#[test]
fn planar_relief_reconstructed_on_its_plane_returns_the_surface() {
    let (place, mesh) = tilted_bumps();
    let e = planar_extract(&mesh, 48, &RansacParams::default(), &no_progress).unwrap();
    let n = e.texels.width;
    let mut worst = 0.0f32;
    for i in 0..n {
        for j in 0..n {
            let t = e.texels.texel(j, i);
            // §4.4 on the same plane: p + dx e1 + dy e2 + dn n.
            let p = e.sample_point(i, j)
                + t[0] * e.plane.e1
                + t[1] * e.plane.e2
                + t[2] * e.plane.normal;
            let q = place.to_local(p);
            worst = worst.max((q.z - bumps(q.x, q.y)).abs());
        }
    }
    eprintln!("reconstruction: worst distance {worst}");
    assert!(
        worst < 5e-4,
        "the reconstructed point is {worst} off the surface"
    );
}

#[test]
fn height_field_extraction_recovers_the_relief() {
    let (place, mesh) = tilted_bumps();
    let e = mesh_height_field(&mesh, 64, &RansacParams::default(), &no_progress).unwrap();
    assert_base_plane(&e, &place);
    let h_mean = mean(samples(&e, &place).map(|(q, _)| bumps(q.x, q.y)));
    let dn_mean = mean(e.texels.data.chunks(3).map(|t| t[2]));
    assert!(
        dn_mean.abs() < 1e-6,
        "the mean height is removed: {dn_mean}"
    );
    let mut worst = 0.0f32;
    for (q, t) in samples(&e, &place) {
        assert_eq!((t[0], t[1]), (0.0, 0.0));
        worst = worst.max((t[2] - (bumps(q.x, q.y) - h_mean)).abs());
    }
    eprintln!("height field: worst dn error {worst}");
    assert!(worst < 0.001, "dn differs from the relief by {worst}");
}

#[test]
fn the_height_field_takes_the_highest_crossing_of_an_overhang() {
    // A flat square with a second, smaller flap folded back over it at height 0.2: the
    // samples under the flap must see the flap.
    let place = Placement::tilted();
    let mut positions = Vec::new();
    let mut triangles = Vec::new();
    let n = 40u32;
    for i in 0..=n {
        for j in 0..=n {
            let x = -1.0 + 2.0 * j as f32 / n as f32;
            let y = -1.0 + 2.0 * i as f32 / n as f32;
            positions.push(place.to_world(Vec3::new(x, y, 0.0)));
        }
    }
    for i in 0..n {
        for j in 0..n {
            let a = i * (n + 1) + j;
            triangles.push([a, a + 1, a + n + 2]);
            triangles.push([a, a + n + 2, a + n + 1]);
        }
    }
    // The flap: a quad over [-0.5, 0.5] × [-0.5, 0.5] at z = 0.2, sharing no vertex.
    let base = positions.len() as u32;
    for (x, y) in [(-0.5, -0.5), (0.5, -0.5), (0.5, 0.5), (-0.5, 0.5)] {
        positions.push(place.to_world(Vec3::new(x, y, 0.2)));
    }
    triangles.push([base, base + 1, base + 2]);
    triangles.push([base, base + 2, base + 3]);
    let mesh = Mesh::new(positions, triangles);
    let e = mesh_height_field(&mesh, 32, &RansacParams::default(), &no_progress).unwrap();
    let under: Vec<f32> = samples(&e, &place)
        .filter(|(q, _)| q.x.abs() < 0.45 && q.y.abs() < 0.45)
        .map(|(_, t)| t[2])
        .collect();
    let outside: Vec<f32> = samples(&e, &place)
        .filter(|(q, _)| q.x.abs() > 0.55 || q.y.abs() > 0.55)
        .map(|(_, t)| t[2])
        .collect();
    assert!(!under.is_empty() && !outside.is_empty());
    for (&a, &b) in under.iter().zip(&outside) {
        assert!(
            (a - b - 0.2).abs() < 1e-3,
            "under the flap {a}, beside it {b}"
        );
    }
}

/// A flat patch with 0.004 ripples, 30% of whose area (x > 0.4) is a ridge 0.3 high.
fn ridge(x: f32, y: f32) -> f32 {
    let ripple = 0.004 * (20.0 * x).sin_pure() * (17.0 * y).sin_pure();
    if x > 0.4 {
        ripple + 0.3 * (std::f32::consts::PI * (x - 0.4) / 0.6).sin_pure()
    } else {
        ripple
    }
}

#[test]
fn ransac_finds_the_plane_despite_30_percent_outliers() {
    let place = Placement::tilted();
    let mesh = relief_mesh(100, &ridge, &place, None);
    let truth = place.rot * Vec3::Z;
    let fit = fit_plane_ransac(&mesh, &RansacParams::default()).unwrap();
    let angle = fit.plane.normal.angle_between(truth).to_degrees();
    eprintln!(
        "ransac: angle {angle}°, inliers {} of {}",
        fit.inliers, fit.samples
    );
    assert!(angle < 1.0, "RANSAC normal off by {angle}°");
    // The plane passes through the flat part, not halfway up the ridge.
    let o = place.to_local(fit.plane.origin);
    assert!(o.z.abs() < 0.005, "plane origin at height {}", o.z);
    // About 63% are inliers: the flat 70% of the projection is less of the surface's area,
    // which the samples follow, because the ridge's flanks are steep.
    let frac = fit.inliers as f32 / fit.samples as f32;
    assert!((0.55..0.75).contains(&frac), "inlier fraction {frac}");
    // A plain least-squares fit is pulled off by the ridge: the test has teeth.
    let pts = surface_samples(&mesh, 4096, 1).unwrap();
    let (_, n) = pca_plane(&pts).unwrap();
    let ls_angle = n.as_vec3().angle_between(truth).to_degrees();
    let ls_angle = ls_angle.min(180.0 - ls_angle);
    assert!(
        ls_angle > 3.0,
        "least squares alone is already good ({ls_angle}°)"
    );
}

/// A gently curved bumpy patch sampled directly as an N×N geometry image: a paraboloid cap
/// with a sinusoidal relief of amplitude `amp` along its normal.
fn curved_geometry_image(n: u32, amp: f32, place: &Placement) -> (GeometryImage, Vec<f32>) {
    let c = 0.15;
    let wavelength = 0.25;
    let mut positions = Vec::new();
    let mut normals = Vec::new();
    let mut relief = Vec::new();
    for i in 0..n {
        for j in 0..n {
            let u = -1.0 + 2.0 * j as f32 / (n - 1) as f32;
            let v = -1.0 + 2.0 * i as f32 / (n - 1) as f32;
            let base = Vec3::new(u, v, -c * (u * u + v * v));
            let normal = Vec3::new(2.0 * c * u, 2.0 * c * v, 1.0).normalize();
            let tau = std::f32::consts::TAU;
            let h = amp * (tau * u / wavelength).sin_pure() * (tau * v / wavelength).sin_pure();
            positions.push(place.to_world(base + h * normal));
            normals.push(place.rot * normal);
            relief.push(h);
        }
    }
    let gi = GeometryImage {
        n,
        positions,
        normals,
        mate_rep: (0..n * n).collect(),
    };
    (gi, relief)
}

#[test]
fn bilateral_keeps_the_bumps_and_removes_the_curvature() {
    let place = Placement::tilted();
    let n = 64;
    let amp = 0.02;
    let (gi, relief) = curved_geometry_image(n, amp, &place);
    let e = bilateral_difference(&gi, None, &BilateralParams::default(), &no_progress).unwrap();
    assert_eq!((e.texels.width, e.texels.channels), (n, 3));
    let dn: Vec<f32> = e.texels.data.chunks(3).map(|t| t[2]).collect();
    let dn_mean = mean(dn.iter().copied());
    let h_mean = mean(relief.iter().copied());
    // The raw height above the tangent plane at the centre varies by 0.3 (curvature) but
    // the relief only by 2 × 0.02.
    let (mut worst_in, mut worst_all, mut rms) = (0.0f32, 0.0f32, 0.0f64);
    let border = (3.0 * e.sigma_grid) as u32;
    for i in 0..n {
        for j in 0..n {
            let k = (i * n + j) as usize;
            let err = ((dn[k] - dn_mean) - (relief[k] - h_mean)).abs();
            worst_all = worst_all.max(err);
            rms += (err as f64).powi(2);
            if (border..n - border).contains(&i) && (border..n - border).contains(&j) {
                worst_in = worst_in.max(err);
            }
        }
    }
    let rms = (rms / (n * n) as f64).sqrt();
    eprintln!("bilateral: worst interior {worst_in}, worst {worst_all}, rms {rms}");
    assert!(worst_in < 0.1 * amp, "interior dn error {worst_in}");
    assert!(rms < 0.1 * amp as f64, "rms dn error {rms}");
    // The texels reconstruct the input on the smoothed base.
    for k in 0..(n * n) as usize {
        let t = &e.texels.data[3 * k..3 * k + 3];
        let f = e.frames[k];
        let p = e.smoothed[k] + t[0] * f.x + t[1] * f.y + t[2] * f.n;
        assert!((p - gi.positions[k]).length() < 1e-5);
    }
}

#[test]
fn a_coloured_sample_gives_six_channels_with_its_colours() {
    let place = Placement::tilted();
    let mesh = relief_mesh(80, &bumps, &place, Some(&gradient));
    for e in [
        planar_extract(&mesh, 32, &RansacParams::default(), &no_progress).unwrap(),
        mesh_height_field(&mesh, 32, &RansacParams::default(), &no_progress).unwrap(),
    ] {
        assert_eq!(e.texels.channels, 6);
        let mut worst = 0.0f32;
        let n = e.texels.width;
        for i in 0..n {
            for j in 0..n {
                let t = e.texels.texel(j, i);
                // The colour where the texel's surface point is (planar texels may be
                // offset tangentially by dx, dy).
                let p = e.sample_point(i, j) + t[0] * e.plane.e1 + t[1] * e.plane.e2;
                let q = place.to_local(p);
                let want = gradient(q.x, q.y);
                for c in 0..3 {
                    worst = worst.max((t[3 + c] - want[c]).abs());
                }
            }
        }
        assert!(worst < 0.01, "colour off by {worst}");
    }
    // Bilateral: the caller's per-sample colours are carried through.
    let (gi, _) = curved_geometry_image(16, 0.01, &place);
    let cols: Vec<[f32; 3]> = (0..256).map(|k| [k as f32 / 255.0, 0.5, 1.0]).collect();
    let e =
        bilateral_difference(&gi, Some(&cols), &BilateralParams::default(), &no_progress).unwrap();
    assert_eq!(e.texels.channels, 6);
    assert_eq!(e.texels.texel(3, 2)[3..6], cols[2 * 16 + 3]);
}

fn grid_mesh(n: u32) -> Mesh {
    relief_mesh(
        n,
        &|_, _| 0.0,
        &Placement {
            rot: Mat3::IDENTITY,
            shift: Vec3::ZERO,
        },
        None,
    )
}

/// Faces of `mesh` whose three vertices satisfy `inside`, as sorted position triples.
fn faces_inside(mesh: &Mesh, inside: &dyn Fn(Vec3) -> bool) -> Vec<[[i64; 3]; 3]> {
    let key = |p: Vec3| [(p.x * 1e5) as i64, (p.y * 1e5) as i64, (p.z * 1e5) as i64];
    let mut out: Vec<[[i64; 3]; 3]> = mesh
        .triangles
        .iter()
        .filter(|t| t.iter().all(|&v| inside(mesh.positions[v as usize])))
        .map(|t| {
            let mut k = t.map(|v| key(mesh.positions[v as usize]));
            k.sort();
            k
        })
        .collect();
    out.sort();
    out
}

#[test]
fn sphere_and_box_regions_pick_the_faces_inside() {
    let mesh = grid_mesh(20);
    let sphere = Region::Sphere {
        center: [0.1, -0.2, 0.0],
        radius: 0.5,
    };
    let patch = select_region(&mesh, Some(&sphere)).unwrap();
    let want = faces_inside(&mesh, &|p| (p - Vec3::new(0.1, -0.2, 0.0)).length() <= 0.5);
    assert!(want.len() > 50);
    assert_eq!(faces_inside(&patch, &|_| true), want);
    // Compact: every vertex is used.
    let mut used = vec![false; patch.positions.len()];
    patch
        .triangles
        .iter()
        .flatten()
        .for_each(|&v| used[v as usize] = true);
    assert!(used.iter().all(|&u| u));

    let boxed = Region::Box {
        min: [-0.55, 0.05, -1.0],
        max: [0.35, 0.75, 1.0],
    };
    let patch = select_region(&mesh, Some(&boxed)).unwrap();
    let want = faces_inside(&mesh, &|p| {
        (-0.55..=0.35).contains(&p.x) && (0.05..=0.75).contains(&p.y)
    });
    assert_eq!(faces_inside(&patch, &|_| true), want);
    assert_eq!(patch.triangles.len(), 2 * 8 * 6);
}

#[test]
fn a_region_keeps_its_largest_connected_piece_and_the_colours() {
    // Two separate grids side by side: a box over both keeps the larger piece.
    let color = |x: f32, y: f32| [0.5 + 0.5 * x, 0.5 + 0.5 * y, 0.0, 1.0];
    // The small piece has more triangles but a quarter of the area.
    let small = relief_mesh(
        12,
        &|_, _| 0.0,
        &Placement {
            rot: Mat3::IDENTITY,
            shift: Vec3::new(-3.0, 0.0, 0.0),
        },
        Some(&color),
    );
    let big = relief_mesh(
        6,
        &|_, _| 0.0,
        &Placement {
            rot: Mat3::from_diagonal(Vec3::splat(2.0)),
            shift: Vec3::new(3.0, 0.0, 0.0),
        },
        Some(&color),
    );
    let offset = small.positions.len() as u32;
    let mut positions = small.positions.clone();
    positions.extend(&big.positions);
    let mut colors = small.colors.clone().unwrap();
    colors.extend(big.colors.clone().unwrap());
    let mut triangles = small.triangles.clone();
    triangles.extend(big.triangles.iter().map(|t| t.map(|v| v + offset)));
    let mesh = Mesh::with_colors(positions, triangles, Some(colors));
    let all = Region::Box {
        min: [-10.0; 3],
        max: [10.0; 3],
    };
    let patch = select_region(&mesh, Some(&all)).unwrap();
    assert_eq!(patch.triangles.len(), big.triangles.len());
    assert!(patch.positions.iter().all(|p| p.x > 0.5));
    let cols = patch.colors.as_ref().unwrap();
    for (p, c) in patch.positions.iter().zip(cols) {
        let want = color((p.x - 3.0) / 2.0, p.y / 2.0);
        assert!((c[0] - want[0]).abs() < 1e-6 && (c[1] - want[1]).abs() < 1e-6);
    }
    // No region: the same.
    assert_eq!(
        select_region(&mesh, None).unwrap().triangles.len(),
        big.triangles.len()
    );
}

#[test]
fn an_empty_region_is_an_error_naming_the_region() {
    let mesh = grid_mesh(10);
    let far = Region::Sphere {
        center: [5.0, 5.0, 5.0],
        radius: 0.5,
    };
    let e = select_region(&mesh, Some(&far)).unwrap_err();
    assert!(matches!(e, ExtractError::EmptyRegion { .. }));
    let msg = e.to_string();
    assert!(
        msg.contains("the sample region") && msg.contains("holds no triangles"),
        "{msg}"
    );
    assert!(msg.contains("sphere at (5, 5, 5) of radius 0.5"), "{msg}");
    // A sphere smaller than a triangle holds none of them either.
    let tiny = Region::Sphere {
        center: [0.0; 3],
        radius: 0.01,
    };
    assert!(matches!(
        select_region(&mesh, Some(&tiny)),
        Err(ExtractError::EmptyRegion { .. })
    ));
    let bad = Region::Sphere {
        center: [0.0; 3],
        radius: 0.0,
    };
    let msg = select_region(&mesh, Some(&bad)).unwrap_err().to_string();
    assert!(msg.contains("radius"), "{msg}");
}

fn grey_image(w: u32, h: u32, f: &dyn Fn(u32, u32) -> f32) -> Image {
    let mut img = Image::new(w, h);
    for y in 0..h {
        for x in 0..w {
            let g = f(x, y);
            img.pixels[(y * w + x) as usize] = [g, g, g, 1.0];
        }
    }
    img
}

#[test]
fn a_grey_image_becomes_heights_around_its_mean() {
    let img = grey_image(20, 16, &|x, y| (x + 2 * y) as f32 / 60.0);
    let h = height_field_image(Path::new("leather.png"), img.view(), 0.5, 8, true).unwrap();
    assert!(h.warning.is_none());
    let t = h.texels;
    assert_eq!((t.width, t.height, t.channels), (20, 16, 3));
    // Mean grey: mean x = 9.5, mean y = 7.5 → (9.5 + 15) / 60.
    let mean_grey = (9.5 + 15.0) / 60.0;
    for y in 0..16 {
        for x in 0..20 {
            let want = ((x + 2 * y) as f32 / 60.0 - mean_grey) * 0.5;
            let got = t.texel(x, y);
            assert_eq!((got[0], got[1]), (0.0, 0.0));
            assert!(
                (got[2] - want).abs() < 1e-6,
                "({x}, {y}): {} vs {want}",
                got[2]
            );
        }
    }
}

#[test]
fn a_coloured_image_is_read_by_its_luma_with_a_warning_or_refused_when_strict() {
    let mut img = grey_image(20, 16, &|_, _| 0.5);
    // Within the 2/255 tolerance: still grey, either way, and no warning.
    img.pixels[5] = [0.5, 0.5 + 1.5 / 255.0, 0.5, 1.0];
    for strict in [false, true] {
        let h = height_field_image(Path::new("a.png"), img.view(), 1.0, 8, strict).unwrap();
        assert!(h.warning.is_none());
    }
    // Pure red, green and blue pixels of the same encoded value: their heights follow the
    // luma weights (green brightest, blue darkest), not their mean.
    img.pixels[(2 * 20 + 3) as usize] = [0.9, 0.0, 0.0, 1.0];
    img.pixels[(2 * 20 + 4) as usize] = [0.0, 0.9, 0.0, 1.0];
    img.pixels[(2 * 20 + 5) as usize] = [0.0, 0.0, 0.9, 1.0];
    let h = height_field_image(Path::new("leather.png"), img.view(), 2.0, 8, false).unwrap();
    let w = h.warning.expect("a warning");
    assert!(
        w.starts_with("leather.png: a colour image (pixel (3, 2)") && w.contains("strict_grey"),
        "{w}"
    );
    let dn = |x: u32| h.texels.texel(x, 2)[2];
    let grey = h.texels.texel(0, 0)[2];
    for (x, weight) in [(3, 0.2126f32), (4, 0.7152), (5, 0.0722)] {
        // Height difference to a 0.5 grey pixel: 2 × (0.9 weight − 0.5).
        let want = 2.0 * (0.9 * weight - 0.5);
        assert!(
            (dn(x) - grey - want).abs() < 1e-5,
            "{x}: {} vs {want}",
            dn(x) - grey
        );
    }
    // The old refusal, kept as an option.
    let e = height_field_image(Path::new("leather.png"), img.view(), 1.0, 8, true).unwrap_err();
    let msg = e.to_string();
    assert!(
        msg.starts_with("leather.png: pixel (3, 2) is not grey"),
        "{msg}"
    );
    // A pixel that is not a number is refused either way.
    img.pixels[7] = [f32::NAN, 0.5, 0.5, 1.0];
    for strict in [false, true] {
        let e = height_field_image(Path::new("l.png"), img.view(), 1.0, 8, strict).unwrap_err();
        assert!(
            e.to_string()
                .contains("pixel (7, 0) is not a finite number"),
            "{e}"
        );
    }
}

#[test]
fn a_too_small_image_is_an_error_naming_the_size_needed() {
    let img = grey_image(20, 12, &|_, _| 0.5);
    let e = height_field_image(Path::new("leather.png"), img.view(), 1.0, 16, false).unwrap_err();
    let msg = e.to_string();
    assert!(msg.contains("leather.png"), "{msg}");
    assert!(msg.contains("20×12"), "{msg}");
    assert!(msg.contains("a sample too small for the template"), "{msg}");
    assert!(msg.contains("at least 16×16"), "{msg}");
    assert!(height_field_image(Path::new("l.png"), img.view(), 1.0, 12, false).is_ok());
}

#[test]
fn a_closed_sample_cannot_be_extracted_by_projection() {
    // An octahedron: no boundary.
    let mesh = Mesh::new(
        vec![Vec3::X, -Vec3::X, Vec3::Y, -Vec3::Y, Vec3::Z, -Vec3::Z],
        vec![
            [0, 2, 4],
            [2, 1, 4],
            [1, 3, 4],
            [3, 0, 4],
            [2, 0, 5],
            [1, 2, 5],
            [3, 1, 5],
            [0, 3, 5],
        ],
    );
    let e = planar_extract(&mesh, 16, &RansacParams::default(), &no_progress).unwrap_err();
    assert!(matches!(e, ExtractError::NoBoundary { .. }), "{e}");
}

#[test]
fn params_read_from_toml_and_validate_by_field() {
    let p: ExtractParams = toml::from_str(
        "method = \"bilateral\"\nsize = 128\nsigma_grid = 6\n\
         region = { shape = \"sphere\", center = [0, 0, 0], radius = 0.1 }",
    )
    .unwrap();
    assert_eq!(p.method, ExtractMethod::Bilateral);
    assert_eq!(p.size, 128);
    assert_eq!(p.sigma_grid, Some(6.0));
    assert_eq!(p.ransac_iterations, 500);
    p.validate().unwrap();
    assert!(toml::from_str::<ExtractParams>("sizes = 3").is_err());
    assert!(toml::from_str::<ExtractParams>("method = \"smooth\"").is_err());
    // The defaults with one field changed: the error names it, its range and its value.
    let error = |change: fn(&mut ExtractParams)| {
        let mut bad = ExtractParams::default();
        change(&mut bad);
        bad.validate().unwrap_err().to_string()
    };
    assert_eq!(error(|p| p.size = 4), "size must be in 8..=1024, got 4");
    assert_eq!(
        error(|p| p.inlier_distance = Some(-1.0)),
        "inlier_distance must be a finite number > 0, got -1"
    );
    assert_eq!(
        error(|p| p.sigma_grid = Some(f32::NAN)),
        "sigma_grid must be in 0.5..=1024, got NaN"
    );
}

fn in_pool<T: Send>(threads: usize, f: impl FnOnce() -> T + Send) -> T {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap()
        .install(f)
}

fn bits(t: &TexelImage) -> Vec<u32> {
    t.data.iter().map(|x| x.to_bits()).collect()
}

#[test]
fn extraction_does_not_depend_on_the_thread_count() {
    let place = Placement::tilted();
    let mesh = relief_mesh(60, &bumps, &place, None);
    let (gi, _) = curved_geometry_image(48, 0.02, &place);
    let coloured = relief_mesh(40, &ripples, &place, Some(&gradient));
    let bilateral = ExtractParams {
        method: ExtractMethod::Bilateral,
        size: 32,
        ..Default::default()
    };
    let run = || {
        (
            bits(
                &planar_extract(&mesh, 32, &RansacParams::default(), &no_progress)
                    .unwrap()
                    .texels,
            ),
            bits(
                &mesh_height_field(&mesh, 32, &RansacParams::default(), &no_progress)
                    .unwrap()
                    .texels,
            ),
            bits(
                &bilateral_difference(&gi, None, &BilateralParams::default(), &no_progress)
                    .unwrap()
                    .texels,
            ),
            bits(
                &extract_mesh_texture(&coloured, &bilateral, &no_progress)
                    .unwrap()
                    .texels,
            ),
        )
    };
    let one = in_pool(1, run);
    let two = in_pool(2, run);
    assert!(one == two, "results differ between 1 and 2 threads");
}

#[test]
fn geometry_image_samples_take_the_colours_of_the_disk_under_them() {
    // A disk over [0, 3]² in grid units (positions = uv), with a vertex inserted in the middle
    // of the bottom edge (no patch vertex of its own) and colours linear in position: every
    // sample must get the linear colour, the inserted vertex's included.
    use glam::Vec2;
    use texsyn::stages::extract::bilateral_difference::geometry_image_colors;
    let uv = vec![
        Vec2::new(0.0, 0.0),
        Vec2::new(3.0, 0.0),
        Vec2::new(3.0, 3.0),
        Vec2::new(0.0, 3.0),
        Vec2::new(1.5, 0.0),
    ];
    let positions: Vec<Vec3> = uv.iter().map(|q| Vec3::new(q.x, q.y, 0.0)).collect();
    let disk = Mesh::new(positions, vec![[0, 4, 3], [4, 1, 2], [4, 2, 3]]);
    let original = vec![0, 1, 2, 3, u32::MAX];
    let lin = |q: Vec2| [q.x / 3.0, q.y / 3.0, 0.5, 1.0];
    let patch_colors: Vec<[f32; 4]> = uv[..4].iter().map(|&q| lin(q)).collect();
    let cols = geometry_image_colors(4, &disk, &uv, &original, &patch_colors);
    assert_eq!(cols.len(), 16);
    for i in 0..4 {
        for j in 0..4 {
            let want = lin(Vec2::new(j as f32, i as f32));
            let got = cols[i * 4 + j];
            for c in 0..3 {
                assert!(
                    (got[c] - want[c]).abs() < 1e-5,
                    "({i}, {j}): {got:?} vs {want:?}"
                );
            }
        }
    }
}

/// A fine sinusoidal relief (wavelength 0.25, amplitude 0.02): texture, not shape.
fn ripples(x: f32, y: f32) -> f32 {
    let k = std::f32::consts::TAU / 0.25;
    0.02 * (k * x).sin_pure() * (k * y).sin_pure()
}

#[test]
fn every_method_returns_texels_that_rebuild_the_sample_on_its_base() {
    let place = Placement::tilted();
    let mesh = relief_mesh(120, &ripples, &place, Some(&gradient));
    for method in [
        ExtractMethod::Planar,
        ExtractMethod::HeightField,
        ExtractMethod::Bilateral,
    ] {
        let params = ExtractParams {
            method,
            size: 64,
            ..Default::default()
        };
        let e = extract_mesh_texture(&mesh, &params, &no_progress).unwrap();
        assert_eq!(
            (e.texels.width, e.texels.height, e.texels.channels),
            (64, 64, 6)
        );
        assert_eq!((e.base.len(), e.frames.len()), (64 * 64, 64 * 64));
        assert_eq!(e.patch_faces, mesh.triangles.len());
        let dn_mean = mean(e.texels.data.chunks(6).map(|t| t[2]));
        let (mut on_surface, mut relief, mut colour) = (0.0f32, 0.0f32, 0.0f32);
        for (k, t) in e.texels.data.chunks(6).enumerate() {
            let f = e.frames[k];
            let q = place.to_local(e.base[k] + t[0] * f.x + t[1] * f.y + t[2] * f.n);
            on_surface = on_surface.max((q.z - ripples(q.x, q.y)).abs());
            // Where the base is flat, dn is the relief itself.
            relief = relief.max(((t[2] - dn_mean) - ripples(q.x, q.y)).abs());
            let want = gradient(q.x, q.y);
            for c in 0..3 {
                colour = colour.max((t[3 + c] - want[c]).abs());
            }
        }
        eprintln!("{method:?}: off the surface {on_surface}, relief {relief}, colour {colour}");
        assert!(
            on_surface < 1e-3,
            "{method:?}: rebuilt point {on_surface} off the surface"
        );
        assert!(
            relief < 0.004,
            "{method:?}: dn differs from the relief by {relief}"
        );
        assert!(colour < 0.01, "{method:?}: colour off by {colour}");
    }
}

//! Long thin parts (issue 12 §2): on a capsule six times as long as it is wide, the geometry
//! image stretches the cylinder differently along and across its axis, and synthesis in grid
//! texels turned the relief into streaks along the part. The relief must keep its (isotropic)
//! shape on the surface: its gradient energy along the axis and across it must be comparable.

mod common;
use common::{artifact, repo, run_config};
use glam::DVec3;
use texsyn::artifact::Format;
use texsyn::geom::geometry_image::{GeometryImage, TexelImage};
use texsyn_core::math::PureMath;

/// Radius 1, cylinder from z = −5 to z = 5, hemispherical caps: 12 long, 2 wide.
const HALF: f64 = 5.0;

/// A closed capsule as OFF text: `around` vertices a ring, `rings` rings along the cylinder,
/// `cap` rings on each cap between the cylinder's end and the pole.
fn capsule_off(around: usize, rings: usize, cap: usize) -> String {
    let mut verts: Vec<DVec3> = vec![DVec3::new(0.0, 0.0, -HALF - 1.0)];
    let mut ring_z_r: Vec<(f64, f64)> = Vec::new();
    let quarter = std::f64::consts::FRAC_PI_2;
    for c in 1..=cap {
        let a = quarter * c as f64 / (cap + 1) as f64; // from the pole
        ring_z_r.push((-HALF - a.cos_pure(), a.sin_pure()));
    }
    for r in 0..rings {
        ring_z_r.push((-HALF + 2.0 * HALF * r as f64 / (rings - 1) as f64, 1.0));
    }
    for c in (1..=cap).rev() {
        let a = quarter * c as f64 / (cap + 1) as f64;
        ring_z_r.push((HALF + a.cos_pure(), a.sin_pure()));
    }
    for &(z, r) in &ring_z_r {
        for k in 0..around {
            let t = std::f64::consts::TAU * k as f64 / around as f64;
            verts.push(DVec3::new(r * t.cos_pure(), r * t.sin_pure(), z));
        }
    }
    verts.push(DVec3::new(0.0, 0.0, HALF + 1.0));
    let nr = ring_z_r.len();
    let at = |ring: usize, k: usize| 1 + ring * around + k % around;
    let top = verts.len() - 1;
    let mut faces = Vec::new();
    for k in 0..around {
        faces.push([0, at(0, k + 1), at(0, k)]);
        faces.push([top, at(nr - 1, k), at(nr - 1, k + 1)]);
    }
    for ring in 0..nr - 1 {
        for k in 0..around {
            faces.push([at(ring, k), at(ring, k + 1), at(ring + 1, k + 1)]);
            faces.push([at(ring, k), at(ring + 1, k + 1), at(ring + 1, k)]);
        }
    }
    let mut s = format!("OFF\n{} {} 0\n", verts.len(), faces.len());
    for v in &verts {
        s += &format!("{} {} {}\n", v.x, v.y, v.z);
    }
    for f in &faces {
        s += &format!("3 {} {} {}\n", f[0], f[1], f[2]);
    }
    s
}

/// The relief's gradient energy along the capsule's axis and across it, over the grid
/// triangles of the geometry image that lie on the cylinder (away from the caps): per
/// triangle, the gradient of the linear interpolant of dn on the 3D triangle, weighted by
/// area. Returns (along, across) per unit area; an isotropic relief has them about equal (one
/// tangent direction each).
fn energy_along_across(gi: &GeometryImage, t: &TexelImage) -> (f64, f64) {
    let n = gi.n as usize;
    let p = |k: usize| gi.positions[k].as_dvec3();
    // Mates carry their representative's texel (as the reconstruction reads them).
    let h = |k: usize| {
        let r = gi.mate_rep[k] as usize;
        t.texel((r % n) as u32, (r / n) as u32)[2] as f64
    };
    let (mut along, mut across, mut area) = (0.0, 0.0, 0.0);
    let mut tri = |a: usize, b: usize, c: usize| {
        let (p0, p1, p2) = (p(a), p(b), p(c));
        if [p0, p1, p2].iter().any(|q| q.z.abs() > HALF - 0.5) {
            return;
        }
        let (e1, e2) = (p1 - p0, p2 - p0);
        let (g11, g12, g22) = (e1.dot(e1), e1.dot(e2), e2.dot(e2));
        let det = g11 * g22 - g12 * g12;
        let ar = 0.5 * det.max(0.0).sqrt();
        if ar < 1e-9 {
            return;
        }
        let (d1, d2) = (h(b) - h(a), h(c) - h(a));
        // g = α e1 + β e2 with g·e1 = d1, g·e2 = d2.
        let alpha = (g22 * d1 - g12 * d2) / det;
        let beta = (g11 * d2 - g12 * d1) / det;
        let g = alpha * e1 + beta * e2;
        let gz = g.z;
        along += ar * gz * gz;
        across += ar * (g.length_squared() - gz * gz);
        area += ar;
    };
    for i in 0..n - 1 {
        for j in 0..n - 1 {
            let k = i * n + j;
            tri(k, k + 1, k + n);
            tri(k + n + 1, k + n, k + 1);
        }
    }
    assert!(area > 10.0, "the cylinder is covered: area {area}");
    (along / area, across / area)
}

/// Runs relief_cow's settings on the capsule with `sets` and returns along/across.
fn anisotropy(sets: &[&str]) -> f64 {
    let dir = tempfile::tempdir().unwrap();
    let mesh = dir.path().join("capsule.off");
    std::fs::write(&mesh, capsule_off(32, 41, 6)).unwrap();
    let mesh_set = format!("inputs.mesh={}", mesh.display());
    let mut all = vec![
        mesh_set.as_str(),
        "parameterize.size=129",
        "analyse_exemplar.orientations=4",
        "analyse_exemplar.scales=3",
        "field.density_offset=0.0",
        "reconstruct.preview_size=32",
    ];
    all.extend_from_slice(sets);
    let cache = tempfile::tempdir().unwrap();
    let r = run_config(
        &repo().join("configs/relief_cow.toml"),
        &all,
        &[],
        cache.path(),
    )
    .unwrap();
    let gi = GeometryImage::view(artifact(&r, "parameterize")).unwrap();
    let texels = TexelImage::view(artifact(&r, "synthesize")).unwrap();
    let (along, across) = energy_along_across(&gi, &texels);
    let ratio = along / across;
    eprintln!("capsule {sets:?}: gradient energy along {along:.4} across {across:.4}, ratio {ratio:.3}");
    ratio
}

#[test]
fn relief_on_a_long_thin_capsule_keeps_its_shape() {
    let ratio = anisotropy(&[]);
    assert!(
        (0.5..=2.0).contains(&ratio),
        "the relief is stretched on the capsule: gradient energy along / across the axis {ratio:.3} \
         (isotropic bumps give about 1; streaks along the part give much less)"
    );
}

//! Long thin parts: on a capsule eleven times as long as it is wide, the geometry
//! image spaces its samples about twice as far apart along the axis as around it, and
//! synthesis in grid texels turned the relief into streaks along the part. The relief must
//! keep its (isotropic) shape on the surface: its squared differences along the axis and
//! around it, measured on the unrolled cylinder, must be comparable.

use crate::common;
use common::{artifact, repo, run_config};
use glam::DVec3;
use texsyn::artifact::Format;
use texsyn::geom::geometry_image::{GeometryImage, TexelImage};
use texsyn_core::math::PureMath;

/// Cylinder from z = −HALF to HALF of radius RADIUS, hemispherical caps: 11 long, 1 wide.
const HALF: f64 = 5.0;
const RADIUS: f64 = 0.5;

/// A closed capsule as OFF text: `around` vertices a ring, `rings` rings along the cylinder,
/// `cap` rings on each cap between the cylinder's end and the pole.
fn capsule_off(around: usize, rings: usize, cap: usize) -> String {
    let mut verts: Vec<DVec3> = vec![DVec3::new(0.0, 0.0, -HALF - RADIUS)];
    let mut ring_z_r: Vec<(f64, f64)> = Vec::new();
    let quarter = std::f64::consts::FRAC_PI_2;
    for c in 1..=cap {
        let a = quarter * c as f64 / (cap + 1) as f64; // from the pole
        ring_z_r.push((-HALF - RADIUS * a.cos_pure(), RADIUS * a.sin_pure()));
    }
    for r in 0..rings {
        ring_z_r.push((-HALF + 2.0 * HALF * r as f64 / (rings - 1) as f64, RADIUS));
    }
    for c in (1..=cap).rev() {
        let a = quarter * c as f64 / (cap + 1) as f64;
        ring_z_r.push((HALF + RADIUS * a.cos_pure(), RADIUS * a.sin_pure()));
    }
    for &(z, r) in &ring_z_r {
        for k in 0..around {
            let t = std::f64::consts::TAU * k as f64 / around as f64;
            verts.push(DVec3::new(r * t.cos_pure(), r * t.sin_pure(), z));
        }
    }
    verts.push(DVec3::new(0.0, 0.0, HALF + RADIUS));
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

/// The relief unrolled: the cylinder's samples (away from the caps) binned by arc length
/// around and height along the axis into square cells of side `cell`, each cell the mean dn of
/// its samples; then the mean squared difference of neighbouring cells along the axis and
/// around it. Binning averages texel-scale noise the same way in both directions, which the
/// grid (spaced differently along and across) does not.
fn unrolled_along_across(gi: &GeometryImage, t: &TexelImage, cell: f64) -> (f64, f64) {
    let n = gi.n as usize;
    let around = (std::f64::consts::TAU * RADIUS / cell).round() as usize;
    let zmax = HALF - RADIUS;
    let rows = (2.0 * zmax / cell).floor() as usize;
    let mut sum = vec![0.0f64; around * rows];
    let mut count = vec![0u32; around * rows];
    for k in 0..n * n {
        let p = gi.positions[k].as_dvec3();
        if p.z.abs() >= zmax {
            continue;
        }
        let a = p.y.atan2_pure(p.x).rem_euclid(std::f64::consts::TAU);
        let c = ((a / std::f64::consts::TAU * around as f64) as usize).min(around - 1);
        let r = (((p.z + zmax) / cell) as usize).min(rows - 1);
        let rep = gi.mate_rep[k] as usize;
        sum[r * around + c] += t.texel((rep % n) as u32, (rep / n) as u32)[2] as f64;
        count[r * around + c] += 1;
    }
    let h = |r: usize, c: usize| {
        let k = r * around + c % around;
        (count[k] > 0).then(|| sum[k] / count[k] as f64)
    };
    let (mut along, mut na, mut across, mut nc) = (0.0, 0, 0.0, 0);
    for r in 0..rows {
        for c in 0..around {
            if let (Some(a), Some(b)) = (h(r, c), h(r, c + 1)) {
                across += (b - a) * (b - a);
                nc += 1;
            }
            if r + 1 < rows
                && let (Some(a), Some(b)) = (h(r, c), h(r + 1, c))
            {
                along += (b - a) * (b - a);
                na += 1;
            }
        }
    }
    assert!(na > 200 && nc > 200, "cells filled: {na} {nc}");
    (along / na as f64, across / nc as f64)
}

/// Runs relief_cow's settings on the capsule with `sets` (a 257² geometry image, density
/// offset 0: bumps several texels wide even along the axis, where the grid is coarser) and
/// returns along / across of [`unrolled_along_across`] for cells of 0.05 (about
/// the grid's spacing) and 0.1.
fn anisotropy(sets: &[&str]) -> [f64; 2] {
    let dir = tempfile::tempdir().unwrap();
    let mesh = dir.path().join("capsule.off");
    std::fs::write(&mesh, capsule_off(32, 41, 6)).unwrap();
    let mesh_set = format!("inputs.mesh={}", mesh.display());
    let mut all = vec![
        mesh_set.as_str(),
        "parameterize.size=257",
        "field.density_offset=0.0",
        "analyse_exemplar.orientations=4",
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
    [0.05, 0.1].map(|cell| {
        let (along, across) = unrolled_along_across(&gi, &texels, cell);
        let ratio = along / across;
        eprintln!(
            "capsule {sets:?}, cells of {cell}: squared differences along {along:.4} across \
             {across:.4}, ratio {ratio:.3}"
        );
        ratio
    })
}

/// On main: ratios 0.150 (cells of 0.05) and 0.191 (0.1), streaks along the capsule; with the
/// templates in the surface metric 0.738 and 0.747. The sample itself (nops.png) has 0.86
/// between its rows and columns.
#[test]
fn relief_on_a_long_thin_capsule_keeps_its_shape() {
    for ratio in anisotropy(&[]) {
        assert!(
            (0.5..=2.0).contains(&ratio),
            "the relief is stretched on the capsule: squared differences along / across the \
             axis {ratio:.3} (the sample's own is 0.86; streaks along the part give much less)"
        );
    }
    // The paper's grid-texel templates, kept behind the switch, are what drew the streaks.
    let old = anisotropy(&["synthesize.anisotropic=false"]);
    assert!(old[0] < 0.4, "grid-texel templates: {old:?}");
}

//! Geometric texture synthesis over geometry images (Lai et al. 2005, §4.2–4.3): texel variants
//! and boundary-consistent synthesis on synthetic geometry images (tests/common/geometry_texture.rs,
//! shared with the `geometry_texture_*` examples, which time and show the same cases).

use crate::common;
use common::geometry_texture::{
    bumps, channel, cylinder, field, flat, folded, stripes, synth, variants,
};
use glam::Vec2;
use texsyn::geom::geometry_image::TexelImage;
use texsyn::stages::analyse_exemplar::texel_variants::{TexelVariantParams, build_texel_variants};
use texsyn::stages::synthesize::geometry_texture::{
    GeometrySynthParams, ParamField, Search, synthesize_geometry_texture,
};
use texsyn_core::math::PureMath;

fn mean_std(v: &[f32]) -> (f64, f64) {
    let n = v.len() as f64;
    let m = v.iter().map(|&x| x as f64).sum::<f64>() / n;
    let s = (v.iter().map(|&x| (x as f64 - m).powi(2)).sum::<f64>() / n).sqrt();
    (m, s)
}

/// Sums of squared finite differences of dn along x (columns) and y (rows).
fn gradient_energy(t: &TexelImage) -> (f64, f64) {
    let (mut ex, mut ey) = (0.0, 0.0);
    for y in 0..t.height - 1 {
        for x in 0..t.width - 1 {
            let v = t.texel(x, y)[2] as f64;
            ex += (t.texel(x + 1, y)[2] as f64 - v).powi(2);
            ey += (t.texel(x, y + 1)[2] as f64 - v).powi(2);
        }
    }
    (ex, ey)
}

/// Asserts that the stripes of `t` run across axis `axis` (0: x, 1: y), its dn changing along
/// it more than 6 times as much as along the other, and that its (dx, dy) vectors point along
/// it, their spread there more than 4 times the other's.
fn assert_stripes_across(t: &TexelImage, axis: usize, what: &str) {
    let (ex, ey) = gradient_energy(t);
    let energy = [ex, ey];
    let spread = [0, 1].map(|c| mean_std(&channel(t, c)).1);
    let (a, b) = (axis, 1 - axis);
    assert!(
        energy[a] > 6.0 * energy[b],
        "{what}: stripes across {} expected, energies {ex} {ey}",
        ["x", "y"][a]
    );
    assert!(
        spread[a] > 4.0 * spread[b],
        "{what}: vectors along {} expected, dx {} dy {}",
        ["x", "y"][a],
        spread[0],
        spread[1]
    );
}

/// The dominant period of dn along rows: the period in [2, 48] (steps of 0.05 texels) with the
/// most power, summed over rows.
fn dominant_period(t: &TexelImage) -> f64 {
    let (m, _) = mean_std(&channel(t, 2));
    let mut best = (0.0, 0.0);
    let mut p = 2.0f64;
    while p <= 48.0 {
        let w = std::f64::consts::TAU / p;
        let mut power = 0.0;
        for y in 0..t.height {
            let (mut re, mut im) = (0.0, 0.0);
            for x in 0..t.width {
                let v = t.texel(x, y)[2] as f64 - m;
                re += v * (w * x as f64).cos_pure();
                im += v * (w * x as f64).sin_pure();
            }
            power += re * re + im * im;
        }
        if power > best.1 {
            best = (p, power);
        }
        p += 0.05;
    }
    best.0
}

fn bits(t: &TexelImage) -> Vec<u32> {
    t.data.iter().map(|v| v.to_bits()).collect()
}

#[test]
fn mated_texels_are_bit_identical_and_the_cylinder_seam_is_hidden() {
    let sample = bumps(48, 5, false);
    let v = variants(&sample);
    let n = 65;
    let gi = cylinder(n);
    let f = field(n, Vec2::Y, 1.0);
    for search in [Search::KCoherence, Search::PerTexel] {
        let p = GeometrySynthParams {
            seed: 3,
            search,
            ..Default::default()
        };
        seam_is_hidden(&gi, &f, &v, &p, n);
    }
}

/// Mated texels are bit-identical, and the cylinder's seam is as hidden as the inside is
/// smooth, clearly more than without the passes that read across the cut (boundary
/// resynthesis, and for k-coherence the correction passes).
fn seam_is_hidden(
    gi: &texsyn::geom::geometry_image::GeometryImage,
    f: &ParamField,
    v: &texsyn::stages::analyse_exemplar::texel_variants::TexelVariants,
    p: &GeometrySynthParams,
    n: u32,
) {
    let out = synthesize_geometry_texture(gi, f, &v.as_ref(), p, &|_| {}).unwrap();
    for i in 0..n {
        assert_eq!(
            bits_of(out.texel(0, i)),
            bits_of(out.texel(n - 1, i)),
            "row {i}"
        );
    }
    // Across the cut, column 0 (≡ n−1) neighbours column n−2: the jump there should look like
    // any jump between neighbouring columns, and clearly less than without resynthesis.
    let seam = |t: &TexelImage| {
        (0..n)
            .map(|i| (t.texel(0, i)[2] - t.texel(n - 2, i)[2]).abs() as f64)
            .sum::<f64>()
            / n as f64
    };
    let inner = |t: &TexelImage| {
        let mut s = 0.0;
        for i in 0..n {
            for j in 8..n - 9 {
                s += (t.texel(j, i)[2] - t.texel(j + 1, i)[2]).abs() as f64;
            }
        }
        s / (n * (n - 17)) as f64
    };
    let without = synthesize_geometry_texture(
        gi,
        f,
        &v.as_ref(),
        &GeometrySynthParams {
            boundary_passes: 0,
            correction_passes: 0,
            ..p.clone()
        },
        &|_| {},
    )
    .unwrap();
    let (with_ratio, without_ratio) = (seam(&out) / inner(&out), seam(&without) / inner(&without));
    assert!(with_ratio < 1.6, "{:?}: seam/inner {with_ratio}", p.search);
    assert!(
        without_ratio > 1.25 * with_ratio,
        "{:?}: resynthesis should lower the seam: {without_ratio} vs {with_ratio}",
        p.search
    );
}

fn bits_of(v: &[f32]) -> Vec<u32> {
    v.iter().map(|x| x.to_bits()).collect()
}

#[test]
fn a_cut_folded_at_a_corner_gives_identical_texels_with_turned_frames() {
    let sample = bumps(48, 6, true);
    // Colour channels make the analysis slower; two orientations and one scale suffice here.
    let p = TexelVariantParams {
        orientations: 4,
        scales: 1,
        ..Default::default()
    };
    let v = build_texel_variants(&sample, &p, &|_| {}).unwrap();
    let n = 33;
    let out = synth(&folded(n), &field(n, Vec2::new(0.6, 0.8), 1.0), &v, 1);
    for j in 1..n {
        // Sample (0, j) is texel (x = j, y = 0); its mate (j, 0) is texel (0, j).
        assert_eq!(bits_of(out.texel(j, 0)), bits_of(out.texel(0, j)), "j {j}");
    }
}

#[test]
fn output_statistics_are_close_to_the_sample() {
    for (name, sample) in [
        ("bumps", bumps(64, 7, false)),
        ("stripes", stripes(64, 9.0)),
    ] {
        let v = variants(&sample);
        let n = 65;
        let out = synth(&flat(n), &field(n, Vec2::Y, 1.0), &v, 0);
        let (sm, ss) = mean_std(&channel(&sample, 2));
        let (om, os) = mean_std(&channel(&out, 2));
        assert!(
            (om - sm).abs() < 0.15 * ss,
            "{name}: mean {om} vs {sm} (std {ss})"
        );
        assert!((os / ss - 1.0).abs() < 0.2, "{name}: std {os} vs {ss}");
        // Bumps: not a few texels copied over and over, many distinct values.
        if name == "bumps" {
            let mut vals = channel(&out, 2);
            vals.sort_by(f32::total_cmp);
            vals.dedup();
            assert!(
                vals.len() > 1000,
                "{name}: only {} distinct values",
                vals.len()
            );
        }
    }
}

#[test]
fn stripes_turn_with_the_field_and_so_do_their_vectors() {
    let v = variants(&stripes(64, 8.0));
    let n = 65;
    let gi = flat(n);
    // Up along +y: as in the sample, and its dx (0.3 cos) stays in dx.
    let up = synth(&gi, &field(n, Vec2::Y, 1.0), &v, 0);
    assert_stripes_across(&up, 0, "up");

    // Up along +x: the sample turned by −90° (R(θ) takes the sample's up (0, 1) to (1, 0)), so
    // the stripes run across y and (dx, dy) = (c, 0) becomes (0, −c).
    let side = synth(&gi, &field(n, Vec2::X, 1.0), &v, 0);
    assert_stripes_across(&side, 1, "side");
    // The sign: compare dy with the slope of dn along y.
    let mut agree = 0.0;
    for y in 1..n - 1 {
        for x in 0..n {
            let d = side.texel(x, y + 1)[2] - side.texel(x, y - 1)[2];
            agree += (d * side.texel(x, y)[1]) as f64;
        }
    }
    // Sample: d(dn)/dx = (2π/P) cos a and dx = 0.3 cos a agree in sign. Turned by −90°, a
    // content offset +x goes to −y, so d(dn)/d(−y) agrees with −dy: d(dn)/dy agrees with dy.
    assert!(agree > 0.0, "dy and the dn slope along y disagree: {agree}");
}

#[test]
fn variant_rotation_turns_the_vectors_with_the_pattern() {
    let sample = stripes(48, 8.0);
    let p = TexelVariantParams {
        orientations: 4,
        ..Default::default()
    };
    let v = build_texel_variants(&sample, &p, &|_| {}).unwrap();
    let r = v.as_ref();
    let mid = p.middle_scale();
    let quarter = r.level(r.variant(mid, 1), 0);
    assert_eq!((quarter.width, quarter.height), (48, 48));
    let w = quarter.width as usize;
    let at = |x: usize, y: usize| &quarter.texels[(y * w + x) * 3..(y * w + x) * 3 + 3];
    for y in 0..w {
        for x in 0..w {
            let t = at(x, y);
            // (0.3 cos a, 0) turned by +90° is (0, 0.3 cos a); dn constant along x.
            assert!(t[0].abs() < 1e-6, "dx {}", t[0]);
            assert!((t[2] - at(0, y)[2]).abs() < 1e-6);
            // The content at sample column s shows at variant row s: dy = 0.3 cos, dn = sin.
            let a = std::f32::consts::TAU * y as f32 / 8.0;
            assert!((t[1] - 0.3 * a.cos_pure()).abs() < 1e-5 && (t[2] - a.sin_pure()).abs() < 1e-5);
        }
    }
    // 45°: a cropped square inside the rotated sample; the vector turned by 45°.
    let p8 = TexelVariantParams::default();
    let v8 = build_texel_variants(&sample, &p8, &|_| {}).unwrap();
    let r8 = v8.as_ref();
    let d = r8.level(r8.variant(mid, 1), 0);
    assert_eq!(d.width, (47.0 / 2f64.sqrt()) as u32 + 1);
    for t in d.texels.chunks(3) {
        // (c, 0) turned by 45°: (c/√2, c/√2).
        assert!((t[0] - t[1]).abs() < 1e-5);
    }
}

#[test]
fn relative_scale_picks_enlarged_or_reduced_variants() {
    // Stripes of period 8: T1 has period 16, T2 8, T3 4.
    let v = variants(&stripes(64, 8.0));
    let n = 65;
    let gi = flat(n);
    let period = |r: f32| dominant_period(&synth(&gi, &field(n, Vec2::Y, r), &v, 0));
    let (p_half, p_one, p_two) = (period(0.5), period(1.0), period(2.0));
    // R = 0.5: grid points close together on the surface, so the texture spans twice as many
    // of them; R = 2: half as many. level = log2 R + 2 picks T1, T2, T3.
    assert!((p_one - 8.0).abs() < 0.5, "R = 1: period {p_one}");
    assert!((p_half - 16.0).abs() < 1.6, "R = 0.5: period {p_half}");
    assert!((p_two - 4.0).abs() < 0.4, "R = 2: period {p_two}");
    // In between, the two neighbouring scales mix: R = √2 has stripes of period 8 and 4.
    let mixed = synth(&gi, &field(n, Vec2::Y, std::f32::consts::SQRT_2), &v, 0);
    let p_mixed = dominant_period(&mixed);
    assert!((3.5..8.5).contains(&p_mixed), "R = √2: period {p_mixed}");
}

#[test]
fn output_does_not_depend_on_the_thread_count_and_follows_the_seed() {
    let sample = bumps(48, 8, true);
    let p = TexelVariantParams {
        orientations: 4,
        ..Default::default()
    };
    let v = build_texel_variants(&sample, &p, &|_| {}).unwrap();
    let n = 33;
    let gi = cylinder(n);
    let nn = (n * n) as usize;
    let f = ParamField {
        dir: (0..nn)
            .map(|k| Vec2::from_angle(k as f32 * 0.003).rotate(Vec2::Y))
            .collect(),
        rel_scale: (0..nn)
            .map(|k| 0.5 + 1.5 * (k as u32 % n) as f32 / n as f32)
            .collect(),
    };
    let run = |threads: usize, seed: u64| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| synth(&gi, &f, &v, seed))
    };
    // Progress runs from 0 to 1 without stepping back.
    let seen = std::cell::RefCell::new(Vec::new());
    let pr = GeometrySynthParams {
        seed: 4,
        ..Default::default()
    };
    let a = synthesize_geometry_texture(&gi, &f, &v.as_ref(), &pr, &|x| seen.borrow_mut().push(x))
        .unwrap();
    let seen = seen.into_inner();
    assert_eq!((seen[0], *seen.last().unwrap()), (0.0, 1.0));
    assert!(seen.windows(2).all(|w| w[0] <= w[1]), "{seen:?}");
    assert_eq!(bits(&a), bits(&run(1, 4)));
    let b = run(2, 4);
    assert_eq!(bits(&a), bits(&b));
    let c = run(2, 5);
    let differ = a
        .data
        .chunks(6)
        .zip(c.data.chunks(6))
        .filter(|(x, y)| x != y)
        .count();
    assert!(differ > nn / 2, "another seed changed only {differ} texels");
    // (The variants' own thread-count independence is a unit test of texel_variants.)
}

#[test]
fn too_small_samples_and_bad_inputs_are_errors() {
    let e = build_texel_variants(&stripes(16, 5.0), &TexelVariantParams::default(), &|_| {})
        .unwrap_err()
        .to_string();
    assert!(e.contains("16×16") && e.contains("at least"), "{e}");
    let v = variants(&stripes(48, 6.0));
    let p = GeometrySynthParams::default();
    // 3 levels need a side 4k + 1.
    let e = synthesize_geometry_texture(
        &flat(31),
        &field(31, Vec2::Y, 1.0),
        &v.as_ref(),
        &p,
        &|_| {},
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("side 31"), "{e}");
    let mut f = field(33, Vec2::Y, 1.0);
    f.rel_scale[40] = 0.0;
    let e = synthesize_geometry_texture(&flat(33), &f, &v.as_ref(), &p, &|_| {})
        .unwrap_err()
        .to_string();
    assert!(e.contains("(1, 7)"), "{e}");
    let mut f = field(33, Vec2::Y, 1.0);
    f.dir.pop();
    assert!(synthesize_geometry_texture(&flat(33), &f, &v.as_ref(), &p, &|_| {}).is_err());
}

//! Jump maps on real exemplars: analysis (stages/analyse_exemplar/jump_map.rs), 2D synthesis
//! (stages/synthesize/synth2d.rs) and rendering (stages/reconstruct/blend2d.rs).

use crate::common;
use common::jump_map::{EXEMPLARS, coherence, patch_ssd, stats};
use common::load_exemplar as load;
use std::sync::OnceLock;

use texsyn::image::Image;
use texsyn::image::knn::squared_distance;
use texsyn::image::neighbourhood::{NeighbourhoodParams, Neighbourhoods};
use texsyn::image::pca::{Pca, PcaParams};
use texsyn::random::counter_hash;
use texsyn::stages::analyse_exemplar::jump_map::{
    Jump, JumpMap, JumpMapParams, JumpMapRef, build_jump_map,
};
use texsyn::stages::reconstruct::blend2d::render_2d;
use texsyn::stages::synthesize::synth2d::{Synth2dParams, synthesize_2d};

/// Exemplars and their default jump maps, computed once for all tests.
fn corpus() -> &'static Vec<(String, Image, JumpMap)> {
    static CORPUS: OnceLock<Vec<(String, Image, JumpMap)>> = OnceLock::new();
    CORPUS.get_or_init(|| {
        EXEMPLARS
            .iter()
            .map(|name| {
                let img = load(name);
                let jm = build_jump_map(img.view(), &JumpMapParams::default(), &|_| {});
                (name.to_string(), img, jm)
            })
            .collect()
    })
}

fn pixel_distance(a: (u32, u32), b: (u32, u32)) -> f32 {
    let dx = a.0 as f32 - b.0 as f32;
    let dy = a.1 as f32 - b.1 as f32;
    (dx * dx + dy * dy).sqrt()
}

#[test]
fn weights_are_normalized_and_sorted_best_first() {
    for (name, img, jm) in corpus() {
        let k = JumpMapParams::default().jumps_per_pixel;
        assert_eq!((jm.width, jm.height, jm.k), (img.width, img.height, k));
        assert_eq!(jm.jumps.len(), (img.width * img.height * k) as usize);
        let mut below_one = 0;
        for (i, slots) in jm.jumps.chunks(k as usize).enumerate() {
            let used = slots.iter().take_while(|j| j.weight > 0.0).count();
            assert!(used >= 1, "{name}: pixel {i} has no jump");
            assert!(
                slots[used..].iter().all(|j| j.weight == 0.0),
                "{name}: pixel {i}: used slot after an empty one"
            );
            let sum: f32 = slots.iter().map(|j| j.weight).sum();
            assert!(
                sum > 0.0 && sum <= 1.0 + 1e-5,
                "{name}: pixel {i}: sum {sum}"
            );
            if sum < 0.999 {
                below_one += 1;
            }
            for s in slots[..used].windows(2) {
                assert!(
                    s[0].weight >= s[1].weight,
                    "{name}: pixel {i} not best first"
                );
            }
            for j in &slots[..used] {
                assert!(j.weight.is_finite() && j.weight > 0.0);
                assert!((j.x as u32) < jm.width && (j.y as u32) < jm.height);
            }
        }
        // Poor matches make sums below one somewhere, good ones sums of one elsewhere.
        let n = (img.width * img.height) as usize;
        assert!(
            below_one > 0 && below_one < n,
            "{name}: {below_one} of {n} below one"
        );
        assert!(JumpMapRef::new(jm.width, jm.height, jm.k, &jm.jumps).is_ok());
    }
}

#[test]
fn jumps_leave_the_exclusion_radius_and_each_other() {
    let r = JumpMapParams::default().exclusion_radius;
    for (name, _, jm) in corpus() {
        for y in 0..jm.height {
            for x in 0..jm.width {
                let js = jm.jumps_at(x, y);
                for (a, j) in js.iter().enumerate() {
                    let t = (j.x as u32, j.y as u32);
                    assert!(
                        pixel_distance((x, y), t) > r,
                        "{name}: ({x}, {y}) jumps to {t:?}, within {r}"
                    );
                    for o in &js[..a] {
                        assert!(
                            pixel_distance((o.x as u32, o.y as u32), t) > r,
                            "{name}: ({x}, {y}): jumps {o:?} and {j:?} are too close"
                        );
                    }
                }
            }
        }
    }
}

#[test]
fn jumps_connect_similar_neighbourhoods() {
    for (name, img, jm) in corpus() {
        let (w, h) = (img.width, img.height);
        let (mut jump_sum, mut jump_n) = (0.0f64, 0usize);
        let (mut rand_sum, mut rand_n) = (0.0f64, 0usize);
        for y in 0..h {
            for x in 0..w {
                let j = jm.jumps_at(x, y)[0];
                jump_sum += patch_ssd(img.view(), (x, y), (j.x as u32, j.y as u32)) as f64;
                jump_n += 1;
                // A random partner outside the exclusion radius.
                let i = (y * w + x) as u64;
                let mut t = 0;
                loop {
                    let hsh = counter_hash(99, t, i);
                    let o = ((hsh % w as u64) as u32, ((hsh >> 32) % h as u64) as u32);
                    t += 1;
                    if pixel_distance((x, y), o) > 4.0 {
                        rand_sum += patch_ssd(img.view(), (x, y), o) as f64;
                        rand_n += 1;
                        break;
                    }
                }
            }
        }
        let (jm_mean, rand_mean) = (jump_sum / jump_n as f64, rand_sum / rand_n as f64);
        assert!(
            jm_mean < 0.35 * rand_mean,
            "{name}: best jumps' patch SSD {jm_mean} vs random pairs' {rand_mean}"
        );
    }
}

/// The jumps are exactly the greedy definition: nearest in PCA space, outside the exclusion
/// radius of the pixel and of every better jump. Checked by brute force on one exemplar.
#[test]
fn jumps_are_the_nearest_admissible_matches() {
    let img = load("leopard.png"); // 64×62
    let params = JumpMapParams {
        search_eps: 0.0,
        ..Default::default()
    };
    let jm = build_jump_map(img.view(), &params, &|_| {});
    let nb = Neighbourhoods::new(
        img.view(),
        &NeighbourhoodParams {
            levels: params.levels,
            window: params.window,
            coarse_weight: params.coarse_weight,
        },
    );
    let all = nb.all();
    let pca = Pca::fit(&all, nb.dim(), &PcaParams::default());
    let feats = pca.project_all(&all);
    let d = pca.components();
    assert!((4..=16).contains(&d));
    let w = img.width;
    let r2 = params.exclusion_radius * params.exclusion_radius;
    let n = (img.width * img.height) as usize;
    let far = |a: usize, b: usize| {
        let (ax, ay) = ((a as u32 % w) as f32, (a as u32 / w) as f32);
        let (bx, by) = ((b as u32 % w) as f32, (b as u32 / w) as f32);
        (ax - bx) * (ax - bx) + (ay - by) * (ay - by) > r2
    };
    for p in (0..n).step_by(37) {
        let q = &feats[p * d..(p + 1) * d];
        let mut order: Vec<(f32, usize)> = (0..n)
            .map(|i| (squared_distance(q, &feats[i * d..(i + 1) * d]), i))
            .collect();
        order.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        let mut chosen: Vec<usize> = Vec::new();
        for &(_, i) in &order {
            if chosen.len() == params.jumps_per_pixel as usize {
                break;
            }
            if far(i, p) && chosen.iter().all(|&c| far(i, c)) {
                chosen.push(i);
            }
        }
        let got: Vec<usize> = jm
            .jumps_at(p as u32 % w, p as u32 / w)
            .iter()
            .map(|j| (j.y as u32 * w + j.x as u32) as usize)
            .collect();
        assert_eq!(got, chosen, "pixel {p}");
    }
}

#[test]
fn jump_map_is_identical_for_one_and_two_threads() {
    let img = load("marble1.png");
    let params = JumpMapParams {
        // Several PCA chunks and a non-default shape, to exercise the reductions.
        jumps_per_pixel: 5,
        ..Default::default()
    };
    let run = |threads| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| build_jump_map(img.view(), &params, &|_| {}))
    };
    let a = run(1);
    let b = run(2);
    let bytes = |m: &JumpMap| bytemuck::cast_slice::<Jump, u8>(&m.jumps).to_vec();
    assert_eq!(bytes(&a), bytes(&b));
}

#[test]
fn progress_runs_from_zero_to_one() {
    let img = load("leopard.png");
    let seen = std::sync::Mutex::new(Vec::new());
    build_jump_map(img.view(), &JumpMapParams::default(), &|f| {
        seen.lock().unwrap().push(f)
    });
    let seen = seen.into_inner().unwrap();
    assert_eq!(seen.first(), Some(&0.0));
    assert_eq!(seen.last(), Some(&1.0));
    assert!(seen.windows(2).all(|s| s[0] <= s[1]), "{seen:?}");
}

#[test]
fn synthesized_addresses_stay_inside_and_depend_only_on_the_seed() {
    for (name, _, jm) in corpus() {
        for (w, h) in [(97u32, 61u32), (128, 128), (1, 40)] {
            let a = synthesize_2d(jm.as_ref(), w, h, &Synth2dParams::default(), 7);
            assert_eq!(a.len(), (w * h) as usize);
            assert!(
                a.iter()
                    .all(|p| (p[0] as u32) < jm.width && (p[1] as u32) < jm.height),
                "{name}: address outside the exemplar"
            );
            let again = synthesize_2d(jm.as_ref(), w, h, &Synth2dParams::default(), 7);
            assert_eq!(a, again);
            let other = synthesize_2d(jm.as_ref(), w, h, &Synth2dParams::default(), 8);
            assert_ne!(a, other, "{name}: the seed changes nothing");
        }
    }
}

#[test]
fn continuation_controls_patch_size() {
    for (name, _, jm) in corpus() {
        for combine_neighbours in [false, true] {
            let c = |continuation: f32| {
                let p = Synth2dParams {
                    continuation,
                    combine_neighbours,
                    ..Default::default()
                };
                coherence(&synthesize_2d(jm.as_ref(), 128, 128, &p, 1), 128, 128)
            };
            let (huge, medium, small) = (c(1e6), c(20.0), c(0.5));
            let what = format!("{name}, combine_neighbours {combine_neighbours}");
            // With jumps forced only by the exemplar's edges, patches are large.
            assert!(
                huge > 0.85,
                "{what}: coherence {huge} with a huge continuation"
            );
            assert!(
                small < medium - 0.1 && medium < huge - 0.05,
                "{what}: coherence small {small}, medium {medium}, huge {huge}"
            );
            // With a continuation weight of 0.5 against jump weights summing to about 1 per
            // neighbour, most steps jump.
            assert!(
                small < 0.6,
                "{what}: coherence {small} with a small continuation"
            );
        }
    }
}

#[test]
fn combining_neighbours_fragments_patches_less() {
    for (name, _, jm) in corpus() {
        let c = |combine_neighbours| {
            let p = Synth2dParams {
                continuation: 1e6,
                combine_neighbours,
                ..Default::default()
            };
            (0..4)
                .map(|seed| coherence(&synthesize_2d(jm.as_ref(), 128, 128, &p, seed), 128, 128))
                .sum::<f64>()
                / 4.0
        };
        let (single, combined) = (c(false), c(true));
        assert!(
            combined > single + 0.01,
            "{name}: coherence {combined} combined vs {single} with one random source"
        );
    }
}

#[test]
fn synthesized_images_have_the_exemplar_colour_statistics() {
    for (name, img, jm) in corpus() {
        let addr = synthesize_2d(jm.as_ref(), 192, 192, &Synth2dParams::default(), 3);
        let out = render_2d(img.view(), &addr, 192, 192, 1);
        let (want, got) = (stats(img), stats(&out));
        for c in 0..3 {
            let (wm, ws) = want[c];
            let (gm, gs) = got[c];
            assert!(
                (gm - wm).abs() < 0.15 * ws,
                "{name} channel {c}: mean {gm} vs {wm} (std {ws})"
            );
            assert!(
                (gs / ws - 1.0).abs() < 0.12,
                "{name} channel {c}: std {gs} vs {ws}"
            );
        }
        // And the rendered pixels are exemplar pixels where no seam is near (r = 0: all).
        let copy = render_2d(img.view(), &addr, 192, 192, 0);
        for (p, a) in copy.pixels.iter().zip(&addr) {
            assert_eq!(*p, img.view().get(a[0] as u32, a[1] as u32));
        }
    }
}

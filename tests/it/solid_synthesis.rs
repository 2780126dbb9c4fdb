//! Solid synthesis on real exemplars: candidate triples and slabs
//! (stages/analyse_exemplar/candidate_triples.rs), history windows, dependent sets and the
//! on-demand brick synthesis (stages/synthesize/solid/solid_synthesis/).

use crate::common;
use common::load_exemplar as load;
use common::solid::{cube, rotated_field, transpose, trivial_cube};
use std::sync::OnceLock;

use glam::{Quat, Vec3};
use texsyn::artifact::AlignedBytes;
use texsyn::image::Image;
use texsyn::image::patch_score::{ScoreParams, patch_score};
use texsyn::random::counter_hash;
use texsyn::stages::analyse_exemplar::candidate_triples::{
    AnalysisError, CandidateParams, SolidAnalysis, SolidAnalysisRef, Triple, analyse,
};
use texsyn::stages::reconstruct::solid_colour::{SolidColourRule, VoxelTriples};
use texsyn::stages::synthesize::solid::dependent_set::{ChunkedNeed, dependent_set};
use texsyn::stages::synthesize::solid::history_window::Schedule;
use texsyn::stages::synthesize::solid::solid_synthesis::{
    BatchLimits, Brick, BrickStore, MemoryBrickStore, NeighbourhoodColour, Scheme, SolidParams,
    SolidSynthesis, VoxelRequest,
};

fn crop(img: &Image, x0: u32, y0: u32, w: u32, h: u32) -> Image {
    let mut out = Image::new(w, h);
    for y in 0..h {
        for x in 0..w {
            out.pixels[(y * w + x) as usize] = img.pixels[((y0 + y) * img.width + x0 + x) as usize];
        }
    }
    out
}

/// A small, fast setup: a 48² crop of marble1, 3 levels, N = 5 then 7.
fn small_params() -> CandidateParams {
    CandidateParams {
        levels: 3,
        neighbourhood_coarsest: 5,
        neighbourhood: 7,
        ..Default::default()
    }
}

fn small() -> &'static (Image, SolidAnalysis) {
    static S: OnceLock<(Image, SolidAnalysis)> = OnceLock::new();
    S.get_or_init(|| {
        let img = crop(&load("marble1.png"), 20, 30, 48, 48);
        let a = analyse([img.view(); 3], &small_params()).unwrap();
        (img, a)
    })
}

fn small_solid_params() -> SolidParams {
    let mut p = SolidParams::paper(3);
    p.cell = 8;
    p.subpart = 16;
    p.levels[0].passes = 2;
    p
}

/// Mean over the section's 5×5 patches of the squared distance to the nearest 5×5 exemplar
/// patch (toroidal exemplar), per pixel and channel.
fn nearest_patch_distance(section: &[[f32; 3]], sw: usize, sh: usize, ex: &Image) -> f32 {
    let (ew, eh) = (ex.width as i64, ex.height as i64);
    let mut total = 0.0f64;
    let mut count = 0;
    for sy in 2..sh - 2 {
        for sx in 2..sw - 2 {
            let mut best = f32::INFINITY;
            for ey in 0..eh {
                for ex_ in 0..ew {
                    let mut d = 0.0f32;
                    'p: for j in -2..=2i64 {
                        for i in -2..=2i64 {
                            let s =
                                section[(sy as i64 + j) as usize * sw + (sx as i64 + i) as usize];
                            let e = ex.pixels[((ey + j).rem_euclid(eh) * ew
                                + (ex_ + i).rem_euclid(ew))
                                as usize];
                            for c in 0..3 {
                                let t = s[c] - e[c];
                                d += t * t;
                            }
                            if d >= best {
                                break 'p;
                            }
                        }
                    }
                    best = best.min(d);
                }
            }
            total += best as f64;
            count += 1;
        }
    }
    (total / count as f64 / 75.0) as f32
}

#[test]
fn analysis_arrays_round_trip_in_place() {
    let (_, a) = small();
    // Store each array in its own 64-byte-aligned buffer, as a mapped artifact would.
    let buffers: Vec<(String, AlignedBytes)> = a
        .arrays()
        .into_iter()
        .map(|(n, b)| (n, AlignedBytes::from_slice(b)))
        .collect();
    let views: Vec<(String, &[u8])> = buffers
        .iter()
        .map(|(n, b)| (n.clone(), b.as_slice()))
        .collect();
    let meta_bytes = serde_json::to_vec(&a.meta).unwrap();
    let meta = serde_json::from_slice(&meta_bytes).unwrap();
    let r = SolidAnalysisRef::from_arrays(meta, &views).unwrap();
    assert_eq!(r.stack, &a.stack[..]);
    assert_eq!(r.features, &a.features[..]);
    assert_eq!(r.candidates, &a.candidates[..]);
    assert_eq!(r.slabs, &a.slabs[..]);
    assert_eq!(r.pca_basis, &a.pca_basis[..]);
    // Zero copy: the views point into the buffers.
    let cand = buffers.iter().find(|(n, _)| n == "candidates").unwrap();
    assert_eq!(
        r.candidates.as_ptr() as usize,
        cand.1.as_slice().as_ptr() as usize
    );
    // Same answers as the owned analysis.
    let o = a.as_ref();
    for li in 0..3 {
        assert_eq!(r.candidates(li, 1, [7, 9]), o.candidates(li, 1, [7, 9]));
        assert_eq!(r.feature(li, 0, [3, 4]), o.feature(li, 0, [3, 4]));
    }
    // A truncated array or a triple outside the exemplar is an error, not a panic later.
    let mut short = views.clone();
    let i = short.iter().position(|(n, _)| n == "features").unwrap();
    short[i].1 = &short[i].1[..short[i].1.len() - 4];
    assert!(matches!(
        SolidAnalysisRef::from_arrays(a.meta.clone(), &short),
        Err(AnalysisError::Corrupt(_))
    ));
    let mut bad = a.clone();
    bad.candidates[5].c[2][0] = 500;
    let bad_views: Vec<(String, &[u8])> = bad.arrays();
    assert!(SolidAnalysisRef::from_arrays(a.meta.clone(), &bad_views).is_err());
}

#[test]
fn analysis_is_identical_on_any_thread_count() {
    let img = crop(&load("wood2.png"), 0, 0, 40, 40);
    let run = |threads| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| analyse([img.view(); 3], &small_params()).unwrap())
    };
    let (a, b) = (run(1), run(2));
    assert!(a == b);
    let bytes = |x: &SolidAnalysis| -> Vec<Vec<u8>> {
        x.arrays().into_iter().map(|(_, b)| b.to_vec()).collect()
    };
    assert_eq!(bytes(&a), bytes(&b));
}

#[test]
fn candidate_triples_beat_random_triples_by_crossbar_error() {
    let (img, a) = small();
    let r = a.as_ref();
    let (w, h) = (img.width, img.height);
    for li in 0..3 {
        let mut cand = 0.0f64;
        let mut rand = 0.0f64;
        let mut n = 0;
        for plane in 0..3 {
            for y in (0..h as u16).step_by(3) {
                for x in (0..w as u16).step_by(3) {
                    cand += r.crossbar_error(li, &r.candidates(li, plane, [x, y])[0]) as f64;
                    let k = counter_hash(7, li as u64, n);
                    let c = |s: u32| {
                        [
                            ((k >> s) % w as u64) as u16,
                            ((k >> (s + 8)) % h as u64) as u16,
                        ]
                    };
                    let mut t = Triple::new(c(0), c(16), c(32));
                    t.c[plane] = [x, y];
                    rand += r.crossbar_error(li, &t) as f64;
                    n += 1;
                }
            }
        }
        assert!(
            cand < 0.3 * rand,
            "level {li}: candidates {cand}, random {rand}"
        );
    }
}

#[test]
fn exemplars_of_different_sizes_are_an_error_naming_the_sizes() {
    let a = crop(&load("marble1.png"), 0, 0, 48, 48);
    let b = crop(&load("marble1.png"), 0, 0, 40, 48);
    let e = analyse([a.view(), b.view(), a.view()], &small_params()).unwrap_err();
    assert_eq!(
        e,
        AnalysisError::SizeMismatch {
            xy: (48, 48),
            yz: (40, 48),
            zx: (48, 48)
        }
    );
    let msg = e.to_string();
    assert!(msg.contains("48×48") && msg.contains("40×48"), "{msg}");
    let e = analyse(
        [a.view(); 3],
        &CandidateParams {
            neighbourhood: 6,
            ..small_params()
        },
    )
    .unwrap_err();
    assert!(
        e.to_string().contains("analyse_exemplar.neighbourhood"),
        "{e}"
    );
}

fn all_bricks(s: &SolidSynthesis, store: &MemoryBrickStore) -> Vec<(u32, [i32; 3], Brick)> {
    let mut out = vec![];
    for level in 1..=s.levels() {
        for b in store.bricks(level) {
            out.push((level, b, (*store.get(level, b).unwrap()).clone()));
        }
    }
    out
}

#[test]
fn voxels_are_the_same_whatever_else_was_requested_and_on_any_thread_count() {
    let (_, a) = small();
    let vol = cube(40);
    let field = rotated_field(
        &vol,
        Quat::from_rotation_z(0.4) * Quat::from_rotation_x(0.3),
    );
    let s = SolidSynthesis::new(a.as_ref(), &field, vol, small_solid_params()).unwrap();
    let req_a = VoxelRequest::from_box([0, 0, 12], [40, 40, 13]);
    let req_b = VoxelRequest::from_box([20, 5, 10], [30, 25, 30]);
    let run = |threads: usize, reqs: &[&VoxelRequest]| {
        let store = MemoryBrickStore::new();
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| {
                for r in reqs {
                    s.synthesize(r, &store).unwrap();
                }
            });
        store
    };
    let only_a = run(2, &[&req_a]);
    let only_b = run(2, &[&req_b]);
    let both = run(2, &[&req_b, &req_a]);
    let a_one_thread = run(1, &[&req_a]);
    for v in req_a.voxels() {
        let t = s.triple_at(&only_a, 3, v).unwrap();
        assert_eq!(Some(t), s.triple_at(&both, 3, v), "{v:?}");
        assert_eq!(Some(t), s.triple_at(&a_one_thread, 3, v), "{v:?}");
    }
    let mut overlap = 0;
    for v in req_b.voxels() {
        let t = s.triple_at(&only_b, 3, v).unwrap();
        assert_eq!(Some(t), s.triple_at(&both, 3, v), "{v:?}");
        overlap += req_a.contains(v) as usize;
    }
    assert!(overlap > 0);
    // Every brick two stores share is identical, at every level.
    let reference = all_bricks(&s, &both);
    let mut shared = 0;
    for store in [&only_a, &only_b, &a_one_thread] {
        for (level, b, brick) in all_bricks(&s, store) {
            let r = reference
                .iter()
                .find(|(l, c, _)| *l == level && *c == b)
                .unwrap();
            assert!(r.2 == brick, "brick {b:?} of level {level} differs");
            shared += 1;
        }
    }
    assert!(shared > 10);
    // The synthesized voxels are not all alike (no degenerate constant solution).
    let distinct: std::collections::BTreeSet<Triple> = req_a
        .voxels()
        .map(|v| s.triple_at(&only_a, 3, v).unwrap())
        .collect();
    assert!(distinct.len() > 200, "{}", distinct.len());
}

/// A level split into batches (to bound the working memory) gives every brick, at every
/// level, the bytes of the level done at once, on any thread count, and no batch's working
/// values exceed the limit (unless one brick alone does).
#[test]
fn batches_bound_the_working_set_and_leave_every_brick_unchanged() {
    crate::full_tier_only!("a volume big enough for several batches per level");
    let (_, a) = small();
    let vol = cube(64);
    let field = rotated_field(&vol, Quat::from_rotation_y(0.3));
    let s = SolidSynthesis::new(a.as_ref(), &field, vol, small_solid_params()).unwrap();
    let req = VoxelRequest::plane(&vol, Vec3::splat(32.0), Vec3::new(0.3, 0.2, 1.0));
    let whole = MemoryBrickStore::new();
    let r_whole = s.synthesize(&req, &whole).unwrap();
    let finest = r_whole.levels.len() - 1;
    assert!(r_whole.levels.iter().all(|l| l.batches == 1));
    // One brick's dependent set alone, at the finest level: the least a limit can hold.
    let needed = &s.bricks_needed(&req)[finest];
    let one = needed[needed.len() / 2];
    let (lo, hi) = s.brick_box(one);
    let single = SolidSynthesis::new(a.as_ref(), &field, vol, small_solid_params())
        .unwrap()
        .with_batch_limits(BatchLimits {
            box_voxels: u64::MAX,
            chunk_voxels: u64::MAX,
        });
    let one_brick = single
        .synthesize(&VoxelRequest::from_box(lo, hi), &MemoryBrickStore::new())
        .unwrap();
    let least = one_brick.levels[finest].largest_batch_voxels;
    let limit = (r_whole.levels[finest].largest_batch_voxels / 3).max(2 * least);
    assert!(limit < r_whole.levels[finest].largest_batch_voxels);
    let limits = BatchLimits {
        box_voxels: u64::MAX,
        chunk_voxels: limit,
    };
    let batched = SolidSynthesis::new(a.as_ref(), &field, vol, small_solid_params())
        .unwrap()
        .with_batch_limits(limits);
    for threads in [1, 2] {
        let store = MemoryBrickStore::new();
        let r = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| batched.synthesize(&req, &store).unwrap());
        let l = &r.levels[finest];
        assert!(l.batches > 1, "{l:?}");
        assert!(l.largest_batch_voxels <= limit, "{l:?}, limit {limit}");
        // The overlap of the batches is synthesized twice: more work, never less.
        assert!(l.voxels >= r_whole.levels[finest].voxels);
        assert_eq!(
            all_bricks(&batched, &store),
            all_bricks(&s, &whole),
            "{threads} threads"
        );
    }
    // A box limit alone splits too (the dense box of a dependent set), to the same bricks.
    let boxed = SolidSynthesis::new(a.as_ref(), &field, vol, small_solid_params())
        .unwrap()
        .with_batch_limits(BatchLimits {
            box_voxels: 20_000,
            chunk_voxels: u64::MAX,
        });
    let store = MemoryBrickStore::new();
    let r = boxed.synthesize(&req, &store).unwrap();
    assert!(r.levels[finest].batches > 1);
    assert_eq!(all_bricks(&boxed, &store), all_bricks(&s, &whole));
    // The dependent set counts each voxel once however the level is batched; the work
    // (`batch_voxels`) counts the overlap again.
    let (one, split) = (s.dependent_set(&req), batched.dependent_set(&req));
    for (o, b) in one.iter().zip(&split) {
        assert_eq!(
            (b.voxels, b.corrections),
            (o.voxels, o.corrections),
            "level {}",
            o.level
        );
        assert_eq!(o.batch_voxels, o.voxels, "level {}: one batch", o.level);
        assert!(b.batch_voxels >= b.voxels, "level {}", b.level);
    }
    assert!(split[finest].batch_voxels > split[finest].voxels);
}

/// Bricks by (level, coordinates).
type Bricks = std::collections::HashMap<(u32, [i32; 3]), std::sync::Arc<Brick>>;

/// A store that keeps its bricks only until released, and records how many levels it held.
#[derive(Default)]
struct ReleasingStore {
    map: std::sync::Mutex<Bricks>,
    most_levels: std::sync::atomic::AtomicUsize,
    released: std::sync::Mutex<Vec<u32>>,
}

impl BrickStore for ReleasingStore {
    fn get(&self, level: u32, brick: [i32; 3]) -> Option<std::sync::Arc<Brick>> {
        self.map.lock().unwrap().get(&(level, brick)).cloned()
    }
    fn put(&self, level: u32, brick: [i32; 3], b: std::sync::Arc<Brick>) {
        let mut map = self.map.lock().unwrap();
        map.insert((level, brick), b);
        let levels: std::collections::BTreeSet<u32> = map.keys().map(|k| k.0).collect();
        self.most_levels
            .fetch_max(levels.len(), std::sync::atomic::Ordering::Relaxed);
    }
    fn release(&self, level: u32) {
        self.map.lock().unwrap().retain(|k, _| k.0 != level);
        self.released.lock().unwrap().push(level);
    }
}

/// Each level is released as soon as the next finer one is done, so at most two levels are
/// resident, the finest alone at the end, and the synthesis never reads a released brick
/// (it would fail with a missing brick).
#[test]
fn a_level_is_released_once_its_finer_level_is_done() {
    let (_, a) = small();
    let (vol, field) = trivial_cube(48);
    let s = SolidSynthesis::new(a.as_ref(), &field, vol, small_solid_params()).unwrap();
    let req = VoxelRequest::from_box([0, 0, 20], [48, 48, 21]);
    let store = ReleasingStore::default();
    s.synthesize(&req, &store).unwrap();
    assert_eq!(*store.released.lock().unwrap(), vec![1, 2]);
    assert_eq!(
        store.most_levels.load(std::sync::atomic::Ordering::Relaxed),
        2
    );
    let reference = MemoryBrickStore::new();
    s.synthesize(&req, &reference).unwrap();
    assert!(store.map.lock().unwrap().keys().all(|k| k.0 == 3));
    for v in req.voxels() {
        assert_eq!(s.triple_at(&store, 3, v), s.triple_at(&reference, 3, v));
        assert!(s.triple_at(&store, 3, v).is_some());
    }
}

/// The chunked form of a dependent set holds the same bytes as the dense one, in fewer
/// voxels when the set is thin.
#[test]
fn chunked_dependent_sets_hold_the_dense_bytes() {
    let domain = glam::IVec3::splat(64);
    // Two small targets in opposite corners: a large box, a small set.
    let targets = [
        (glam::IVec3::splat(2), glam::IVec3::splat(6)),
        (glam::IVec3::splat(56), glam::IVec3::splat(60)),
    ];
    let dense = dependent_set(&Schedule::dual_grid(2, true, 8), domain, &targets, 2);
    let chunked = ChunkedNeed::from_grid(&dense);
    for i in 0..dense.need.len() {
        let p = dense.position(i);
        assert_eq!(chunked.get(p), dense.need[i], "{p:?}");
    }
    assert_eq!(chunked.get(glam::IVec3::splat(-1)), 0);
    assert_eq!(chunked.voxels(), dense.voxels());
    assert_eq!(chunked.corrections(), dense.corrections());
    assert!(chunked.voxels() > 0);
    assert!(chunked.chunk_voxels() < dense.need.len() as u64 / 2);
}

#[test]
fn an_overlapping_request_reuses_bricks() {
    let (_, a) = small();
    let (vol, field) = trivial_cube(48);
    let s = SolidSynthesis::new(a.as_ref(), &field, vol, small_solid_params()).unwrap();
    let first = VoxelRequest::from_box([0, 0, 20], [48, 48, 21]);
    let second = VoxelRequest::from_box([0, 0, 22], [48, 48, 23]);
    let store = MemoryBrickStore::new();
    let r1 = s.synthesize(&first, &store).unwrap();
    let r2 = s.synthesize(&second, &store).unwrap();
    let fresh = s.synthesize(&second, &MemoryBrickStore::new()).unwrap();
    assert!(r1.bricks_computed() > 0);
    assert!(
        r2.bricks_computed() < fresh.bricks_computed(),
        "{} vs {}",
        r2.bricks_computed(),
        fresh.bricks_computed()
    );
    assert!(r2.levels.iter().any(|l| l.bricks_reused > 0));
    // At the finest level both need the same bricks; below, only what the missing ones need.
    assert_eq!(r2.levels[2].bricks_needed, fresh.levels[2].bricks_needed);
    for (a, b) in r2.levels.iter().zip(&fresh.levels) {
        assert!(a.bricks_needed <= b.bricks_needed);
        assert_eq!(a.bricks_computed + a.bricks_reused, a.bricks_needed);
    }
    // Asking again computes nothing.
    let r3 = s.synthesize(&second, &store).unwrap();
    assert_eq!(r3.bricks_computed(), 0);
    assert_eq!(r3.voxels(), 0);
    // The bricks a request needs are what a fresh synthesis stores.
    let needed = s.bricks_needed(&second);
    let fresh_store = MemoryBrickStore::new();
    s.synthesize(&second, &fresh_store).unwrap();
    for (li, bricks) in needed.iter().enumerate() {
        assert_eq!(
            *bricks,
            fresh_store.bricks(li as u32 + 1),
            "level {}",
            li + 1
        );
    }
}

#[test]
fn dual_grid_depends_on_fewer_voxels_than_plain_correction() {
    let (_, a) = small();
    let (vol, field) = trivial_cube(96);
    let req = VoxelRequest::plane(&vol, Vec3::splat(48.0), Vec3::new(0.2, 0.3, 1.0));
    let mut params = small_solid_params();
    params.levels[1].passes = 3;
    params.levels[2].passes = 3;
    let dual = SolidSynthesis::new(a.as_ref(), &field, vol, params.clone()).unwrap();
    let plain =
        SolidSynthesis::new(a.as_ref(), &field, vol, params.with_scheme(Scheme::Plain)).unwrap();
    let d = dual.dependent_set(&req);
    let p = plain.dependent_set(&req);
    for li in 1..3 {
        assert!(
            d[li].voxels < p[li].voxels && d[li].corrections < p[li].corrections,
            "level {}: dual {:?} plain {:?}",
            li + 1,
            (d[li].voxels, d[li].corrections),
            (p[li].voxels, p[li].corrections)
        );
        assert!(d[li].bricks.len() <= p[li].bricks.len());
    }
    // The finest level of the dual scheme stays within a few cells of the plane.
    assert!(
        d[2].voxels * 2 < p[2].voxels,
        "{} vs {}",
        d[2].voxels,
        p[2].voxels
    );
}

/// The stencil the dependent set dilates by is as tight as the reads (⌊e + ½⌋ for nearest
/// sampling, the exact lattice for the trivial field): the set shrinks, and every voxel, at
/// every level, is what the one-voxel-wider stencil of before gives, for a constant field and
/// for one that turns and scales over the volume.
#[test]
fn the_exact_stencil_gives_the_same_voxels_from_a_thinner_set() {
    let (_, a) = small();
    let vol = cube(40);
    let trivial = common::solid::trivial_field(&vol);
    let rotated = rotated_field(
        &vol,
        Quat::from_rotation_y(0.5) * Quat::from_rotation_x(0.2),
    );
    // A field that turns and scales from node to node: the reach bounds every read through
    // the largest scale and the √2 of a turned frame, not one frame's exact extent (a larger
    // volume, so that the sets do not fill it).
    let big = cube(72);
    let mut varying = common::solid::trivial_field(&big);
    let nodes = varying.rotations.len() as f32;
    for (i, (q, s)) in varying
        .rotations
        .iter_mut()
        .zip(varying.scales.iter_mut())
        .enumerate()
    {
        let t = i as f32 / nodes;
        *q = Quat::from_rotation_y(1.2 * t) * Quat::from_rotation_x(0.7 * (1.0 - t));
        *s = 0.7 + 0.3 * t;
    }
    let plane = |vol: &texsyn::stages::parameterize::volume_embedding::Volume| {
        let c = vol.dims[0] as f32 / 2.0;
        VoxelRequest::plane(vol, Vec3::splat(c), Vec3::new(0.1, 0.2, 1.0))
    };
    for (name, vol, field) in [
        ("trivial", vol, &trivial),
        ("rotated", vol, &rotated),
        ("varying", big, &varying),
    ] {
        let req = plane(&vol);
        let exact = SolidSynthesis::new(a.as_ref(), field, vol, small_solid_params()).unwrap();
        let wide = SolidSynthesis::new(a.as_ref(), field, vol, small_solid_params())
            .unwrap()
            .widen_reach(1);
        if name == "trivial" {
            // N = 5, 7, 7: the sample offsets reach N_h exactly, trilinear or not.
            assert_eq!(exact.reach(), [2, 3, 3]);
        }
        let (de, dw) = (exact.dependent_set(&req), wide.dependent_set(&req));
        for (e, w) in de.iter().zip(&dw) {
            assert!(e.voxels <= w.voxels, "{name} level {}", e.level);
        }
        assert!(
            de[2].voxels < dw[2].voxels,
            "{name}: {} vs {}",
            de[2].voxels,
            dw[2].voxels
        );
        let (se, sw) = (MemoryBrickStore::new(), MemoryBrickStore::new());
        exact.synthesize(&req, &se).unwrap();
        wide.synthesize(&req, &sw).unwrap();
        let mut compared = 0;
        for (level, b, brick) in all_bricks(&exact, &se) {
            let other = sw.get(level, b).expect("the wider set makes every brick");
            assert!(
                *other == brick,
                "{name}: brick {b:?} of level {level} differs"
            );
            compared += 1;
        }
        assert!(compared > 10, "{name}: {compared}");
        for v in req.voxels() {
            assert_eq!(
                exact.triple_at(&se, 3, v),
                wide.triple_at(&sw, 3, v),
                "{name} {v:?}"
            );
        }
    }
}

/// On the trivial field a correction reads only the squares of its weighted exemplar planes,
/// so the dependent set dilates by those (the flat stencil) and not by the whole cube: a
/// thinner set, and every brick of every level the same as the cube's. Both a plane of weight
/// 0 (wood2 in xy and zx) and all three planes.
#[test]
fn the_flat_stencil_gives_the_same_voxels_from_a_thinner_set() {
    let (vol, field) = trivial_cube(40);
    // Whole voxel steps of 2 are on the lattice too: reads every second voxel of the planes.
    let mut doubled = field.clone();
    doubled.scales.iter_mut().for_each(|s| *s = 2.0);
    let req = VoxelRequest::plane(&vol, Vec3::splat(20.0), Vec3::new(0.1, 0.2, 1.0));
    let (_, all_planes) = small();
    let (_, two_planes) = wood_layers();
    for (name, a, field) in [
        ("three planes", all_planes, &field),
        ("two planes", two_planes, &field),
        ("two planes, scale 2", two_planes, &doubled),
    ] {
        let flat = SolidSynthesis::new(a.as_ref(), field, vol, small_solid_params()).unwrap();
        let cube = SolidSynthesis::new(a.as_ref(), field, vol, small_solid_params())
            .unwrap()
            .cube_stencil();
        assert_ne!(
            flat.stencil(2),
            cube.stencil(2),
            "{name}: the stencil is flat"
        );
        let (df, dc) = (flat.dependent_set(&req), cube.dependent_set(&req));
        for (f, c) in df.iter().zip(&dc) {
            assert!(f.voxels <= c.voxels, "{name} level {}", f.level);
        }
        let (f, c) = (
            df.iter().map(|l| l.voxels).sum::<u64>(),
            dc.iter().map(|l| l.voxels).sum::<u64>(),
        );
        assert!(f < c, "{name}: {f} vs {c}");
        let (sf, sc) = (MemoryBrickStore::new(), MemoryBrickStore::new());
        flat.synthesize(&req, &sf).unwrap();
        cube.synthesize(&req, &sc).unwrap();
        let mut compared = 0;
        for (level, b, brick) in all_bricks(&flat, &sf) {
            let other = sc.get(level, b).expect("the cube's set makes every brick");
            assert!(
                *other == brick,
                "{name}: brick {b:?} of level {level} differs"
            );
            compared += 1;
        }
        assert!(compared > 10, "{name}: {compared}");
    }
}

/// A 48² crop of wood2 as a solid layered across x: xy shows the stripes, zx the transposed
/// stripes, yz (weight 0) is not matched.
fn wood_layers() -> &'static (Image, SolidAnalysis) {
    static S: OnceLock<(Image, SolidAnalysis)> = OnceLock::new();
    S.get_or_init(|| {
        let img = crop(&load("wood2.png"), 10, 20, 48, 48);
        let tr = transpose(&img);
        let params = CandidateParams {
            plane_weights: [1.0, 0.0, 1.0],
            ..small_params()
        };
        let a = analyse([img.view(), img.view(), tr.view()], &params).unwrap();
        (img, a)
    })
}

#[test]
fn a_section_looks_more_like_the_exemplar_than_random_triples() {
    let (img, a) = wood_layers();
    let (vol, field) = trivial_cube(32);
    let s = SolidSynthesis::new(a.as_ref(), &field, vol, small_solid_params()).unwrap();
    let store = MemoryBrickStore::new();
    s.synthesize(&VoxelRequest::from_box([0, 0, 16], [32, 32, 17]), &store)
        .unwrap();
    let r = a.as_ref();
    let mut synth = vec![];
    let mut random = vec![];
    for y in 0..32 {
        for x in 0..32 {
            synth.push(s.colour_at(&store, [x, y, 16]).unwrap());
            let k = counter_hash(3, 0, (y * 32 + x) as u64);
            let c = |s: u32| [((k >> s) % 48) as u16, ((k >> (s + 8)) % 48) as u16];
            random.push(r.colour(2, &Triple::new(c(0), c(16), c(32))));
        }
    }
    let ds = nearest_patch_distance(&synth, 32, 32, img);
    let dr = nearest_patch_distance(&random, 32, 32, img);
    assert!(ds < 0.5 * dr, "synthesized {ds}, random {dr}");
}

/// A z-section of a sketch-free solid of the marble crop, coloured as the reconstruct node
/// colours it, with neighbourhoods and colour rule of one kind: the section as an image.
fn marble_section(neighbourhoods: NeighbourhoodColour, rule: SolidColourRule) -> Image {
    let (_, a) = small();
    let (vol, field) = trivial_cube(40);
    let mut p = small_solid_params();
    p.neighbourhood_colour = neighbourhoods;
    let s = SolidSynthesis::new(a.as_ref(), &field, vol, p).unwrap();
    let store = MemoryBrickStore::new();
    let voxels: Vec<[i32; 3]> = (0..40)
        .flat_map(|y| (0..40).map(move |x| [x, y, 20]))
        .collect();
    let (triples, _) = s.synthesize_voxels(&voxels, &store).unwrap();
    let mut shown = VoxelTriples::new(&field, &vol, rule);
    shown.add(&voxels, &triples, a.as_ref());
    let mut img = Image::new(40, 40);
    for (i, v) in voxels.iter().enumerate() {
        let c = shown.colour((*v).into(), Some(Vec3::Z)).unwrap();
        img.pixels[i] = [c[0], c[1], c[2], 1.0];
    }
    img
}

/// Three texels averaged are a blur wherever a triple is not consistent across its planes: a
/// section must be matched and shown as what a cut along its plane holds, the plane's own
/// texels. Then the section keeps the exemplar's gradient energy (its marble veins); the
/// averaged solid keeps under half of it.
#[test]
fn a_section_keeps_the_exemplar_s_detail_where_the_averaged_solid_blurs_it() {
    let (img, _) = small();
    let params = ScoreParams {
        patch: 5,
        ..Default::default()
    };
    let score = |section: &Image| patch_score(section.view(), img.view(), &params).unwrap();
    let plane = score(&marble_section(
        NeighbourhoodColour::Plane,
        SolidColourRule::Facing,
    ));
    let mean = score(&marble_section(
        NeighbourhoodColour::Mean,
        SolidColourRule::Mean,
    ));
    assert!(
        plane.gradient_ratio >= 0.7,
        "plane neighbourhoods, facing colours: gradient ratio {:.3}",
        plane.gradient_ratio
    );
    assert!(
        mean.gradient_ratio < 0.5,
        "mean neighbourhoods and colours: gradient ratio {:.3} (the setup no longer shows \
         the blur it guards against)",
        mean.gradient_ratio
    );
    assert!(
        plane.coverage > 1.5 * mean.coverage,
        "coverage {:.3} against the mean's {:.3}",
        plane.coverage,
        mean.coverage
    );
}

/// A pyramid deeper than the analysis' and an odd cell are refused. (Bricks round-trip with
/// their format, in src/artifact/solid.rs.)
#[test]
fn bad_setups_are_errors() {
    let (_, a) = small();
    let (vol, field) = trivial_cube(16);
    let e = SolidSynthesis::new(a.as_ref(), &field, vol, SolidParams::paper(4))
        .err()
        .unwrap();
    assert!(e.to_string().contains("3 levels"), "{e}");
    let mut p = small_solid_params();
    p.cell = 7;
    let e = SolidSynthesis::new(a.as_ref(), &field, cube(16), p)
        .err()
        .unwrap();
    assert!(e.to_string().contains("synthesize.cell"), "{e}");
}

#[test]
fn the_pyramid_depth_is_derived_from_whichever_of_its_two_settings_is_given() {
    use texsyn::stages::synthesize::solid::solid_synthesis::couple_levels;
    let couple = |depth: u32, n: usize, given: [bool; 2]| {
        let (mut d, mut l) = (depth, SolidParams::paper(4).levels[..n].to_vec());
        couple_levels(&mut d, &mut l, given).map(|()| (d, l))
    };
    // Only the depth: the paper's settings for that many levels.
    assert_eq!(
        couple(3, 4, [true, false]).unwrap(),
        (3, SolidParams::paper(3).levels)
    );
    // Neither: the default depth with the paper's settings, as before the coupling.
    assert_eq!(
        couple(4, 4, [false, false]).unwrap(),
        (4, SolidParams::default().levels)
    );
    // Only the levels: their count.
    let (d, l) = couple(4, 2, [false, true]).unwrap();
    assert_eq!((d, l.len()), (2, 2));
    // Both, agreeing or not.
    assert_eq!(couple(2, 2, [true, true]).unwrap().0, 2);
    let e = couple(3, 2, [true, true]).unwrap_err();
    assert_eq!(e.key(), "synthesize.levels");
    assert!(
        e.to_string().contains("analyse_exemplar.levels is 3"),
        "{e}"
    );
    let e = couple(4, 0, [false, true]).unwrap_err();
    assert!(e.to_string().contains("has 0 entries"), "{e}");
}

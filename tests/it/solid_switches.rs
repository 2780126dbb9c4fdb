//! The solid method's switches for §4.3 and §6 of the paper, each off by default: feature
//! masks (`analyse_exemplar.feature_mask`, stages/analyse_exemplar/feature_mask.rs), the
//! coarse-level field smoothing (`synthesize.field_smoothing`,
//! stages/field/coarse_field_smoothing.rs) and integration along the field at coarse levels
//! (`synthesize.field_integration`, stages/synthesize/solid/field_integration.rs). Each test
//! measures what its switch is for, so a switch that did nothing, or the wrong thing, fails.

use crate::common;
use common::load_exemplar as load;
use common::solid::{cube, jittered, rings_field, rotated_field, transpose, trivial_field};
use std::sync::OnceLock;

use glam::{IVec3, Quat};
use texsyn::image::Image;
use texsyn::stages::analyse_exemplar::candidate_triples::{
    CandidateParams, SolidAnalysis, analyse, analyse_masked, analyse_transposed,
};
use texsyn::stages::analyse_exemplar::feature_mask::{FeatureMaskParams, feature_channel};
use texsyn::stages::field::quaternion_field::RotationField;
use texsyn::stages::synthesize::solid::solid_synthesis::{
    BrickStore, MemoryBrickStore, SolidParams, SolidSynthesis, VoxelRequest,
};

fn params(mask: Option<FeatureMaskParams>) -> CandidateParams {
    CandidateParams {
        levels: 3,
        neighbourhood_coarsest: 5,
        neighbourhood: 7,
        feature_mask: mask,
        ..Default::default()
    }
}

fn solid_params() -> SolidParams {
    let mut p = SolidParams::paper(3);
    p.cell = 8;
    p.subpart = 16;
    p
}

fn brick() -> &'static Image {
    static B: OnceLock<Image> = OnceLock::new();
    B.get_or_init(|| load("brick.png"))
}

/// A small analysis for the field tests (marble, whose matching is not under test).
fn marble() -> &'static SolidAnalysis {
    static A: OnceLock<SolidAnalysis> = OnceLock::new();
    A.get_or_init(|| {
        let img = load("marble1.png");
        analyse([img.view(); 3], &params(None)).unwrap()
    })
}

/// The mean feature channel over the middle z section of a 40³ cube of brick.png (on all three
/// planes, trivial field), with or without the mask; and the exemplar's mean.
fn mortar_in_section(mask: Option<FeatureMaskParams>) -> (f32, f32) {
    let img = brick();
    let chan = feature_channel(img.view(), &FeatureMaskParams::default()).unwrap();
    let a = analyse([img.view(); 3], &params(mask)).unwrap();
    let vol = cube(40);
    let field = trivial_field(&vol);
    let s = SolidSynthesis::new(a.as_ref(), &field, vol, solid_params()).unwrap();
    let store = MemoryBrickStore::new();
    s.synthesize(&VoxelRequest::from_box([0, 0, 20], [40, 40, 21]), &store)
        .unwrap();
    let mut sum = 0.0;
    for y in 0..40 {
        for x in 0..40 {
            let t = s.triple_at(&store, 3, [x, y, 20]).unwrap();
            for p in 0..3 {
                sum += chan[t.c[p][1] as usize * img.width as usize + t.c[p][0] as usize];
            }
        }
    }
    let exemplar = chan.iter().sum::<f32>() / chan.len() as f32;
    (sum / (3.0 * 1600.0), exemplar)
}

/// Brick on all three planes cannot hold in one solid; matched on colour alone, synthesis
/// escapes into the brick faces and the mortar — the feature — thins out in the section
/// (measured: mean channel 0.143 against the exemplar's 0.288 here, 0.041 at 4 levels). With
/// the mask's channel in the appearance vectors the section's share of mortar comes at least
/// twice as close to the exemplar's (0.244 here).
#[test]
fn a_feature_mask_keeps_the_mortar_of_a_brick_exemplar() {
    let (without, exemplar) = mortar_in_section(None);
    let (with, _) = mortar_in_section(Some(FeatureMaskParams::default()));
    eprintln!("mean feature channel: without {without:.3}, with {with:.3}, exemplar {exemplar:.3}");
    assert!(
        (with - exemplar).abs() < 0.5 * (without - exemplar).abs(),
        "mean feature channel: without mask {without:.3}, with {with:.3}, exemplar {exemplar:.3}"
    );
}

/// Without a mask the analysis has no appearance array and matches on colour: the mask is
/// what changes the matched vectors, and only it.
#[test]
fn the_feature_mask_changes_matching_not_the_colours() {
    let img = brick();
    let off = analyse([img.view(); 3], &params(None)).unwrap();
    let on = analyse([img.view(); 3], &params(Some(FeatureMaskParams::default()))).unwrap();
    assert!(off.appearance.is_empty());
    assert_eq!(on.appearance.len(), off.stack.len());
    // Output colours come from the same stacks; the matched neighbourhoods differ.
    assert_eq!(on.stack, off.stack);
    assert_ne!(on.features, off.features);
    // Stored and read back in place, the appearance array comes with it.
    let arrays = on.arrays();
    let r = texsyn::stages::analyse_exemplar::candidate_triples::SolidAnalysisRef::from_arrays(
        on.meta.clone(),
        &arrays,
    )
    .unwrap();
    assert_eq!(r.appearance.len(), on.appearance.len());
}

/// A drawn mask of the very texels the detector finds is the detector's mask: the analysis
/// matches the same appearance vectors. A mask drawn elsewhere changes them.
#[test]
fn a_drawn_mask_takes_the_place_of_the_detected_curves() {
    let img = brick();
    let p = params(Some(FeatureMaskParams::default()));
    let detected = analyse([img.view(); 3], &p).unwrap();
    let chan = feature_channel(img.view(), &FeatureMaskParams::default()).unwrap();
    let drawn_at = |keep: &dyn Fn(u32, u32) -> bool| {
        Image::from_fn(img.width, img.height, |x, y| {
            let on = chan[(y * img.width + x) as usize] == 1.0 && keep(x, y);
            let v = if on { 1.0 } else { 0.0 };
            [v, v, v, 1.0]
        })
    };
    let same = drawn_at(&|_, _| true);
    let drawn = analyse_masked([img.view(); 3], [Some(same.view()); 3], &p).unwrap();
    assert!(drawn.features == detected.features, "features differ");
    assert!(
        drawn.appearance == detected.appearance,
        "appearance differs"
    );
    // Only the left half's curves drawn: other appearance, other matching.
    let half = drawn_at(&|x, _| x < img.width / 2);
    let other = analyse_masked([img.view(); 3], [Some(half.view()); 3], &p).unwrap();
    assert!(other.features != detected.features, "features alike");
    assert!(other.stack == detected.stack, "colour stacks differ");
    // A transposed plane reads its mask transposed too.
    let (tr, half_tr) = (transpose(img), transpose(&half));
    let turned = analyse_transposed([img.view(); 3], [Some(half.view()); 3], [true; 3], &p);
    let pre = analyse_masked([tr.view(); 3], [Some(half_tr.view()); 3], &p).unwrap();
    assert!(turned.unwrap().features == pre.features, "features differ");
    // A mask needs the channel's settings, and the exemplar's size.
    let e = analyse_masked(
        [img.view(); 3],
        [Some(same.view()), None, None],
        &params(None),
    );
    assert!(
        e.unwrap_err()
            .to_string()
            .contains("feature channel is off")
    );
    let small = Image::from_fn(8, 8, |_, _| [1.0; 4]);
    let e = analyse_masked([img.view(); 3], [None, Some(small.view()), None], &p).unwrap_err();
    assert!(
        e.to_string().contains("yz plane's drawn mask is 8×8"),
        "{e}"
    );
}

/// Mean angle (radians) between the frames the coarsest level reads at face-neighbouring
/// voxels.
fn coarse_roughness(s: &SolidSynthesis) -> f64 {
    let dims = s.pyramid().level_dims(1);
    let f = s.field_of(0);
    let q = |v: IVec3| f.rotation_at(s.pyramid().position(1, v));
    let (mut sum, mut n) = (0.0f64, 0);
    for z in 0..dims.z {
        for y in 0..dims.y {
            for x in 0..dims.x {
                let v = IVec3::new(x, y, z);
                for d in [IVec3::X, IVec3::Y, IVec3::Z] {
                    let w = v + d;
                    if w.cmplt(dims).all() {
                        sum += q(v).angle_between(q(w)) as f64;
                        n += 1;
                    }
                }
            }
        }
    }
    sum / n as f64
}

/// A jittered rings field jumps from node to node; the smoothed field of the coarse levels
/// turns less from voxel to voxel (its rings remain: the ring field's own turning is most of
/// what is left), the finest level still reads the field itself, and without the switch
/// nothing changes.
#[test]
fn coarse_field_smoothing_reduces_the_frame_jumps_between_coarse_voxels() {
    let vol = cube(64);
    let field = jittered(&rings_field(&vol, 16), 0.35, 7);
    let off = SolidSynthesis::new(marble().as_ref(), &field, vol, solid_params()).unwrap();
    let on_params = SolidParams {
        field_smoothing: 2.0,
        ..solid_params()
    };
    let on = SolidSynthesis::new(marble().as_ref(), &field, vol, on_params).unwrap();
    let (r_off, r_on) = (coarse_roughness(&off), coarse_roughness(&on));
    eprintln!("mean turn between coarsest voxels: {r_off:.4} → {r_on:.4} rad");
    assert!(r_on < 0.7 * r_off, "mean turn {r_off:.4} → {r_on:.4} rad");
    assert!(std::ptr::eq(on.field_of(2), &field));
    assert!(std::ptr::eq(off.field_of(0), &field));
    // Coarse levels are the coarser half: levels 1 and 2 of 3.
    assert!(on.field_of(1) != &field);
}

/// With both coarse-level switches on, the stencil still covers every read: the voxels of a
/// request are the same whatever else was requested before them, and the switches change the
/// result under a curved field (they are not inert) but not under a constant one (where the
/// field's lines are straight and smoothing has nothing to remove).
#[test]
fn coarse_level_switches_keep_bricks_independent_of_the_request() {
    let vol = cube(40);
    let both = SolidParams {
        field_smoothing: 2.0,
        field_integration: true,
        ..solid_params()
    };
    fn run<'a>(
        field: &'a RotationField,
        p: &SolidParams,
        reqs: &[&VoxelRequest],
    ) -> (SolidSynthesis<'a>, MemoryBrickStore) {
        let vol = cube(40);
        let s = SolidSynthesis::new(marble().as_ref(), field, vol, p.clone()).unwrap();
        let store = MemoryBrickStore::new();
        for r in reqs {
            s.synthesize(r, &store).unwrap();
        }
        (s, store)
    }
    let req_a = VoxelRequest::from_box([0, 0, 20], [40, 40, 21]);
    let req_b = VoxelRequest::from_box([8, 30, 0], [24, 34, 40]);
    let rings = rings_field(&vol, 10);
    let (s, only_a) = run(&rings, &both, &[&req_a]);
    let (_, b_then_a) = run(&rings, &both, &[&req_b, &req_a]);
    let (_, plain) = run(&rings, &solid_params(), &[&req_a]);
    let integrate_only = SolidParams {
        field_integration: true,
        ..solid_params()
    };
    let (_, integrated) = run(&rings, &integrate_only, &[&req_a]);
    let (mut changed, mut changed_by_integration) = (0, 0);
    for v in req_a.voxels() {
        let t = s.triple_at(&only_a, 3, v).unwrap();
        assert_eq!(Some(t), s.triple_at(&b_then_a, 3, v), "{v:?}");
        let p = s.triple_at(&plain, 3, v);
        changed += (Some(t) != p) as usize;
        changed_by_integration += (s.triple_at(&integrated, 3, v) != p) as usize;
    }
    assert!(changed > 400, "{changed} of 1600 voxels changed");
    assert!(
        changed_by_integration > 400,
        "{changed_by_integration} of 1600 voxels changed by integration alone"
    );
    for l in 1..=3 {
        for b in b_then_a.bricks(l) {
            if let Some(x) = only_a.get(l, b) {
                assert!(
                    *x == *b_then_a.get(l, b).unwrap(),
                    "brick {b:?} of level {l}"
                );
            }
        }
    }
    // A constant field: the same bricks with and without the switches.
    let tilted = rotated_field(&vol, Quat::from_rotation_z(0.4));
    let (s1, x) = run(&tilted, &both, &[&req_a]);
    let (_, y) = run(&tilted, &solid_params(), &[&req_a]);
    for v in req_a.voxels() {
        assert_eq!(s1.triple_at(&x, 3, v), s1.triple_at(&y, 3, v), "{v:?}");
    }
}

/// Bad switch values are refused naming the setting.
#[test]
fn bad_switch_values_are_errors_naming_the_setting() {
    let vol = cube(16);
    let field = trivial_field(&vol);
    let p = SolidParams {
        field_smoothing: -1.0,
        ..solid_params()
    };
    let e = SolidSynthesis::new(marble().as_ref(), &field, vol, p)
        .err()
        .unwrap();
    assert!(e.to_string().contains("synthesize.field_smoothing"), "{e}");
    let bad = CandidateParams {
        feature_mask: Some(FeatureMaskParams {
            radius: 0.0,
            ..Default::default()
        }),
        ..params(None)
    };
    let e = bad.validate().unwrap_err();
    assert!(e.to_string().contains("feature_mask.radius"), "{e}");
}

//! `texsyn score` and `[score]` as a user meets them: the numbers, where they appear, and the
//! errors. The measures themselves are tested on planted cases in
//! `core/src/image/patch_score.rs` (verbatim crop, shuffled pixels, blur, brute force).

use crate::common;
use common::cli::texsyn;
use common::repo;
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Output;
use texsyn_core::math::PureMath;

fn json(o: &Output) -> Value {
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    serde_json::from_slice(&o.stdout).expect("JSON on stdout")
}

/// A small synth2d config (64² from the 64×62 leopard) in `dir`, with `extra` appended.
fn synth2d_config(dir: &Path, extra: &str) -> PathBuf {
    let leopard = repo().join("configs/assets/leopard.png");
    let text = format!(
        "method = \"synth2d\"\n[inputs]\nexemplar = {:?}\n[synthesize]\nwidth = 64\nheight = 64\n{extra}",
        leopard.to_str().unwrap()
    );
    let path = dir.join("small.toml");
    std::fs::write(&path, text).unwrap();
    path
}

fn score_of(v: &Value) -> &Value {
    &v["items"][0]["score"]
}

#[test]
fn score_reports_the_measures_and_run_json_repeats_them_when_asked() {
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    synth2d_config(dir, "[score]\npatch = 5\nseed = 3\n");
    let scored = json(&texsyn(
        &["score", "small.toml", "--cache", "c", "--json"],
        dir,
    ));
    assert_eq!(scored["method"], "synth2d");
    assert_eq!(scored["patch"], 5);
    let s = score_of(&scored);
    let ratio = s["ratio"].as_f64().unwrap();
    // Jump-map synthesis copies runs of the exemplar: nearer than unseen parts of it, not 0.
    assert!(ratio > 0.0 && ratio < 1.5, "{s}");
    for key in ["coverage", "largest_offset"] {
        let x = s[key].as_f64().unwrap();
        assert!(x > 0.0 && x <= 1.0, "{key}: {s}");
    }
    // 60 × 60 positions of 5 × 5 patches in a 64² output: all scored.
    assert_eq!(s["queries"], 3600);
    assert_eq!(s["subsampled"], false);

    // The same numbers in `run --json`, because the config has `[score]`.
    let run = json(&texsyn(
        &["run", "small.toml", "--cache", "c", "--out", "o", "--json"],
        dir,
    ));
    assert_eq!(run["scores"]["items"], scored["items"]);

    // `--set` reaches `[score]`: another seed, other crops for the baseline.
    let other = json(&texsyn(
        &[
            "score",
            "small.toml",
            "--cache",
            "c",
            "--json",
            "--set",
            "score.seed=4",
        ],
        dir,
    ));
    assert_ne!(
        score_of(&other)["baseline_rms"],
        score_of(&scored)["baseline_rms"]
    );

    // `enabled = false`, or no `[score]`: `run` does not score (and `score` still does).
    for extra in ["[score]\nenabled = false\n", ""] {
        synth2d_config(dir, extra);
        let run = json(&texsyn(
            &["run", "small.toml", "--cache", "c", "--out", "o", "--json"],
            dir,
        ));
        assert!(run.get("scores").is_none(), "{extra:?}");
        let scored = json(&texsyn(
            &["score", "small.toml", "--cache", "c", "--json"],
            dir,
        ));
        assert_eq!(scored["patch"], 7);
    }

    // Several configs (or --markdown): one table.
    let o = texsyn(&["score", "small.toml", "small.toml", "--cache", "c"], dir);
    let table = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success());
    assert!(table.starts_with("| config | output | ratio"), "{table}");
    assert_eq!(table.matches("| small.toml | synthesized.png |").count(), 2);
}

#[test]
fn bad_score_sections_and_missing_inputs_are_named() {
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    let cases = [
        ("[score]\npach = 5\n", vec!["small.toml", "score", "pach"]),
        (
            "[score]\npatch = 0\n",
            vec!["small.toml", "score.patch", "0"],
        ),
        (
            "[score]\nmax_queries = 0\n",
            vec!["small.toml", "score.max_queries"],
        ),
        ("score = 3\n", vec!["small.toml", "score"]),
    ];
    for (extra, words) in cases {
        // `score = 3` must come before any table.
        let path = synth2d_config(dir, "");
        if extra.starts_with('[') {
            synth2d_config(dir, extra);
        } else {
            let text = std::fs::read_to_string(&path).unwrap();
            std::fs::write(&path, format!("{extra}{text}")).unwrap();
        }
        for args in [
            &["score", "small.toml", "--cache", "c"][..],
            &["run", "small.toml", "--cache", "c", "--out", "o"][..],
        ] {
            let o = texsyn(args, dir);
            assert!(!o.status.success(), "{args:?} {extra:?}");
            let e = String::from_utf8_lossy(&o.stderr);
            for w in &words {
                assert!(e.contains(w), "{args:?} {extra:?}: {e}");
            }
            assert!(!e.contains("panicked"), "{e}");
        }
    }
    // An exemplar that is not there: the error names it (nothing to score against).
    let text = "method = \"synth2d\"\n[inputs]\nexemplar = \"gone.png\"\n[score]\n";
    std::fs::write(dir.join("gone.toml"), text).unwrap();
    let o = texsyn(&["score", "gone.toml", "--cache", "c"], dir);
    assert!(!o.status.success());
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(
        e.contains("gone.png") && e.contains("inputs.exemplar"),
        "{e}"
    );
    // A config that is not there.
    let o = texsyn(&["score", "nope.toml", "--cache", "c"], dir);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("nope.toml"));
}

/// The demo (jump maps), made small: the blended surface is scored on unfolded discs, and the
/// OBJ's coordinate seams against randomly placed ones.
#[test]
fn jump_maps_score_their_surface_and_seams() {
    let d = tempfile::tempdir().unwrap();
    let o = texsyn(
        &[
            "score",
            repo().join("configs/demo.toml").to_str().unwrap(),
            "--cache",
            "c",
            "--json",
            "--set",
            "reconstruct.atlas_size=1024",
            "--set",
            "reconstruct.preview_size=32",
        ],
        d.path(),
    );
    let v = json(&o);
    let item = &v["items"][0];
    let s = &item["score"];
    let ratio = s["ratio"].as_f64().unwrap();
    assert!(ratio > 0.0 && ratio < 2.0, "{item}");
    // The §4.4 blend averages three lookups: blurrier than the exemplar.
    assert!(s["gradient_ratio"].as_f64().unwrap() < 1.0, "{item}");
    let seams = &item["extra"]["seams"];
    let (n, total) = (
        seams["seam_edges"].as_u64().unwrap(),
        seams["interior_edges"].as_u64().unwrap(),
    );
    assert!(n > 0 && n <= total, "{seams}");
    // The walk continues coordinates where it can: its seams are less visible than random
    // placements.
    let r = seams["ratio"].as_f64().unwrap();
    assert!(r > 0.0 && r < 1.0, "{seams}");
}

/// The demo at a texture scale large against the cow (60 texels per unit: an edge spans about
/// 1.5 exemplar texels), with brick: blending over 3 texels (`reconstruct.blend_radius`) makes
/// the walk's jumps less visible on the blended surface than §4.4's one-triangle ramp, while
/// the discs keep most of their detail; the OBJ's coordinate seams are the same; a radius out
/// of range is refused naming the key.
#[test]
fn a_wider_blend_hides_the_jumps_at_a_large_texture_scale() {
    let d = tempfile::tempdir().unwrap();
    let score = |radius: &str| {
        let o = texsyn(
            &[
                "score",
                repo().join("configs/demo.toml").to_str().unwrap(),
                "--cache",
                "c",
                "--json",
                "--set",
                "inputs.exemplar=\"assets/brick.png\"",
                "--set",
                "parameterize.scale=60",
                "--set",
                "parameterize.rotation=0",
                "--set",
                "reconstruct.atlas_size=256",
                "--set",
                "reconstruct.preview_size=32",
                "--set",
                &format!("reconstruct.blend_radius={radius}"),
            ],
            d.path(),
        );
        json(&o)["items"][0].clone()
    };
    let (narrow, wide) = (score("0"), score("3"));
    let seam = |v: &Value| v["extra"]["blended_seams"]["ratio"].as_f64().unwrap();
    // Under the one-triangle ramp a jump edge's ends differ more than the texture does over
    // the same offset; the wide blend brings that below it.
    assert!(seam(&narrow) > 1.2, "{narrow}");
    assert!(seam(&wide) < 0.6 * seam(&narrow), "{wide} vs {narrow}");
    let grad = |v: &Value| v["score"]["gradient_ratio"].as_f64().unwrap();
    assert!(grad(&wide) > 0.6 * grad(&narrow), "{wide} vs {narrow}");
    assert_eq!(narrow["extra"]["seams"], wide["extra"]["seams"]);
    let o = texsyn(
        &[
            "run",
            repo().join("configs/demo.toml").to_str().unwrap(),
            "--cache",
            "c",
            "--set",
            "reconstruct.blend_radius=100",
        ],
        d.path(),
    );
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && e.contains("reconstruct.blend_radius"),
        "{e}"
    );
}

/// A small geometry-image run: the relief scored at density offset 0, and the mesh checks.
#[test]
fn geometry_images_score_the_relief_and_check_the_mesh() {
    let d = tempfile::tempdir().unwrap();
    let mut args = vec![
        "score".to_string(),
        repo().join("configs/relief_cow.toml").display().to_string(),
        "--cache".into(),
        "c".into(),
        "--json".into(),
    ];
    for s in [
        "parameterize.size=65",
        "analyse_exemplar.orientations=4",
        "analyse_exemplar.scales=3",
        "field.density_offset=0.0",
        "reconstruct.preview_size=32",
    ] {
        args.push("--set".into());
        args.push(s.into());
    }
    let args: Vec<&str> = args.iter().map(|s| s.as_str()).collect();
    let v = json(&texsyn(&args, d.path()));
    let item = &v["items"][0];
    assert!(item["score"]["ratio"].as_f64().unwrap() > 0.0, "{item}");
    assert_eq!(item["extra"]["density_offset"], 0.0);
    assert!(item.get("notes").is_none(), "{item}");
    let mesh = &item["extra"]["mesh"];
    let triangles = mesh["triangles"].as_u64().unwrap();
    assert!(triangles > 2 * 60 * 60, "{mesh}");
    // The cow is closed, and so must its relief be.
    for k in [
        "boundary_edges",
        "non_manifold_edges",
        "unreferenced_vertices",
    ] {
        assert_eq!(mesh[k].as_u64(), Some(0), "{k}: {mesh}");
    }
    assert!(
        mesh["flipped_faces"].as_u64().unwrap() < triangles,
        "{mesh}"
    );
    // The second row reads the relief along the surface, in the sample's frame, against the
    // sample at the synthesis's median scale (3 scales at offset 0: the middle one, 1).
    let frame = &v["items"][1];
    assert!(
        frame["output"]
            .as_str()
            .unwrap()
            .contains("along the surface"),
        "{frame}"
    );
    let s = &frame["score"];
    assert!(s["ratio"].as_f64().unwrap() > 0.0, "{frame}");
    assert!(s["queries"].as_u64().unwrap() > 100, "{frame}");
    assert_eq!(frame["extra"]["reference_scale"], 1, "{frame}");
    let skipped = frame["extra"]["skipped_patches"].as_f64().unwrap();
    assert!(skipped > 0.0 && skipped < 0.5, "{frame}");
    assert_eq!(v["items"].as_array().unwrap().len(), 2);
}

/// A solid surface request has no planar image: `score` synthesizes a section of the same
/// solid for scoring (and says so); a section request is scored as it is.
#[test]
fn solid_surface_requests_are_scored_on_a_section_made_for_it() {
    let d = tempfile::tempdir().unwrap();
    let small = [
        "parameterize.resolution=40",
        "analyse_exemplar.levels=3",
        "analyse_exemplar.neighbourhood_coarsest=5",
        "analyse_exemplar.neighbourhood=5",
        "synthesize.levels=[{ passes = 2, scheme = \"plain\" }, { passes = 2 }, { passes = 2 }]",
        "reconstruct.preview_size=32",
        "reconstruct.atlas_size=1024",
        "score.patch=3",
    ];
    let config = repo().join("configs/solid_trivial.toml");
    let mut args = vec!["score", config.to_str().unwrap(), "--cache", "c", "--json"];
    for s in &small {
        args.push("--set");
        args.push(s);
    }
    let v = json(&texsyn(&args, d.path()));
    let item = &v["items"][0];
    assert_eq!(
        item["output"], "section.png (a section made for scoring)",
        "{v}"
    );
    assert_eq!(item["exemplar"], "inputs.xy", "{v}");
    assert!(item["score"]["ratio"].as_f64().unwrap() > 0.0, "{item}");
    let notes = item["notes"].to_string();
    assert!(notes.contains("section synthesized for scoring"), "{notes}");

    // `run` with `[score]` does not synthesize more than asked: not scored, with the reason.
    args[0] = "run";
    args.extend(["--out", "o", "--set", "score.enabled=true"]);
    let v = json(&texsyn(&args, d.path()));
    let reason = v["scores"]["not_scored"][0].as_str().unwrap();
    assert!(reason.contains("surface request"), "{reason}");
}

/// A feature-aligned config in `dir`: `mesh` (OBJ text) with one straight curve from `from`
/// to `to`, wood2's stripes, small.
fn feature_aligned_config(dir: &Path, name: &str, mesh: &str, from: [f32; 3], to: [f32; 3]) {
    std::fs::write(dir.join(format!("{name}.obj")), mesh).unwrap();
    let wood = repo().join("tests/data/exemplars/wood2.png");
    let config = format!(
        "method = \"feature_aligned\"\n[inputs]\nmesh = \"{name}.obj\"\nexemplar = {:?}\n\
         [extract]\nfeatures = \"curves\"\ncurves = [ {{ points = [{from:?}, {to:?}] }} ]\n\
         [parameterize]\nscale = 120.0\n[synthesize]\niterations = 5\n\
         [reconstruct]\npreview_size = 48\natlas_size = 256\n",
        wood.to_str().unwrap()
    );
    std::fs::write(dir.join(format!("{name}.toml")), config).unwrap();
}

/// OBJ text of a grid of `cols` × `rows + 1` vertices at `at(i, j)`, closed around when
/// `wrap` (column `cols` is column 0).
fn grid_obj(cols: usize, rows: usize, wrap: bool, at: impl Fn(usize, usize) -> [f32; 3]) -> String {
    let mut obj = String::new();
    for j in 0..=rows {
        for i in 0..cols {
            let [x, y, z] = at(i, j);
            obj += &format!("v {x} {y} {z}\n");
        }
    }
    let cells = if wrap { cols } else { cols - 1 };
    for j in 0..rows {
        for i in 0..cells {
            let v = |i: usize, j: usize| j * cols + i % cols + 1;
            let (a, b, c, e) = (v(i, j), v(i + 1, j), v(i + 1, j + 1), v(i, j + 1));
            obj += &format!("f {a} {b} {c}\nf {a} {c} {e}\n");
        }
    }
    obj
}

/// What `score --json` says of a feature-aligned result.
#[derive(Debug)]
struct AlignedScores {
    alignment_deg: f64,
    gradient_ratio: f64,
    /// The exemplar's own alignment.
    exemplar_alignment_deg: f64,
    /// The floor: the exemplar laid out verbatim in the same discs, read as the atlas reads.
    floor_ratio: f64,
    floor_gradient_ratio: f64,
}

/// `score --json` of `name`.toml in `dir` with `sets`, for the aligned result.
fn aligned_scores(dir: &Path, name: &str, sets: &[&str]) -> AlignedScores {
    let config = format!("{name}.toml");
    let mut args = vec!["score", &config, "--cache", "c", "--json", "-q"];
    for s in sets {
        args.extend(["--set", s]);
    }
    let v = json(&texsyn(&args, dir));
    let item = &v["items"][0];
    assert!(
        item["output"].as_str().unwrap().starts_with("the aligned"),
        "{item}"
    );
    let number = |x: &Value| x.as_f64().unwrap_or_else(|| panic!("no number: {item}"));
    AlignedScores {
        alignment_deg: number(&item["extra"]["alignment_deg"]),
        gradient_ratio: number(&item["score"]["gradient_ratio"]),
        exemplar_alignment_deg: number(&item["extra"]["exemplar_alignment_deg"]),
        floor_ratio: number(&item["extra"]["floor"]["ratio"]),
        floor_gradient_ratio: number(&item["extra"]["floor"]["gradient_ratio"]),
    }
}

/// Feature-aligned texturing with one straight curve, wood2's stripes laid along the field:
/// on a flat sheet the atlas's nearest reads keep the stripes' detail (gradient ratio ≥ 0.7),
/// the default bicubic reads between texels lose some and bilinear reads more, and the lines
/// follow the field (≤ 15°); the score's `floor` (wood2 laid out verbatim in the same discs,
/// read the same way) is exact for nearest reads and blurred in the same order for the
/// others, and the default keeps at least 0.8 of its floor's gradient energy;
/// on a cylinder, where the tangent planes turn, they follow it too. `alignment_deg` is
/// measured where the texture lies; the exemplar's own (a few degrees: straight stripes) is
/// its baseline.
#[test]
fn feature_aligned_stripes_follow_the_field_on_a_sheet_and_a_cylinder() {
    let d = tempfile::tempdir().unwrap();
    let sheet = grid_obj(31, 30, false, |i, j| {
        [i as f32 / 30.0, j as f32 / 30.0, 0.0]
    });
    feature_aligned_config(
        d.path(),
        "sheet",
        &sheet,
        [0.05, 0.5, 0.0],
        [0.95, 0.5, 0.0],
    );
    let shipped = aligned_scores(d.path(), "sheet", &["compare=false"]);
    assert!(shipped.alignment_deg <= 15.0, "sheet: {shipped:?}");
    assert!(
        shipped.exemplar_alignment_deg < 5.0,
        "wood2's own alignment: {shipped:?}"
    );
    let nearest = aligned_scores(
        d.path(),
        "sheet",
        &["reconstruct.lookup=\"nearest\"", "compare=false"],
    );
    let bilinear = aligned_scores(
        d.path(),
        "sheet",
        &["reconstruct.lookup=\"bilinear\"", "compare=false"],
    );
    assert!(nearest.gradient_ratio >= 0.7, "sheet, nearest: {nearest:?}");
    assert!(
        bilinear.gradient_ratio < shipped.gradient_ratio
            && shipped.gradient_ratio < nearest.gradient_ratio,
        "bilinear {bilinear:?}, bicubic {shipped:?}, nearest {nearest:?}"
    );
    // The floor: nearest reads of a verbatim layout are exact crops of the exemplar; reads
    // between texels blur it, bilinear more than bicubic. The default's texture keeps most
    // of what its own read leaves a flawless layout.
    assert_eq!(nearest.floor_ratio, 0.0, "{nearest:?}");
    assert!(
        shipped.floor_ratio > 0.0
            && bilinear.floor_gradient_ratio < shipped.floor_gradient_ratio
            && shipped.floor_gradient_ratio < nearest.floor_gradient_ratio,
        "floors: bilinear {bilinear:?}, bicubic {shipped:?}, nearest {nearest:?}"
    );
    assert!(
        shipped.gradient_ratio >= 0.8 * shipped.floor_gradient_ratio,
        "{shipped:?}"
    );
    // Without an atlas the run writes vertex colours, and those are scored: smoother than
    // the nearest reads between vertices, with the reason named.
    let v = json(&texsyn(
        &[
            "score",
            "sheet.toml",
            "--cache",
            "c",
            "--json",
            "-q",
            "--set",
            "reconstruct.lookup=\"nearest\"",
            "--set",
            "compare=false",
            "--set",
            "reconstruct.atlas_size=0",
        ],
        d.path(),
    ));
    let item = &v["items"][0];
    assert!(
        item["output"].as_str().unwrap().contains("vertex colours"),
        "{item}"
    );
    let plain = item["score"]["gradient_ratio"].as_f64().unwrap();
    assert!(
        plain < nearest.gradient_ratio,
        "vertex colours {plain}, nearest {nearest:?}"
    );
    let reason = v["not_scored"].to_string();
    assert!(reason.contains("reconstruct.atlas_size"), "{reason}");

    let cylinder = grid_obj(40, 24, true, |i, j| {
        let a = i as f32 / 40.0 * std::f32::consts::TAU;
        [0.3 * a.cos_pure(), 0.3 * a.sin_pure(), j as f32 / 24.0]
    });
    feature_aligned_config(
        d.path(),
        "cylinder",
        &cylinder,
        [0.3, 0.0, 0.05],
        [0.3, 0.0, 0.95],
    );
    let bent = aligned_scores(d.path(), "cylinder", &["compare=false"]);
    assert!(bent.alignment_deg <= 15.0, "cylinder: {bent:?}");
}

/// Graph matching's score reports the face areas' spread as read and after adaptive
/// pre-subdivision (§3.2.2, Fig. 6), so a sweep over `area_factor` tabulates it: without
/// pre-subdivision the two agree; with it the cow's spread falls and its coarsest level grows.
#[test]
fn graph_matching_s_score_reports_the_area_spread_before_and_after_pre_subdivision() {
    let d = tempfile::tempdir().unwrap();
    let score = |factor: &str| {
        let o = texsyn(
            &[
                "score",
                repo().join("configs/graph_matching.toml").to_str().unwrap(),
                "--cache",
                "c",
                "--json",
                "--set",
                "parameterize.scale=30",
                "--set",
                &format!("parameterize.area_factor={factor}"),
                // The paper's fixed rounds: the default early stop also stops where edges
                // span a texel, which the cow's do at this scale.
                "--set",
                "parameterize.adaptive_min_gain=0",
                "--set",
                "parameterize.adaptive_rounds=3",
                "--set",
                "reconstruct.preview_size=32",
            ],
            d.path(),
        );
        json(&o)["items"][0]["extra"].clone()
    };
    let (none, some) = (score("0"), score("1.5"));
    let f = |v: &Value, k: &str| v[k].as_f64().unwrap();
    assert_eq!(
        f(&none, "area_spread"),
        f(&none, "area_spread_input"),
        "{none}"
    );
    assert_eq!(f(&none, "area_spread_input"), f(&some, "area_spread_input"));
    // The cow as read: 113 % (BENCHMARKS, Fig. 6); a pre-subdivided cow is well below it.
    assert!(f(&none, "area_spread_input") > 1.0, "{none}");
    assert!(
        f(&some, "area_spread") < 0.8 * f(&some, "area_spread_input"),
        "{some}"
    );
    assert!(
        f(&some, "coarse_faces") > f(&none, "coarse_faces"),
        "{some} {none}"
    );
}

/// Graph matching's baked atlas holds the exemplar's own detail: inside each copied patch it
/// reads the exemplar at the interpolated address, not the finest level's vertex colours, so
/// scored through the same discs with nearest reads it keeps far more of the exemplar's
/// gradient energy than the vertex colours do (0.77 against 0.43 on the cow at scale 30; the
/// default bicubic reads 0.53).
/// Without an atlas, or with one too small for the cow's triangles (which the export replaces
/// with vertex colours), only the vertex colours are scored.
#[test]
fn graph_matching_s_baked_atlas_reads_the_exemplar_inside_copied_patches() {
    let d = tempfile::tempdir().unwrap();
    let score = |sets: &[&str]| {
        let config = repo().join("configs/graph_matching.toml");
        let mut args = vec!["score", config.to_str().unwrap(), "--cache", "c", "--json"];
        for s in ["parameterize.scale=30", "reconstruct.preview_size=32"]
            .iter()
            .chain(sets)
        {
            args.extend(["--set", s]);
        }
        json(&texsyn(&args, d.path()))
    };
    let report = score(&[
        "reconstruct.atlas_size=1024",
        "reconstruct.lookup=\"nearest\"",
    ]);
    let items = report["items"].as_array().unwrap();
    assert_eq!(items.len(), 2, "{items:?}");
    let gradient = |i: &Value| i["score"]["gradient_ratio"].as_f64().unwrap();
    let (vertex, baked) = (&items[0], &items[1]);
    assert!(
        baked["output"].as_str().unwrap().contains("baked atlas"),
        "{baked}"
    );
    let share = baked["extra"]["looked_up_share"].as_f64().unwrap();
    assert!((0.3..1.0).contains(&share), "{share}");
    assert!(
        gradient(baked) >= gradient(vertex) + 0.2,
        "baked {} against vertex colours {}",
        gradient(baked),
        gradient(vertex)
    );
    // The default bicubic reads keep less than nearest's but still more than the vertex
    // colours (bilinear reads between texels fall below them: 0.40 against 0.43).
    let shipped = score(&["reconstruct.atlas_size=1024"]);
    let shipped = &shipped["items"].as_array().unwrap()[1];
    assert!(
        gradient(shipped) > gradient(vertex) && gradient(shipped) < gradient(baked),
        "bicubic {} against vertex colours {} and nearest {}",
        gradient(shipped),
        gradient(vertex),
        gradient(baked)
    );
    let without = score(&["reconstruct.atlas_size=0"])["items"].clone();
    assert_eq!(without.as_array().unwrap().len(), 1, "{without}");
    // An atlas too small for the cow's triangles: the export writes vertex colours, so there
    // is no baked texture to score, and the report says why.
    let small = score(&["reconstruct.atlas_size=256"]);
    assert_eq!(small["items"].as_array().unwrap().len(), 1, "{small}");
    let reason = small["not_scored"].to_string();
    assert!(reason.contains("reconstruct.atlas_size"), "{reason}");
}

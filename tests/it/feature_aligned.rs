//! The feature-aligned method end to end: its outputs, determinism, what a rerun recomputes,
//! that the feature constraint puts the texture's lines on the shape's lines, and the errors a
//! user meets.

use crate::common;
use common::{
    artifact, assert_runs_fail_naming, assert_same_hashes_on_any_thread_count, materialized, ran,
    repo, run_config,
};
use texsyn::artifact::Format;
use texsyn::artifact::feature_aligned::OrientedField;
use texsyn::geom::edge_refine::Refined;
use texsyn::pipeline::RunResult;
use texsyn::stages::analyse_exemplar::texture_feature_lines::TextureFeatures;
use texsyn::stages::synthesize::texture_optimization::{SurfaceSynthesis, curve_distance};

/// Small: a coarse scale (fandisk refined to about 20,000 vertices), few iterations and tiny
/// previews and atlas.
const SMALL: &[&str] = &[
    "parameterize.scale=60",
    "synthesize.iterations=3",
    "reconstruct.preview_size=48",
    "reconstruct.atlas_size=256",
];

fn run(config: &str, sets: &[&str], cache: &std::path::Path) -> Result<RunResult, String> {
    run_config(&repo().join("configs").join(config), SMALL, sets, cache)
}

#[test]
fn outputs_are_written_and_the_same_for_any_thread_count() {
    assert_same_hashes_on_any_thread_count(|cache| {
        run("feature_aligned.toml", &[], cache).unwrap()
    });
    let cache = tempfile::tempdir().unwrap();
    let r = run("feature_aligned.toml", &[], cache.path()).unwrap();
    let out = materialized(&r, "reconstruct");
    for f in [
        "textured.ply",
        "textured.glb",
        "preview.png",
        "unaligned_preview.png",
        "comparison.png",
        "lines.obj",
        "lines_preview.png",
        "field.png",
        "texture_features.png",
        "report.json",
    ] {
        assert!(out.path().join(f).is_file(), "{f} missing");
    }
    let refined = Refined::view(artifact(&r, "parameterize")).unwrap();
    let ply = std::fs::read(out.path().join("textured.ply")).unwrap();
    let header = String::from_utf8_lossy(&ply[..200]).to_string();
    assert!(
        header.contains(&format!("element vertex {}\n", refined.mesh.vertex_count())),
        "{header}"
    );
    // The refined mesh's edges are at most one texel (1/60 object units) long.
    let longest =
        texsyn::geom::edge_refine::longest_edge(&refined.mesh.positions, &refined.mesh.triangles);
    assert!(longest <= 1.0 / 60.0 + 1e-6, "{longest}");
    // The report carries the field's singularities with both orientations.
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.path().join("report.json")).unwrap()).unwrap();
    assert_eq!(report["shape_features"]["source"], "crease");
    // Fig. 3 / Fig. 6: the greedy orientation leaves fewer singularities than an arbitrary one
    // (fandisk: 0 against 45 at the shipped scale).
    let greedy = report["field"]["singular_triangles"].as_u64().unwrap();
    let arbitrary = report["field"]["singular_triangles_arbitrary_orientation"]
        .as_u64()
        .unwrap();
    assert!(greedy < arbitrary, "greedy {greedy}, arbitrary {arbitrary}");
    // lines.obj reads back as curves (the round trip users rely on to edit them).
    let obj = std::fs::read(out.path().join("lines.obj")).unwrap();
    let curves =
        texsyn::stages::extract::shape_features::read_curves_file("lines.obj", &obj).unwrap();
    let field = OrientedField::view(artifact(&r, "field")).unwrap();
    assert_eq!(curves.len(), field.field.curves.len());
}

#[test]
fn the_feature_constraint_puts_texture_lines_on_shape_lines() {
    // Near the shape's curves (within half a patch), each vertex's source texel should be as far
    // from the exemplar's lines as the vertex is from the shape's lines (§5.2). The mean
    // mismatch with the constraint must be at most half of that without it.
    let cache = tempfile::tempdir().unwrap();
    let r = run("feature_aligned.toml", &[], cache.path()).unwrap();
    let refined = Refined::view(artifact(&r, "parameterize")).unwrap();
    let field = OrientedField::view(artifact(&r, "field")).unwrap();
    let tf = TextureFeatures::view(artifact(&r, "analyse_exemplar")).unwrap();
    let sources: Vec<u32> = field
        .field
        .curves
        .iter()
        .flat_map(|(c, _)| refined.refine_path(&c.vertices, c.closed))
        .collect();
    let texel = 1.0 / 60.0;
    let d = curve_distance(&refined.mesh, &sources);
    let patch =
        texsyn::stages::synthesize::texture_optimization::TextureOptimizationParams::default()
            .patch;
    let mismatch = |node: &str| {
        let s = SurfaceSynthesis::view(artifact(&r, node)).unwrap();
        let (mut sum, mut n) = (0.0f64, 0usize);
        for (v, src) in s.source.iter().enumerate() {
            let dv = d[v] / texel;
            if dv < patch as f32 / 2.0 {
                let x = (src[0].round() as i64).clamp(0, tf.width as i64 - 1) as usize;
                let y = (src[1].round() as i64).clamp(0, tf.height as i64 - 1) as usize;
                sum += (tf.distance[y * tf.width as usize + x] - dv).abs() as f64;
                n += 1;
            }
        }
        assert!(n > 100, "{node}: only {n} vertices near the curves");
        sum / n as f64
    };
    let (with, without) = (mismatch("synthesize"), mismatch("synthesize.unaligned"));
    assert!(
        with <= 0.5 * without,
        "mean |D(source) − d(vertex)|: {with:.2} texels with the constraint, {without:.2} without"
    );
}

#[test]
fn a_rerun_recomputes_only_what_changed() {
    let cache = tempfile::tempdir().unwrap();
    run("feature_aligned.toml", &[], cache.path()).unwrap();
    let r = run("feature_aligned.toml", &["synthesize.seed=7"], cache.path()).unwrap();
    assert_eq!(
        ran(&r),
        ["synthesize", "synthesize.unaligned", "reconstruct"],
        "a new seed reruns synthesis and export only"
    );
    let r = run(
        "feature_aligned.toml",
        &["reconstruct.streak_length=5"],
        cache.path(),
    )
    .unwrap();
    assert_eq!(ran(&r), ["reconstruct"]);
    let r = run("feature_aligned.toml", &["compare=false"], cache.path()).unwrap();
    assert_eq!(ran(&r), ["reconstruct"], "the aligned synthesis is reused");
}

#[test]
fn user_curves_and_crest_lines_configs_run() {
    let cache = tempfile::tempdir().unwrap();
    let r = run(
        "feature_aligned_curves.toml",
        &["parameterize.scale=40", "compare=false"],
        cache.path(),
    )
    .unwrap();
    let field = OrientedField::view(artifact(&r, "field")).unwrap();
    assert!(!field.field.curves.is_empty());
    let r = run(
        "feature_aligned_crest.toml",
        &["parameterize.scale=40", "compare=false"],
        cache.path(),
    )
    .unwrap();
    let out = materialized(&r, "reconstruct");
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.path().join("report.json")).unwrap()).unwrap();
    assert_eq!(report["shape_features"]["source"], "crest");
}

/// A file in a temporary directory, for inputs no shipped config has.
fn write(dir: &std::path::Path, name: &str, bytes: &[u8]) -> String {
    let p = dir.join(name);
    std::fs::write(&p, bytes).unwrap();
    p.display().to_string()
}

fn png(w: u32, h: u32, f: impl Fn(u32, u32) -> u8) -> Vec<u8> {
    let img = image::GrayImage::from_fn(w, h, |x, y| image::Luma([f(x, y)]));
    let mut out = Vec::new();
    img.write_to(&mut std::io::Cursor::new(&mut out), image::ImageFormat::Png)
        .unwrap();
    out
}

#[test]
fn bad_inputs_are_clear_errors_naming_the_key() {
    let dir = tempfile::tempdir().unwrap();
    let flat = write(
        dir.path(),
        "flat.obj",
        b"v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3\nf 1 3 4\n",
    );
    let grey = write(dir.path(), "grey.png", &png(64, 64, |_, _| 128));
    let small_mask = write(
        dir.path(),
        "mask.png",
        &png(10, 10, |x, _| (x == 5) as u8 * 255),
    );
    let mesh = format!("inputs.mesh=\"{flat}\"");
    let exemplar = format!("inputs.exemplar=\"{grey}\"");
    let mask = format!("inputs.feature_mask=\"{small_mask}\"");
    assert_runs_fail_naming(
        run,
        &[
            (
                "feature_aligned.toml",
                &[&mesh, "extract.features=\"crease\""],
                &["extract.crease.angle", "extract.curves"],
            ),
            (
                "feature_aligned.toml",
                &[&exemplar],
                &["analyse_exemplar.threshold", "inputs.feature_mask"],
            ),
            (
                "feature_aligned.toml",
                &[&mask],
                &["inputs.feature_mask", "10×10", "96×96"],
            ),
            (
                "feature_aligned.toml",
                &[
                    "extract.features=\"curves\"",
                    "extract.curves=[{points=[[0.0,0.0,0.0],[5.0,5.0,5.0]]}]",
                ],
                &["extract.curves[0]"],
            ),
            (
                "feature_aligned_curves.toml",
                &["synthesize.patch=48"],
                &["synthesize.patch", "64×64", "every rotation"],
            ),
            (
                "feature_aligned.toml",
                &["parameterize.scale=100000"],
                &["parameterize.scale", "parameterize.max_vertices"],
            ),
        ],
    );
}

/// The curves of lines.obj as position sequences, in file order.
fn obj_lines(text: &str) -> Vec<Vec<[String; 3]>> {
    let vs: Vec<[String; 3]> = text
        .lines()
        .filter_map(|l| l.strip_prefix("v "))
        .map(|l| {
            let p: Vec<&str> = l.split_whitespace().collect();
            [p[0].to_owned(), p[1].to_owned(), p[2].to_owned()]
        })
        .collect();
    text.lines()
        .filter_map(|l| l.strip_prefix("l "))
        .map(|l| {
            l.split_whitespace()
                .map(|i| vs[i.parse::<usize>().unwrap() - 1].clone())
                .collect()
        })
        .collect()
}

/// Runs feature_aligned.toml, turns the second longest line of its lines.obj round (greedy
/// orientation starts from the longest, §4.1, and would keep that one's direction whatever
/// it is), in place or moved into a `g user fixed` group at the end, and gives the file back
/// with `extra` settings. Returns the line as first written and the second run's lines.obj.
fn edit_and_give_back(into_fixed_group: bool, extra: &[&str]) -> (Vec<[String; 3]>, String) {
    let cache = tempfile::tempdir().unwrap();
    let first = run("feature_aligned.toml", &["compare=false"], cache.path()).unwrap();
    let out = materialized(&first, "reconstruct");
    let text = std::fs::read_to_string(out.path().join("lines.obj")).unwrap();
    let lines = obj_lines(&text);
    assert!(lines.len() >= 2, "{} lines", lines.len());
    let mut by_length: Vec<usize> = (0..lines.len()).collect();
    by_length.sort_by_key(|&i| std::cmp::Reverse(lines[i].len()));
    let chosen = by_length[1];
    let (mut edited, mut moved, mut k) = (String::new(), String::new(), 0);
    for l in text.lines() {
        match l.strip_prefix("l ") {
            Some(ids) => {
                if k == chosen {
                    let mut ids: Vec<&str> = ids.split_whitespace().collect();
                    ids.reverse();
                    let turned = format!("l {}\n", ids.join(" "));
                    if into_fixed_group {
                        moved = format!("g user fixed\n{turned}");
                    } else {
                        edited += &turned;
                    }
                } else {
                    edited += &format!("{l}\n");
                }
                k += 1;
            }
            None => edited += &format!("{l}\n"),
        }
    }
    edited += &moved;
    let dir = tempfile::tempdir().unwrap();
    let path = write(dir.path(), "lines.obj", edited.as_bytes());
    let file = format!("extract.curves_file={path:?}");
    let mut sets = vec!["compare=false", "extract.features=\"curves\"", &file];
    sets.extend(extra);
    let again = run("feature_aligned.toml", &sets, cache.path()).unwrap();
    let out = materialized(&again, "reconstruct");
    let back = std::fs::read_to_string(out.path().join("lines.obj")).unwrap();
    (lines[chosen].clone(), back)
}

/// An edited lines.obj given back with `field.orientation = "given"` keeps the edit: a line
/// the user turned round comes back turned round (the greedy step would re-orient it).
#[test]
fn an_edited_lines_obj_given_back_keeps_its_directions() {
    let (line, back) = edit_and_give_back(false, &["field.orientation=\"given\""]);
    let back = obj_lines(&back);
    let mut turned = line.clone();
    turned.reverse();
    assert!(
        back.contains(&turned),
        "the edited line is not back as edited"
    );
    assert!(!back.contains(&line), "the edited line came back as before");
}

/// An edited lines.obj given back with the edited line in a `fixed` group keeps that line's
/// direction under the default greedy orientation (which orients the other lines around it),
/// and writes it in a `fixed` group again, so the next round trip keeps it too.
#[test]
fn a_line_moved_into_a_fixed_group_keeps_its_direction_under_greedy_orientation() {
    let (line, back_text) = edit_and_give_back(true, &[]);
    let back = obj_lines(&back_text);
    let mut turned = line;
    turned.reverse();
    let at = back.iter().position(|l| *l == turned);
    assert!(at.is_some(), "the fixed line is not back as edited");
    // It is written under a group naming `fixed`, and it is the only such line.
    let mut group_fixed = Vec::new();
    let mut in_fixed = false;
    for l in back_text.lines() {
        if let Some(g) = l.strip_prefix("g ") {
            in_fixed = g.split_whitespace().any(|n| n == "fixed");
        } else if l.starts_with("l ") {
            group_fixed.push(in_fixed);
        }
    }
    let fixed_lines: Vec<usize> = (0..group_fixed.len()).filter(|&i| group_fixed[i]).collect();
    assert_eq!(fixed_lines, [at.unwrap()], "lines written as fixed");
}

/// `parameterize.scale = "auto"` is lowered until the refined mesh fits
/// `parameterize.max_vertices`, where a refusal would leave the user to find a number; a scale
/// the user gives is kept and refused with the budget named.
#[test]
fn auto_scale_is_lowered_to_fit_the_vertex_budget_and_a_given_scale_is_refused() {
    let config = repo().join("configs/feature_aligned.toml");
    let budget = "parameterize.max_vertices=20000";
    let plan = common::plan_config(&config, &[], &["parameterize.scale=\"auto\"", budget]);
    let plan = plan.unwrap();
    let node = (plan.dag.nodes.iter())
        .find(|n| n.name == "parameterize")
        .unwrap();
    let scale = node.params_json["scale"].as_f64().unwrap() as f32;
    let assets = repo().join("configs/assets");
    let mesh = texsyn::geom::io::read_mesh(&assets.join("fandisk.off")).unwrap();
    let (width, _) = image::image_dimensions(assets.join("brick.png")).unwrap();
    let (lo, hi) = mesh.bounds();
    let rule = width as f32 / (0.25 * (hi - lo).length());
    assert!(scale < 0.5 * rule, "scale {scale}, the rule's {rule}");
    let p = texsyn::stages::parameterize::edge_refinement::RefineParams {
        scale,
        edge: 1.0,
        max_vertices: 20_000,
    };
    let refined = texsyn::stages::parameterize::edge_refinement::node(&mesh, &p).unwrap();
    assert!(refined.mesh.vertex_count() > 20_000 / 6);

    let cache = tempfile::tempdir().unwrap();
    let given = format!("parameterize.scale={rule}");
    let Err(err) = run_config(&config, &[], &[&given, budget], cache.path()) else {
        panic!("scale {rule} refined within 20,000 vertices");
    };
    assert!(err.contains("parameterize.max_vertices"), "{err}");
}

/// The automatic scale's fit to the vertex budget refines the mesh, so `texsyn run`
/// remembers it in the cache (`plan-memo`): a rerun takes the remembered scale without
/// refining (a changed memo changes the scale the plan uses, which shows it is read), a
/// damaged memo is worked out again, another budget is another memo, and `--recheck` reads
/// none.
#[test]
fn the_auto_scale_s_budget_fit_is_remembered_in_the_cache() {
    let d = tempfile::tempdir().unwrap();
    let config = repo().join("configs/feature_aligned.toml");
    let config = config.to_str().unwrap();
    let fit = |budget: u32, extra: &[&str]| {
        let budget = format!("parameterize.max_vertices={budget}");
        let mut args = vec!["run", config, "--cache", "c", "--out", "o", "-v"];
        for set in [
            "parameterize.scale=\"auto\"",
            &budget,
            "compare=false",
            "reconstruct.preview_size=64",
            "reconstruct.atlas_size=0",
        ] {
            args.extend(["--set", set]);
        }
        args.extend(extra);
        let o = common::cli::succeeded(common::cli::texsyn(&args, d.path()));
        let log = common::cli::stderr(&o);
        let line = (log.lines())
            .find(|l| l.contains("lowered from"))
            .unwrap_or_else(|| panic!("no fit logged: {log}"))
            .to_owned();
        let to = line.split(" to ").nth(1).unwrap();
        to.split_whitespace()
            .next()
            .unwrap()
            .parse::<f32>()
            .unwrap()
    };
    let memos = || -> Vec<std::path::PathBuf> {
        let dir = d.path().join("c/plan-memo");
        let mut m: Vec<_> = (std::fs::read_dir(dir).unwrap())
            .map(|e| e.unwrap().path())
            .collect();
        m.sort();
        m
    };
    // The first run opens the cache after planning: the memo is written by the second.
    let fitted = fit(20_000, &[]);
    assert_eq!(fit(20_000, &[]), fitted);
    let written = memos();
    assert_eq!(written.len(), 1, "{written:?}");
    let half = (fitted / 2.0 * 1e4).round() / 1e4;
    std::fs::write(&written[0], half.to_le_bytes()).unwrap();
    assert_eq!(fit(20_000, &[]), half, "the remembered scale was not used");
    assert_eq!(
        fit(20_000, &["--recheck"]),
        fitted,
        "--recheck used the memo"
    );
    // Above the scale it lowers: damage.
    std::fs::write(&written[0], (fitted * 100.0).to_le_bytes()).unwrap();
    assert_eq!(fit(20_000, &[]), fitted);
    std::fs::write(&written[0], b"??").unwrap();
    assert_eq!(fit(20_000, &[]), fitted);
    let smaller = fit(15_000, &[]);
    assert!(
        smaller < fitted,
        "{smaller} within 15,000 vertices, {fitted} within 20,000"
    );
    assert_eq!(memos().len(), 2, "another budget, another memo");
}

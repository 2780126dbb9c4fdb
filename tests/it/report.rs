//! `texsyn report`: the page of a run and of a sweep, read as HTML in the default tier (what it
//! embeds, that it needs no network, the lock's verdict), and opened in headless Chromium in
//! the full tier (`scripts/browser`: no console errors, the 3D view draws the model, sorting a
//! table reorders its rows).

use crate::common::cli::{succeeded, texsyn};
use crate::common::repo;
use base64::Engine;
use std::path::Path;

/// The base64 text of the `<script type="application/octet-stream" id=ID>` element.
fn embedded<'a>(html: &'a str, id: &str) -> &'a str {
    let open = format!("<script type=\"application/octet-stream\" id=\"{id}\">");
    let start = html
        .find(&open)
        .unwrap_or_else(|| panic!("no element {id}"))
        + open.len();
    let end = start + html[start..].find("</script>").unwrap();
    &html[start..end]
}

/// What a page must not do to open from disk: fetch anything.
fn assert_offline(html: &str) {
    for bad in [
        "src=\"http",
        "href=\"http",
        "src='http",
        "@import",
        "url(http",
    ] {
        assert!(!html.contains(bad), "the page fetches something: {bad}");
    }
}

/// `texsyn report` of the demo into `root`; the page's text.
fn demo_report(root: &Path, sets: &[&str]) -> String {
    let (cache, out) = (root.join("cache"), root.join("out"));
    let mut args = vec![
        "report",
        "configs/demo.toml",
        "-q",
        "--cache",
        cache.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ];
    for s in sets {
        args.extend(["--set", s]);
    }
    succeeded(texsyn(&args, &repo()));
    std::fs::read_to_string(out.join("report.html")).unwrap()
}

#[test]
fn a_run_s_page_embeds_its_model_previews_and_dag_and_says_whether_its_lock_verifies() {
    let root = tempfile::tempdir().unwrap();
    let html = demo_report(root.path(), &[]);
    assert_offline(&html);
    // The model in the 3D view is the run's .glb, byte for byte.
    assert_eq!(html.matches("class=\"texsyn-viewer\"").count(), 1);
    assert!(html.contains("&quot;label&quot;:&quot;textured&quot;"));
    // Jump maps also have a patch view: a second model, toggled in the same view.
    assert!(html.contains("&quot;label&quot;:&quot;patches&quot;"));
    // The 3D view stands the model as the previews do: the demo gives +Y.
    assert!(html.contains("&quot;up&quot;:[0.0,1.0,0.0]"));
    let glb = base64::engine::general_purpose::STANDARD
        .decode(embedded(&html, "run-glb-0"))
        .unwrap();
    assert_eq!(
        glb,
        std::fs::read(root.path().join("out/textured.glb")).unwrap()
    );
    // The previews and the exemplar are inlined images.
    assert!(html.contains("alt=\"preview.png\" "));
    assert!(html.contains("alt=\"patches.png\" "));
    assert!(html.matches("<img src=\"data:image/png;base64,").count() >= 4);
    // One box per input file and per node, with its status, and one edge per input.
    let boxes = html.matches("<g class=\"node ").count();
    let edges = html.matches("<path class=\"edge\"").count();
    assert_eq!(html.matches("<g class=\"node file\"").count(), 2);
    assert_eq!(boxes, 2 + 7, "cow.obj, wood1.png and the demo's 7 nodes");
    assert!(
        edges >= boxes - 2,
        "every node reads something: {edges} edges"
    );
    assert!(
        html.contains("<g class=\"node ran\""),
        "a cold run computes"
    );
    // The shipped lock verifies from an empty cache; other overrides are not judged by it.
    assert!(html.contains("<span class=\"ok\">verifies</span>"));
    let other = demo_report(root.path(), &["synthesize.seed=2"]);
    assert!(!other.contains("verifies</span>"));
    assert!(other.contains("was made with other overrides"));
    assert!(other.contains("<code>--set synthesize.seed=2</code>"));
    // Another seed reruns synthesis and what follows; the rest is found in the cache.
    assert!(other.contains("<g class=\"node cached\""));
    assert!(other.contains("<g class=\"node ran\""));
}

/// Runs `texsyn sweep` of a sweep file with `axes` (TOML lines under `[axes]`) over `base`
/// (a config of the repository) in `root`, then `texsyn report` of it; whether the sweep
/// succeeded and the page's text.
fn sweep_and_report(root: &Path, base: &str, axes: &str) -> (bool, String) {
    let sweep = root.join("sweep.toml");
    std::fs::write(
        &sweep,
        format!(
            "base = \"{}\"\n[axes]\n{axes}\n",
            repo().join(base).display()
        ),
    )
    .unwrap();
    let (cache, out) = (root.join("cache"), root.join("sweep"));
    let run = |cmd: &str| {
        texsyn(
            &[
                cmd,
                sweep.to_str().unwrap(),
                "-q",
                "--cache",
                cache.to_str().unwrap(),
                "--out",
                out.to_str().unwrap(),
            ],
            &repo(),
        )
    };
    let swept = run("sweep").status.success();
    succeeded(run("report"));
    (
        swept,
        std::fs::read_to_string(out.join("report.html")).unwrap(),
    )
}

#[test]
fn a_sweep_s_page_has_a_thumbnail_a_row_a_filter_value_and_a_section_per_point() {
    let root = tempfile::tempdir().unwrap();
    let (swept, html) = sweep_and_report(
        root.path(),
        "configs/synth2d.toml",
        "\"synthesize.seed\" = [1, 2, 3]",
    );
    assert!(swept);
    assert_offline(&html);
    for i in 0..3 {
        let id = format!("point-{i:03}");
        assert_eq!(
            html.matches(&format!("href=\"#{id}\"")).count(),
            2,
            "{id}: linked from the gallery and the table"
        );
        assert!(html.contains(&format!("<section id=\"{id}\">")));
        assert!(html.contains(&format!("<option>{}</option>", i + 1)));
    }
    // Each thumbnail is an image made from that point's own output.
    let gallery =
        &html[html.find("class=\"gallery\"").unwrap()..html.find("id=\"results\"").unwrap()];
    let thumbs: Vec<&str> = gallery
        .split("<img src=\"data:image/png;base64,")
        .skip(1)
        .map(|s| s.split('"').next().unwrap())
        .collect();
    assert_eq!(thumbs.len(), 3);
    assert!(
        thumbs[0] != thumbs[1] && thumbs[1] != thumbs[2],
        "seeds give other images"
    );
    assert!(html.contains("<table class=\"sortable\" id=\"results\">"));
    assert!(html.contains("data-table=\"results\" data-column=\"1\""));
}

/// `scripts/browser ARGS` from the repository; its JSON summary when it passed.
fn browser(args: &[&str]) -> String {
    let o = std::process::Command::new(repo().join("scripts/browser"))
        .args(args)
        .current_dir(repo())
        .output()
        .unwrap();
    let out = String::from_utf8_lossy(&o.stdout).into_owned();
    assert!(
        o.status.success(),
        "scripts/browser {args:?} failed:\n{out}\n{}",
        String::from_utf8_lossy(&o.stderr)
    );
    out
}

#[test]
fn the_pages_open_in_chromium_with_no_errors_draw_the_model_and_sort() {
    crate::full_tier_only!("headless Chromium");
    crate::common::install_browser();
    let root = tempfile::tempdir().unwrap();
    demo_report(root.path(), &[]);
    let page = root.path().join("out/report.html");
    let summary = browser(&["check-report", page.to_str().unwrap(), "--sort", "nodes"]);
    assert!(summary.contains("\"pass\": true"), "{summary}");

    let sweep_root = root.path().join("seeds");
    std::fs::create_dir(&sweep_root).unwrap();
    let (swept, _) = sweep_and_report(
        &sweep_root,
        "configs/demo.toml",
        "\"synthesize.seed\" = [3, 1, 2]",
    );
    assert!(swept);
    let page = sweep_root.join("sweep/report.html");
    let summary = browser(&["check-report", page.to_str().unwrap(), "--sort", "results"]);
    assert!(summary.contains("\"pass\": true"), "{summary}");
}

#[test]
fn a_failed_point_shows_its_error_and_no_thumbnail_on_the_sweep_s_page() {
    let root = tempfile::tempdir().unwrap();
    std::fs::write(root.path().join("bad.png"), "not a png").unwrap();
    let wood = repo().join("configs/assets/wood2.png");
    let (swept, html) = sweep_and_report(
        root.path(),
        "configs/synth2d.toml",
        &format!(
            "\"inputs.exemplar\" = [\"{}\", \"bad.png\"]",
            wood.display()
        ),
    );
    assert!(!swept, "a sweep with a failed point exits non-zero");
    let failed = &html[html.find("<section id=\"point-001\">").unwrap()..];
    assert!(
        failed.contains("state failed"),
        "the failed point is not marked"
    );
    assert!(
        failed.contains("cannot decode image"),
        "its error is not shown"
    );
    let gallery =
        &html[html.find("class=\"gallery\"").unwrap()..html.find("id=\"results\"").unwrap()];
    assert_eq!(
        gallery.matches("<img src=").count(),
        1,
        "only the point that ran has a thumbnail"
    );
    assert!(gallery.contains("no preview (failed)"));
}

#[test]
fn the_3d_view_stands_a_z_up_mesh_up_as_the_previews_do() {
    // graph_matching_open leaves reconstruct.up at "auto"; its mushroom is modelled Z-up.
    let root = tempfile::tempdir().unwrap();
    let out = root.path().join("out");
    succeeded(texsyn(
        &[
            "report",
            "configs/graph_matching_open.toml",
            "-q",
            "--cache",
            root.path().join("cache").to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ],
        &repo(),
    ));
    let html = std::fs::read_to_string(out.join("report.html")).unwrap();
    assert!(
        html.contains("&quot;up&quot;:[0.0,0.0,1.0]"),
        "the mushroom is not stood on +Z"
    );
}

//! A made-up method wired through the typed node API in a few lines: its node's key follows
//! its parameters, its code version and its inputs' content (and their order), and nothing
//! else: not the input file's path, not another node's parameters.

use std::path::{Path, PathBuf};
use texsyn::cache::Cache;
use texsyn::image::Image;
use texsyn::methods::import;
use texsyn::pipeline::{self, Dag, NodeSpec, RunOptions, Stage};

#[derive(serde::Serialize)]
struct Gain {
    gain: f32,
}

/// tint = gain × the first image + the second; a downstream node with its own parameter.
fn tint_method(first: &Path, second: &Path, gain: f32, version: u32, downstream: f32) -> Dag {
    let mut dag = Dag::default();
    let a = import::<Image>(&mut dag, "import.a", first, "inputs.a").unwrap();
    let b = import::<Image>(&mut dag, "import.b", second, "inputs.b").unwrap();
    let tint = dag.node(
        NodeSpec::new(Stage::Synthesize, "tint", version),
        Gain { gain },
        (a, b),
        |_, p, (a, b)| {
            let mut out = Image::new(a.width, a.height);
            for ((o, x), y) in out
                .pixels
                .iter_mut()
                .zip(a.pixels)
                .zip(b.pixels.iter().cycle())
            {
                *o = std::array::from_fn(|c| p.gain * x[c] + y[c]);
            }
            Ok(out)
        },
    );
    dag.node(
        NodeSpec::new(Stage::Reconstruct, "scale", 1),
        Gain { gain: downstream },
        tint,
        |_, p, t| {
            let mut out = Image::new(t.width, t.height);
            for (o, x) in out.pixels.iter_mut().zip(t.pixels) {
                *o = x.map(|v| v * p.gain);
            }
            Ok(out)
        },
    );
    dag
}

fn exemplar(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/exemplars")
        .join(name)
}

/// The key of the `tint` node (runs the DAG in a fresh cache: keys depend on content).
fn tint_key(dag: &Dag) -> String {
    let cache = tempfile::tempdir().unwrap();
    let r = pipeline::run(
        dag,
        &Cache::open(cache.path()).unwrap(),
        RunOptions::default(),
    )
    .unwrap();
    let node = r.reports.iter().find(|n| n.node == "synthesize").unwrap();
    assert_eq!(node.algorithm, "tint");
    node.key.clone()
}

#[test]
fn a_made_up_methods_key_follows_parameters_version_and_input_content_only() {
    let (wood, marble) = (exemplar("wood1.png"), exemplar("marble1.png"));
    let base = tint_key(&tint_method(&wood, &marble, 0.5, 1, 1.0));
    let dir = tempfile::tempdir().unwrap();
    let copy = dir.path().join("renamed.png");
    std::fs::copy(&wood, &copy).unwrap();

    // What the key must follow, and what it must not: the same bytes under another name, a
    // downstream node's parameters.
    let follows = [
        ("parameters", tint_method(&wood, &marble, 0.25, 1, 1.0)),
        ("code version", tint_method(&wood, &marble, 0.5, 2, 1.0)),
        ("input content", tint_method(&marble, &marble, 0.5, 1, 1.0)),
        ("input order", tint_method(&marble, &wood, 0.5, 1, 1.0)),
    ];
    let ignores = [
        ("deterministic", tint_method(&wood, &marble, 0.5, 1, 1.0)),
        ("file path", tint_method(&copy, &marble, 0.5, 1, 1.0)),
        (
            "downstream parameters",
            tint_method(&wood, &marble, 0.5, 1, 3.0),
        ),
    ];
    for (what, dag) in follows {
        assert_ne!(base, tint_key(&dag), "{what}");
    }
    for (what, dag) in ignores {
        assert_eq!(base, tint_key(&dag), "{what}");
    }
}

//! The method registry: a method written outside texsyn, in this one file, is registered at
//! run time and runs end to end through the library functions that `run`, `score` and `sweep`
//! use (planning, the pipeline, the score hook, a sweep's points and their state), and the
//! registry refuses a second method under a taken name.

use crate::common;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use std::sync::Once;
use texsyn::artifact::Bundle;
use texsyn::cache::Cache;
use texsyn::config::Config;
use texsyn::image::Image;
use texsyn::methods::{self, Method, MethodError, Planned, import};
use texsyn::ops::sweep::{PointState, Sweep, SweepDir, point_state};
use texsyn::pipeline::{self, Dag, Handle, NodeError, NodeSpec, RunOptions, Stage};
use texsyn::score::{Item, Run, ScoreFailure};

/// A toy method: the exemplar tiled `repeat` × `repeat` times, shifted by `shift` pixels.
struct Tiling;

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct TilingConfig {
    #[allow(dead_code)] // the registry read it to find this method
    method: String,
    inputs: TilingInputs,
    #[serde(default)]
    synthesize: TilingParams,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct TilingInputs {
    exemplar: PathBuf,
}

#[derive(Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
struct TilingParams {
    repeat: u32,
    shift: u32,
}

impl Default for TilingParams {
    fn default() -> Self {
        TilingParams {
            repeat: 2,
            shift: 0,
        }
    }
}

struct TilingNodes {
    exemplar: Handle<Image>,
    tiled: Handle<Bundle>,
}

impl Method for Tiling {
    fn name(&self) -> &'static str {
        "toy_tiling"
    }

    fn plan(&self, config: &Config) -> Result<(Dag, Box<dyn Planned>), MethodError> {
        let c: TilingConfig = config.parse()?;
        if !(1..=4).contains(&c.synthesize.repeat) {
            return Err(config.invalid("synthesize.repeat", "must be 1..=4").into());
        }
        let mut dag = Dag::default();
        let path = config.resolve(&c.inputs.exemplar);
        let exemplar = import::<Image>(&mut dag, "import.exemplar", &path, "inputs.exemplar")?;
        let tiled = dag.node(
            NodeSpec::new(Stage::Synthesize, "toy_tiling", 1),
            c.synthesize,
            exemplar,
            |_, p, ex| {
                let (w, h) = (ex.width, ex.height);
                if w == 0 || h == 0 {
                    return Err(NodeError::input("an empty exemplar"));
                }
                let out = Image::from_fn(w * p.repeat, h * p.repeat, |x, y| {
                    ex.get((x + p.shift) % w, y % h)
                });
                let png = texsyn::export::encode_png(&out.to_rgba8(), false);
                Ok(Bundle::from(vec![("tiled.png".to_string(), png)]))
            },
        );
        Ok((dag, Box::new(TilingNodes { exemplar, tiled })))
    }
}

impl Planned for TilingNodes {
    fn score(&self, run: &Run<'_>, _: &mut Vec<String>) -> Result<Vec<Item>, ScoreFailure> {
        let out = run.image(self.tiled, "tiled.png")?;
        let ex = run.view(self.exemplar)?;
        let mut item = Item::new("tiled.png", "inputs.exemplar");
        run.score_into(&mut item, out.view(), None, ex)?;
        Ok(vec![item])
    }
}

static TILING: Tiling = Tiling;

fn register_once() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| methods::register(&TILING).expect("the name is free"));
}

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// A config of the toy method in `dir`, with its `[score]`.
fn write_config(dir: &Path) -> PathBuf {
    let exemplar = repo().join("tests/data/exemplars/brick.png");
    let path = dir.join("tiling.toml");
    let text = format!(
        "method = \"toy_tiling\"\n\n[inputs]\nexemplar = {:?}\n\n[synthesize]\nrepeat = 2\n\n[score]\nmax_queries = 2000\n",
        exemplar.display().to_string()
    );
    std::fs::write(&path, text).unwrap();
    path
}

#[test]
fn a_method_registered_at_run_time_plans_runs_and_scores() {
    register_once();
    assert!(methods::names().contains(&"toy_tiling"));
    let dir = tempfile::tempdir().unwrap();
    let config_path = write_config(dir.path());
    let cache = Cache::open(&dir.path().join("cache")).unwrap();

    let config = Config::load(&config_path, &[]).unwrap();
    let plan = methods::plan(&config).unwrap();
    assert_eq!(plan.method, "toy_tiling");
    assert!(!plan.splits_into_shards());
    let result = pipeline::run(&plan.dag, &cache, RunOptions::default()).unwrap();
    let out = dir.path().join("out");
    let tiled = &result.artifacts[plan.dag.node_index("synthesize").unwrap()];
    pipeline::outputs::materialize(tiled, &out).unwrap();
    let png = image::open(out.join("tiled.png")).unwrap();
    let brick = image::open(repo().join("tests/data/exemplars/brick.png")).unwrap();
    assert_eq!(
        (png.width(), png.height()),
        (2 * brick.width(), 2 * brick.height())
    );

    // A tiling copies the exemplar: every patch but those across a tile's edge is found in it
    // (measured 0.07), where unrelated content scores near 1.
    let section = plan.score.clone().expect("the config has [score]");
    let report = plan.score_run(&result, &section).unwrap();
    assert_eq!(report.method, "toy_tiling");
    let score = report.items[0].score.as_ref().expect("scored");
    assert!(score.ratio < 0.2, "ratio {}", score.ratio);

    // A rerun finds everything cached.
    let again = pipeline::run(&plan.dag, &cache, RunOptions::default()).unwrap();
    assert!(common::ran(&again).is_empty(), "{:?}", common::ran(&again));

    // Its own parameters are checked by its own schema.
    let bad = Config::load(&config_path, &["synthesize.repeat=9".into()]).unwrap();
    let e = methods::plan(&bad).err().expect("refused").to_string();
    assert!(e.contains("synthesize.repeat"), "{e}");
    let unknown = Config::load(&config_path, &["synthesize.tiles=3".into()]).unwrap();
    let e = methods::plan(&unknown).err().expect("refused").to_string();
    assert!(e.contains("tiles"), "{e}");
}

#[test]
fn a_registered_method_sweeps() {
    register_once();
    let dir = tempfile::tempdir().unwrap();
    write_config(dir.path());
    let sweep_path = dir.path().join("shifts.toml");
    std::fs::write(
        &sweep_path,
        "base = \"tiling.toml\"\n\n[axes]\n\"synthesize.shift\" = [0, 3]\n",
    )
    .unwrap();
    let sweep = Sweep::load(&sweep_path).unwrap();
    assert_eq!(sweep.points.len(), 2);
    let cache = Cache::open(&dir.path().join("cache")).unwrap();
    let sweep_dir = SweepDir::new(&dir.path().join("sweep-out"));
    let mut hashes = Vec::new();
    for point in &sweep.points {
        let state = point_state(&sweep, &sweep_dir, point, &cache).unwrap();
        match state {
            PointState::WouldRun { nodes } => {
                assert!(nodes.iter().any(|n| n == "synthesize"), "{nodes:?}")
            }
            PointState::Done => panic!("point {} is done before it ran", point.index),
        }
        let config = sweep.point_config(point).unwrap();
        let plan = methods::plan(&config).unwrap();
        let result = pipeline::run(&plan.dag, &cache, RunOptions::default()).unwrap();
        let i = plan.dag.node_index("synthesize").unwrap();
        hashes.push(result.reports[i].content_hash.clone());
    }
    // The shift reaches the node: two points, two results, one shared import.
    assert_ne!(hashes[0], hashes[1]);
}

#[test]
fn a_taken_name_is_refused() {
    register_once();
    struct Impostor;
    impl Method for Impostor {
        fn name(&self) -> &'static str {
            "jump_maps"
        }
        fn plan(&self, _: &Config) -> Result<(Dag, Box<dyn Planned>), MethodError> {
            unreachable!("never registered")
        }
    }
    static IMPOSTOR: Impostor = Impostor;
    let e = methods::register(&IMPOSTOR).expect_err("refused");
    assert!(e.to_string().contains("jump_maps"), "{e}");
    assert!(methods::register(&TILING).is_err(), "registered twice");
}

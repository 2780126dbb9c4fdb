//! `texsyn status`: says what `run` would compute, node by node, without computing (like
//! make -n); with `--shard i/N`, also what that shard would compute.

use super::{Globals, load_plan, load_shardable_plan, print_json, print_shard};
use anyhow::Result;
use std::path::{Path, PathBuf};
use texsyn::cache::Cache;
use texsyn::pipeline::executor::StatusLine;
use texsyn::pipeline::{self, RunOptions, Shard, ShardResult};

#[derive(clap::Args)]
pub struct StatusArgs {
    config: PathBuf,
    #[arg(long = "set", value_name = "STAGE.KEY=VALUE")]
    sets: Vec<String>,
    /// Also say what `run --shard i/N` would compute: its finest bricks and, when the
    /// synthesis' inputs are cached, the bricks per level it would compute.
    #[arg(long, value_name = "i/N")]
    shard: Option<String>,
}

/// `texsyn status`.
pub fn status(args: &StatusArgs, g: &Globals) -> Result<i32> {
    let StatusArgs {
        config,
        sets,
        shard,
    } = args;
    let shard: Option<Shard> = shard.as_deref().map(str::parse).transpose()?;
    let plan = match shard {
        Some(_) => load_shardable_plan(config, sets)?,
        None => load_plan(config, sets)?,
    };
    let cache = Cache::open(&g.cache_dir)?;
    let lines = pipeline::status(&plan.dag, &cache);
    let opts = RunOptions::default();
    let planned = shard
        .map(|s| pipeline::run_shard(&plan.dag, &cache, opts, s, true))
        .transpose()?;
    if g.json {
        match &planned {
            Some(p) => print_json(&serde_json::json!({
                "nodes": lines,
                "shard": p,
            }))?,
            None => print_json(&lines)?,
        }
    } else {
        print_status(&lines, planned.as_ref(), config);
    }
    Ok(0)
}

/// The status table, then what the shard would do.
fn print_status(lines: &[StatusLine], planned: Option<&ShardResult>, config: &Path) {
    println!("{:<24} {:<17} {:<20} state", "node", "stage", "algorithm");
    for l in lines {
        let state = match l.state {
            "cached" => "cached",
            "run" => "would run",
            _ => "would run if its inputs change",
        };
        println!("{:<24} {:<17} {:<20} {state}", l.node, l.stage, l.algorithm);
    }
    if let Some(p) = planned {
        print_shard(p, config, true);
    }
}

//! `texsyn graph`: prints a config's DAG in Graphviz DOT.

use super::{Globals, load_plan};
use anyhow::Result;
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct GraphArgs {
    config: PathBuf,
    #[arg(long = "set", value_name = "STAGE.KEY=VALUE")]
    sets: Vec<String>,
}

/// `texsyn graph`.
pub fn graph(args: &GraphArgs, _: &Globals) -> Result<i32> {
    let plan = load_plan(&args.config, &args.sets)?;
    print!("{}", plan.dag.to_dot());
    Ok(0)
}

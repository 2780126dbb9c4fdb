//! `texsyn score`: scores runs' results against their exemplars (nearest-patch measures),
//! running what is not cached first but writing no outputs; one config's report, or one
//! table of several configs.

use super::{Globals, print_json, run_config, score_plan};
use anyhow::Result;
use std::path::{Path, PathBuf};
use texsyn::config::Config;
use texsyn::score::Report;

#[derive(clap::Args)]
pub struct ScoreArgs {
    #[arg(required = true)]
    configs: Vec<PathBuf>,
    #[arg(long = "set", value_name = "STAGE.KEY=VALUE")]
    sets: Vec<String>,
    /// Print a Markdown table (BENCHMARKS.md's quality table).
    #[arg(long)]
    markdown: bool,
}

/// `texsyn score`.
pub fn score(args: &ScoreArgs, g: &Globals) -> Result<i32> {
    let ScoreArgs {
        configs,
        sets,
        markdown,
    } = args;
    let mut reports = Vec::new();
    for config in configs {
        // A glob over a config folder also meets the files configs name (curves):
        // with several files, one without `method` is passed over, said on stderr.
        if configs.len() > 1
            && Config::load(config, &[]).is_ok_and(|c| !c.table.contains_key("method"))
        {
            eprintln!(
                "{}: no `method`, not a config; passed over",
                config.display()
            );
            continue;
        }
        reports.push(score_config(config, sets, g)?);
    }
    if g.json {
        if reports.len() == 1 && !*markdown {
            print_json(&reports[0])?;
        } else {
            print_json(&reports)?;
        }
    } else if *markdown || reports.len() > 1 {
        print!("{}", texsyn::score::markdown_table(&reports));
    } else if !g.quiet {
        print!("{}", texsyn::score::report_text(&reports[0]));
    }
    Ok(0)
}

/// Runs `config` (computing what is not cached) and scores its results with the config's
/// `[score]` section (or the defaults).
fn score_config(config: &Path, sets: &[String], g: &Globals) -> Result<Report> {
    let (plan, result) = run_config(config, sets, &g.cache_dir, g.progress)?;
    let section = plan.score.clone().unwrap_or_default();
    // A solid surface has no planar image: a section of the same solid is synthesized (from
    // the cached bricks where they overlap) and scored.
    match plan.score_substitute(&result) {
        Some(set) => {
            let mut with = sets.to_vec();
            with.push(set.clone());
            let (plan2, result2) = run_config(config, &with, &g.cache_dir, g.progress)?;
            let mut r = score_plan(config, &plan2, &result2, &section)?;
            for item in &mut r.items {
                item.output = format!("{} (a section made for scoring)", item.output);
                item.notes.push(format!(
                    "the config requests the surface; this is a section synthesized for \
                     scoring (--set '{set}')"
                ));
            }
            Ok(r)
        }
        None => score_plan(config, &plan, &result, &section),
    }
}

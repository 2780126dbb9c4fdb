//! A config turned into work: the method it names, found in the registry, plans its DAG.

use super::{MethodError, Planned, find, names};
use crate::config::Config;
use crate::pipeline::{Dag, RunResult};
use crate::score::{Report, ScoreFailure, ScoreSection};
use std::path::PathBuf;

/// A config turned into work: the DAG, and what the method keeps for after the run.
pub struct Plan {
    pub dag: Dag,
    /// The config's `method`.
    pub method: String,
    /// The config's `[score]` section, when it has one (validated).
    pub score: Option<ScoreSection>,
    /// The config the method planned from (without `[score]`).
    config: Config,
    planned: Box<dyn Planned>,
}

impl Plan {
    /// Default output directory (`out/<config stem>`), used unless `--out` is given; an error
    /// naming the config when its stem is not a plain folder name ([`crate::config::default_out`]).
    pub fn default_out(&self) -> Result<PathBuf, crate::config::ConfigError> {
        crate::config::default_out(&self.config.path, &self.config.stem)
    }

    /// Scores a run of this plan (its `result`) with `section`'s parameters.
    pub fn score_run(
        &self,
        result: &RunResult,
        section: &ScoreSection,
    ) -> Result<Report, ScoreFailure> {
        crate::score::report(&self.config, &self.method, section, |params, not_scored| {
            let run = crate::score::Run {
                config: &self.config,
                result,
                params: *params,
            };
            self.planned.score(&run, not_scored)
        })
    }

    /// See [`Planned::score_substitute`].
    pub fn score_substitute(&self, result: &RunResult) -> Option<String> {
        self.planned.score_substitute(result)
    }

    /// Whether some of its work can be split among machines (`--shard`).
    pub fn splits_into_shards(&self) -> bool {
        self.dag.nodes.iter().any(|n| n.splits_into_shards())
    }
}

pub fn plan(config: &Config) -> Result<Plan, MethodError> {
    let name = config.method()?.to_owned();
    // `[score]` reads the run's artifacts after it and never reaches a node, so it is taken
    // out before the method parses its sections (and adding it changes no key).
    let score = ScoreSection::from_config(config)?;
    let mut without_score = config.clone();
    without_score.table.remove("score");
    let method = find(&name).ok_or_else(|| MethodError::UnknownMethod {
        path: config.path.clone(),
        method: name.clone(),
        known: names().join(", "),
    })?;
    let (dag, planned) = method.plan(&without_score)?;
    Ok(Plan {
        dag,
        method: name,
        score,
        config: without_score,
        planned,
    })
}

//! The Slurm executor: a sweep's points as one `sbatch` job array (and, for a sharded solid,
//! the shards as one array and each point's gather as a job that starts when that point's
//! shards have succeeded), each task the same `texsyn run` the local executor starts, on the same cache.
//!
//! The array's state lives in `OUT/slurm/` (see [`crate::ops::slurm`]), so a sweep whose client was
//! killed is re-attached by running the same `texsyn sweep` again: it waits for the tasks
//! still in the queue, then submits only the points that are still not done (failed, lost or
//! never submitted), after checking with a probe job that the compute nodes see the cache
//! folder.

use super::table::Failures;
use super::{CommonArgs, Point, Sweep, SweepDir, point_command};
use crate::ops::slurm::{self, SlurmOptions, Task, TaskOutcome, TaskStatus};
use std::path::{Path, PathBuf};
use std::time::Duration;

/// How often squeue is asked.
const POLL: Duration = Duration::from_millis(500);

/// The task list of a sweep: for each point, its shards (if sharded) and its own run (the
/// gather, when sharded). Task `k` of point `p` is at `p * per_point + k`, so a task's index
/// never depends on which points are still to do.
pub struct TaskList {
    pub tasks: Vec<Task>,
    pub per_point: usize,
    pub shards: u32,
}

impl TaskList {
    pub fn new(exe: &Path, sweep: &Sweep, dir: &SweepDir, common: &CommonArgs) -> TaskList {
        let shards = sweep.shards.unwrap_or(1).max(1);
        let per_point = if shards > 1 { shards as usize + 1 } else { 1 };
        let mut tasks = Vec::new();
        for p in &sweep.points {
            if shards > 1 {
                for s in 0..shards {
                    tasks.push(Task {
                        argv: point_command(exe, sweep, dir, p, Some((s, shards)), common),
                        name: format!("{} shard {s}/{shards}", p.folder_name()),
                    });
                }
            }
            tasks.push(Task {
                argv: point_command(exe, sweep, dir, p, None, common),
                name: p.folder_name(),
            });
        }
        TaskList {
            tasks,
            per_point,
            shards,
        }
    }

    /// The index of point `p`'s own run (its gather, when sharded).
    fn main_task(&self, p: &Point) -> usize {
        p.index * self.per_point + self.per_point - 1
    }

    fn shard_tasks(&self, p: &Point) -> impl Iterator<Item = usize> + use<> {
        let first = p.index * self.per_point;
        first..first + self.per_point - 1
    }
}

/// The state folder of the sweep's Slurm jobs.
pub fn state_dir(dir: &SweepDir) -> PathBuf {
    dir.root.join("slurm")
}

/// Waits for tasks an earlier client left in the queue (a killed `texsyn sweep`). Returns
/// whether there were any.
pub fn reattach(
    dir: &SweepDir,
    progress: &mut dyn FnMut(&[TaskOutcome]),
) -> Result<bool, slurm::SlurmError> {
    let state = state_dir(dir);
    if !state.join("submissions.json").is_file() {
        return Ok(false);
    }
    let now = slurm::status(&state)?;
    if !now
        .iter()
        .any(|t| matches!(t.status, TaskStatus::Active(_)))
    {
        return Ok(false);
    }
    slurm::attach_with(&state, POLL, |s| progress(s))?;
    Ok(true)
}

/// Submits the points of `todo` and waits for them; returns the failures by point, each
/// naming its Slurm job id and log.
pub fn run(
    list: &TaskList,
    dir: &SweepDir,
    todo: &[&Point],
    cache: &Path,
    opts: &SlurmOptions,
    progress: &mut dyn FnMut(&[TaskOutcome]),
) -> Result<Failures, slurm::SlurmError> {
    let state = state_dir(dir);
    // An array's task indices must be below the cluster's MaxArraySize: say so before any
    // job is submitted, rather than after the shards' array.
    let highest = todo.iter().map(|p| list.main_task(p)).max().unwrap_or(0);
    if let Some(max) = slurm::max_array_size()?
        && highest >= max
    {
        return Err(slurm::SlurmError::State {
            dir: state,
            why: format!(
                "the sweep needs array task index {highest}, but this cluster's MaxArraySize is \
                 {max} (indices 0 to {}): split the sweep into smaller sweeps, or raise \
                 MaxArraySize in slurm.conf",
                max - 1
            ),
        });
    }
    // The nodes must see the cache, and the sweep's folder, where the tasks write their
    // reports, exit status and logs.
    slurm::probe_shared_folder(cache, opts)?;
    std::fs::create_dir_all(&dir.root).map_err(|source| slurm::SlurmError::State {
        dir: dir.root.clone(),
        why: format!("cannot create it: {source}"),
    })?;
    slurm::probe_shared_folder(&dir.root, opts)?;
    let mains: Vec<usize> = todo.iter().map(|p| list.main_task(p)).collect();
    if list.shards > 1 {
        let shards: Vec<usize> = todo.iter().flat_map(|p| list.shard_tasks(p)).collect();
        let array = slurm::submit_array(&state, &list.tasks, &shards, opts, None)?;
        // Each point's gather waits for its own shards only (`afterok:A_i:A_j`), so a failed
        // shard cancels its own point's gather and no other.
        for p in todo {
            let own: Vec<String> = list
                .shard_tasks(p)
                .map(|i| format!("{array}_{i}"))
                .collect();
            let after = slurm::JobId(own.join(":"));
            slurm::submit_single(&state, &list.tasks, list.main_task(p), opts, Some(&after))?;
        }
    } else {
        slurm::submit_array(&state, &list.tasks, &mains, opts, None)?;
    }
    let outcomes = slurm::attach_with(&state, POLL, |s| progress(s))?;
    let mut failures = Failures::new();
    for p in todo {
        let failed = list
            .shard_tasks(p)
            .chain([list.main_task(p)])
            .map(|i| &outcomes[i])
            .find(|o| !o.status.succeeded());
        if let Some(o) = failed {
            let why = o
                .log
                .as_deref()
                .and_then(super::local::last_error)
                .map(|e| format!("{e}; "))
                .unwrap_or_default();
            failures.insert(p.index, format!("{why}{o}"));
        }
    }
    Ok(failures)
}

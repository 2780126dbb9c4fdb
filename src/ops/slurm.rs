//! Slurm job arrays over a state folder: submit a list of commands as one
//! `sbatch` array, wait for them in a way that survives the client being killed, report each
//! task's exit status, job id and log, and resubmit only what failed or is missing.
//!
//! This layer knows nothing about what the tasks do: a task is a command line (`argv`) and a
//! name. `texsyn sweep --executor slurm` gives it one `texsyn run …` per sweep point; a sharded
//! solid gives it one task per shard and a gather task that depends on the array.
//!
//! # The state folder
//!
//! Everything a later client needs lives in one folder (`state_dir`), which must be on a
//! filesystem the compute nodes see (the tasks write their exit status into it):
//!
//! ```text
//! tasks.json          the task list: count and names (rewritten by every submission)
//! tasks/<i>.argv      task i's command line, NUL-separated (read by the wrapper, bash mapfile)
//! task.sh             the batch script: runs tasks/<i>.argv, records exit/<i>
//! submissions.json    every submission: kind (array or single), job id, indices, unix time
//! exit/<i>            written by the wrapper when task i's command ends, however it ends:
//!                     `exit=<code>`, `job=<slurm job id>`, `host=<node>`
//! logs/<job>_<i>.log  the task's stdout and stderr (sbatch --output), one per submission
//! .lock               held (flock) while a client submits, so two submissions do not interleave
//! ```
//!
//! # Waiting without accounting
//!
//! The local cluster (and many small ones) runs without accounting storage, so there is no
//! `sacct`. A task's state is read from `squeue -t all`, which shows a job while it is pending
//! or running and for `MinJobAge` seconds after it ends (default 300 s); after that the job is
//! gone. So: a task is *active* while squeue shows it in a non-final state; once it is not, its
//! exit file says how its command ended. A task that left the queue without an exit file was
//! killed before its command ended (time limit, `scancel`, node failure, out of memory, a
//! failed dependency): it is reported as lost, with squeue's final state when squeue still has
//! it. Because the exit file is written by the task itself and the submissions are on disk, any
//! process can [`attach`] to the folder and finish a wait another one started.
//!
//! On NFS a file written on a compute node can take a few seconds (the attribute cache,
//! `actimeo`) to appear on the client; [`attach`] therefore rereads the exit files of tasks that
//! look lost once more after a grace period before reporting them.
//!
//! Known gap: a client killed between `sbatch` returning and `submissions.json` being written
//! (a few milliseconds) leaves a job that no state file names; a rerun would submit its tasks
//! again (harmless for texsyn's runs, which share work through the cache, but it costs).

use serde::{Deserialize, Serialize};
use std::ffi::{OsStr, OsString};
use std::fmt;
use std::fs::{self, File};
use std::io::{self, Write};
use std::os::unix::ffi::OsStrExt;
use std::os::unix::fs::PermissionsExt;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, SystemTime, UNIX_EPOCH};

/// Slurm resources for every task of a submission: the `[slurm]` table of a sweep or solid
/// config, or the matching command-line flags. Every field is optional; an absent one leaves
/// the cluster's default.
#[derive(Debug, Clone, Default, PartialEq, Eq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct SlurmOptions {
    /// `--partition`. Default: the cluster's default partition.
    pub partition: Option<String>,
    /// `--time`, in Slurm's formats: `MINUTES`, `MM:SS`, `HH:MM:SS`, `D-HH`, `D-HH:MM`,
    /// `D-HH:MM:SS`, or `UNLIMITED`. Default: the partition's limit.
    #[serde(default, deserialize_with = "de_time")]
    pub time: Option<String>,
    /// `--mem`, memory per node, in bytes (the config may say `"4G"`); rounded up to whole MiB
    /// for sbatch. A task's own memory budget (`--max-memory`) should not exceed it.
    /// Default: the cluster's `DefMemPerCPU`/`DefMemPerNode`.
    #[serde(default, deserialize_with = "de_mem")]
    pub mem: Option<u64>,
    /// `--cpus-per-task`, at least 1. Default: 1.
    pub cpus_per_task: Option<u32>,
    /// `--account`. Default: the user's default account.
    pub account: Option<String>,
}

impl SlurmOptions {
    /// Checks every field, so that a bad value is refused before anything is submitted.
    pub fn check(&self) -> Result<(), SlurmError> {
        let bad = |field: &'static str, value: String, why: &str| SlurmError::BadOption {
            field,
            value,
            why: why.to_owned(),
        };
        for (field, v) in [("partition", &self.partition), ("account", &self.account)] {
            if let Some(v) = v
                && (v.is_empty() || v.contains(|c: char| c.is_whitespace() || c == ','))
            {
                return Err(bad(
                    field,
                    v.clone(),
                    "must be one name, without spaces or commas",
                ));
            }
        }
        if let Some(t) = &self.time
            && let Err(why) = check_time(t)
        {
            return Err(bad("time", t.clone(), &why));
        }
        if self.mem == Some(0) {
            return Err(bad("mem", "0".into(), "must be more than 0 bytes"));
        }
        if self.cpus_per_task == Some(0) {
            return Err(bad("cpus_per_task", "0".into(), "must be at least 1"));
        }
        Ok(())
    }

    /// The sbatch flags these options stand for.
    pub fn sbatch_args(&self) -> Vec<String> {
        let mut args = Vec::new();
        if let Some(p) = &self.partition {
            args.push(format!("--partition={p}"));
        }
        if let Some(t) = &self.time {
            args.push(format!("--time={t}"));
        }
        if let Some(m) = self.mem {
            args.push(format!("--mem={}M", m.div_ceil(1024 * 1024)));
        }
        if let Some(c) = self.cpus_per_task {
            args.push(format!("--cpus-per-task={c}"));
        }
        if let Some(a) = &self.account {
            args.push(format!("--account={a}"));
        }
        args
    }
}

/// Slurm's time formats (sbatch(1), `--time`).
fn check_time(t: &str) -> Result<(), String> {
    let up = t.to_ascii_uppercase();
    if up == "UNLIMITED" || up == "INFINITE" {
        return Ok(());
    }
    let all_digits = |s: &str| !s.is_empty() && s.bytes().all(|b| b.is_ascii_digit());
    let (days, rest) = match t.split_once('-') {
        Some((d, r)) => (Some(d), r),
        None => (None, t),
    };
    let parts: Vec<&str> = rest.split(':').collect();
    let ok = days.is_none_or(all_digits) && parts.iter().all(|p| all_digits(p)) && parts.len() <= 3;
    if ok {
        Ok(())
    } else {
        Err(
            "not a Slurm time (MINUTES, MM:SS, HH:MM:SS, D-HH, D-HH:MM, D-HH:MM:SS or UNLIMITED)"
                .into(),
        )
    }
}

fn de_time<'de, D: serde::Deserializer<'de>>(d: D) -> Result<Option<String>, D::Error> {
    #[derive(Deserialize)]
    #[serde(untagged)]
    enum T {
        Minutes(u64),
        Text(String),
    }
    let t = match T::deserialize(d)? {
        T::Minutes(m) => m.to_string(),
        T::Text(s) => s,
    };
    check_time(&t).map_err(|why| serde::de::Error::custom(format!("time {t:?}: {why}")))?;
    Ok(Some(t))
}

fn de_mem<'de, D: serde::Deserializer<'de>>(d: D) -> Result<Option<u64>, D::Error> {
    #[derive(Deserialize)]
    #[serde(untagged)]
    enum M {
        Bytes(u64),
        Text(String),
    }
    let bytes = match M::deserialize(d)? {
        M::Bytes(b) => b,
        M::Text(s) => crate::cache::parse_size(&s)
            .map_err(|e| serde::de::Error::custom(format!("mem: {e}")))?,
    };
    if bytes == 0 {
        return Err(serde::de::Error::custom("mem: must be more than 0 bytes"));
    }
    Ok(Some(bytes))
}

/// One command to run as one Slurm task. Its index is its position in the task list.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Task {
    /// The command line, program first. Run in the submitting client's working directory, with
    /// its environment (sbatch's default `--export=ALL`).
    pub argv: Vec<OsString>,
    /// A name for reports (e.g. the sweep point's folder).
    pub name: String,
}

/// A Slurm job id as sbatch printed it: an array's id, or a single job's.
#[derive(Debug, Clone, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(transparent)]
pub struct JobId(pub String);

impl fmt::Display for JobId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

/// What happened to one task, as far as the state folder and squeue know.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum TaskStatus {
    /// Never submitted from this state folder.
    NotSubmitted,
    /// Pending or running; squeue's state (`PENDING`, `RUNNING`, …).
    Active(String),
    /// Its command ended with this exit code (128 + N when killed by signal N while the
    /// wrapper lived on).
    Exited(i32),
    /// Left the queue without recording an exit status: killed by Slurm (time limit, memory,
    /// `scancel`, a failed dependency) or lost with its node. `slurm_state` is squeue's final
    /// state (`TIMEOUT`, `CANCELLED`, `NODE_FAIL`, `OUT_OF_MEMORY`, …) while squeue still
    /// shows the job, else `None`.
    Lost { slurm_state: Option<String> },
}

impl TaskStatus {
    pub fn succeeded(&self) -> bool {
        matches!(self, TaskStatus::Exited(0))
    }
    /// Failed, lost or never submitted: what a rerun submits again.
    pub fn needs_rerun(&self) -> bool {
        match self {
            TaskStatus::Exited(code) => *code != 0,
            TaskStatus::Lost { .. } | TaskStatus::NotSubmitted => true,
            TaskStatus::Active(_) => false,
        }
    }
}

/// One task's state: its index and name, the Slurm job id of its latest submission
/// (`<array>_<index>` for an array task, `<job>` for a single job), and that submission's log.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TaskOutcome {
    pub index: usize,
    pub name: String,
    pub job_id: Option<String>,
    pub status: TaskStatus,
    pub log: Option<PathBuf>,
}

impl fmt::Display for TaskOutcome {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "task {} ({})", self.index, self.name)?;
        if let Some(job) = &self.job_id {
            write!(f, ", Slurm job {job}")?;
        }
        match &self.status {
            TaskStatus::NotSubmitted => write!(f, ": not submitted")?,
            TaskStatus::Active(s) => write!(f, ": {}", s.to_lowercase())?,
            TaskStatus::Exited(0) => write!(f, ": succeeded")?,
            TaskStatus::Exited(c) => write!(f, ": failed with exit code {c}")?,
            TaskStatus::Lost { slurm_state } => write!(
                f,
                ": killed before its command ended ({})",
                slurm_state.as_deref().unwrap_or(
                    "no exit status recorded and no longer in the queue: time limit, memory, \
                     scancel or node failure"
                )
            )?,
        }
        if let Some(log) = &self.log
            && !matches!(self.status, TaskStatus::NotSubmitted)
        {
            write!(f, "; log {}", log.display())?;
        }
        Ok(())
    }
}

#[derive(Debug, thiserror::Error)]
pub enum SlurmError {
    #[error(
        "`{tool}` was not found on PATH ({path}): install Slurm's client tools (Debian/Ubuntu: \
         apt-get install slurm-client; or use your cluster's login node), or start a one-node \
         development cluster on this machine with scripts/slurm-local"
    )]
    ToolMissing { tool: &'static str, path: String },
    #[error(
        "the Slurm controller does not respond: `{command}` failed: {stderr}\nstart the local \
         cluster with scripts/slurm-local, or check SLURM_CONF and the cluster's slurmctld"
    )]
    ControllerDown { command: String, stderr: String },
    #[error("{path}: {source}")]
    Io { path: PathBuf, source: io::Error },
    #[error("[slurm] {field} = {value:?}: {why}")]
    BadOption {
        field: &'static str,
        value: String,
        why: String,
    },
    #[error("task {index}: {why}")]
    BadTask { index: usize, why: String },
    #[error("state folder {dir}: {why}")]
    State { dir: PathBuf, why: String },
    #[error("task {index} is still {state} as Slurm job {job}: not submitting it again")]
    StillActive {
        index: usize,
        job: String,
        state: String,
    },
    #[error("`{command}` failed: {stderr}")]
    Command { command: String, stderr: String },
    #[error(
        "the compute nodes cannot use {dir} (it must be on a filesystem every node sees): \
         {why}\nprobe job {job}, log {log}:\n{log_text}"
    )]
    Probe {
        dir: PathBuf,
        job: String,
        why: String,
        log: PathBuf,
        log_text: String,
    },
}

fn io_at(path: &Path) -> impl FnOnce(io::Error) -> SlurmError + '_ {
    move |source| SlurmError::Io {
        path: path.to_owned(),
        source,
    }
}

/// The full path of a Slurm tool found on PATH.
pub fn find_tool(tool: &'static str) -> Result<PathBuf, SlurmError> {
    let path = std::env::var_os("PATH").unwrap_or_default();
    std::env::split_paths(&path)
        .map(|dir| dir.join(tool))
        .find(|p| {
            p.metadata()
                .is_ok_and(|m| m.is_file() && m.permissions().mode() & 0o111 != 0)
        })
        .ok_or_else(|| SlurmError::ToolMissing {
            tool,
            path: if path.is_empty() {
                "empty".into()
            } else {
                path.to_string_lossy().into_owned()
            },
        })
}

/// Runs a Slurm tool; its stdout on success, a [`SlurmError::Command`] with its stderr if not.
fn run_tool(tool: &'static str, args: &[&OsStr]) -> Result<String, SlurmError> {
    let exe = find_tool(tool)?;
    let command = || {
        let mut s = tool.to_owned();
        for a in args {
            s.push(' ');
            s.push_str(&a.to_string_lossy());
        }
        s
    };
    let out = Command::new(&exe)
        .args(args)
        .output()
        .map_err(|e| SlurmError::Command {
            command: command(),
            stderr: e.to_string(),
        })?;
    if !out.status.success() {
        return Err(SlurmError::Command {
            command: command(),
            stderr: String::from_utf8_lossy(&out.stderr).trim().to_owned(),
        });
    }
    Ok(String::from_utf8_lossy(&out.stdout).into_owned())
}

/// Checks, before anything is submitted, that the Slurm tools are on PATH and the controller
/// answers (`sinfo`).
pub fn preflight() -> Result<(), SlurmError> {
    for tool in ["sbatch", "squeue", "sinfo", "scontrol"] {
        find_tool(tool)?;
    }
    match run_tool("sinfo", &["-h".as_ref(), "-o".as_ref(), "%P".as_ref()]) {
        Ok(_) => Ok(()),
        Err(SlurmError::Command { command, stderr }) => {
            Err(SlurmError::ControllerDown { command, stderr })
        }
        Err(e) => Err(e),
    }
}

/// The wrapper every task runs (see the module doc). `$1` is the state folder, `$2` the task
/// index for a single (non-array) job.
const TASK_SCRIPT: &str = r#"#!/bin/bash
# Written by texsyn (src/ops/slurm.rs): runs one task of a state folder and records how it ended.
# Usage (by sbatch): task.sh STATE_DIR [INDEX]; an array task takes its index from
# SLURM_ARRAY_TASK_ID.
state="$1"
index="${SLURM_ARRAY_TASK_ID:-$2}"
if [ -n "${SLURM_ARRAY_JOB_ID:-}" ]; then job="${SLURM_ARRAY_JOB_ID}_${SLURM_ARRAY_TASK_ID}"; else job="$SLURM_JOB_ID"; fi
argv="$state/tasks/$index.argv"
if ! mapfile -d '' -t args < "$argv"; then
    echo "texsyn-slurm: task $index (job $job) on $(hostname): cannot read $argv; is $state on a filesystem this node sees?" >&2
    exit 120
fi
echo "texsyn-slurm: task $index (job $job) on $(hostname): ${args[*]@Q}" >&2
"${args[@]}"
code=$?
echo "texsyn-slurm: task $index (job $job) exited with code $code" >&2
tmp="$state/exit/.$index.$job.tmp"
printf 'exit=%s\njob=%s\nhost=%s\n' "$code" "$job" "$(hostname)" > "$tmp" && mv -f "$tmp" "$state/exit/$index"
exit $code
"#;

/// squeue states in which a job has not ended yet (squeue(1), JOB STATE CODES).
const ACTIVE_STATES: &[&str] = &[
    "PENDING",
    "RUNNING",
    "CONFIGURING",
    "COMPLETING",
    "SUSPENDED",
    "REQUEUED",
    "REQUEUE_FED",
    "REQUEUE_HOLD",
    "RESIZING",
    "RESV_DEL_HOLD",
    "SIGNALING",
    "SPECIAL_EXIT",
    "STAGE_OUT",
    "STOPPED",
];

#[derive(Debug, Clone, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
enum SubmissionKind {
    Array,
    Single,
}

/// One `sbatch` call, as recorded in `submissions.json`.
#[derive(Debug, Clone, Serialize, Deserialize)]
struct Submission {
    kind: SubmissionKind,
    job_id: JobId,
    indices: Vec<usize>,
    /// Seconds since the Unix epoch.
    submitted: u64,
    depends_on: Option<JobId>,
}

impl Submission {
    /// The Slurm id of task `index` in this submission.
    fn task_job(&self, index: usize) -> String {
        match self.kind {
            SubmissionKind::Array => format!("{}_{index}", self.job_id),
            SubmissionKind::Single => self.job_id.0.clone(),
        }
    }
}

#[derive(Debug, Clone, Serialize, Deserialize)]
struct TaskList {
    names: Vec<String>,
}

const SUBMISSIONS: &str = "submissions.json";
const TASKS: &str = "tasks.json";
const SCRIPT: &str = "task.sh";

/// The state folder made absolute (sbatch's `--output` and the tasks need absolute paths).
fn absolute(state_dir: &Path) -> Result<PathBuf, SlurmError> {
    let dir = std::path::absolute(state_dir).map_err(io_at(state_dir))?;
    let s = dir.as_os_str().as_bytes();
    if s.contains(&b'%') || s.contains(&b'\n') || s.contains(&b'\\') {
        return Err(SlurmError::State {
            dir,
            why: "the path contains '%', '\\' or a newline, which sbatch's --output would \
                  read as a pattern; use another folder"
                .into(),
        });
    }
    Ok(dir)
}

fn log_path(dir: &Path, job_id: &JobId, index: usize) -> PathBuf {
    dir.join("logs").join(format!("{job_id}_{index}.log"))
}

fn read_json<T: for<'de> Deserialize<'de>>(
    dir: &Path,
    file: &str,
) -> Result<Option<T>, SlurmError> {
    let path = dir.join(file);
    match fs::read(&path) {
        Ok(bytes) => serde_json::from_slice(&bytes)
            .map(Some)
            .map_err(|e| SlurmError::State {
                dir: dir.to_owned(),
                why: format!("{file} cannot be read: {e}"),
            }),
        Err(e) if e.kind() == io::ErrorKind::NotFound => Ok(None),
        Err(e) => Err(io_at(&path)(e)),
    }
}

/// Writes a file whole or not at all (temporary file, fsync, rename).
fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), SlurmError> {
    let tmp = path.with_extension(format!("tmp.{}", std::process::id()));
    let mut f = File::create(&tmp).map_err(io_at(&tmp))?;
    f.write_all(bytes).map_err(io_at(&tmp))?;
    f.sync_all().map_err(io_at(&tmp))?;
    fs::rename(&tmp, path).map_err(io_at(path))
}

/// `0-3,5,7-9` from sorted, distinct indices.
fn array_spec(indices: &[usize]) -> String {
    let mut parts = Vec::new();
    let mut i = 0;
    while i < indices.len() {
        let mut j = i;
        while j + 1 < indices.len() && indices[j + 1] == indices[j] + 1 {
            j += 1;
        }
        parts.push(if i == j {
            indices[i].to_string()
        } else {
            format!("{}-{}", indices[i], indices[j])
        });
        i = j + 1;
    }
    parts.join(",")
}

fn unix_now() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map(|d| d.as_secs())
        .unwrap_or(0)
}

/// How one sbatch call is made.
struct Submit<'a> {
    kind: SubmissionKind,
    indices: Vec<usize>,
    opts: &'a SlurmOptions,
    depends_on: Option<&'a JobId>,
    /// Submit held (`--hold`); the caller releases it.
    hold: bool,
}

/// Submits `tasks[i]` for every `i` in `indices` as one Slurm job array and records the
/// submission in `state_dir` (created if missing). `tasks` is the whole task list (an index is
/// a position in it), so that later reports name every task, submitted or not. With
/// `depends_on`, the array starts only after that job (array) has completed successfully
/// (`--dependency=afterok`) and is cancelled if it fails (`--kill-on-invalid-dep=yes`).
///
/// Refused before anything is submitted: missing Slurm tools, a controller that does not
/// answer, bad options, an empty or out-of-range index list, an empty command, and an index
/// still pending or running from an earlier submission of this folder.
pub fn submit_array(
    state_dir: &Path,
    tasks: &[Task],
    indices: &[usize],
    opts: &SlurmOptions,
    depends_on: Option<&JobId>,
) -> Result<JobId, SlurmError> {
    let mut indices = indices.to_vec();
    indices.sort_unstable();
    indices.dedup();
    submit(
        state_dir,
        tasks,
        Submit {
            kind: SubmissionKind::Array,
            indices,
            opts,
            depends_on,
            hold: false,
        },
    )
}

/// Submits `tasks[index]` alone as an ordinary (non-array) job, e.g. the gather step after a
/// sharded array: with `depends_on = Some(array)` it runs only once every task of the array
/// succeeded, and is cancelled (reported lost, `CANCELLED`) if one failed.
pub fn submit_single(
    state_dir: &Path,
    tasks: &[Task],
    index: usize,
    opts: &SlurmOptions,
    depends_on: Option<&JobId>,
) -> Result<JobId, SlurmError> {
    submit(
        state_dir,
        tasks,
        Submit {
            kind: SubmissionKind::Single,
            indices: vec![index],
            opts,
            depends_on,
            hold: false,
        },
    )
}

fn submit(state_dir: &Path, tasks: &[Task], how: Submit<'_>) -> Result<JobId, SlurmError> {
    how.opts.check()?;
    preflight()?;
    let dir = absolute(state_dir)?;
    let bad = |index: usize, why: &str| SlurmError::BadTask {
        index,
        why: why.to_owned(),
    };
    if how.indices.is_empty() {
        return Err(SlurmError::State {
            dir,
            why: "nothing to submit (no task indices)".into(),
        });
    }
    for &i in &how.indices {
        let Some(task) = tasks.get(i) else {
            return Err(bad(
                i,
                &format!("no such task (the list has {})", tasks.len()),
            ));
        };
        if task.argv.is_empty() {
            return Err(bad(i, "empty command line"));
        }
        if task.argv.iter().any(|a| a.as_bytes().contains(&0)) {
            return Err(bad(i, "an argument contains a NUL byte"));
        }
    }
    for sub in ["tasks", "exit", "logs"] {
        fs::create_dir_all(dir.join(sub)).map_err(io_at(&dir.join(sub)))?;
    }
    // One submitting client at a time per folder.
    let lock_path = dir.join(".lock");
    let lock = File::create(&lock_path).map_err(io_at(&lock_path))?;
    lock.lock().map_err(io_at(&lock_path))?;

    // Never run a task twice at once: refuse indices still in the queue.
    let before = status(&dir)?;
    for &i in &how.indices {
        if let Some(TaskOutcome {
            status: TaskStatus::Active(state),
            job_id,
            ..
        }) = before.get(i)
        {
            return Err(SlurmError::StillActive {
                index: i,
                job: job_id.clone().unwrap_or_default(),
                state: state.to_lowercase(),
            });
        }
    }

    let list = TaskList {
        names: tasks.iter().map(|t| t.name.clone()).collect(),
    };
    write_atomic(
        &dir.join(TASKS),
        &serde_json::to_vec_pretty(&list).expect("task list serializes"),
    )?;
    for &i in &how.indices {
        let mut bytes = Vec::new();
        for a in &tasks[i].argv {
            bytes.extend_from_slice(a.as_bytes());
            bytes.push(0);
        }
        write_atomic(&dir.join("tasks").join(format!("{i}.argv")), &bytes)?;
        // A new submission's outcome must not be read from an earlier run's exit file.
        let exit = dir.join("exit").join(i.to_string());
        match fs::remove_file(&exit) {
            Ok(()) => {}
            Err(e) if e.kind() == io::ErrorKind::NotFound => {}
            Err(e) => return Err(io_at(&exit)(e)),
        }
    }
    let script = dir.join(SCRIPT);
    write_atomic(&script, TASK_SCRIPT.as_bytes())?;

    let cwd = std::env::current_dir().map_err(io_at(Path::new(".")))?;
    let name = format!(
        "texsyn-{}",
        dir.file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default()
    );
    let mut args: Vec<OsString> = vec!["--parsable".into(), format!("--job-name={name}").into(), {
        let mut s = OsString::from("--chdir=");
        s.push(&cwd);
        s
    }];
    let mut output = OsString::from("--output=");
    output.push(dir.join("logs"));
    match how.kind {
        SubmissionKind::Array => {
            args.push(format!("--array={}", array_spec(&how.indices)).into());
            output.push("/%A_%a.log");
        }
        SubmissionKind::Single => output.push(format!("/%j_{}.log", how.indices[0])),
    }
    args.push(output);
    args.extend(how.opts.sbatch_args().into_iter().map(OsString::from));
    if let Some(dep) = how.depends_on {
        args.push(format!("--dependency=afterok:{dep}").into());
        args.push("--kill-on-invalid-dep=yes".into());
    }
    if how.hold {
        args.push("--hold".into());
    }
    args.push(script.into_os_string());
    args.push(dir.clone().into_os_string());
    if how.kind == SubmissionKind::Single {
        args.push(how.indices[0].to_string().into());
    }
    let arg_refs: Vec<&OsStr> = args.iter().map(|a| a.as_os_str()).collect();
    let out = run_tool("sbatch", &arg_refs)?;
    let id = out.trim().split(';').next().unwrap_or("").trim().to_owned();
    if id.is_empty() || !id.bytes().all(|b| b.is_ascii_digit()) {
        return Err(SlurmError::Command {
            command: "sbatch --parsable".into(),
            stderr: format!("unexpected output {out:?} (expected a job id)"),
        });
    }
    let job_id = JobId(id);

    let mut subs: Vec<Submission> = read_json(&dir, SUBMISSIONS)?.unwrap_or_default();
    subs.push(Submission {
        kind: how.kind,
        job_id: job_id.clone(),
        indices: how.indices,
        submitted: unix_now(),
        depends_on: how.depends_on.cloned(),
    });
    write_atomic(
        &dir.join(SUBMISSIONS),
        &serde_json::to_vec_pretty(&subs).expect("submissions serialize"),
    )?;
    drop(lock);
    Ok(job_id)
}

/// squeue's state of every task of these jobs: Slurm task id (`12_3` or `12`) → state.
fn queue_states(jobs: &[&JobId]) -> Result<std::collections::HashMap<String, String>, SlurmError> {
    let mut states = std::collections::HashMap::new();
    if jobs.is_empty() {
        return Ok(states);
    }
    let list = jobs
        .iter()
        .map(|j| j.0.as_str())
        .collect::<Vec<_>>()
        .join(",");
    let args: [&OsStr; 8] = [
        "-h".as_ref(),
        "-r".as_ref(),
        "-t".as_ref(),
        "all".as_ref(),
        "-j".as_ref(),
        list.as_ref(),
        "-o".as_ref(),
        "%i|%T".as_ref(),
    ];
    match run_tool("squeue", &args) {
        Ok(out) => {
            for line in out.lines() {
                if let Some((id, state)) = line.trim().split_once('|') {
                    states.insert(id.to_owned(), state.to_owned());
                }
            }
            Ok(states)
        }
        // Every job named has been purged from the controller (MinJobAge): none is queued.
        Err(SlurmError::Command { stderr, .. }) if stderr.contains("Invalid job id") => Ok(states),
        Err(e) => Err(e),
    }
}

/// The exit code task `index` recorded for Slurm job `job`, if it did.
fn read_exit(dir: &Path, index: usize, job: &str) -> Option<i32> {
    let text = fs::read_to_string(dir.join("exit").join(index.to_string())).ok()?;
    let mut code = None;
    let mut matches = false;
    for line in text.lines() {
        if let Some(c) = line.strip_prefix("exit=") {
            code = c.trim().parse().ok();
        } else if let Some(j) = line.strip_prefix("job=") {
            matches = j.trim() == job;
        }
    }
    if matches { code } else { None }
}

/// Every task's state now, without waiting: one squeue call.
pub fn status(state_dir: &Path) -> Result<Vec<TaskOutcome>, SlurmError> {
    let dir = absolute(state_dir)?;
    let list: TaskList = read_json(&dir, TASKS)?.unwrap_or(TaskList { names: Vec::new() });
    let subs: Vec<Submission> = read_json(&dir, SUBMISSIONS)?.unwrap_or_default();
    // The latest submission of each index.
    let mut latest: Vec<Option<&Submission>> = vec![None; list.names.len()];
    for s in &subs {
        for &i in &s.indices {
            if i >= latest.len() {
                latest.resize(i + 1, None);
            }
            latest[i] = Some(s);
        }
    }
    let mut jobs: Vec<&JobId> = latest.iter().flatten().map(|s| &s.job_id).collect();
    jobs.sort_by(|a, b| a.0.cmp(&b.0));
    jobs.dedup();
    let queue = queue_states(&jobs)?;
    Ok(latest
        .iter()
        .enumerate()
        .map(|(index, sub)| {
            let name = list.names.get(index).cloned().unwrap_or_default();
            let Some(sub) = sub else {
                return TaskOutcome {
                    index,
                    name,
                    job_id: None,
                    status: TaskStatus::NotSubmitted,
                    log: None,
                };
            };
            let job = sub.task_job(index);
            let in_queue = queue.get(&job);
            let status = match read_exit(&dir, index, &job) {
                Some(code) => TaskStatus::Exited(code),
                None => match in_queue {
                    Some(s) if ACTIVE_STATES.contains(&s.as_str()) => TaskStatus::Active(s.clone()),
                    other => TaskStatus::Lost {
                        slurm_state: other.cloned(),
                    },
                },
            };
            TaskOutcome {
                index,
                name,
                log: Some(log_path(&dir, &sub.job_id, index)),
                job_id: Some(job),
                status,
            }
        })
        .collect())
}

/// How long a task that looks lost is given for its exit file to appear (NFS attribute
/// caches) before it is reported lost.
const LOST_GRACE: Duration = Duration::from_secs(3);
/// squeue failing this many polls in a row (the controller restarting, the network) ends the
/// wait with its error.
const MAX_POLL_FAILURES: u32 = 20;

/// Waits until no task of `state_dir` is pending or running, polling squeue every `poll`, and
/// returns every task's outcome (tasks never submitted included, as `NotSubmitted`). Any
/// process can call it, also after the client that submitted was killed: everything it needs is
/// in the folder and in Slurm.
pub fn attach(state_dir: &Path, poll: Duration) -> Result<Vec<TaskOutcome>, SlurmError> {
    attach_with(state_dir, poll, |_| {})
}

/// [`attach`], calling `progress` with every poll's snapshot (for a progress line).
pub fn attach_with(
    state_dir: &Path,
    poll: Duration,
    mut progress: impl FnMut(&[TaskOutcome]),
) -> Result<Vec<TaskOutcome>, SlurmError> {
    let dir = absolute(state_dir)?;
    if read_json::<Vec<Submission>>(&dir, SUBMISSIONS)?.is_none() {
        return Err(SlurmError::State {
            dir,
            why: format!("nothing was submitted from this folder (no {SUBMISSIONS})"),
        });
    }
    let mut failures = 0;
    let mut graced = false;
    loop {
        let snapshot = match status(&dir) {
            Ok(s) => {
                failures = 0;
                s
            }
            Err(e @ (SlurmError::Command { .. } | SlurmError::ToolMissing { .. })) => {
                failures += 1;
                if failures >= MAX_POLL_FAILURES {
                    return Err(e);
                }
                tracing::warn!("polling Slurm failed ({failures}/{MAX_POLL_FAILURES}): {e}");
                std::thread::sleep(poll);
                continue;
            }
            Err(e) => return Err(e),
        };
        progress(&snapshot);
        let active = snapshot
            .iter()
            .any(|t| matches!(t.status, TaskStatus::Active(_)));
        let lost = snapshot
            .iter()
            .any(|t| matches!(t.status, TaskStatus::Lost { .. }));
        if !active && (!lost || graced) {
            return Ok(snapshot);
        }
        if !active && lost {
            graced = true;
            std::thread::sleep(LOST_GRACE.max(poll));
        } else {
            std::thread::sleep(poll);
        }
    }
}

/// The tasks a rerun should submit: failed, lost, or never submitted, and not still in the
/// queue. One squeue call, no waiting.
pub fn to_resubmit(state_dir: &Path) -> Result<Vec<usize>, SlurmError> {
    Ok(status(state_dir)?
        .into_iter()
        .filter(|t| t.status.needs_rerun())
        .map(|t| t.index)
        .collect())
}

/// The cluster's `MaxArraySize` (`scontrol show config`): array task indices must be below
/// it. `None` when scontrol does not say.
pub fn max_array_size() -> Result<Option<usize>, SlurmError> {
    let out = run_tool("scontrol", &[OsStr::new("show"), OsStr::new("config")])?;
    Ok(out.lines().find_map(|l| {
        let (k, v) = l.split_once('=')?;
        (k.trim() == "MaxArraySize").then(|| v.trim().parse().ok())?
    }))
}

/// A random hex token (for the probe's marker): time, process id and a counter hashed.
fn random_token() -> String {
    use std::sync::atomic::{AtomicU64, Ordering};
    static COUNTER: AtomicU64 = AtomicU64::new(0);
    let nanos = SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map(|d| d.as_nanos())
        .unwrap_or(0);
    let mut h = blake3::Hasher::new();
    h.update(&nanos.to_le_bytes());
    h.update(&std::process::id().to_le_bytes());
    h.update(&COUNTER.fetch_add(1, Ordering::Relaxed).to_le_bytes());
    h.finalize().to_hex()[..24].to_owned()
}

/// The shell program the probe job runs: it reads the marker, compares it with the token it
/// was given, and writes the token back into the reply file.
const PROBE_SCRIPT: &str = r#"marker="$1"; token="$2"; reply="$3"
if ! seen="$(cat "$marker" 2>&1)"; then
    echo "texsyn probe: cannot read the marker $marker on $(hostname): $seen" >&2; exit 3
fi
if [ "$seen" != "$token" ]; then
    echo "texsyn probe: the marker $marker on $(hostname) holds '$seen', not '$token'" >&2; exit 4
fi
printf '%s\n' "$token" > "$reply" || exit 5
echo "texsyn probe: $(hostname) sees $marker"
"#;

/// Checks that the compute nodes see `dir` (the cache folder) as this machine does, before a
/// sweep is submitted: writes a random marker into `dir`, submits a one-task probe job (with
/// `opts`, so it lands where the sweep will) that reads the marker and writes it back, waits,
/// and compares. A clear error, with the probe's log, when the job cannot read the marker, sees
/// other contents, cannot write back, or fails. The probe's files live in
/// `dir/.texsyn-slurm-probe-<token>/` and are removed when the probe succeeds (kept for
/// inspection when it fails).
pub fn probe_shared_folder(dir: &Path, opts: &SlurmOptions) -> Result<(), SlurmError> {
    probe_shared_folder_with(dir, opts, |_| Ok(()))
}

/// [`probe_shared_folder`] with a hook: the probe job is submitted held (`sbatch --hold`),
/// `while_held` runs with the marker's path, then the job is released. Tests use the hook to
/// delete the marker, which is what a node that does not see `dir` experiences, without a
/// second machine and without a race against the job.
pub fn probe_shared_folder_with(
    dir: &Path,
    opts: &SlurmOptions,
    while_held: impl FnOnce(&Path) -> io::Result<()>,
) -> Result<(), SlurmError> {
    opts.check()?;
    preflight()?;
    let dir = absolute(dir)?;
    if !dir.is_dir() {
        return Err(SlurmError::State {
            dir,
            why: "the folder does not exist".into(),
        });
    }
    let token = random_token();
    let state = dir.join(format!(".texsyn-slurm-probe-{token}"));
    fs::create_dir(&state).map_err(io_at(&state))?;
    let marker = state.join("marker");
    let reply = state.join("reply");
    write_atomic(&marker, format!("{token}\n").as_bytes())?;
    let task = Task {
        argv: vec![
            "/bin/sh".into(),
            "-c".into(),
            PROBE_SCRIPT.into(),
            "texsyn-probe".into(),
            marker.clone().into(),
            token.clone().into(),
            reply.clone().into(),
        ],
        name: "shared-folder probe".into(),
    };
    let job = submit(
        &state,
        std::slice::from_ref(&task),
        Submit {
            kind: SubmissionKind::Single,
            indices: vec![0],
            opts,
            depends_on: None,
            hold: true,
        },
    )?;
    let released = while_held(&marker)
        .map_err(io_at(&marker))
        .and_then(|()| run_tool("scontrol", &["release".as_ref(), job.0.as_ref()]));
    if let Err(e) = released {
        let _ = run_tool("scancel", &[job.0.as_ref()]);
        return Err(e);
    }
    let outcome = attach(&state, Duration::from_millis(250))?
        .into_iter()
        .next()
        .expect("the probe's one task");
    let log = outcome.log.clone().unwrap_or_default();
    let fail = |why: String| {
        let log_text = match fs::read_to_string(&log) {
            Ok(t) if t.trim().is_empty() => "(empty)".to_owned(),
            Ok(t) => t.trim_end().to_owned(),
            Err(e) => format!(
                "(cannot be read here: {e}; the node could not write it into the folder either)"
            ),
        };
        SlurmError::Probe {
            dir: dir.clone(),
            job: job.0.clone(),
            why,
            log: log.clone(),
            log_text,
        }
    };
    match outcome.status {
        TaskStatus::Exited(0) => {}
        TaskStatus::Exited(3) => {
            return Err(fail(format!(
                "the probe job could not read the marker {}",
                marker.display()
            )));
        }
        TaskStatus::Exited(4) => {
            return Err(fail(format!(
                "the probe job read other contents from the marker {}",
                marker.display()
            )));
        }
        TaskStatus::Exited(code) => {
            return Err(fail(format!("the probe job failed with exit code {code}")));
        }
        TaskStatus::Lost { slurm_state } => {
            return Err(fail(format!(
                "the probe job ended without recording an exit status in the folder ({})",
                slurm_state.as_deref().unwrap_or("no longer in the queue")
            )));
        }
        TaskStatus::Active(_) | TaskStatus::NotSubmitted => unreachable!("attach waits"),
    }
    match fs::read_to_string(&reply) {
        Ok(t) if t.trim() == token => {}
        Ok(t) => {
            return Err(fail(format!(
                "the reply {} holds {:?}, not the token {token:?}",
                reply.display(),
                t.trim()
            )));
        }
        Err(e) => {
            return Err(fail(format!(
                "the job succeeded but its reply {} is not visible here ({e})",
                reply.display()
            )));
        }
    }
    fs::remove_dir_all(&state).map_err(io_at(&state))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn array_spec_compresses_runs() {
        assert_eq!(array_spec(&[0, 1, 2, 3]), "0-3");
        assert_eq!(array_spec(&[1, 3, 4, 5, 9]), "1,3-5,9");
        assert_eq!(array_spec(&[7]), "7");
    }

    #[test]
    fn options_deserialize_and_convert() {
        let o: SlurmOptions = toml::from_str(
            "partition = \"gpu\"\ntime = \"1-02:00:00\"\nmem = \"1.5G\"\ncpus_per_task = 4\naccount = \"lab\"",
        )
        .unwrap();
        assert_eq!(
            o.sbatch_args(),
            [
                "--partition=gpu",
                "--time=1-02:00:00",
                "--mem=1536M",
                "--cpus-per-task=4",
                "--account=lab"
            ]
        );
        let minutes: SlurmOptions = toml::from_str("time = 90\nmem = 1000").unwrap();
        // 1000 bytes round up to one whole MiB, never down to 0 (which means "all" to Slurm).
        assert_eq!(minutes.sbatch_args(), ["--time=90", "--mem=1M"]);
        assert!(SlurmOptions::default().sbatch_args().is_empty());
    }

    #[test]
    fn bad_options_are_refused_with_their_field() {
        for (text, field) in [
            ("partitions = \"x\"", "partitions"),
            ("time = \"2 hours\"", "time"),
            ("time = \"1:2:3:4\"", "time"),
            ("mem = \"lots\"", "mem"),
            ("mem = 0", "mem"),
        ] {
            let e = toml::from_str::<SlurmOptions>(text)
                .unwrap_err()
                .to_string();
            assert!(e.contains(field), "{text}: {e}");
        }
        let o = SlurmOptions {
            cpus_per_task: Some(0),
            ..Default::default()
        };
        assert!(o.check().unwrap_err().to_string().contains("cpus_per_task"));
        let o = SlurmOptions {
            partition: Some("a b".into()),
            ..Default::default()
        };
        assert!(o.check().unwrap_err().to_string().contains("partition"));
    }

    #[test]
    fn exit_file_of_another_job_is_ignored() {
        let dir = tempfile::tempdir().unwrap();
        fs::create_dir(dir.path().join("exit")).unwrap();
        fs::write(dir.path().join("exit/2"), "exit=7\njob=41_2\nhost=n1\n").unwrap();
        assert_eq!(read_exit(dir.path(), 2, "41_2"), Some(7));
        assert_eq!(read_exit(dir.path(), 2, "42_2"), None);
        assert_eq!(read_exit(dir.path(), 3, "41_3"), None);
    }
}

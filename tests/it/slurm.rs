//! The Slurm job-array layer (src/slurm.rs) against a real one-node cluster, started by
//! scripts/slurm-local once per test binary. Without the cluster these tests FAIL, naming why;
//! `TEXSYN_NO_SLURM=1` skips them loudly instead (for machines without root; CI never sets it).
//!
//! Child processes (a client to kill mid-wait, a client with PATH stripped) are this test
//! binary run again on the ignored test `child_helper`, with `TEXSYN_SLURM_CHILD` saying what
//! to do.

use std::ffi::OsString;
use std::fs;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};
use texsyn::ops::slurm::{self, SlurmError, SlurmOptions, Task, TaskStatus};

use crate::common;
use common::cluster::cluster;

const POLL: Duration = Duration::from_millis(300);

fn sh(script: &str, args: &[&str]) -> Vec<OsString> {
    let mut argv: Vec<OsString> = vec!["/bin/sh".into(), "-c".into(), script.into(), "sh".into()];
    argv.extend(args.iter().map(OsString::from));
    argv
}

fn task(name: &str, argv: Vec<OsString>) -> Task {
    Task {
        argv,
        name: name.into(),
    }
}

/// A one-minute time limit, so a broken test cannot hold the cluster.
fn opts() -> SlurmOptions {
    SlurmOptions {
        time: Some("2".into()),
        mem: Some(64 << 20),
        ..Default::default()
    }
}

/// A folder on the local disk the daemons (root) can reach.
fn state_dir() -> tempfile::TempDir {
    tempfile::Builder::new()
        .prefix("texsyn-slurm-test-")
        .tempdir()
        .unwrap()
}

#[test]
fn array_of_four_runs_each_command_and_reports_exit_codes_and_logs() {
    if !cluster("array_of_four") {
        return;
    }
    let dir = state_dir();
    let state = dir.path().join("state");
    let codes = [0, 3, 0, 5];
    // An argument with spaces and quotes must reach the command unchanged.
    let odd = "a b 'c' \"d\" $HOME";
    let tasks: Vec<Task> = codes
        .iter()
        .enumerate()
        .map(|(i, code)| {
            task(
                &format!("t{i}"),
                sh(
                    r#"printf 'out-%s<%s>\n' "$1" "$2"; exit "$3""#,
                    &[&i.to_string(), odd, &code.to_string()],
                ),
            )
        })
        .collect();
    let job = slurm::submit_array(&state, &tasks, &[0, 1, 2, 3], &opts(), None).unwrap();
    let outcomes = slurm::attach(&state, POLL).unwrap();
    assert_eq!(outcomes.len(), 4);
    for (i, o) in outcomes.iter().enumerate() {
        assert_eq!(o.index, i);
        assert_eq!(o.name, format!("t{i}"));
        assert_eq!(o.status, TaskStatus::Exited(codes[i]), "{o}");
        assert_eq!(o.job_id.as_deref(), Some(format!("{job}_{i}").as_str()));
        let log = o.log.as_ref().unwrap();
        assert_eq!(log, &state.join(format!("logs/{job}_{i}.log")));
        let text = fs::read_to_string(log).unwrap();
        assert!(text.contains(&format!("out-{i}<{odd}>\n")), "{text}");
    }
    // Only the failed ones are rerun candidates.
    assert_eq!(slurm::to_resubmit(&state).unwrap(), [1, 3]);
}

#[test]
fn failed_task_is_named_with_job_and_log_and_rerun_submits_only_it() {
    if !cluster("failed_task_rerun") {
        return;
    }
    let dir = state_dir();
    let state = dir.path().join("state");
    let flag = dir.path().join("fixed");
    let runs = dir.path().join("runs");
    fs::create_dir(&runs).unwrap();
    // Task 1 fails until the flag exists; every run of every task leaves a line in runs/<i>.
    let script = r#"echo run >> "$1/$2"; if [ "$2" = 1 ] && [ ! -e "$3" ]; then echo "task 1 breaks" >&2; exit 7; fi"#;
    let tasks: Vec<Task> = (0..4)
        .map(|i| {
            task(
                &format!("point-{i}"),
                sh(
                    script,
                    &[
                        runs.to_str().unwrap(),
                        &i.to_string(),
                        flag.to_str().unwrap(),
                    ],
                ),
            )
        })
        .collect();
    // Task 3 is left out: it counts as missing.
    let first = slurm::submit_array(&state, &tasks, &[0, 1, 2], &opts(), None).unwrap();
    let outcomes = slurm::attach(&state, POLL).unwrap();
    assert_eq!(outcomes[1].status, TaskStatus::Exited(7));
    assert_eq!(outcomes[3].status, TaskStatus::NotSubmitted);
    let report = outcomes[1].to_string();
    let log = state.join(format!("logs/{first}_1.log"));
    assert!(report.contains(&format!("{first}_1")), "{report}");
    assert!(report.contains(&log.display().to_string()), "{report}");
    assert!(report.contains("exit code 7"), "{report}");
    assert!(fs::read_to_string(&log).unwrap().contains("task 1 breaks"));

    let rerun = slurm::to_resubmit(&state).unwrap();
    assert_eq!(rerun, [1, 3]);
    fs::write(&flag, "").unwrap();
    let second = slurm::submit_array(&state, &tasks, &rerun, &opts(), None).unwrap();
    assert_ne!(first, second);
    let outcomes = slurm::attach(&state, POLL).unwrap();
    for o in &outcomes {
        assert!(o.status.succeeded(), "{o}");
    }
    // Tasks 0 and 2 keep their first job; 1 and 3 come from the rerun.
    let jobs: Vec<_> = outcomes.iter().map(|o| o.job_id.clone().unwrap()).collect();
    assert_eq!(
        jobs,
        [
            format!("{first}_0"),
            format!("{second}_1"),
            format!("{first}_2"),
            format!("{second}_3")
        ]
    );
    let count = |i: usize| {
        fs::read_to_string(runs.join(i.to_string()))
            .map(|t| t.lines().count())
            .unwrap_or(0)
    };
    assert_eq!([count(0), count(1), count(2), count(3)], [1, 2, 1, 1]);
    assert!(slurm::to_resubmit(&state).unwrap().is_empty());
    // The first run's failure log stays next to the rerun's.
    assert!(log.exists());
}

#[test]
fn gather_job_runs_after_the_array_and_is_cancelled_when_it_fails() {
    if !cluster("gather") {
        return;
    }
    let dir = state_dir();
    let out = dir.path().join("out");
    fs::create_dir(&out).unwrap();
    let o = out.to_str().unwrap();
    let make = |fail: &str| -> Vec<Task> {
        let mut tasks: Vec<Task> = (0..3)
            .map(|i| {
                task(
                    &format!("shard-{i}"),
                    sh(
                        r#"sleep 1; [ "$2" = "$3" ] && exit 9; echo "$2" > "$1/$2""#,
                        &[o, &i.to_string(), fail],
                    ),
                )
            })
            .collect();
        tasks.push(task(
            "gather",
            sh(r#"cat "$1/0" "$1/1" "$1/2" > "$1/gathered""#, &[o]),
        ));
        tasks
    };
    let state = dir.path().join("ok");
    let tasks = make("none");
    let array = slurm::submit_array(&state, &tasks, &[0, 1, 2], &opts(), None).unwrap();
    let gather = slurm::submit_single(&state, &tasks, 3, &opts(), Some(&array)).unwrap();
    let outcomes = slurm::attach(&state, POLL).unwrap();
    assert!(
        outcomes.iter().all(|o| o.status.succeeded()),
        "{outcomes:?}"
    );
    assert_eq!(outcomes[3].job_id.as_deref(), Some(gather.0.as_str()));
    // The gather saw every shard's file: it ran after them.
    assert_eq!(
        fs::read_to_string(out.join("gathered")).unwrap(),
        "0\n1\n2\n"
    );

    let state = dir.path().join("failing");
    fs::remove_file(out.join("gathered")).unwrap();
    let tasks = make("1");
    let array = slurm::submit_array(&state, &tasks, &[0, 1, 2], &opts(), None).unwrap();
    slurm::submit_single(&state, &tasks, 3, &opts(), Some(&array)).unwrap();
    let outcomes = slurm::attach(&state, POLL).unwrap();
    assert_eq!(outcomes[1].status, TaskStatus::Exited(9));
    assert!(
        matches!(outcomes[3].status, TaskStatus::Lost { .. }),
        "{}",
        outcomes[3]
    );
    assert!(!out.join("gathered").exists());
    assert_eq!(slurm::to_resubmit(&state).unwrap(), [1, 3]);
}

#[test]
fn task_killed_by_slurm_is_reported_lost_and_never_submitted_twice_while_queued() {
    if !cluster("killed_task") {
        return;
    }
    let dir = state_dir();
    let state = dir.path().join("state");
    let tasks = [task("sleeper", sh("sleep 100", &[]))];
    let job = slurm::submit_array(&state, &tasks, &[0], &opts(), None).unwrap();
    let start = Instant::now();
    while !matches!(&slurm::status(&state).unwrap()[0].status, TaskStatus::Active(s) if s == "RUNNING")
    {
        assert!(start.elapsed() < Duration::from_secs(120), "never ran");
        std::thread::sleep(Duration::from_millis(100));
    }
    // A second submission of a running task is refused, naming it.
    let err = slurm::submit_array(&state, &tasks, &[0], &opts(), None).unwrap_err();
    assert!(
        matches!(err, SlurmError::StillActive { index: 0, .. }),
        "{err}"
    );
    let out = Command::new("scancel")
        .arg(format!("{job}_0"))
        .output()
        .unwrap();
    assert!(out.status.success(), "{out:?}");
    let outcomes = slurm::attach(&state, POLL).unwrap();
    // No exit status: the command never ended on its own. squeue still has the job's state.
    assert_eq!(
        outcomes[0].status,
        TaskStatus::Lost {
            slurm_state: Some("CANCELLED".into())
        },
        "{}",
        outcomes[0]
    );
    assert!(outcomes[0].to_string().contains("killed"));
    assert_eq!(slurm::to_resubmit(&state).unwrap(), [0]);
}

/// Runs this test binary again as a child doing `what` (see `child_helper`).
fn child(what: &str, state: &Path) -> Command {
    let mut c = Command::new(std::env::current_exe().unwrap());
    c.args(["slurm::child_helper", "--exact", "--ignored", "--nocapture"])
        .env("TEXSYN_SLURM_CHILD", what)
        .env("TEXSYN_SLURM_CHILD_STATE", state);
    c
}

/// Not a test: the body of the child processes above. Does nothing when run by hand.
#[test]
#[ignore]
fn child_helper() {
    let Some(what) = std::env::var_os("TEXSYN_SLURM_CHILD") else {
        return;
    };
    let state = PathBuf::from(std::env::var_os("TEXSYN_SLURM_CHILD_STATE").unwrap());
    match what.to_str().unwrap() {
        // Two tasks that wait for a `go` file beside the state folder; submit, then wait.
        "submit-and-wait" => {
            let go = state.with_extension("go");
            let tasks: Vec<Task> = (0..2)
                .map(|i| {
                    task(
                        &format!("waiter-{i}"),
                        sh(
                            r#"n=0; while [ ! -e "$1" ] && [ $n -lt 500 ]; do sleep 0.2; n=$((n+1)); done; [ -e "$1" ] && echo "waiter $2 done""#,
                            &[go.to_str().unwrap(), &i.to_string()],
                        ),
                    )
                })
                .collect();
            let job = slurm::submit_array(&state, &tasks, &[0, 1], &opts(), None).unwrap();
            println!("SUBMITTED {job}");
            let outcomes = slurm::attach(&state, POLL).unwrap();
            println!("FINISHED {outcomes:?}");
        }
        "submit" => {
            let tasks = [task("t", sh("true", &[]))];
            match slurm::submit_array(&state, &tasks, &[0], &opts(), None) {
                Ok(job) => println!("SUBMITTED {job}"),
                Err(e) => {
                    eprintln!("ERROR: {e}");
                    std::process::exit(3);
                }
            }
        }
        other => panic!("unknown child mode {other}"),
    }
}

#[test]
fn client_killed_mid_wait_is_reattached_and_finishes() {
    if !cluster("killed_client") {
        return;
    }
    let dir = state_dir();
    let state = dir.path().join("sweep");
    let go = state.with_extension("go");
    let mut client = child("submit-and-wait", &state)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // Wait until the client has submitted and both tasks are in the queue, unfinished.
    let start = Instant::now();
    loop {
        if let Ok(s) = slurm::status(&state)
            && s.len() == 2
            && s.iter().all(|t| matches!(t.status, TaskStatus::Active(_)))
        {
            break;
        }
        if let Some(exit) = client.try_wait().unwrap() {
            let out = client.wait_with_output().unwrap();
            panic!(
                "the client ended ({exit}) before its tasks were queued:\n{}{}",
                String::from_utf8_lossy(&out.stdout),
                String::from_utf8_lossy(&out.stderr)
            );
        }
        assert!(
            start.elapsed() < Duration::from_secs(120),
            "the tasks never showed as queued"
        );
        std::thread::sleep(Duration::from_millis(100));
    }
    client.kill().unwrap();
    let out = client.wait_with_output().unwrap();
    assert!(!out.status.success());
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(stdout.contains("SUBMITTED"), "{stdout}");
    assert!(!stdout.contains("FINISHED"), "{stdout}");
    // The tasks outlive their client; a new process (this one) attaches and finishes the wait.
    assert!(
        slurm::status(&state)
            .unwrap()
            .iter()
            .all(|t| !t.status.needs_rerun())
    );
    fs::write(&go, "").unwrap();
    let outcomes = slurm::attach(&state, POLL).unwrap();
    for o in &outcomes {
        assert_eq!(o.status, TaskStatus::Exited(0), "{o}");
        let log = fs::read_to_string(o.log.as_ref().unwrap()).unwrap();
        assert!(log.contains(&format!("waiter {} done", o.index)), "{log}");
    }
}

#[test]
fn probe_passes_on_a_folder_the_node_sees_and_leaves_nothing() {
    if !cluster("probe_ok") {
        return;
    }
    let dir = state_dir();
    slurm::probe_shared_folder(dir.path(), &opts()).unwrap();
    assert_eq!(fs::read_dir(dir.path()).unwrap().count(), 0);
}

#[test]
fn probe_that_cannot_read_the_marker_stops_with_the_jobs_log() {
    if !cluster("probe_fails") {
        return;
    }
    let dir = state_dir();
    let mut removed = None;
    // The hook runs while the probe job is held: deleting the marker is what a node that does
    // not see the folder experiences.
    let err = slurm::probe_shared_folder_with(dir.path(), &opts(), |marker| {
        removed = Some(marker.to_owned());
        fs::remove_file(marker)
    })
    .unwrap_err();
    let marker = removed.unwrap();
    let SlurmError::Probe { ref log, .. } = err else {
        panic!("not a probe error: {err}");
    };
    let msg = err.to_string();
    assert!(msg.contains("compute nodes cannot use"), "{msg}");
    assert!(msg.contains("could not read the marker"), "{msg}");
    assert!(msg.contains(&marker.display().to_string()), "{msg}");
    // The job's own log, quoted in the error, says what the node saw.
    assert!(
        msg.contains("texsyn probe: cannot read the marker"),
        "{msg}"
    );
    assert!(
        log.exists(),
        "the failed probe's log is kept: {}",
        log.display()
    );
}

#[test]
fn sbatch_missing_from_path_is_a_clear_error_before_submitting() {
    // Needs no cluster: the client must stop before it looks for one.
    let dir = state_dir();
    let state = dir.path().join("state");
    let out = child("submit", &state).env("PATH", "").output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(3), "{stderr}");
    assert!(
        stderr.contains("`sbatch` was not found on PATH"),
        "{stderr}"
    );
    assert!(stderr.contains("scripts/slurm-local"), "{stderr}");
    assert!(!state.exists(), "nothing may be written before the check");
}

#[test]
fn controller_not_responding_is_a_clear_error_before_submitting() {
    if !cluster("controller_down") {
        return;
    }
    let dir = state_dir();
    // The cluster's own configuration, with the controller moved to a port nobody listens on.
    let conf = fs::read_to_string("/etc/slurm/slurm.conf").unwrap();
    let conf: String = conf
        .lines()
        .filter(|l| !l.starts_with("SlurmctldHost") && !l.starts_with("SlurmctldPort"))
        .map(|l| format!("{l}\n"))
        .collect::<String>()
        + "SlurmctldHost=localhost\nSlurmctldPort=6899\n";
    let conf_path = dir.path().join("slurm.conf");
    fs::write(&conf_path, conf).unwrap();
    let state = dir.path().join("state");
    let out = child("submit", &state)
        .env("SLURM_CONF", &conf_path)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(3), "{stderr}");
    assert!(
        stderr.contains("the Slurm controller does not respond"),
        "{stderr}"
    );
    assert!(stderr.contains("sinfo"), "{stderr}");
    assert!(!state.exists(), "nothing may be written before the check");
}

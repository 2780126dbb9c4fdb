//! The memory budget: stages that allocate in proportion to a parameter (an image size, a
//! resolution, an atlas) estimate what they will need before they start and refuse, naming
//! the parameter and a value that fits, rather than dying in the allocator.
//!
//! The budget is `--max-memory` when given, else half of the memory actually available: the
//! smaller of `MemAvailable` and the cgroup's limit minus its usage (a container's or a Slurm
//! job's limit), so a run started inside a job respects the job's share. Half, because a node
//! works next to the artifacts it reads and the one it writes, and the estimates are within a
//! factor of two of the measured peaks.

use std::sync::atomic::{AtomicU64, Ordering};

/// 0 = not set: use the default.
static BUDGET: AtomicU64 = AtomicU64::new(0);

/// Sets the budget in bytes (`--max-memory`); 0 restores the default.
pub fn set_budget(bytes: u64) {
    BUDGET.store(bytes, Ordering::Relaxed);
}

/// The budget in bytes.
pub fn budget() -> u64 {
    match BUDGET.load(Ordering::Relaxed) {
        0 => available().map(|a| a / 2).unwrap_or(8 << 30),
        b => b,
    }
}

/// Memory available to this process, if the system says: the smaller of the kernel's
/// `MemAvailable` and the room left under the cgroup's limit (v2 `memory.max`, or v1
/// `memory.limit_in_bytes`).
pub fn available() -> Option<u64> {
    let meminfo = std::fs::read_to_string("/proc/meminfo").ok().and_then(|s| {
        s.lines()
            .find(|l| l.starts_with("MemAvailable:"))
            .and_then(|l| l.split_whitespace().nth(1))
            .and_then(|kb| kb.parse::<u64>().ok())
            .map(|kb| kb * 1024)
    });
    let read = |p: &str| {
        std::fs::read_to_string(p)
            .ok()
            .and_then(|s| s.trim().parse::<u64>().ok())
    };
    let cgroup = read("/sys/fs/cgroup/memory.max")
        .map(|max| max.saturating_sub(read("/sys/fs/cgroup/memory.current").unwrap_or(0)))
        .or_else(|| {
            read("/sys/fs/cgroup/memory/memory.limit_in_bytes")
                .filter(|&l| l < (1 << 60))
                .map(|l| {
                    l.saturating_sub(
                        read("/sys/fs/cgroup/memory/memory.usage_in_bytes").unwrap_or(0),
                    )
                })
        });
    match (meminfo, cgroup) {
        (Some(a), Some(b)) => Some(a.min(b)),
        (a, b) => a.or(b),
    }
}

/// A size in bytes for messages: "1.5 GiB".
pub fn human(bytes: u64) -> String {
    let units = ["B", "KiB", "MiB", "GiB", "TiB"];
    let mut x = bytes as f64;
    let mut u = 0;
    while x >= 1024.0 && u + 1 < units.len() {
        x /= 1024.0;
        u += 1;
    }
    if u == 0 {
        format!("{bytes} B")
    } else {
        format!("{x:.1} {}", units[u])
    }
}

/// A parameter whose value would need more memory than the budget.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error(
    "{key} = {value} would need about {need} of memory, over the budget of {budget} (--max-memory); {advice}",
    need = human(*need),
    budget = human(*budget)
)]
pub struct OverBudget {
    pub key: String,
    pub value: String,
    pub need: u64,
    pub budget: u64,
    /// What fits: `KEY = VALUE fits`, or, when no value does, that the budget must grow.
    pub advice: String,
}

/// Checks `estimate(value)` against the budget. If it is over, finds the largest value in
/// `1..value` whose estimate fits (by bisection: estimates grow with the value) and names it.
pub fn check_budget(
    key: &str,
    value: u64,
    estimate: impl Fn(u64) -> u64,
    show: impl Fn(u64) -> String,
) -> Result<(), OverBudget> {
    let budget = budget();
    let need = estimate(value);
    if need <= budget {
        return Ok(());
    }
    let (mut lo, mut hi) = (0u64, value);
    while hi - lo > 1 {
        let mid = lo + (hi - lo) / 2;
        if estimate(mid) <= budget {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    Err(OverBudget {
        key: key.to_owned(),
        value: show(value),
        need,
        budget,
        advice: if lo == 0 {
            format!("no value of {key} fits: raise --max-memory")
        } else {
            format!("{key} = {} fits", show(lo))
        },
    })
}

/// The largest peak seen before a [`reset_peak_resident`], so the process's own peak survives
/// the resets that measure one node's.
static PEAK_BEFORE_RESET: AtomicU64 = AtomicU64::new(0);

/// `VmHWM` of /proc/self/status (Linux), in bytes.
fn vm_hwm() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    status
        .lines()
        .find(|l| l.starts_with("VmHWM:"))
        .and_then(|l| l.split_whitespace().nth(1))
        .and_then(|kb| kb.parse::<u64>().ok())
        .map(|kb| kb * 1024)
}

/// This process's peak resident memory so far, if the system says (Linux).
pub fn peak_resident() -> Option<u64> {
    let before = PEAK_BEFORE_RESET.load(Ordering::Relaxed);
    vm_hwm().map(|now| now.max(before))
}

/// Starts measuring a new peak: [`peak_since_reset`] then gives the peak resident memory since
/// this call (the kernel's high-water mark is reset to the current size by writing 5 to
/// /proc/self/clear_refs, Linux 4.0+). False where that is not possible.
pub fn reset_peak_resident() -> bool {
    if let Some(p) = vm_hwm() {
        PEAK_BEFORE_RESET.fetch_max(p, Ordering::Relaxed);
    }
    std::fs::write("/proc/self/clear_refs", "5").is_ok()
}

/// The peak resident memory since the last [`reset_peak_resident`] that succeeded.
pub fn peak_since_reset() -> Option<u64> {
    vm_hwm()
}

/// User + system CPU seconds of this process, all threads (`/proc/self/stat`, Linux; in clock
/// ticks of 1/100 s, the USER_HZ of every Linux architecture). None elsewhere.
pub fn process_cpu_seconds() -> Option<f64> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    // Fields after the command name (in parentheses, which may hold spaces): state is the
    // first, utime the 12th, stime the 13th.
    let rest = &stat[stat.rfind(')')? + 1..];
    let mut f = rest.split_whitespace().skip(11);
    let utime: u64 = f.next()?.parse().ok()?;
    let stime: u64 = f.next()?.parse().ok()?;
    Some((utime + stime) as f64 / 100.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn over_budget_names_the_key_and_a_value_that_fits() {
        set_budget(1 << 20);
        let e = check_budget("synthesize.width", 4096, |w| w * w, |w| w.to_string()).unwrap_err();
        assert_eq!(e.advice, "synthesize.width = 1024 fits");
        let msg = e.to_string();
        assert!(
            msg.contains("synthesize.width = 4096") && msg.contains("16.0 MiB"),
            "{msg}"
        );
        assert!(check_budget("k", 1024, |w| w * w, |w| w.to_string()).is_ok());
        // Under a budget nothing fits, the message says what to change instead of a value.
        let e = check_budget("k", 8, |w| (1 << 21) + w, |w| w.to_string()).unwrap_err();
        let msg = e.to_string();
        assert!(
            msg.ends_with("no value of k fits: raise --max-memory")
                && !msg.contains("k = no value"),
            "{msg}"
        );
        set_budget(0);
        assert!(budget() > 0);
        assert_eq!(human(1536), "1.5 KiB");
    }
}

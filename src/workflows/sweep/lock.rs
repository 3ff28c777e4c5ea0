//! One process at a time in a sweep's output folder.
//!
//! `sweep` and `merge` rewrite `results.csv` from the rows they know when they finish, so
//! two of them in one folder lose each other's rows. Each takes `DIR/.bsdfit.lock` first:
//! created atomically (`create_new`), holding the owner's pid, host name and start time,
//! and removed when the owner ends (on errors too: [`DirLock`] removes it on drop). A lock
//! left by a process that no longer runs on this host (killed, power cut) is taken over
//! with a notice; a lock from another host (a shared file system) cannot be checked, so
//! the error says how to remove it.

use anyhow::Result;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::{Duration, SystemTime, UNIX_EPOCH};

/// The lock file's name inside the folder.
pub const LOCK_FILE: &str = ".bsdfit.lock";

/// Who holds a lock, as written in the lock file.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Holder {
    pub pid: u32,
    pub host: String,
    /// Unix time (s) the holder took the lock.
    pub started: u64,
    /// The command that holds it (`sweep`, `merge`).
    pub command: String,
    /// Unique per acquisition, so a holder removes only its own lock.
    pub token: String,
    /// Start time of the process (Linux: clock ticks since boot), to tell a reused pid.
    pub proc_start: Option<u64>,
    /// The Slurm job of the holder (`SLURM_JOB_ID`), so that a task on another node can
    /// ask Slurm whether it still runs.
    pub slurm_job: Option<String>,
}

impl Holder {
    fn me(command: &str) -> Holder {
        let now = SystemTime::now()
            .duration_since(UNIX_EPOCH)
            .unwrap_or_default();
        let pid = std::process::id();
        Holder {
            pid,
            host: host_name(),
            started: now.as_secs(),
            command: command.to_string(),
            token: format!("{pid}-{}", now.as_nanos()),
            proc_start: process_start(pid),
            slurm_job: std::env::var("SLURM_JOB_ID")
                .ok()
                .filter(|j| !j.trim().is_empty()),
        }
    }

    fn to_text(&self) -> String {
        let mut s = format!(
            "# bsdfit lock: this folder is in use by the process below; removed when it ends\npid: {}\nhost: {}\nstarted: {} (unix {})\ncommand: {}\ntoken: {}\n",
            self.pid,
            self.host,
            iso_utc(self.started),
            self.started,
            self.command,
            self.token
        );
        if let Some(t) = self.proc_start {
            s += &format!("proc_start: {t}\n");
        }
        if let Some(j) = &self.slurm_job {
            s += &format!("slurm_job: {j}\n");
        }
        s
    }

    /// Parse a lock file; None if it says nothing usable (e.g. cut short while written).
    pub fn parse(text: &str) -> Option<Holder> {
        let mut h = Holder::default();
        let mut have_pid = false;
        for line in text.lines() {
            let Some((k, v)) = line.split_once(':') else {
                continue;
            };
            let v = v.trim();
            match k.trim() {
                "pid" => {
                    h.pid = v.parse().ok()?;
                    have_pid = true;
                }
                "host" => h.host = v.to_string(),
                "started" => {
                    h.started = v
                        .split("(unix ")
                        .nth(1)
                        .and_then(|x| x.trim_end_matches(')').trim().parse().ok())
                        .unwrap_or(0)
                }
                "command" => h.command = v.to_string(),
                "token" => h.token = v.to_string(),
                "proc_start" => h.proc_start = v.parse().ok(),
                "slurm_job" => h.slurm_job = Some(v.to_string()).filter(|j| !j.is_empty()),
                _ => {}
            }
        }
        have_pid.then_some(h)
    }

    /// "pid 123 on host foo (bsdfit sweep, started 2025-01-01T10:00:00Z)".
    pub fn describe(&self) -> String {
        format!(
            "pid {} on host {} ({}started {})",
            self.pid,
            if self.host.is_empty() {
                "?"
            } else {
                &self.host
            },
            if self.command.is_empty() {
                String::new()
            } else {
                format!("bsdfit {}, ", self.command)
            },
            if self.started > 0 {
                iso_utc(self.started)
            } else {
                "at an unknown time".into()
            }
        )
    }

    /// Is the holder still running? None when this host cannot tell (another host, and
    /// no Slurm job to ask about).
    fn alive(&self) -> Option<bool> {
        if self.host != host_name() {
            return self.slurm_job.as_deref().and_then(slurm_job_running);
        }
        let alive = process_exists(self.pid);
        if !alive {
            return Some(false);
        }
        // Same pid, but started at another time: the pid was reused, the holder is gone.
        match (self.proc_start, process_start(self.pid)) {
            (Some(a), Some(b)) if a != b => Some(false),
            _ => Some(true),
        }
    }
}

/// This machine's host name (`/proc/sys/kernel/hostname`, `/etc/hostname`, `$HOSTNAME`,
/// `hostname`), or `unknown-host`.
pub fn host_name() -> String {
    let from_file = |p: &str| {
        std::fs::read_to_string(p)
            .ok()
            .map(|s| s.trim().to_string())
            .filter(|s| !s.is_empty())
    };
    from_file("/proc/sys/kernel/hostname")
        .or_else(|| from_file("/etc/hostname"))
        .or_else(|| std::env::var("HOSTNAME").ok().filter(|s| !s.is_empty()))
        .or_else(|| {
            std::process::Command::new("hostname")
                .output()
                .ok()
                .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_string())
                .filter(|s| !s.is_empty())
        })
        .unwrap_or_else(|| "unknown-host".into())
}

/// Does Slurm still run (or hold) job `job`? None when `squeue` cannot say (not on a
/// cluster, or the controller is unreachable).
fn slurm_job_running(job: &str) -> Option<bool> {
    let out = std::process::Command::new("squeue")
        .args(["-h", "-j", job, "-o", "%T"])
        .output()
        .ok()?;
    if out.status.success() {
        // Ended jobs stay listed for a while (MinJobAge) in a final state.
        const ENDED: [&str; 10] = [
            "COMPLETED",
            "FAILED",
            "CANCELLED",
            "TIMEOUT",
            "NODE_FAIL",
            "PREEMPTED",
            "OUT_OF_MEMORY",
            "BOOT_FAIL",
            "DEADLINE",
            "",
        ];
        let text = String::from_utf8_lossy(&out.stdout);
        Some(text.lines().any(|l| !ENDED.contains(&l.trim())))
    } else if String::from_utf8_lossy(&out.stderr).contains("Invalid job id") {
        Some(false)
    } else {
        None
    }
}

/// Does a process with this pid exist on this host?
fn process_exists(pid: u32) -> bool {
    if pid == std::process::id() {
        return true;
    }
    if Path::new("/proc/self").exists() {
        return Path::new(&format!("/proc/{pid}")).exists();
    }
    #[cfg(unix)]
    {
        // `kill -0` tests for existence without sending anything.
        std::process::Command::new("kill")
            .args(["-0", &pid.to_string()])
            .stderr(std::process::Stdio::null())
            .status()
            .map(|s| s.success())
            .unwrap_or(true)
    }
    #[cfg(not(unix))]
    {
        true // cannot tell: treat as running (the error says how to remove the lock)
    }
}

/// Start time of a process (Linux: field 22 of /proc/PID/stat, ticks since boot).
fn process_start(pid: u32) -> Option<u64> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    // The command name (field 2) is in parentheses and may hold spaces.
    let rest = &stat[stat.rfind(')')? + 1..];
    rest.split_whitespace().nth(19)?.parse().ok()
}

/// Unix seconds as an ISO 8601 UTC time.
pub fn iso_utc(secs: u64) -> String {
    let days = (secs / 86_400) as i64;
    let s = secs % 86_400;
    // Civil date from days since 1970-01-01 (H. Hinnant's algorithm).
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z.rem_euclid(146_097);
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = yoe + era * 400 + i64::from(m <= 2);
    format!(
        "{y:04}-{m:02}-{d:02}T{:02}:{:02}:{:02}Z",
        s / 3600,
        (s / 60) % 60,
        s % 60
    )
}

/// The lock on an output folder, held while this value lives.
#[derive(Debug)]
pub struct DirLock {
    path: PathBuf,
    token: String,
}

/// Why a lock could not be taken.
enum Attempt {
    Taken(DirLock),
    Held(Option<Holder>),
}

fn try_create(path: &Path, me: &Holder) -> std::io::Result<Attempt> {
    match std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .open(path)
    {
        Ok(mut f) => {
            let written = f.write_all(me.to_text().as_bytes()).and_then(|_| f.flush());
            if let Err(e) = written {
                let _ = std::fs::remove_file(path);
                return Err(e);
            }
            drop(f);
            // Exclusive creation is atomic on local file systems, NFSv3+ and Lustre. Where
            // it is not, another process may have created the same file at the same time:
            // read it back, and fail loudly rather than share the folder silently.
            let back = std::fs::read_to_string(path).unwrap_or_default();
            if Holder::parse(&back).map(|h| h.token) != Some(me.token.clone()) {
                return Err(std::io::Error::other(format!(
                    "the lock file was changed by another process right after this one created it exclusively: this file system does not make exclusive creation atomic (e.g. NFS v2), so it cannot hold the lock; use a folder on a local, NFSv3+ or Lustre file system ({})",
                    Holder::parse(&back).map(|h| h.describe()).unwrap_or_else(|| "unreadable".into())
                )));
            }
            Ok(Attempt::Taken(DirLock {
                path: path.to_path_buf(),
                token: me.token.clone(),
            }))
        }
        Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {
            let text = std::fs::read_to_string(path).unwrap_or_default();
            Ok(Attempt::Held(Holder::parse(&text)))
        }
        Err(e) => Err(e),
    }
}

impl DirLock {
    /// Take the lock on `dir` (which must exist) for `command`. Another live process
    /// holding it is an error naming it; a stale lock of this host is taken over (with a
    /// notice); a lock of another host is an error that says how to remove it.
    pub fn acquire(dir: &Path, command: &str, notice: &mut dyn FnMut(String)) -> Result<DirLock> {
        let path = dir.join(LOCK_FILE);
        let me = Holder::me(command);
        let io_err = |e: std::io::Error| {
            anyhow::anyhow!("cannot create the lock file {}: {e}", path.display())
        };
        for attempt in 0..50 {
            let held = match try_create(&path, &me).map_err(io_err)? {
                Attempt::Taken(l) => return Ok(l),
                Attempt::Held(h) => h,
            };
            let Some(holder) = held else {
                // Unreadable or being written right now: give the writer a moment, then
                // treat a lock that stays unreadable as stale.
                if attempt < 10 {
                    std::thread::sleep(Duration::from_millis(50));
                    continue;
                }
                notice(format!(
                    "{} is unreadable; taking it over (remove it by hand if another bsdfit uses {})",
                    path.display(),
                    dir.display()
                ));
                take_over(&path, None)?;
                continue;
            };
            match holder.alive() {
                Some(true) => anyhow::bail!(
                    "{} is in use by another bsdfit: {} holds {}. Wait for it to finish; \
                     sweeps meant to run at the same time (e.g. --shard 1/2 and 2/2) write to \
                     their own --out folders, and `bsdfit merge` combines them",
                    dir.display(),
                    holder.describe(),
                    path.display()
                ),
                None => anyhow::bail!(
                    "{} is locked by {}, on another host than this one ({}), so bsdfit cannot \
                     tell whether it still runs. If it does not, remove the lock and run again: \
                     rm {}",
                    dir.display(),
                    holder.describe(),
                    host_name(),
                    path.display()
                ),
                Some(false) => {
                    if take_over(&path, Some(&holder))? {
                        notice(format!(
                            "{}: taking over a stale lock of {} (that process no longer runs)",
                            dir.display(),
                            holder.describe()
                        ));
                    }
                }
            }
        }
        anyhow::bail!(
            "cannot take the lock {}: it keeps changing hands; is another bsdfit starting in {}?",
            path.display(),
            dir.display()
        )
    }

    /// Who holds the lock on `dir`, if anyone (and whether it still runs, when knowable).
    pub fn holder(dir: &Path) -> Option<(Holder, Option<bool>)> {
        let text = std::fs::read_to_string(dir.join(LOCK_FILE)).ok()?;
        let h = Holder::parse(&text)?;
        let alive = h.alive();
        Some((h, alive))
    }

    pub fn path(&self) -> &Path {
        &self.path
    }
}

/// Remove a stale lock, if it is still the one judged stale (`seen`; None: whatever is
/// there). Serialised by a second lock file so two processes recovering the same stale
/// lock cannot remove each other's new one. Ok(true) if this process removed it.
fn take_over(path: &Path, seen: Option<&Holder>) -> Result<bool> {
    let guard = path.with_extension("lock.takeover");
    let got = std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .open(&guard);
    match got {
        Ok(_) => {}
        Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {
            // Another process is recovering the lock; a guard older than 10 s was left by
            // a process that died while doing so.
            let old = std::fs::metadata(&guard)
                .and_then(|m| m.modified())
                .ok()
                .and_then(|t| t.elapsed().ok())
                .is_some_and(|age| age > Duration::from_secs(10));
            if old {
                let _ = std::fs::remove_file(&guard);
            } else {
                std::thread::sleep(Duration::from_millis(50));
            }
            return Ok(false);
        }
        Err(e) => anyhow::bail!("cannot create {}: {e}", guard.display()),
    }
    let now = std::fs::read_to_string(path)
        .ok()
        .and_then(|t| Holder::parse(&t));
    let same = match (seen, &now) {
        (Some(a), Some(b)) => a == b,
        (None, None) => path.exists(),
        _ => false,
    };
    let result = if same {
        std::fs::remove_file(path)
            .map(|_| true)
            .or_else(|e| {
                if e.kind() == std::io::ErrorKind::NotFound {
                    Ok(false)
                } else {
                    Err(e)
                }
            })
            .map_err(|e| anyhow::anyhow!("cannot remove the stale lock {}: {e}", path.display()))
    } else {
        Ok(false)
    };
    let _ = std::fs::remove_file(&guard);
    result
}

impl Drop for DirLock {
    fn drop(&mut self) {
        // Remove the lock only if it is still ours.
        let ours = std::fs::read_to_string(&self.path)
            .ok()
            .and_then(|t| Holder::parse(&t))
            .is_some_and(|h| h.token == self.token);
        if ours {
            let _ = std::fs::remove_file(&self.path);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lock_round_trip_and_release() {
        let d = tempfile::tempdir().unwrap();
        let l = DirLock::acquire(d.path(), "sweep", &mut |m| panic!("{m}")).unwrap();
        let (h, alive) = DirLock::holder(d.path()).unwrap();
        assert_eq!(h.pid, std::process::id());
        assert_eq!(h.command, "sweep");
        assert_eq!(alive, Some(true));
        // A second taker in the same (live) process is refused, naming the pid.
        let e = DirLock::acquire(d.path(), "merge", &mut |_| {}).unwrap_err();
        assert!(
            format!("{e}").contains(&format!("pid {}", std::process::id())),
            "{e}"
        );
        drop(l);
        assert!(!d.path().join(LOCK_FILE).exists());
    }

    #[test]
    fn stale_and_foreign_locks() {
        let d = tempfile::tempdir().unwrap();
        let stale = Holder {
            pid: 999_999_999,
            host: host_name(),
            started: 1,
            command: "sweep".into(),
            token: "x".into(),
            proc_start: None,
            slurm_job: Some("4242".into()),
        };
        // The Slurm job survives the file, so another node can ask Slurm about it.
        assert_eq!(Holder::parse(&stale.to_text()), Some(stale.clone()));
        std::fs::write(d.path().join(LOCK_FILE), stale.to_text()).unwrap();
        let mut notes = Vec::new();
        let l = DirLock::acquire(d.path(), "sweep", &mut |m| notes.push(m)).unwrap();
        assert!(notes.iter().any(|n| n.contains("stale")), "{notes:?}");
        drop(l);
        let foreign = Holder {
            host: "elsewhere.example".into(),
            // Without a Slurm job nothing can tell whether it still runs.
            slurm_job: None,
            ..stale
        };
        std::fs::write(d.path().join(LOCK_FILE), foreign.to_text()).unwrap();
        let e = format!(
            "{}",
            DirLock::acquire(d.path(), "sweep", &mut |_| {}).unwrap_err()
        );
        assert!(e.contains("elsewhere.example") && e.contains("rm "), "{e}");
        assert!(
            d.path().join(LOCK_FILE).exists(),
            "a foreign lock is left alone"
        );
    }

    #[test]
    fn iso_dates() {
        assert_eq!(iso_utc(0), "1970-01-01T00:00:00Z");
        assert_eq!(iso_utc(951_782_400), "2000-02-29T00:00:00Z");
        assert_eq!(iso_utc(1_700_000_000), "2023-11-14T22:13:20Z");
    }
}

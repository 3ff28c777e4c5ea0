//! Progress of long commands (sweep, fit restarts, diagnose, bench) on stderr.
//!
//! On a terminal: an indicatif bar. Elsewhere (CI logs, `2> log`), where indicatif hides
//! its bar, one line every ~10 s, e.g. `sweep: 120/603 fits, 2m10s elapsed, ETA 8m`, so a
//! log shows the run is alive. `BSDFIT_PROGRESS_SECS` sets that interval (`0`: no lines).

use std::io::IsTerminal;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Condvar, Mutex};
use std::time::{Duration, Instant};

/// Seconds between progress lines when stderr is not a terminal.
pub const DEFAULT_INTERVAL_SECS: f64 = 10.0;

struct Shared {
    label: String,
    unit: String,
    total: AtomicU64,
    pos: AtomicU64,
    msg: Mutex<String>,
    start: Instant,
    stop: (Mutex<bool>, Condvar),
}

/// A progress report: a bar on a terminal, else periodic lines.
pub struct Progress {
    shared: Arc<Shared>,
    bar: Option<indicatif::ProgressBar>,
    ticker: Option<std::thread::JoinHandle<()>>,
}

/// "45s", "2m10s", "1h02m".
pub fn fmt_duration(d: Duration) -> String {
    let s = d.as_secs();
    if s < 60 {
        format!("{s}s")
    } else if s < 3600 {
        format!("{}m{:02}s", s / 60, s % 60)
    } else {
        format!("{}h{:02}m", s / 3600, (s / 60) % 60)
    }
}

impl Shared {
    fn line(&self) -> String {
        let (pos, total) = (
            self.pos.load(Ordering::Relaxed),
            self.total.load(Ordering::Relaxed),
        );
        let el = self.start.elapsed();
        let mut s = format!("{}: ", self.label);
        if total > 0 {
            s += &format!("{pos}/{total} {}, {} elapsed", self.unit, fmt_duration(el));
            if pos > 0 && pos < total {
                let eta = el.mul_f64((total - pos) as f64 / pos as f64);
                s += &format!(", ETA {}", fmt_duration(eta));
            }
        } else {
            s += &format!("{} elapsed", fmt_duration(el));
        }
        let msg = self.msg.lock().map(|m| m.clone()).unwrap_or_default();
        if !msg.is_empty() {
            s += &format!(" ({msg})");
        }
        s
    }
}

fn interval() -> Option<Duration> {
    let secs = match std::env::var("BSDFIT_PROGRESS_SECS") {
        Ok(v) => v.trim().parse::<f64>().unwrap_or(DEFAULT_INTERVAL_SECS),
        Err(_) => DEFAULT_INTERVAL_SECS,
    };
    (secs.is_finite() && secs > 0.0).then(|| Duration::from_secs_f64(secs.max(0.05)))
}

impl Progress {
    /// Progress of `total` steps counted in `unit` (e.g. "fits"); `total` 0: unknown.
    pub fn new(label: &str, total: u64, unit: &str) -> Progress {
        let shared = Arc::new(Shared {
            label: label.to_string(),
            unit: unit.to_string(),
            total: AtomicU64::new(total),
            pos: AtomicU64::new(0),
            msg: Mutex::new(String::new()),
            start: Instant::now(),
            stop: (Mutex::new(false), Condvar::new()),
        });
        if std::io::stderr().is_terminal() {
            let bar = if total > 0 {
                let b = indicatif::ProgressBar::new(total);
                b.set_style(
                    indicatif::ProgressStyle::with_template(&format!(
                        "{{spinner}} {label} [{{elapsed_precise}}] {{bar:30}} {{pos}}/{{len}} {unit} (ETA {{eta}}) {{wide_msg}}"
                    ))
                    .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
                );
                b
            } else {
                let b = indicatif::ProgressBar::new_spinner();
                b.set_style(
                    indicatif::ProgressStyle::with_template(&format!(
                        "{{spinner}} {label} [{{elapsed_precise}}] {{wide_msg}}"
                    ))
                    .unwrap_or_else(|_| indicatif::ProgressStyle::default_spinner()),
                );
                b.enable_steady_tick(Duration::from_millis(200));
                b
            };
            return Progress {
                shared,
                bar: Some(bar),
                ticker: None,
            };
        }
        let ticker = interval().map(|every| {
            let sh = shared.clone();
            std::thread::spawn(move || {
                let (lock, cv) = &sh.stop;
                let mut stopped = lock.lock().unwrap_or_else(|e| e.into_inner());
                loop {
                    let (g, timeout) = cv
                        .wait_timeout(stopped, every)
                        .unwrap_or_else(|e| e.into_inner());
                    stopped = g;
                    if *stopped {
                        break;
                    }
                    if timeout.timed_out() {
                        eprintln!("{}", sh.line());
                    }
                }
            })
        });
        Progress {
            shared,
            bar: None,
            ticker,
        }
    }

    pub fn set_position(&self, pos: u64) {
        self.shared.pos.store(pos, Ordering::Relaxed);
        if let Some(b) = &self.bar {
            b.set_position(pos);
        }
    }

    pub fn inc(&self, n: u64) {
        self.shared.pos.fetch_add(n, Ordering::Relaxed);
        if let Some(b) = &self.bar {
            b.inc(n);
        }
    }

    pub fn set_message(&self, msg: impl Into<String>) {
        let msg = msg.into();
        if let Some(b) = &self.bar {
            b.set_message(msg.clone());
        }
        if let Ok(mut m) = self.shared.msg.lock() {
            *m = msg;
        }
    }

    /// Print a line to stderr above the bar (or plainly when there is none).
    pub fn println(&self, msg: impl AsRef<str>) {
        self.suspend(|| eprintln!("{}", msg.as_ref()));
    }

    /// Run `f` (which prints) with the bar hidden.
    pub fn suspend<R>(&self, f: impl FnOnce() -> R) -> R {
        match &self.bar {
            Some(b) => b.suspend(f),
            None => f(),
        }
    }

    /// Time since the progress began.
    pub fn elapsed(&self) -> Duration {
        self.shared.start.elapsed()
    }

    /// Remove the bar and stop the periodic lines.
    pub fn finish(&mut self) {
        if let Some(b) = self.bar.take() {
            b.finish_and_clear();
        }
        if let Some(t) = self.ticker.take() {
            let (lock, cv) = &self.shared.stop;
            if let Ok(mut s) = lock.lock() {
                *s = true;
            }
            cv.notify_all();
            let _ = t.join();
        }
    }
}

impl Drop for Progress {
    fn drop(&mut self) {
        self.finish();
    }
}

/// A sweep's observer on the console: lines on stderr, and a progress bar over the fits
/// (above which a fit's warnings print).
pub struct ConsoleObserver {
    label: String,
    /// What the progress counts.
    unit: &'static str,
    progress: Option<Progress>,
}

impl ConsoleObserver {
    /// An observer whose progress reads `LABEL: 120/603 fits…`.
    pub fn new(label: &str) -> ConsoleObserver {
        ConsoleObserver::counting(label, "fits")
    }

    /// An observer whose progress counts `unit` (`LABEL: 3/12 data sets…`).
    pub fn counting(label: &str, unit: &'static str) -> ConsoleObserver {
        ConsoleObserver {
            label: label.to_string(),
            unit,
            progress: None,
        }
    }
}

impl crate::workflows::sweep::SweepObserver for ConsoleObserver {
    fn note(&mut self, line: &str) {
        match &self.progress {
            Some(p) => p.println(line),
            None => eprintln!("{line}"),
        }
    }
    fn begin(&mut self, total: u64, done: u64) {
        let p = Progress::new(&self.label, total, self.unit);
        p.inc(done);
        self.progress = Some(p);
    }
    fn alert(&mut self, line: &str) {
        self.note(line);
    }
    fn fit_ended(&mut self, what: &str) {
        if let Some(p) = &self.progress {
            p.set_message(what);
            p.inc(1);
        }
    }
    fn end(&mut self) {
        if let Some(mut p) = self.progress.take() {
            p.finish();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::text::{plural, plural_with};

    #[test]
    fn words_and_times() {
        assert_eq!(plural(1, "fit"), "1 fit");
        assert_eq!(plural(0, "fit"), "0 fits");
        assert_eq!(plural_with(3, "data set", "data sets"), "3 data sets");
        assert_eq!(fmt_duration(Duration::from_secs(130)), "2m10s");
        assert_eq!(fmt_duration(Duration::from_secs(7260)), "2h01m");
        let p = Progress::new("sweep", 603, "fits");
        p.set_position(120);
        let l = p.shared.line();
        assert!(
            l.starts_with("sweep: 120/603 fits, ") && l.contains("elapsed"),
            "{l}"
        );
    }
}

//! GPU faults: a device lost (a driver reset, a removed or destroyed device) or hung (a
//! submission that never completes), as one typed error, [`DeviceFault`], so that callers
//! tell a dead device from a bad model or bad input and re-run the work elsewhere; the
//! read-back timeout ([`TIMEOUT_VAR`]); and the fault-injection switch ([`FAULT_VAR`])
//! the tests use to make both happen on purpose.
//!
//! **What is counted.** A device numbers its submissions from 1 in the order they are
//! made: one submission is one queue submission ending in a read-back
//! (`Recorder::submit_and_read`), which is every submission the engine makes (uploads of
//! a batch's records are queue writes, not submissions). Each process opens one device
//! (`bsdfit fit`, `bsdfit sweep`), so N counts that process's submissions; in a sweep,
//! whose workers share the device, which fit's submission is the N-th depends on their
//! timing.
//!
//! **The switch.** `BSDFIT_GPU_FAULT=lost@N` destroys the device (`wgpu::Device::destroy`)
//! just before the N-th submission, so that submission and everything after it fail
//! through wgpu's own channels, as for a device the driver lost: the failed submission,
//! the failed mapping and the device-lost callback. `BSDFIT_GPU_FAULT=hang@N` submits,
//! ahead of the N-th submission's work, compute work that outlasts the read-back timeout
//! (`stall.rs`), so the device's wait for that submission times out, as for a device that
//! stopped answering: only the timeout ends the wait.

use anyhow::{anyhow, bail, Result};
use std::time::Duration;

/// The fault-injection switch: `lost@N` or `hang@N` (N ≥ 1, the device's N-th submission).
pub const FAULT_VAR: &str = "BSDFIT_GPU_FAULT";
/// Seconds a read-back may wait for its submission before the device is taken as hung.
pub const TIMEOUT_VAR: &str = "BSDFIT_GPU_TIMEOUT";
/// The default of [`TIMEOUT_VAR`]: 300 s, generous. The longest single read-back
/// measured on lavapipe (2 shared cores, tests running two at a time) was 1.9 s, in
/// tests/gpu_normal.rs; tests/streamed.rs, gpu_parity.rs and gpu_records.rs stayed under
/// 1.7 s, the bundled sweep on the GPU under 0.6 s, an LM fit of `rmg(ggx)` to 260,610
/// samples (`synth --geometry grid:2.5`, full 64 MiB windows) under 0.4 s, and a compass
/// fit of it (every candidate's costs over all the data in one submission) 1.04 s. The
/// largest submission the engine can make is bounded by its candidates, not its windows:
/// a compass poll of 64 restarts of an 8-parameter model over a whole MERL table (1.1
/// million directions, 3 channels) is ≈ 3e9 evaluations, ≈ 25 s at lavapipe's 1.4e8/s.
/// 300 s leaves ten times that; a device silent for longer is hung.
pub const DEFAULT_TIMEOUT_S: f64 = 300.0;

/// A device that can no longer be given work. Once a device has one, every later use of
/// it fails at once with the same fault.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum DeviceFault {
    /// The device was lost (reset or removed by the driver, or destroyed).
    #[error("the GPU device was lost at submission {submission} ({detail})")]
    Lost { submission: u64, detail: String },
    /// A submission did not complete within the read-back timeout.
    #[error(
        "GPU submission {submission} did not complete within {seconds} s (the read-back \
         timeout, {TIMEOUT_VAR}); the device is taken as hung"
    )]
    Hung { submission: u64, seconds: f64 },
}

impl DeviceFault {
    /// A few words: `GPU lost at submission N` or `GPU hung at submission N`.
    pub fn brief(&self) -> String {
        match self {
            DeviceFault::Lost { submission, .. } => format!("GPU lost at submission {submission}"),
            DeviceFault::Hung { submission, .. } => format!("GPU hung at submission {submission}"),
        }
    }

    /// The submission at which the device failed.
    pub fn submission(&self) -> u64 {
        match self {
            DeviceFault::Lost { submission, .. } | DeviceFault::Hung { submission, .. } => {
                *submission
            }
        }
    }
}

/// The device fault somewhere in `e`'s chain of causes, if any.
pub fn device_fault(e: &anyhow::Error) -> Option<&DeviceFault> {
    e.chain().find_map(|c| c.downcast_ref::<DeviceFault>())
}

/// What the switch does at its submission.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Injected {
    /// Destroy the device before submitting.
    Lost,
    /// Keep the device busy past the timeout ahead of the submission's work.
    Hang,
}

/// A fault to inject: what, and at which submission (1-based).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FaultPlan {
    pub what: Injected,
    pub at: u64,
}

impl std::str::FromStr for FaultPlan {
    type Err = anyhow::Error;

    fn from_str(text: &str) -> Result<FaultPlan> {
        let wrong = || {
            anyhow!("{FAULT_VAR}={text}: expected lost@N or hang@N (N ≥ 1, the GPU submission at which the fault happens)")
        };
        let (what, at) = text.trim().split_once('@').ok_or_else(wrong)?;
        let what = match what.trim() {
            "lost" => Injected::Lost,
            "hang" => Injected::Hang,
            _ => return Err(wrong()),
        };
        let at: u64 = at.trim().parse().map_err(|_| wrong())?;
        if at == 0 {
            return Err(wrong());
        }
        Ok(FaultPlan { what, at })
    }
}

impl FaultPlan {
    /// The plan [`FAULT_VAR`] names (`None` when unset or empty).
    pub fn from_env() -> Result<Option<FaultPlan>> {
        match std::env::var(FAULT_VAR) {
            Ok(v) if !v.trim().is_empty() => v.parse().map(Some),
            Ok(_) | Err(std::env::VarError::NotPresent) => Ok(None),
            Err(e) => bail!("{FAULT_VAR}: {e}"),
        }
    }
}

/// The read-back timeout: [`TIMEOUT_VAR`] seconds (a positive number), else
/// [`DEFAULT_TIMEOUT_S`].
pub fn timeout_from_env() -> Result<Duration> {
    let text = match std::env::var(TIMEOUT_VAR) {
        Ok(v) if !v.trim().is_empty() => v,
        Ok(_) | Err(std::env::VarError::NotPresent) => {
            return Ok(Duration::from_secs_f64(DEFAULT_TIMEOUT_S))
        }
        Err(e) => bail!("{TIMEOUT_VAR}: {e}"),
    };
    parse_timeout(&text)
}

/// `seconds` as a timeout (positive and finite, at most a day).
pub fn parse_timeout(seconds: &str) -> Result<Duration> {
    match seconds.trim().parse::<f64>() {
        Ok(s) if s > 0.0 && s <= 86_400.0 => Ok(Duration::from_secs_f64(s)),
        _ => bail!(
            "{TIMEOUT_VAR}={seconds}: expected the seconds a GPU read-back may wait (a \
             positive number, at most 86400; default {DEFAULT_TIMEOUT_S})"
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn plans_and_timeouts_parse_or_say_what_is_expected() {
        assert_eq!(
            "lost@3".parse::<FaultPlan>().unwrap(),
            FaultPlan {
                what: Injected::Lost,
                at: 3
            }
        );
        assert_eq!(
            " hang @ 1 ".parse::<FaultPlan>().unwrap().what,
            Injected::Hang
        );
        for bad in ["lost", "lost@0", "lost@x", "melt@2", "@2"] {
            let e = bad.parse::<FaultPlan>().unwrap_err().to_string();
            assert!(e.contains(FAULT_VAR) && e.contains("lost@N"), "{e}");
        }
        assert_eq!(parse_timeout("0.5").unwrap(), Duration::from_millis(500));
        for bad in ["0", "-1", "nan", "inf", "soon"] {
            let e = parse_timeout(bad).unwrap_err().to_string();
            assert!(e.contains(TIMEOUT_VAR), "{e}");
        }
    }

    #[test]
    fn faults_are_found_in_a_chain_of_causes() {
        let f = DeviceFault::Hung {
            submission: 4,
            seconds: 2.0,
        };
        let e = anyhow::Error::new(f.clone()).context("fitting fa(eon)");
        assert_eq!(device_fault(&e), Some(&f));
        assert!(f.to_string().contains(TIMEOUT_VAR));
        assert_eq!(f.submission(), 4);
        assert_eq!(f.brief(), "GPU hung at submission 4");
        assert!(device_fault(&anyhow!("a bad model")).is_none());
    }
}

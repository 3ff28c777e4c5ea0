//! Why a Levenberg–Marquardt restart stops.

use super::state::RestartState;
use super::LmOptions;

/// Why a restart stopped.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Termination {
    /// Σr² is not finite at its point: no step can be measured from there.
    NotFinite,
    /// The next step's predicted gain is below `ftol` of Σr² (checked before evaluating
    /// it): no evaluation could tell it from rounding.
    PredictedGain,
    /// An accepted step gained less than `ftol` of Σr².
    SmallGain,
    /// The step was shorter than `xtol`.
    SmallStep,
    /// λ grew past 1e12 over rejected steps.
    Damping,
    /// Σr² fell by less than `stall_gain` of itself over `stall_window` iterations.
    Stalled,
    /// It ran `max_iterations` iterations.
    MaxIterations,
}

/// What an iteration did to a restart, for the termination test.
pub(super) enum Outcome {
    /// The step lowered Σr² by `gain` of itself; it was `length` long (unit box).
    Accepted { gain: f64, length: f64 },
    /// The step did not lower Σr²; it was `length` long.
    Rejected { length: f64 },
}

/// λ beyond which a restart whose steps keep being rejected stops.
const MAX_LAMBDA: f64 = 1e12;

impl RestartState {
    /// Whether the restart stops after an iteration whose step had `outcome` (λ and Σr²
    /// already updated), and why. Records Σr² for the stall test either way.
    pub(super) fn termination(
        &mut self,
        outcome: Outcome,
        opts: &LmOptions,
    ) -> Option<Termination> {
        let stalled = self.stalled(opts);
        match outcome {
            Outcome::Accepted { gain, .. } if gain < opts.ftol => Some(Termination::SmallGain),
            Outcome::Rejected { .. } if self.lambda > MAX_LAMBDA => Some(Termination::Damping),
            Outcome::Accepted { length, .. } | Outcome::Rejected { length }
                if length < opts.xtol =>
            {
                Some(Termination::SmallStep)
            }
            _ => stalled.then_some(Termination::Stalled),
        }
    }

    /// Record Σr² and say whether it fell by less than `stall_gain` of itself over the
    /// last `stall_window` iterations (never when `stall_window` is 0). Why: in a long,
    /// curved valley LM crawls, neither `ftol` nor `xtol` stopping it ([`LmOptions`]).
    fn stalled(&mut self, opts: &LmOptions) -> bool {
        if opts.stall_window == 0 {
            return false;
        }
        self.recent.push_back(self.ss);
        if self.recent.len() <= opts.stall_window {
            return false;
        }
        let old = self.recent.pop_front().unwrap_or(self.ss);
        // false for NaN: a NaN Σr² has already stopped the restart
        old - self.ss < opts.stall_gain * old
    }
}

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

#[cfg(test)]
mod tests {
    //! The termination rules of [`LmOptions`], each checked on a restart state built by
    //! hand, at and beside its threshold.
    use super::*;
    use crate::optim::NormalEquations;
    use std::collections::VecDeque;

    fn restart(ss: f64, lambda: f64) -> RestartState {
        RestartState {
            x: vec![0.5],
            ss,
            normal: NormalEquations {
                jtj: vec![1.0],
                jtr: vec![0.0],
                ss,
            },
            lambda,
            scale: vec![1.0],
            stop: None,
            iterations: 0,
            evaluations: 0,
            recent: VecDeque::new(),
        }
    }

    /// ftol 1e-10, xtol 1e-9 (the defaults), the stall test over `window` iterations.
    fn opts(window: usize) -> LmOptions {
        LmOptions {
            ftol: 1e-10,
            xtol: 1e-9,
            stall_window: window,
            stall_gain: 1e-6,
            ..LmOptions::default()
        }
    }

    fn accepted(gain: f64, length: f64) -> Outcome {
        Outcome::Accepted { gain, length }
    }

    #[test]
    fn an_accepted_step_gaining_less_than_ftol_stops_on_small_gain() {
        let o = opts(0);
        let stop = |gain| restart(1.0, 1e-3).termination(accepted(gain, 0.1), &o);
        assert_eq!(stop(5e-11), Some(Termination::SmallGain));
        assert_eq!(stop(0.0), Some(Termination::SmallGain));
        // "less than ftol": a gain of exactly ftol, or more, goes on.
        assert_eq!(stop(1e-10), None);
        assert_eq!(stop(2e-10), None);
        assert_eq!(stop(0.5), None);
        // A rejected step gains nothing but is not a small gain.
        let rejected = restart(1.0, 1e-3).termination(Outcome::Rejected { length: 0.1 }, &o);
        assert_eq!(rejected, None);
    }

    #[test]
    fn a_rejected_step_stops_on_damping_once_lambda_passes_1e12() {
        let o = opts(0);
        let stop = |lambda| restart(1.0, lambda).termination(Outcome::Rejected { length: 0.1 }, &o);
        assert_eq!(stop(4e12), Some(Termination::Damping));
        assert_eq!(stop(1.0000001e12), Some(Termination::Damping));
        // "past 1e12": λ = 1e12 itself, or less, goes on.
        assert_eq!(stop(1e12), None);
        assert_eq!(stop(1.0), None);
        // An accepted step never stops on λ.
        let acc = restart(1.0, 4e12).termination(accepted(0.5, 0.1), &o);
        assert_eq!(acc, None);
    }

    #[test]
    fn a_step_shorter_than_xtol_stops_on_small_step_accepted_or_rejected() {
        let o = opts(0);
        let acc = |length| restart(1.0, 1e-3).termination(accepted(0.5, length), &o);
        let rej = |length| restart(1.0, 1e-3).termination(Outcome::Rejected { length }, &o);
        assert_eq!(acc(5e-10), Some(Termination::SmallStep));
        assert_eq!(rej(5e-10), Some(Termination::SmallStep));
        assert_eq!(rej(0.0), Some(Termination::SmallStep));
        // "shorter than xtol": exactly xtol, or longer, goes on.
        assert_eq!(acc(1e-9), None);
        assert_eq!(rej(1e-9), None);
        assert_eq!(acc(0.3), None);
        assert_eq!(rej(0.3), None);
    }

    #[test]
    fn the_first_rule_that_applies_names_the_stop() {
        let o = opts(0);
        // Small gain and small step at once: the gain is tested first.
        let s = restart(1.0, 1e-3).termination(accepted(1e-12, 1e-12), &o);
        assert_eq!(s, Some(Termination::SmallGain));
        // λ past its cap and a small step at once: λ is tested first.
        let s = restart(1.0, 4e12).termination(Outcome::Rejected { length: 1e-12 }, &o);
        assert_eq!(s, Some(Termination::Damping));
    }

    /// Feed Σr² values one iteration at a time (each step accepted, long and gaining
    /// more than ftol, so that only the stall test can stop it); the stops.
    fn stall_stops(values: &[f64], o: &LmOptions) -> Vec<Option<Termination>> {
        let mut s = restart(values[0], 1e-3);
        values
            .iter()
            .map(|&ss| {
                s.ss = ss;
                s.termination(accepted(0.5, 0.1), o)
            })
            .collect()
    }

    #[test]
    fn a_sum_of_squares_that_falls_by_less_than_stall_gain_over_the_window_stalls() {
        let o = opts(3);
        // Σr² = 100 falling by 1e-8 of itself per iteration: over 3 iterations by 3e-8,
        // less than 1e-6 of it. Nothing is judged until the window holds 3 iterations
        // before the current one.
        let slow: Vec<f64> = (0..5).map(|i| 100.0 * (1.0 - 1e-8 * i as f64)).collect();
        let stops = stall_stops(&slow, &o);
        assert_eq!(stops[..3], [None, None, None]);
        assert_eq!(stops[3], Some(Termination::Stalled));
        assert_eq!(stops[4], Some(Termination::Stalled));
        // Falling by 1e-5 of itself per iteration is progress.
        let fast: Vec<f64> = (0..8).map(|i| 100.0 * (1.0 - 1e-5 * i as f64)).collect();
        assert!(stall_stops(&fast, &o).iter().all(Option::is_none));
        // Falling by exactly stall_gain over the window (powers of 2, exact) is not
        // "less than" it.
        let exact = LmOptions {
            stall_gain: 0.5,
            ..opts(1)
        };
        assert_eq!(stall_stops(&[1.0, 0.5], &exact), [None, None]);
        assert_eq!(
            stall_stops(&[1.0, 0.75], &exact),
            [None, Some(Termination::Stalled)]
        );
        // A window of 0 never stalls, however flat Σr² is.
        assert!(stall_stops(&[2.0; 30], &opts(0))
            .iter()
            .all(Option::is_none));
    }
}

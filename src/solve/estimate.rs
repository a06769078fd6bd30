//! How long a solve will take, estimated before it starts: one forward and one adjoint
//! application of a channel's operator are timed (the FFT work of one iteration of
//! every solver here, timed warm: the first application plans and touches memory for
//! the first time) and multiplied by the iterations and channels to come. The
//! iterations account for the stop rule: with a convergence test on (the default
//! objective test) a solve usually ends well before the cap, so the estimate is a
//! range, the usual count ([`USUAL_ITERATIONS`]) to the cap.

use crate::model::op::Operator;
use crate::solve::problem::{Problem, SolveSettings};
use serde::Serialize;
use std::time::Instant;

/// Above this many estimated seconds a front-end warns before it starts.
pub const LONG_SOLVE_S: f64 = 60.0;

/// Above this many estimated seconds (a day) a front-end refuses to start unless the
/// user confirms (`--yes`): a solve of days is a mistake far more often than a plan.
pub const CONFIRM_SOLVE_S: f64 = 86_400.0;

/// A duration in the unit a person reads it in: seconds under two minutes, then
/// minutes, hours, days and years (`11564455254 s` is "about 366 years").
pub fn human_duration(seconds: f64) -> String {
    const MINUTE: f64 = 60.0;
    const HOUR: f64 = 3600.0;
    const DAY: f64 = 86_400.0;
    const YEAR: f64 = 365.25 * DAY;
    match seconds {
        s if !s.is_finite() => "an unbounded time".to_string(),
        s if s < 2.0 * MINUTE => format!("{s:.1} s"),
        s if s < 2.0 * HOUR => format!("{:.1} min", s / MINUTE),
        s if s < 2.0 * DAY => format!("{:.1} h", s / HOUR),
        s if s < 2.0 * YEAR => format!("{:.1} days", s / DAY),
        s => format!("{:.0} years", s / YEAR),
    }
}

/// Iterations a solve with the default stop rule (objective, iterate and data term
/// settled: [`crate::solve::optimize::StopRule::obj_tol`]) usually takes. Measured on
/// nine captures with that rule (docs/usage.md, *When a run is done*): 82 and 97
/// (an occluder, a dim disc at 240 x 320), 322 to 489 (dense discs, a textured still,
/// the tutorial's hand), 600 (the cap: the demo, LEDs, a lone disc); median 462. Under
/// the objective-alone rule it was 300 (docs/scene-suite.md).
pub const USUAL_ITERATIONS: usize = 400;

/// One iteration's seconds over one forward plus one adjoint application: the TV step,
/// the momentum and the objective's vector work beside the FFTs (measured on the
/// simulated dense capture, 64 x 80 disc over texture, FISTA with restart, Haar TV:
/// 0.099 s per iteration against 0.050 s for the warm forward + adjoint, 2.0).
pub const ITERATION_OVER_APPLICATION: f64 = 2.0;

/// The estimate of a solve, before it starts.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SolveEstimate {
    /// Seconds of one iteration: a warm forward plus adjoint application of a channel's
    /// operator, as timed, times [`ITERATION_OVER_APPLICATION`].
    pub seconds_per_iteration: f64,
    /// The cap (`--iters`).
    pub iterations: usize,
    /// The iterations a solve usually takes under the stop rule: [`USUAL_ITERATIONS`]
    /// (at most the cap) with a convergence test on, the cap without one.
    pub usual_iterations: usize,
    pub channels: usize,
    /// `usual_iterations x channels x seconds_per_iteration` (at most the time budget
    /// per channel): an order of magnitude, not a bound: the step size's power iteration
    /// when not cached, the still start and a weight search add to the solve, and a
    /// solve's iterations vary with the scene.
    pub seconds: f64,
    /// The same at the cap: the longest the solve takes.
    pub max_seconds: f64,
}

impl SolveEstimate {
    /// Whether the solve is long enough to warn before it starts ([`LONG_SOLVE_S`]).
    pub fn is_long(&self) -> bool {
        self.seconds > LONG_SOLVE_S
    }

    /// Why the solve should not start without the user's word: estimated beyond
    /// [`CONFIRM_SOLVE_S`] (a day). `None`: it may start.
    pub fn needs_confirmation(&self) -> Option<String> {
        (self.seconds > CONFIRM_SOLVE_S).then(|| {
            format!(
                "this solve is estimated to take about {} ({:.0} s; {} iterations x {} channel(s) x {:.4} s), beyond a day",
                human_duration(self.seconds),
                self.seconds,
                self.usual_iterations,
                self.channels,
                self.seconds_per_iteration
            )
        })
    }

    /// Whether the stop rule can end the solve before the cap.
    pub fn stops_early(&self) -> bool {
        self.usual_iterations < self.iterations
    }

    /// One line for a terminal: the range, what it is made of.
    pub fn describe(&self) -> String {
        if self.stops_early() {
            format!(
                "estimated solve time: about {}, at most {} (usually about {} iterations under the stop rule, at most the cap of {}; x {} channel(s) x {:.4} s per iteration, timed)",
                human_duration(self.seconds),
                human_duration(self.max_seconds),
                self.usual_iterations, self.iterations, self.channels, self.seconds_per_iteration
            )
        } else {
            format!(
                "estimated solve time: about {} ({} iterations, no convergence test to end it sooner; x {} channel(s) x {:.4} s per iteration, timed)",
                human_duration(self.seconds),
                self.iterations,
                self.channels,
                self.seconds_per_iteration
            )
        }
    }
}

/// Time a warm forward and adjoint of `problem`'s first channel (on an iterate of ones)
/// and scale it to the iterations `settings`' stop rule usually runs on `channels`
/// channels.
pub fn estimate(problem: &Problem, settings: &SolveSettings, channels: usize) -> SolveEstimate {
    let op = &problem.models()[0];
    let x = vec![1.0f32; op.input_len()];
    let mut y = vec![0.0f32; op.output_len()];
    let mut back = vec![0.0f32; op.input_len()];
    let mut fastest = f64::INFINITY;
    for _ in 0..3 {
        let t0 = Instant::now();
        op.forward(&x, &mut y);
        op.adjoint(&y, &mut back);
        fastest = fastest.min(t0.elapsed().as_secs_f64());
    }
    let seconds_per_iteration = fastest * ITERATION_OVER_APPLICATION;
    let stops_early = settings.obj_tol > 0.0 || settings.rel_tol > 0.0;
    let usual_iterations = if stops_early { settings.iters.min(USUAL_ITERATIONS) } else { settings.iters };
    let budget = |s: f64| settings.time_budget_s.map_or(s, |b| s.min(b * channels as f64));
    SolveEstimate {
        seconds_per_iteration,
        iterations: settings.iters,
        usual_iterations,
        channels,
        seconds: budget(seconds_per_iteration * (usual_iterations * channels) as f64),
        max_seconds: budget(seconds_per_iteration * (settings.iters * channels) as f64),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(seconds: f64) -> SolveEstimate {
        SolveEstimate { seconds_per_iteration: 0.01, iterations: 100, usual_iterations: 100, channels: 1, seconds, max_seconds: seconds }
    }

    #[test]
    fn durations_read_in_human_units_and_a_solve_beyond_a_day_asks_first() {
        assert_eq!(human_duration(14.2), "14.2 s");
        assert_eq!(human_duration(600.0), "10.0 min");
        assert_eq!(human_duration(3.0 * 3600.0), "3.0 h");
        assert_eq!(human_duration(3.0 * 86_400.0), "3.0 days");
        assert_eq!(human_duration(11_564_455_254.0), "366 years");
        assert!(at(CONFIRM_SOLVE_S).needs_confirmation().is_none());
        let why = at(2.0 * CONFIRM_SOLVE_S).needs_confirmation().expect("beyond a day");
        assert!(why.contains("about 2.0 days") && why.contains("172800 s"), "{why}");
        assert!(at(11_564_455_254.0).describe().contains("about 366 years"));
    }
}

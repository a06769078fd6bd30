//! The one loop every solver runs in (after argmin's `Executor`): a solver is a
//! [`Step`], one iteration of its method, and [`run`] drives it.
//!
//! What the loop owns:
//! - the solver clock ([`Clock`]), started before the step is built (its setup, e.g.
//!   the start's `A x0`, is solver time) and paused while an observer runs;
//! - the state: iteration count, the objective of the current iterate, the
//!   termination reason;
//! - the non-finite check: a proposal whose objective is NaN/Inf (or, for steps with
//!   [`Step::CHECK_ITERATE`], one with a NaN/Inf element) ends the run with
//!   [`Termination::NonFinite`] at that iteration; the step is told to
//!   [`abandon`](Step::abandon) it and the last finite iterate, with its objective and
//!   the count of completed iterations, is returned;
//! - the observer call after every accepted iteration (`false` stops the run:
//!   [`Termination::Stopped`]), then the stopping rules of [`StopRule`], by
//!   precedence: relative change, objective change (`obj_tol`, held for
//!   `OBJ_TOL_PATIENCE` iterations, with the iterate settled as long and the data
//!   term over `DATA_WINDOW` iterations), time budget, maximum iterations;
//! - the [`SolveResult`].
//!
//! What a step owns: its buffers (all allocated when it is built; an iteration
//! allocates nothing), the method's arithmetic, which vector is its current iterate,
//! and how it measures the relative change. An iteration is split in two so that the
//! check sits between them: [`Step::propose`] computes the next candidate and its
//! objective without giving up the current iterate; [`Step::accept`] makes it current
//! (or, as MFISTA may, keeps the old one) and prepares the next iteration.

use crate::model::ranks::{One, Ranks};
use crate::solve::optimize::types::{
    IterInfo, Observer, SolveResult, StopRule, Termination, DATA_FALL_PER_OBJ_TOL, DATA_WINDOW, ITERATE_PER_OBJ_TOL, OBJ_TOL_PATIENCE,
};
use std::collections::VecDeque;
use std::time::{Duration, Instant};

/// The two terms of the objective at an iterate, in f64.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Objective {
    pub data_term: f64,
    pub reg_term: f64,
}

impl Objective {
    /// `data_term + reg_term`: the value the non-finite check and the solvers'
    /// comparisons (FISTA's restart, MFISTA's acceptance) use.
    pub(crate) fn total(self) -> f64 {
        self.data_term + self.reg_term
    }
}

/// What a step reports once its proposal is accepted.
pub(crate) struct Accepted {
    /// The objective of the iterate that is current now (the proposal's, or the
    /// previous one where the step keeps its iterate).
    pub objective: Objective,
    /// `||x_k - x_{k-1}|| / ||x_k||` as the method measures it, for the `rel_tol` rule
    /// and the observers.
    pub rel_change: f64,
}

/// One iteration of a solver, driven by [`run`].
pub(crate) trait Step {
    /// Whether the executor scans the proposed iterate for NaN/Inf (one pass over the
    /// video) besides checking its objective.
    const CHECK_ITERATE: bool = true;

    /// Compute the next candidate iterate and its objective; the current iterate
    /// ([`x`](Step::x)) must survive, since the candidate may be abandoned.
    fn propose(&mut self, iteration: usize) -> Objective;

    /// The candidate of the last [`propose`](Step::propose) (for the element check).
    fn proposal(&self) -> &[f32];

    /// The proposal is finite: take it (or keep the current iterate) and prepare the
    /// next iteration. `current` is the objective of the current iterate, `proposed`
    /// what `propose` returned.
    fn accept(&mut self, iteration: usize, current: Objective, proposed: Objective) -> Accepted;

    /// The proposal is not finite and the run ends: make [`x`](Step::x) the last
    /// finite iterate again where `propose` overwrote it. Only
    /// [`into_x`](Step::into_x) follows.
    fn abandon(&mut self) {}

    /// The current iterate.
    fn x(&self) -> &[f32];

    /// The current iterate, by value.
    fn into_x(self) -> Vec<f32>;

    /// The processes the iterate is split across (its data term's,
    /// [`DataTerm::ranks`](crate::model::data::DataTerm::ranks)): the loop's decisions
    /// (a non-finite proposal, a stop) are agreed between them, so that all run the
    /// same iterations.
    fn ranks(&self) -> &dyn Ranks {
        &One
    }
}

/// Build a step with `start` (which returns it and the objective at its start point),
/// then iterate it until a stopping rule, the observer or a non-finite proposal ends
/// the run.
pub(crate) fn run<S: Step>(stop: &StopRule, observer: &mut dyn Observer, start: impl FnOnce() -> (S, Objective)) -> SolveResult {
    let mut clock = Clock::start();
    let (mut step, mut objective) = start();
    let mut termination = Termination::MaxIterations;
    let mut iterations = 0;
    // Iterations in a row whose objective changed by less than `obj_tol`, and whose
    // iterate changed by less than ITERATE_PER_OBJ_TOL * obj_tol; the data terms of the
    // last DATA_WINDOW iterations and the one before them.
    let mut flat = 0usize;
    let mut quiet = 0usize;
    let mut data = DataWindow::new(objective.data_term);
    for iteration in 1..=stop.max_iters {
        let proposed = step.propose(iteration);
        let bad = !proposed.total().is_finite() || (S::CHECK_ITERATE && step.proposal().iter().any(|v| !v.is_finite()));
        if step.ranks().any(bad) {
            step.abandon();
            termination = Termination::NonFinite { iteration };
            break;
        }
        let Accepted { objective: now, rel_change } = step.accept(iteration, objective, proposed);
        let obj_change = (now.total() - objective.total()).abs() / now.total().abs().max(1e-300);
        flat = if obj_change < stop.obj_tol { flat + 1 } else { 0 };
        quiet = if rel_change < ITERATE_PER_OBJ_TOL * stop.obj_tol { quiet + 1 } else { 0 };
        data.push(now.data_term);
        objective = now;
        iterations = iteration;

        let seconds = clock.seconds();
        let info = IterInfo { iteration, seconds, data_term: objective.data_term, reg_term: objective.reg_term, rel_change, x: step.x() };
        let reason = if clock.off(|| observer.observe(&info)) {
            stop_reason(stop, rel_change, seconds, (if stop.wait_for_iterate { flat.min(quiet) } else { flat }, data.settled(stop.obj_tol, stop.noise_floor)))
        } else {
            Some(Termination::Stopped)
        };
        if let Some(reason) = agree(step.ranks(), reason) {
            termination = reason;
            break;
        }
    }
    let seconds = clock.seconds();
    SolveResult { x: step.into_x(), iterations, seconds, termination, data_term: objective.data_term, reg_term: objective.reg_term }
}

/// The data terms of the last [`DATA_WINDOW`] iterations and the one before them (the
/// start's while fewer have run).
struct DataWindow(VecDeque<f64>);

impl DataWindow {
    fn new(start: f64) -> Self {
        let mut d = VecDeque::with_capacity(DATA_WINDOW + 1);
        d.push_back(start);
        DataWindow(d)
    }

    fn push(&mut self, data_term: f64) {
        if self.0.len() == DATA_WINDOW + 1 {
            self.0.pop_front();
        }
        self.0.push_back(data_term);
    }

    /// Whether the data term fell by less than `DATA_FALL_PER_OBJ_TOL * obj_tol` of its
    /// value per iteration over the window (a rise counts as settled: the objective
    /// rule judges the sum), or is at or below the noise floor.
    fn settled(&self, obj_tol: f64, noise_floor: Option<f64>) -> bool {
        let (first, last) = (self.0[0], self.0[self.0.len() - 1]);
        if noise_floor.is_some_and(|f| last <= f) {
            return true;
        }
        let iterations = (self.0.len() - 1).max(1) as f64;
        (first - last) / last.abs().max(1e-300) < DATA_FALL_PER_OBJ_TOL * obj_tol * iterations
    }
}

/// What the relative-change, objective-change and time-budget rules say after an
/// iteration (the iteration limit is the loop's range); `flat` is the number of
/// iterations in a row whose objective and iterate changed by less than their
/// tolerances, and `settled` whether the data term has settled
/// ([`DataWindow::settled`]).
fn stop_reason(stop: &StopRule, rel_change: f64, seconds: f64, (flat, settled): (usize, bool)) -> Option<Termination> {
    if stop.rel_tol > 0.0 && rel_change < stop.rel_tol {
        return Some(Termination::Converged);
    }
    if stop.obj_tol > 0.0 && flat >= OBJ_TOL_PATIENCE && settled {
        return Some(Termination::Converged);
    }
    match stop.time_budget_s {
        Some(b) if seconds >= b => Some(Termination::TimeBudget),
        _ => None,
    }
}

/// The stop every rank takes: the strongest reason any rank has (an observer's stop,
/// then the time budget, then convergence; the last is the same on every rank, since it
/// comes from reduced values). One process: its own reason.
fn agree(ranks: &dyn Ranks, reason: Option<Termination>) -> Option<Termination> {
    if ranks.size() == 1 {
        return reason;
    }
    let code = match reason {
        None => 0.0,
        Some(Termination::Converged) => 1.0,
        Some(Termination::TimeBudget) => 2.0,
        Some(_) => 3.0,
    };
    let mut v = [code];
    ranks.max_f64(&mut v);
    match v[0] as u8 {
        0 => None,
        1 => Some(Termination::Converged),
        2 => Some(Termination::TimeBudget),
        _ => Some(Termination::Stopped),
    }
}

/// Solver clock that excludes the time spent in observers.
struct Clock {
    start: Instant,
    paused: Duration,
}

impl Clock {
    fn start() -> Self {
        Clock { start: Instant::now(), paused: Duration::ZERO }
    }
    fn seconds(&self) -> f64 {
        (self.start.elapsed() - self.paused).as_secs_f64()
    }
    /// Run `f` (an observer call) off the clock.
    fn off<R>(&mut self, f: impl FnOnce() -> R) -> R {
        let t = Instant::now();
        let r = f();
        self.paused += t.elapsed();
        r
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::solve::optimize::types::NoObserver;

    /// Doubles its one-element iterate; the proposal becomes NaN (or, with a finite
    /// objective, its element Inf) at `bad`; the change is fixed.
    struct Doubling {
        x: Vec<f32>,
        next: Vec<f32>,
        bad: usize,
        element_only: bool,
        rel: f64,
        abandoned: bool,
    }

    impl Doubling {
        fn new(bad: usize, element_only: bool) -> Self {
            Doubling { x: vec![1.0], next: vec![0.0], bad, element_only, rel: 0.5, abandoned: false }
        }
    }

    impl Step for Doubling {
        fn propose(&mut self, iteration: usize) -> Objective {
            self.next[0] = 2.0 * self.x[0];
            let mut data_term = self.next[0] as f64;
            if iteration == self.bad {
                if self.element_only {
                    self.next[0] = f32::INFINITY;
                } else {
                    data_term = f64::NAN;
                }
            }
            Objective { data_term, reg_term: 1.0 }
        }
        fn proposal(&self) -> &[f32] {
            &self.next
        }
        fn accept(&mut self, _: usize, _: Objective, proposed: Objective) -> Accepted {
            std::mem::swap(&mut self.x, &mut self.next);
            Accepted { objective: proposed, rel_change: self.rel }
        }
        fn abandon(&mut self) {
            self.abandoned = true;
        }
        fn x(&self) -> &[f32] {
            &self.x
        }
        fn into_x(self) -> Vec<f32> {
            assert_eq!(self.abandoned, self.bad != usize::MAX);
            self.x
        }
    }

    fn start(step: Doubling) -> impl FnOnce() -> (Doubling, Objective) {
        move || (step, Objective { data_term: 1.0, reg_term: 1.0 })
    }

    #[test]
    fn runs_to_the_iteration_limit_and_reports_the_last_iterate() {
        let r = run(&StopRule::iterations(5), &mut NoObserver, start(Doubling::new(usize::MAX, false)));
        assert_eq!((r.termination, r.iterations, r.x[0], r.data_term, r.reg_term), (Termination::MaxIterations, 5, 32.0, 32.0, 1.0));
        let r = run(&StopRule::iterations(0), &mut NoObserver, start(Doubling::new(usize::MAX, false)));
        assert_eq!((r.termination, r.iterations, r.x[0], r.data_term), (Termination::MaxIterations, 0, 1.0, 1.0));
    }

    #[test]
    fn a_non_finite_proposal_ends_the_run_with_the_last_finite_iterate() {
        for element_only in [false, true] {
            let r = run(&StopRule::iterations(10), &mut NoObserver, start(Doubling::new(4, element_only)));
            assert_eq!((r.termination, r.iterations, r.x[0], r.data_term), (Termination::NonFinite { iteration: 4 }, 3, 8.0, 8.0));
        }
        // At the first iteration: the start comes back.
        let r = run(&StopRule::iterations(10), &mut NoObserver, start(Doubling::new(1, false)));
        assert_eq!((r.termination, r.iterations, r.x[0], r.data_term), (Termination::NonFinite { iteration: 1 }, 0, 1.0, 1.0));
    }

    #[test]
    fn the_observer_sees_every_accepted_iterate_and_goes_first() {
        let mut seen = Vec::new();
        let stop = StopRule { max_iters: 10, rel_tol: 1.0, time_budget_s: Some(0.0), obj_tol: 0.0, noise_floor: None, wait_for_iterate: true };
        let r = run(
            &stop,
            &mut |i: &IterInfo| {
                seen.push((i.iteration, i.x[0], i.objective(), i.rel_change));
                false
            },
            start(Doubling::new(usize::MAX, false)),
        );
        assert_eq!((r.termination, r.iterations), (Termination::Stopped, 1));
        assert_eq!(seen, vec![(1, 2.0, 3.0, 0.5)]);
    }

    /// Objective `1 + x` with `x` halving each iteration: the relative objective change
    /// at iteration `k` is about `2^-k`.
    struct Halving {
        x: Vec<f32>,
        next: Vec<f32>,
    }

    impl Step for Halving {
        fn propose(&mut self, _: usize) -> Objective {
            self.next[0] = 0.5 * self.x[0];
            Objective { data_term: 1.0 + self.next[0] as f64, reg_term: 0.0 }
        }
        fn proposal(&self) -> &[f32] {
            &self.next
        }
        fn accept(&mut self, _: usize, _: Objective, proposed: Objective) -> Accepted {
            std::mem::swap(&mut self.x, &mut self.next);
            Accepted { objective: proposed, rel_change: 0.0 }
        }
        fn x(&self) -> &[f32] {
            &self.x
        }
        fn into_x(self) -> Vec<f32> {
            self.x
        }
    }

    #[test]
    fn the_objective_rule_waits_for_a_run_of_flat_iterations_and_a_settled_data_term() {
        let start = || (Halving { x: vec![1.0], next: vec![0.0] }, Objective { data_term: 2.0, reg_term: 0.0 });
        // Change at iteration k: 2^-k / (1 + 2^-k); below 1e-3 from k = 10 on, and
        // OBJ_TOL_PATIENCE such iterations would end the run at 10 + 5 - 1. The data
        // term (the whole objective here) fell by 2^-(k-20) - 2^-k over the last 20
        // iterations, under 3e-3 * 20 = 0.06 of its value from k = 25 on (0.0625 at 24).
        assert_eq!((OBJ_TOL_PATIENCE, DATA_WINDOW, DATA_FALL_PER_OBJ_TOL), (5, 20, 3.0), "the figures below");
        let stop = StopRule { max_iters: 100, rel_tol: 0.0, time_budget_s: None, obj_tol: 1e-3, noise_floor: None, wait_for_iterate: true };
        let r = run(&stop, &mut NoObserver, start);
        assert_eq!((r.termination, r.iterations), (Termination::Converged, 25));
        // Off: the iteration limit.
        let r = run(&StopRule::iterations(30), &mut NoObserver, start);
        assert_eq!((r.termination, r.iterations), (Termination::MaxIterations, 30));
    }

    /// Trades prior for data fit: the objective stays 2 while the data term falls by
    /// 0.01 per iteration until iteration `until`, then holds; the iterate changes by 1
    /// (relative) before iteration `moves_until`, by 0 from then on.
    struct Trading {
        x: Vec<f32>,
        until: usize,
        moves_until: usize,
    }

    impl Step for Trading {
        const CHECK_ITERATE: bool = false;
        fn propose(&mut self, iteration: usize) -> Objective {
            let fall = 0.01 * iteration.min(self.until) as f64;
            Objective { data_term: 2.0 - fall, reg_term: fall }
        }
        fn proposal(&self) -> &[f32] {
            &self.x
        }
        fn accept(&mut self, iteration: usize, _: Objective, proposed: Objective) -> Accepted {
            Accepted { objective: proposed, rel_change: if iteration < self.moves_until { 1.0 } else { 0.0 } }
        }
        fn x(&self) -> &[f32] {
            &self.x
        }
        fn into_x(self) -> Vec<f32> {
            self.x
        }
    }

    #[test]
    fn a_flat_objective_does_not_stop_a_run_whose_data_term_still_falls() {
        let stop = StopRule { max_iters: 100, rel_tol: 0.0, time_budget_s: None, obj_tol: 1e-3, noise_floor: None, wait_for_iterate: true };
        let trading = |until, moves_until| move || (Trading { x: vec![0.0], until, moves_until }, Objective { data_term: 2.0, reg_term: 0.0 });
        // The objective is flat from the first iteration; the data term falls until 30
        // and the last 20 iterations' fall, 0.01 * (50 - k) of about 1.7, is under
        // 0.06 from k = 40 on (0.0588; 0.0647 at 39).
        let r = run(&stop, &mut NoObserver, trading(30, 0));
        assert_eq!((r.termination, r.iterations), (Termination::Converged, 40));
        // Still falling at the cap: the cap ends it.
        let r = run(&StopRule { max_iters: 60, ..stop.clone() }, &mut NoObserver, trading(usize::MAX, 0));
        assert_eq!((r.termination, r.iterations), (Termination::MaxIterations, 60));
        // Still falling, but at the noise floor from iteration 10 (2 - 0.1 = 1.9, under 1.905): the
        // fall fits the noise, and the run ends there.
        let floored = StopRule { noise_floor: Some(1.905), ..stop.clone() };
        let r = run(&floored, &mut NoObserver, trading(usize::MAX, 0));
        assert_eq!((r.termination, r.iterations), (Termination::Converged, 10));
        assert_eq!(stop.clone().with_noise_floor(Some(f64::NAN)).noise_floor, None, "a floor that is not a positive number is none");
        // A data term that never falls: the objective rule alone, after its patience.
        let r = run(&stop, &mut NoObserver, trading(0, 0));
        assert_eq!((r.termination, r.iterations), (Termination::Converged, OBJ_TOL_PATIENCE));
    }

    #[test]
    fn a_flat_objective_does_not_stop_a_run_whose_iterate_still_moves() {
        let stop = StopRule { max_iters: 100, rel_tol: 0.0, time_budget_s: None, obj_tol: 1e-3, noise_floor: None, wait_for_iterate: true };
        let moving = |moves_until| move || (Trading { x: vec![0.0], until: 0, moves_until }, Objective { data_term: 2.0, reg_term: 0.0 });
        // Objective and data term flat throughout; the iterate settles at 50 and
        // OBJ_TOL_PATIENCE quiet iterations end the run at 50 + 5 - 1.
        let r = run(&stop, &mut NoObserver, moving(50));
        assert_eq!((r.termination, r.iterations), (Termination::Converged, 49 + OBJ_TOL_PATIENCE));
        assert_eq!(ITERATE_PER_OBJ_TOL, 2.0);
        // Never settles: the cap.
        let r = run(&stop, &mut NoObserver, moving(usize::MAX));
        assert_eq!((r.termination, r.iterations), (Termination::MaxIterations, 100));
    }

    #[test]
    fn a_rule_that_does_not_wait_for_the_iterate_stops_on_the_objective_and_the_data_term() {
        let stop = StopRule { max_iters: 100, rel_tol: 0.0, time_budget_s: None, obj_tol: 1e-3, noise_floor: None, wait_for_iterate: false };
        let moving = |moves_until| move || (Trading { x: vec![0.0], until: 0, moves_until }, Objective { data_term: 2.0, reg_term: 0.0 });
        // The iterate moves until 50; the objective and the data term are flat from the
        // start: the patience alone ends the run.
        let r = run(&stop, &mut NoObserver, moving(50));
        assert_eq!((r.termination, r.iterations), (Termination::Converged, OBJ_TOL_PATIENCE));
        // A data term that still falls holds the run as before (the iterate moving too).
        let trading = |until| move || (Trading { x: vec![0.0], until, moves_until: usize::MAX }, Objective { data_term: 2.0, reg_term: 0.0 });
        let r = run(&stop, &mut NoObserver, trading(30));
        assert_eq!((r.termination, r.iterations), (Termination::Converged, 40));
    }

    #[test]
    fn relative_change_goes_before_the_time_budget_and_the_iteration_limit() {
        let r = run(
            &StopRule { max_iters: 1, rel_tol: 1.0, time_budget_s: Some(0.0), obj_tol: 0.0, noise_floor: None, wait_for_iterate: true },
            &mut NoObserver,
            start(Doubling::new(usize::MAX, false)),
        );
        assert_eq!((r.termination, r.iterations), (Termination::Converged, 1));
        let r = run(
            &StopRule { max_iters: 1, rel_tol: 0.1, time_budget_s: Some(0.0), obj_tol: 0.0, noise_floor: None, wait_for_iterate: true },
            &mut NoObserver,
            start(Doubling::new(usize::MAX, false)),
        );
        assert_eq!((r.termination, r.iterations), (Termination::TimeBudget, 1));
    }

    #[test]
    fn observer_time_is_off_the_clock() {
        let mut slept = false;
        let r = run(
            &StopRule::iterations(2),
            &mut |_: &IterInfo| {
                std::thread::sleep(Duration::from_millis(200));
                slept = true;
                true
            },
            start(Doubling::new(usize::MAX, false)),
        );
        assert!(slept && r.seconds < 0.1, "{}", r.seconds);
    }

    #[test]
    fn without_the_element_check_only_the_objective_is_checked() {
        struct Unchecked(Doubling);
        impl Step for Unchecked {
            const CHECK_ITERATE: bool = false;
            fn propose(&mut self, iteration: usize) -> Objective {
                self.0.propose(iteration)
            }
            fn proposal(&self) -> &[f32] {
                panic!("not asked for without the element check")
            }
            fn accept(&mut self, it: usize, current: Objective, proposed: Objective) -> Accepted {
                self.0.accept(it, current, proposed)
            }
            fn x(&self) -> &[f32] {
                self.0.x()
            }
            fn into_x(self) -> Vec<f32> {
                self.0.x
            }
        }
        // The Inf element of iteration 3 is taken (its objective is finite); the
        // objective of the next proposal is not, and ends the run there.
        let r = run(&StopRule::iterations(5), &mut NoObserver, || (Unchecked(Doubling::new(3, true)), Objective { data_term: 1.0, reg_term: 1.0 }));
        assert_eq!((r.termination, r.iterations, r.x[0], r.data_term), (Termination::NonFinite { iteration: 4 }, 3, f32::INFINITY, 8.0));
    }

    /// A second rank, simulated: its stop reasons come from a script (0 none, 1
    /// converged, 2 time budget, 3 stopped), merged by `max_f64` as the MPI ranks do.
    struct OtherRank(std::sync::Mutex<Vec<f64>>);
    impl Ranks for OtherRank {
        fn rank(&self) -> usize {
            0
        }
        fn size(&self) -> usize {
            2
        }
        fn sum_f64(&self, _: &mut [f64]) {}
        fn max_f64(&self, v: &mut [f64]) {
            let mut script = self.0.lock().unwrap();
            let other = if script.is_empty() { 0.0 } else { script.remove(0) };
            v[0] = v[0].max(other);
        }
        fn sum_f32(&self, _: &mut [f32]) {}
        fn broadcast_f64(&self, _: &mut [f64]) {}
        fn exchange_halo(&self, _: &[f32], _: &[f32], _: &mut [f32], _: &mut [f32]) {}
        fn gather_frames(&self, _: &[f32], _: &[std::ops::Range<usize>], _: usize, _: Option<&mut [f32]>) {}
    }

    struct OnRanks<'r>(Doubling, &'r OtherRank);
    impl Step for OnRanks<'_> {
        fn propose(&mut self, iteration: usize) -> Objective {
            self.0.propose(iteration)
        }
        fn proposal(&self) -> &[f32] {
            self.0.proposal()
        }
        fn accept(&mut self, it: usize, current: Objective, proposed: Objective) -> Accepted {
            self.0.accept(it, current, proposed)
        }
        fn x(&self) -> &[f32] {
            self.0.x()
        }
        fn into_x(self) -> Vec<f32> {
            self.0.x
        }
        fn ranks(&self) -> &dyn Ranks {
            self.1
        }
    }

    #[test]
    fn every_rank_stops_when_one_does() {
        // Each iteration asks twice: the non-finite check (its flag), then the stop.
        // The other rank's observer stops at iteration 3: this rank stops there too.
        let other = OtherRank(std::sync::Mutex::new(vec![0.0, 0.0, 0.0, 0.0, 0.0, 3.0]));
        let r = run(&StopRule::iterations(10), &mut NoObserver, || {
            (OnRanks(Doubling::new(usize::MAX, false), &other), Objective { data_term: 1.0, reg_term: 1.0 })
        });
        assert_eq!((r.termination, r.iterations), (Termination::Stopped, 3));
        // Its time budget at iteration 2.
        let other = OtherRank(std::sync::Mutex::new(vec![0.0, 0.0, 0.0, 2.0]));
        let r = run(&StopRule::iterations(10), &mut NoObserver, || {
            (OnRanks(Doubling::new(usize::MAX, false), &other), Objective { data_term: 1.0, reg_term: 1.0 })
        });
        assert_eq!((r.termination, r.iterations), (Termination::TimeBudget, 2));
        // A non-finite proposal on the other rank at iteration 2 ends this rank's run
        // with its last finite iterate.
        let other = OtherRank(std::sync::Mutex::new(vec![0.0, 0.0, 1.0]));
        let r = run(&StopRule::iterations(10), &mut NoObserver, || {
            (OnRanks(Doubling::new(usize::MAX, false), &other), Objective { data_term: 1.0, reg_term: 1.0 })
        });
        assert_eq!((r.termination, r.iterations, r.x[0]), (Termination::NonFinite { iteration: 2 }, 1, 2.0));
    }
}

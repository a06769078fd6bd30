//! The solver loop allocates nothing: with the operator's buffers sized by a first
//! solve, a solve of 13 iterations makes exactly as many heap allocations as one of 3
//! (the difference would be the per-iteration allocations).

use rollcam::model::data::DataTerm;
use rollcam::model::op::Operator;
use rollcam::perf::bench::{build, preset, scene};
use rollcam::solve::optimize::{Fista, NoObserver, RestartTest, StopRule};
use rollcam::solve::prox::TotalVariation;
use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};

struct Counting;
static ALLOCS: AtomicUsize = AtomicUsize::new(0);

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, l: Layout) -> *mut u8 {
        ALLOCS.fetch_add(1, Ordering::Relaxed);
        System.alloc(l)
    }
    unsafe fn dealloc(&self, p: *mut u8, l: Layout) {
        System.dealloc(p, l)
    }
    unsafe fn realloc(&self, p: *mut u8, l: Layout, n: usize) -> *mut u8 {
        ALLOCS.fetch_add(1, Ordering::Relaxed);
        System.realloc(p, l, n)
    }
}

#[global_allocator]
static A: Counting = Counting;

#[test]
fn iterations_do_not_allocate() {
    // Inside a pool, rayon schedules on its workers' own deques (calls from outside a
    // pool go through a shared queue that grows in blocks).
    let pool = rayon::ThreadPoolBuilder::new().num_threads(2).build().unwrap();
    pool.install(|| {
        let p = preset("small").unwrap();
        let a = build(&p, None);
        let (k, m, n) = a.video_shape();
        let mut b = vec![0.0; m * n];
        a.forward(&scene(k, m, n), &mut b);
        let tv = TotalVariation::new((k, m, n), 1e-3, 2.0);
        let solve = |iters: usize| {
            let f = Fista { lipschitz: 10.0, stop: StopRule::iterations(iters), restart: Some(RestartTest::Objective) };
            let before = ALLOCS.load(Ordering::SeqCst);
            let r = f.solve(&a, &DataTerm::new(&b), &tv, None, &mut NoObserver);
            assert_eq!(r.iterations, iters);
            ALLOCS.load(Ordering::SeqCst) - before
        };
        solve(2); // sizes the operator's buffers
        let (short, long) = (solve(3), solve(13));
        assert!(short > 0, "the solve's own vectors are allocated before the loop");
        assert_eq!(short, long, "10 more iterations made {} more allocations", long as isize - short as isize);
    });
}

//! [`Ranks`] over MPI's world communicator.
//!
//! Sums of scalars are all-gathered and added in rank order, the sensor image is
//! reduced to rank 0 and broadcast, so every rank holds the same bits. Halo frames go
//! by paired send-receives along the chain of ranks; the video is gathered on rank 0
//! frame by frame (no message over one frame, whatever the video's size).
//!
//! MPI is initialised with `Funneled` threading: only the thread that initialised it
//! calls MPI (the solvers' worker threads never do); every call checks that.

use crate::model::ranks::{Ranks, Traffic};
use mpi::collective::SystemOperation;
use mpi::environment::Universe;
use mpi::point_to_point::{Destination, Source};
use mpi::topology::{Communicator, SimpleCommunicator};
use mpi::traits::{CommunicatorCollectives, Root};
use std::ops::Range;
use std::sync::atomic::{AtomicU64, Ordering};
use std::thread::ThreadId;

/// The processes of `MPI_COMM_WORLD`; MPI is finalised when this is dropped.
pub struct Mpi {
    world: SimpleCommunicator,
    rank: usize,
    size: usize,
    thread: ThreadId,
    sent: AtomicU64,
    received: AtomicU64,
    calls: AtomicU64,
    // Declared last: dropped (MPI finalised) after the communicator.
    _universe: Universe,
}

// SAFETY: the communicator is a handle MPI may only be called with from the thread that
// initialised it (`Funneled`); every method asserts it is on that thread, so sharing a
// reference with the solvers' worker threads never makes them call MPI.
unsafe impl Send for Mpi {}
unsafe impl Sync for Mpi {}

impl Mpi {
    /// Initialise MPI (once per process).
    pub fn init() -> anyhow::Result<Mpi> {
        let (universe, threading) =
            mpi::initialize_with_threading(mpi::Threading::Funneled).ok_or_else(|| anyhow::anyhow!("MPI was already initialised in this process"))?;
        if threading < mpi::Threading::Funneled {
            tracing::warn!(?threading, "the MPI library gives less than funneled threading; MPI calls are made from the main thread only");
        }
        let world = universe.world();
        let (rank, size) = (world.rank() as usize, world.size() as usize);
        Ok(Mpi {
            world,
            rank,
            size,
            thread: std::thread::current().id(),
            sent: AtomicU64::new(0),
            received: AtomicU64::new(0),
            calls: AtomicU64::new(0),
            _universe: universe,
        })
    }

    /// End every process of the run with `code` (an error on one rank would leave the
    /// others waiting in a collective).
    pub fn abort(&self, code: i32) -> ! {
        self.world.abort(code)
    }

    fn count(&self, sent: usize, received: usize) {
        assert_eq!(std::thread::current().id(), self.thread, "MPI called from a thread other than the one that initialised it");
        self.sent.fetch_add(sent as u64, Ordering::Relaxed);
        self.received.fetch_add(received as u64, Ordering::Relaxed);
        self.calls.fetch_add(1, Ordering::Relaxed);
    }
}

impl Ranks for Mpi {
    fn rank(&self) -> usize {
        self.rank
    }
    fn size(&self) -> usize {
        self.size
    }

    fn sum_f64(&self, values: &mut [f64]) {
        let n = values.len();
        let mut all = vec![0.0f64; n * self.size];
        self.count(8 * n * (self.size - 1), 8 * n * (self.size - 1));
        self.world.all_gather_into(&values[..], &mut all[..]);
        for (i, v) in values.iter_mut().enumerate() {
            *v = (0..self.size).map(|r| all[r * n + i]).sum();
        }
    }

    fn max_f64(&self, values: &mut [f64]) {
        let send = values.to_vec();
        self.count(8 * values.len() * (self.size - 1), 8 * values.len() * (self.size - 1));
        self.world.all_reduce_into(&send[..], values, SystemOperation::max());
    }

    fn sum_f32(&self, values: &mut [f32]) {
        let bytes = 4 * values.len();
        let root = self.world.process_at_rank(0);
        if self.rank == 0 {
            let send = values.to_vec();
            self.count(bytes * (self.size - 1), bytes * (self.size - 1));
            root.reduce_into_root(&send[..], values, SystemOperation::sum());
        } else {
            self.count(bytes, bytes);
            root.reduce_into(&values[..], SystemOperation::sum());
        }
        root.broadcast_into(values);
    }

    fn broadcast_f64(&self, values: &mut [f64]) {
        let bytes = 8 * values.len();
        if self.rank == 0 {
            self.count(bytes * (self.size - 1), 0);
        } else {
            self.count(0, bytes);
        }
        self.world.process_at_rank(0).broadcast_into(values);
    }

    fn exchange_halo(&self, first: &[f32], last: &[f32], before: &mut [f32], after: &mut [f32]) {
        if self.size == 1 {
            return;
        }
        let (r, end) = (self.rank, self.size - 1);
        let prev = (r > 0).then(|| self.world.process_at_rank(r as i32 - 1));
        let next = (r < end).then(|| self.world.process_at_rank(r as i32 + 1));
        // First frames go down the chain, last frames up; each rank sends and receives
        // at most one frame each way.
        match (&prev, &next) {
            (Some(p), Some(n)) => {
                mpi::point_to_point::send_receive_into(first, p, after, n);
                mpi::point_to_point::send_receive_into(last, n, before, p);
            }
            (None, Some(n)) => {
                n.receive_into(after);
                n.send(last);
            }
            (Some(p), None) => {
                p.send(first);
                p.receive_into(before);
            }
            (None, None) => {}
        }
        let sent = 4 * (prev.is_some() as usize * first.len() + next.is_some() as usize * last.len());
        let received = 4 * (prev.is_some() as usize * before.len() + next.is_some() as usize * after.len());
        self.count(sent, received);
    }

    fn gather_frames(&self, local: &[f32], blocks: &[Range<usize>], frame_len: usize, out: Option<&mut [f32]>) {
        let origin = blocks[0].start;
        if self.rank == 0 {
            let out = out.expect("rank 0 gathers the video");
            let mine = &blocks[0];
            out[(mine.start - origin) * frame_len..(mine.end - origin) * frame_len].copy_from_slice(local);
            for (r, b) in blocks.iter().enumerate().skip(1) {
                let p = self.world.process_at_rank(r as i32);
                for f in b.clone() {
                    p.receive_into(&mut out[(f - origin) * frame_len..(f - origin + 1) * frame_len]);
                }
                self.count(0, 4 * b.len() * frame_len);
            }
        } else {
            let root = self.world.process_at_rank(0);
            for frame in local.chunks(frame_len) {
                root.send(frame);
            }
            self.count(4 * local.len(), 0);
        }
    }

    fn traffic(&self) -> Traffic {
        Traffic {
            sent_bytes: self.sent.load(Ordering::Relaxed),
            received_bytes: self.received.load(Ordering::Relaxed),
            calls: self.calls.load(Ordering::Relaxed),
        }
    }
}

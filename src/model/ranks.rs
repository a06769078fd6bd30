//! Processes that share one problem (MPI ranks), each holding a contiguous block of the
//! video's frames: the few exchanges the forward model and the solvers need, as a
//! trait with no MPI in it. [`One`] is the single process; the MPI implementation lives
//! in `crate::cluster` (cargo feature `mpi`).
//!
//! Every reduction gives every rank the same bits (the implementation adds in rank
//! order, or reduces to rank 0 and broadcasts), so decisions taken from reduced values
//! (FISTA's restart, the stopping rules) are taken alike on every rank.

use crate::model::shutter::ShutterWeights;
use std::ops::Range;

/// Bytes one process has handed to and received from the exchanges so far.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct Traffic {
    pub sent_bytes: u64,
    pub received_bytes: u64,
    /// Collective and point-to-point calls made.
    pub calls: u64,
}

impl std::ops::Add for Traffic {
    type Output = Traffic;
    fn add(self, o: Traffic) -> Traffic {
        Traffic { sent_bytes: self.sent_bytes + o.sent_bytes, received_bytes: self.received_bytes + o.received_bytes, calls: self.calls + o.calls }
    }
}

impl Traffic {
    /// The traffic between `earlier` and `self`.
    pub fn since(self, earlier: Traffic) -> Traffic {
        Traffic {
            sent_bytes: self.sent_bytes - earlier.sent_bytes,
            received_bytes: self.received_bytes - earlier.received_bytes,
            calls: self.calls - earlier.calls,
        }
    }
}

/// The processes that share a problem.
pub trait Ranks: Send + Sync {
    /// This process's rank, `0..size()`.
    fn rank(&self) -> usize;
    /// Number of processes.
    fn size(&self) -> usize;
    /// Sum every entry over the ranks.
    fn sum_f64(&self, values: &mut [f64]);
    /// Largest value of every entry over the ranks.
    fn max_f64(&self, values: &mut [f64]);
    /// Sum a sensor-sized image over the ranks (the forward's partial sums).
    fn sum_f32(&self, values: &mut [f32]);
    /// Rank 0's values on every rank.
    fn broadcast_f64(&self, values: &mut [f64]);
    /// Send `first` to the previous rank and `last` to the next; receive the previous
    /// rank's `last` into `before` and the next rank's `first` into `after`. The ends
    /// (rank 0's `before`, the last rank's `after`) are left as they are. Empty `last`
    /// and `before` on every rank make it one-way (first frames only).
    fn exchange_halo(&self, first: &[f32], last: &[f32], before: &mut [f32], after: &mut [f32]);
    /// Gather every rank's block of frames (`blocks[r]` frames of `frame_len` values,
    /// `local` on this rank) into `out` on rank 0, in frame order; other ranks pass
    /// `None`.
    fn gather_frames(&self, local: &[f32], blocks: &[Range<usize>], frame_len: usize, out: Option<&mut [f32]>);
    /// What this process has exchanged so far.
    fn traffic(&self) -> Traffic {
        Traffic::default()
    }
    /// Whether any rank says `flag`.
    fn any(&self, flag: bool) -> bool {
        if self.size() == 1 {
            return flag;
        }
        let mut v = [flag as u8 as f64];
        self.max_f64(&mut v);
        v[0] > 0.0
    }
}

/// How a problem's vectors are spread over the processes: the ranks (sums over the
/// input, the video, are summed over them) and the output entries this rank counts in
/// sums over the output (a rank's block is exact only on the sensor rows its frames
/// touch, [`crate::model::split`]; every entry is counted by exactly one rank).
#[derive(Clone, Copy)]
pub struct Partition<'a> {
    pub ranks: &'a dyn Ranks,
    /// `None`: every output entry (one process).
    pub owned: Option<&'a [bool]>,
}

impl Partition<'static> {
    /// One process holding the whole problem.
    pub const ONE: Partition<'static> = Partition { ranks: &One, owned: None };
}

impl Partition<'_> {
    /// `||y||^2` of an output, in f64, over the ranks (each entry counted once).
    pub fn output_norm_sq(&self, y: &[f32]) -> f64 {
        let local = match self.owned {
            None => crate::model::op::dot(y, y),
            Some(o) => y.iter().zip(o).filter(|(_, &own)| own).map(|(&v, _)| v as f64 * v as f64).sum(),
        };
        let mut s = [local];
        self.ranks.sum_f64(&mut s);
        s[0]
    }
}

/// One process: every exchange is the identity.
#[derive(Clone, Copy, Debug, Default)]
pub struct One;

impl Ranks for One {
    fn rank(&self) -> usize {
        0
    }
    fn size(&self) -> usize {
        1
    }
    fn sum_f64(&self, _: &mut [f64]) {}
    fn max_f64(&self, _: &mut [f64]) {}
    fn sum_f32(&self, _: &mut [f32]) {}
    fn broadcast_f64(&self, _: &mut [f64]) {}
    fn exchange_halo(&self, _: &[f32], _: &[f32], _: &mut [f32], _: &mut [f32]) {}
    fn gather_frames(&self, local: &[f32], _: &[Range<usize>], _: usize, out: Option<&mut [f32]>) {
        if let Some(out) = out {
            out.copy_from_slice(local);
        }
    }
}

/// Contiguous blocks of `work.len()` frames for `ranks` processes, each with about the
/// same total `work` (the cost of a frame: the sensor rows it is exposed on, plus a
/// share for the element-wise passes, [`frame_work`]). Every block holds at least one
/// frame; `None` when there are fewer frames than ranks.
pub fn balanced_blocks(work: &[f64], ranks: usize) -> Option<Vec<Range<usize>>> {
    let k = work.len();
    if ranks == 0 || k < ranks {
        return None;
    }
    let total: f64 = work.iter().sum();
    let mut blocks = Vec::with_capacity(ranks);
    let mut start = 0usize;
    let mut acc = 0.0f64;
    for r in 0..ranks {
        let left = ranks - r - 1;
        if left == 0 {
            blocks.push(start..k);
            break;
        }
        let target = total * (r + 1) as f64 / ranks as f64;
        let mut end = start + 1;
        acc += work[start];
        // Take frames while the running sum stays closer to the target with them,
        // leaving at least one frame for each later block.
        while end < k - left && (acc + work[end] - target).abs() <= (acc - target).abs() {
            acc += work[end];
            end += 1;
        }
        blocks.push(start..end);
        start = end;
    }
    Some(blocks)
}

/// The cost of each frame of `weights` in one iteration, in sensor rows: the rows its
/// shutter weights touch (the forward and adjoint sum each of those over the frame's
/// rows), plus `video_rows / 8` for the frame's own passes (its row transforms, the TV
/// map, the element-wise updates), which every frame pays, exposed or not. The eighth
/// is an estimate, not a measurement per preset.
pub fn frame_work(weights: &ShutterWeights, video_rows: usize) -> Vec<f64> {
    (0..weights.frames()).map(|k| weights.rows_of_frame(k).iter().map(|r| r.len()).sum::<usize>() as f64 + video_rows as f64 / 8.0).collect()
}

/// Ranks as threads of one process (tests): edge frames over channels along the chain,
/// collectives through a shared board between two barriers, sums in rank order as the
/// MPI ranks add them.
#[cfg(test)]
pub(crate) mod threads {
    use super::Ranks;
    use std::ops::Range;
    use std::sync::mpsc::{channel, Receiver, Sender};
    use std::sync::{Arc, Barrier, Mutex};

    struct Board {
        barrier: Barrier,
        f64s: Mutex<Vec<Vec<f64>>>,
        f32s: Mutex<Vec<Vec<f32>>>,
    }

    pub(crate) struct ThreadRanks {
        rank: usize,
        size: usize,
        to_prev: Option<Sender<Vec<f32>>>,
        to_next: Option<Sender<Vec<f32>>>,
        from_prev: Mutex<Option<Receiver<Vec<f32>>>>,
        from_next: Mutex<Option<Receiver<Vec<f32>>>>,
        board: Arc<Board>,
    }

    impl ThreadRanks {
        /// `size` ranks, rank `r` at index `r`: hand each to its own thread.
        pub(crate) fn chain(size: usize) -> Vec<ThreadRanks> {
            let board = Arc::new(Board { barrier: Barrier::new(size), f64s: Mutex::new(vec![Vec::new(); size]), f32s: Mutex::new(vec![Vec::new(); size]) });
            let mut ranks: Vec<ThreadRanks> = (0..size)
                .map(|rank| ThreadRanks {
                    rank,
                    size,
                    to_prev: None,
                    to_next: None,
                    from_prev: Mutex::new(None),
                    from_next: Mutex::new(None),
                    board: board.clone(),
                })
                .collect();
            for r in 0..size.saturating_sub(1) {
                let (up, up_rx) = channel();
                let (down, down_rx) = channel();
                ranks[r].to_next = Some(up);
                *ranks[r + 1].from_prev.get_mut().unwrap() = Some(up_rx);
                ranks[r + 1].to_prev = Some(down);
                *ranks[r].from_next.get_mut().unwrap() = Some(down_rx);
            }
            ranks
        }

        /// Post `mine` in this rank's slot of `slots`, then let `read` see every rank's
        /// (between two barriers, so no slot changes while it is read).
        fn post<T: Clone, R>(&self, slots: &Mutex<Vec<Vec<T>>>, mine: &[T], read: impl FnOnce(&[Vec<T>]) -> R) -> R {
            slots.lock().unwrap()[self.rank] = mine.to_vec();
            self.board.barrier.wait();
            let r = read(&slots.lock().unwrap());
            self.board.barrier.wait();
            r
        }
    }

    impl Ranks for ThreadRanks {
        fn rank(&self) -> usize {
            self.rank
        }
        fn size(&self) -> usize {
            self.size
        }
        fn sum_f64(&self, values: &mut [f64]) {
            let mine = values.to_vec();
            self.post(&self.board.f64s, &mine, |all| {
                for (i, v) in values.iter_mut().enumerate() {
                    *v = all.iter().map(|a| a[i]).sum();
                }
            });
        }
        fn max_f64(&self, values: &mut [f64]) {
            let mine = values.to_vec();
            self.post(&self.board.f64s, &mine, |all| {
                for (i, v) in values.iter_mut().enumerate() {
                    *v = all.iter().map(|a| a[i]).fold(f64::NEG_INFINITY, f64::max);
                }
            });
        }
        fn sum_f32(&self, values: &mut [f32]) {
            let mine = values.to_vec();
            self.post(&self.board.f32s, &mine, |all| {
                for (i, v) in values.iter_mut().enumerate() {
                    *v = all.iter().map(|a| a[i]).sum();
                }
            });
        }
        fn broadcast_f64(&self, values: &mut [f64]) {
            let mine = values.to_vec();
            self.post(&self.board.f64s, &mine, |all| values.copy_from_slice(&all[0]));
        }
        fn exchange_halo(&self, first: &[f32], last: &[f32], before: &mut [f32], after: &mut [f32]) {
            if let Some(tx) = &self.to_prev {
                tx.send(first.to_vec()).unwrap();
            }
            if let Some(tx) = &self.to_next {
                tx.send(last.to_vec()).unwrap();
            }
            if let Some(rx) = &*self.from_prev.lock().unwrap() {
                before.copy_from_slice(&rx.recv().unwrap());
            }
            if let Some(rx) = &*self.from_next.lock().unwrap() {
                after.copy_from_slice(&rx.recv().unwrap());
            }
        }
        fn gather_frames(&self, local: &[f32], blocks: &[Range<usize>], frame_len: usize, out: Option<&mut [f32]>) {
            let origin = blocks[0].start;
            self.post(&self.board.f32s, local, |all| {
                if let Some(out) = out {
                    for (b, part) in blocks.iter().zip(all) {
                        out[(b.start - origin) * frame_len..(b.end - origin) * frame_len].copy_from_slice(part);
                    }
                }
            });
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn blocks_cover_every_frame_once_in_order() {
        for ranks in 1..6 {
            for k in ranks..20 {
                let work: Vec<f64> = (0..k).map(|i| 1.0 + (i % 3) as f64).collect();
                let b = balanced_blocks(&work, ranks).unwrap();
                assert_eq!(b.len(), ranks);
                assert_eq!(b[0].start, 0);
                assert_eq!(b[ranks - 1].end, k);
                for w in b.windows(2) {
                    assert_eq!(w[0].end, w[1].start);
                }
                assert!(b.iter().all(|r| !r.is_empty()), "{b:?}");
            }
        }
        assert!(balanced_blocks(&[1.0, 1.0], 3).is_none());
    }

    #[test]
    fn blocks_follow_the_work_not_the_count() {
        // The first half of the frames costs three times the second half's.
        let work: Vec<f64> = (0..40).map(|i| if i < 20 { 3.0 } else { 1.0 }).collect();
        let b = balanced_blocks(&work, 2).unwrap();
        let sums: Vec<f64> = b.iter().map(|r| work[r.clone()].iter().sum()).collect();
        assert_eq!(b[0], 0..13, "{b:?}");
        assert!((sums[0] - sums[1]).abs() <= 3.0, "{sums:?}");
        // Equal work: equal counts.
        assert_eq!(balanced_blocks(&[1.0; 9], 3).unwrap(), vec![0..3, 3..6, 6..9]);
    }
}

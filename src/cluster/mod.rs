//! Several processes on one capture: the MPI implementation of
//! [`crate::model::ranks::Ranks`] (cargo feature `mpi`, the system Open MPI through the
//! `mpi` crate), and how a process learns that an MPI launcher started it.
//!
//! Only the command line uses this layer; the model and the solvers see the trait.

#[cfg(feature = "mpi")]
pub mod mpi;

/// Environment variables through which MPI launchers give each process the number of
/// processes started (Open MPI's `mpirun`, then MPICH's and Intel MPI's Hydra).
const MPI_SIZE_VARIABLES: [&str; 2] = ["OMPI_COMM_WORLD_SIZE", "PMI_SIZE"];

/// The number of processes an MPI launcher started (one included: `mpirun -np 1`),
/// with the variable that says so; `None` when no launcher started this process.
pub fn launched_ranks() -> Option<(u64, &'static str)> {
    MPI_SIZE_VARIABLES.iter().find_map(|&var| std::env::var(var).ok().and_then(|v| v.trim().parse::<u64>().ok()).filter(|&n| n >= 1).map(|n| (n, var)))
}

/// Whether this build can split a capture across MPI ranks.
pub const MPI_BUILT: bool = cfg!(feature = "mpi");

/// How many of the launcher's processes run on this machine (Open MPI's
/// `OMPI_COMM_WORLD_LOCAL_SIZE`, MPICH's `MPI_LOCALNRANKS`), when it says.
pub fn ranks_on_this_machine() -> Option<usize> {
    ["OMPI_COMM_WORLD_LOCAL_SIZE", "MPI_LOCALNRANKS"]
        .iter()
        .find_map(|v| std::env::var(v).ok().and_then(|s| s.trim().parse::<usize>().ok()).filter(|&n| n >= 1))
}

/// A warning for a rank with more worker threads than the CPUs it may run on (an MPI
/// launcher binds each rank to one core by default, and the threads then share it), or
/// `None`.
pub fn binding_warning(rank: usize, threads: usize) -> Option<String> {
    let cpus = std::thread::available_parallelism().map(|n| n.get()).ok()?;
    (threads > cpus).then(|| {
        format!("MPI rank {rank} has {threads} worker threads but may run on {cpus} CPU(s): they share them; give mpirun --bind-to none (or a binding to a socket), or fewer threads (RAYON_NUM_THREADS)")
    })
}

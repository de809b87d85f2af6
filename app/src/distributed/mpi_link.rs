//! [`Link`] over MPI (rsmpi, the system's OpenMPI or MPICH), and the `--mpi` entry point.
//!
//! MPI is initialized asking for `MPI_THREAD_MULTIPLE` and accepted from
//! `MPI_THREAD_SERIALIZED` up: the viewer renders from a job thread, not from the thread
//! that initialized MPI, and calls are serialized by a lock here. Messages are byte
//! vectors with the [`Tag`] as MPI tag, received with `MPI_Improbe` (polling: a blocking
//! probe spins a core).

use std::sync::Mutex;

use mpi::Threading;
use mpi::point_to_point::{Destination as _, MatchedReceiveVec as _, Source as _};
use mpi::topology::{Communicator as _, SimpleCommunicator};

use super::link::{Envelope, Link, Tag};

/// The world communicator, one MPI call at a time.
pub struct MpiLink {
    rank: usize,
    size: usize,
    calls: Mutex<()>,
}

impl MpiLink {
    /// Call after [`initialize`].
    pub fn world() -> Self {
        let world = SimpleCommunicator::world();
        Self {
            rank: world.rank() as usize,
            size: world.size() as usize,
            calls: Mutex::new(()),
        }
    }
}

/// Room for rank 0's buffered sends: jobs (a few kB) and batches (a few bytes) to every rank,
/// with a rank that has stopped reading them.
const SEND_BUFFER_BYTES: usize = 16 << 20;

/// Initializes MPI (once per process) and attaches the buffer of rank 0's sends; the universe
/// finalizes MPI when dropped (which waits for buffered sends to be delivered: with a rank that
/// stopped answering, end the job with [`Link::abort`] instead).
pub fn initialize() -> anyhow::Result<mpi::environment::Universe> {
    let (mut universe, level) = mpi::initialize_with_threading(Threading::Multiple)
        .ok_or_else(|| anyhow::anyhow!("MPI was already initialized"))?;
    universe.set_buffer_size(SEND_BUFFER_BYTES);
    if level < Threading::Serialized {
        anyhow::bail!(
            "this MPI library offers thread level {level:?}; Isoscope needs at least Serialized"
        );
    }
    Ok(universe)
}

impl Link for MpiLink {
    fn rank(&self) -> usize {
        self.rank
    }

    fn size(&self) -> usize {
        self.size
    }

    fn send(&self, to: usize, tag: Tag, bytes: &[u8]) {
        let _guard = self.calls.lock();
        let world = SimpleCommunicator::world();
        let process = world.process_at_rank(to as i32);
        if self.rank == 0 {
            // Buffered (MPI_Bsend, into the buffer `initialize` attaches): rank 0 must never
            // block on a rank that has stopped, or it could not notice the silence and fail
            // the frame (a blocking send waits for the receiver once a message passes the
            // eager limit or its queue is full).
            process.buffered_send_with_tag(bytes, tag as i32);
        } else {
            process.send_with_tag(bytes, tag as i32);
        }
    }

    fn try_recv(&self) -> Option<Envelope> {
        let _guard = self.calls.lock();
        let world = SimpleCommunicator::world();
        let matched = world.any_process().immediate_matched_probe()?;
        let (bytes, status) = matched.matched_receive_vec::<u8>();
        Some(Envelope {
            from: status.source_rank() as usize,
            tag: Tag::from_i32(status.tag())?,
            bytes,
        })
    }

    fn recv(&self) -> Option<Envelope> {
        // Polls rather than blocking in MPI_Mprobe, which spins a core at 100 % in OpenMPI
        // and would take it from the rendering threads of a rank sharing the node.
        loop {
            if let Some(e) = self.try_recv() {
                return Some(e);
            }
            std::thread::sleep(std::time::Duration::from_micros(100));
        }
    }

    fn abort(&self, code: i32) {
        SimpleCommunicator::world().abort(code);
    }
}

//! The message link between ranks: MPI in a real job (`mpi_link`, cargo feature
//! `mpi`), threads and channels in tests ([`LocalLink`]), behind one small trait.
//!
//! Every message is a tag and bytes, point to point. Rank 0 polls without blocking (it
//! renders its own chunks between polls and must notice a silent rank); the other ranks
//! only ever wait for rank 0.

use std::sync::Mutex;
use std::sync::mpsc::{Receiver, Sender, channel};

/// What a message is (its MPI tag).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
pub enum Tag {
    /// 0 → worker: a frame to render ([`super::wire::FrameJob`], JSON).
    Job = 1,
    /// 0 → worker: chunk ids of the frame to render; none: the frame is done.
    Batch = 2,
    /// 0 → worker: end the serve loop.
    Quit = 3,
    /// worker → 0: the input is open (empty), once, before any frame.
    Opened = 10,
    /// worker → 0: ready for the frame of its job (frame number).
    Ready = 11,
    /// worker → 0: the pixels of a batch ([`super::wire::BatchResult`]).
    Result = 12,
    /// worker → 0: opening or preparing a frame failed (UTF-8 text).
    Error = 13,
}

impl Tag {
    pub fn from_i32(tag: i32) -> Option<Tag> {
        Some(match tag {
            1 => Tag::Job,
            2 => Tag::Batch,
            3 => Tag::Quit,
            10 => Tag::Opened,
            11 => Tag::Ready,
            12 => Tag::Result,
            13 => Tag::Error,
            _ => return None,
        })
    }
}

/// A received message.
#[derive(Debug, Clone, PartialEq)]
pub struct Envelope {
    pub from: usize,
    pub tag: Tag,
    pub bytes: Vec<u8>,
}

/// Point-to-point messages between the ranks of one job.
pub trait Link: Send {
    fn rank(&self) -> usize;
    /// Number of ranks.
    fn size(&self) -> usize;
    fn send(&self, to: usize, tag: Tag, bytes: &[u8]);
    /// A message from any rank, if one has arrived.
    fn try_recv(&self) -> Option<Envelope>;
    /// Waits for a message from any rank (`None` when the link is gone).
    fn recv(&self) -> Option<Envelope>;
    /// Ends every rank of the job (MPI_Abort); used when a rank stops answering.
    fn abort(&self, code: i32);
}

/// Ranks as threads of one process, for tests: an unbounded channel per rank.
pub struct LocalLink {
    rank: usize,
    inbox: Mutex<Receiver<Envelope>>,
    /// A sender to every other rank's inbox (none to its own, so that its inbox
    /// disconnects when every other rank has ended).
    peers: Vec<Option<Sender<Envelope>>>,
}

impl LocalLink {
    /// The links of a job of `size` ranks, rank order.
    pub fn group(size: usize) -> Vec<LocalLink> {
        let (senders, receivers): (Vec<_>, Vec<_>) = (0..size).map(|_| channel()).unzip();
        receivers
            .into_iter()
            .enumerate()
            .map(|(rank, inbox)| LocalLink {
                rank,
                inbox: Mutex::new(inbox),
                peers: senders
                    .iter()
                    .enumerate()
                    .map(|(r, s)| (r != rank).then(|| s.clone()))
                    .collect(),
            })
            .collect()
    }
}

impl Link for LocalLink {
    fn rank(&self) -> usize {
        self.rank
    }

    fn size(&self) -> usize {
        self.peers.len()
    }

    fn send(&self, to: usize, tag: Tag, bytes: &[u8]) {
        // A rank that has ended drops its inbox; like MPI to a dead rank, nothing arrives.
        if let Some(Some(peer)) = self.peers.get(to) {
            let _ = peer.send(Envelope {
                from: self.rank,
                tag,
                bytes: bytes.to_vec(),
            });
        }
    }

    fn try_recv(&self) -> Option<Envelope> {
        // Empty or disconnected: nothing to read either way.
        self.inbox.lock().ok()?.try_recv().ok()
    }

    fn recv(&self) -> Option<Envelope> {
        self.inbox.lock().ok()?.recv().ok()
    }

    fn abort(&self, code: i32) {
        panic!("rank {} aborted the job with code {code}", self.rank);
    }
}

//! Which rank renders which tiles of a frame: dynamic batches, stable from frame to frame.
//!
//! The image is cut into *chunks* of [`CHUNK_TILES`]×[`CHUNK_TILES`] renderer tiles (64×64
//! samples). At the start of a frame every rank is given a queue: the chunks it rendered in
//! the previous frame of the same size (so that, while the camera moves little, a rank keeps
//! tracing the same part of the data and its caches and resident treelets stay warm; seed
//! 004 §7.5.1), or, for the first frame, one contiguous band of rows per rank. A rank asks
//! for work and gets a *batch* from its own queue, guided-self-scheduling style: about
//! `remaining / (2 · ranks)` chunks, fewer as the frame empties, so that a slow rank ends up
//! with fewer chunks and nobody waits long at the end. A rank whose queue is empty takes
//! chunks from the back of the longest other queue (the chunks its owner would reach last).

use std::collections::VecDeque;

use volume_core::render::{PixelRegion, TILE};

/// Side of a chunk in renderer tiles.
pub const CHUNK_TILES: u32 = 4;

/// The chunk grid of one frame size.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ChunkGrid {
    pub width: u32,
    pub height: u32,
    /// Progressive scale (one ray per `scale × scale` pixels).
    pub scale: u32,
}

impl ChunkGrid {
    /// Side of a chunk in pixels.
    pub fn chunk_px(&self) -> u32 {
        TILE * CHUNK_TILES * self.scale.max(1)
    }

    /// Chunks across and down.
    pub fn dims(&self) -> [u32; 2] {
        let c = self.chunk_px();
        [self.width.div_ceil(c), self.height.div_ceil(c)]
    }

    pub fn len(&self) -> usize {
        let [x, y] = self.dims();
        x as usize * y as usize
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The pixels of chunk `id` (row-major), clipped to the image.
    pub fn region(&self, id: u32) -> PixelRegion {
        let c = self.chunk_px();
        let [nx, _] = self.dims();
        let (cx, cy) = (id % nx, id / nx);
        PixelRegion {
            x: [cx * c, ((cx + 1) * c).min(self.width)],
            y: [cy * c, ((cy + 1) * c).min(self.height)],
        }
    }
}

/// One frame's hand-out of chunks to `ranks` ranks.
#[derive(Debug)]
pub struct Schedule {
    ranks: usize,
    queues: Vec<VecDeque<u32>>,
    remaining: usize,
    /// Who took each chunk this frame.
    owner: Vec<u32>,
}

impl Schedule {
    /// A frame of `grid` over `ranks` ranks; `previous` is who rendered each chunk of the
    /// last frame (used when it has one entry per chunk and names only existing ranks).
    pub fn new(grid: ChunkGrid, ranks: usize, previous: Option<&[u32]>) -> Self {
        let n = grid.len();
        let ranks = ranks.max(1);
        let mut queues = vec![VecDeque::new(); ranks];
        match previous {
            Some(p) if p.len() == n && p.iter().all(|&r| (r as usize) < ranks) => {
                for (id, &r) in p.iter().enumerate() {
                    queues[r as usize].push_back(id as u32);
                }
            }
            _ => {
                // Contiguous row-major runs: rank r starts with chunks [r·n/R, (r+1)·n/R).
                for id in 0..n {
                    queues[id * ranks / n.max(1)].push_back(id as u32);
                }
            }
        }
        Self {
            ranks,
            queues,
            remaining: n,
            owner: vec![0; n],
        }
    }

    /// Chunks not yet handed out.
    pub fn remaining(&self) -> usize {
        self.remaining
    }

    /// The next batch for `rank` (empty when the frame has none left), at most `max` chunks.
    pub fn next_batch(&mut self, rank: usize, max: usize) -> Vec<u32> {
        if self.remaining == 0 || rank >= self.ranks {
            return Vec::new();
        }
        let guided = self.remaining.div_ceil(2 * self.ranks).clamp(1, max.max(1));
        let mut batch = Vec::with_capacity(guided);
        if self.queues[rank].is_empty() {
            // Steal from the back of the longest queue, at most half of it.
            let victim = (0..self.ranks)
                .max_by_key(|&r| self.queues[r].len())
                .expect("at least one rank");
            let take = guided.min(self.queues[victim].len().div_ceil(2));
            for _ in 0..take {
                batch.extend(self.queues[victim].pop_back());
            }
            batch.reverse();
        } else {
            let take = guided.min(self.queues[rank].len());
            batch.extend(self.queues[rank].drain(..take));
        }
        self.remaining -= batch.len();
        for &id in &batch {
            self.owner[id as usize] = rank as u32;
        }
        batch
    }

    /// Who took each chunk; the `previous` of the next frame.
    pub fn owners(&self) -> &[u32] {
        &self.owner
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn chunks_tile_the_image_exactly() {
        for grid in [
            ChunkGrid {
                width: 1024,
                height: 1024,
                scale: 1,
            },
            ChunkGrid {
                width: 150,
                height: 70,
                scale: 1,
            },
            ChunkGrid {
                width: 150,
                height: 70,
                scale: 4,
            },
        ] {
            let mut covered = vec![0u8; (grid.width * grid.height) as usize];
            for id in 0..grid.len() as u32 {
                let r = grid.region(id);
                assert!(r.x[0] < r.x[1] && r.y[0] < r.y[1], "{grid:?} chunk {id}");
                assert_eq!(r.x[0] % grid.chunk_px(), 0);
                for y in r.y[0]..r.y[1] {
                    for x in r.x[0]..r.x[1] {
                        covered[(y * grid.width + x) as usize] += 1;
                    }
                }
            }
            assert!(covered.iter().all(|&c| c == 1), "{grid:?}");
        }
        let g = ChunkGrid {
            width: 1024,
            height: 1024,
            scale: 1,
        };
        assert_eq!((g.dims(), g.len()), ([16, 16], 256));
    }

    fn drain(s: &mut Schedule, order: &[usize]) -> Vec<Vec<u32>> {
        let mut got = vec![Vec::new(); s.ranks];
        'outer: loop {
            for &r in order {
                if s.remaining() == 0 {
                    break 'outer;
                }
                got[r].extend(s.next_batch(r, usize::MAX));
            }
        }
        got
    }

    #[test]
    fn every_chunk_is_handed_out_once_and_a_fast_rank_takes_more() {
        let grid = ChunkGrid {
            width: 1024,
            height: 768,
            scale: 1,
        };
        let mut s = Schedule::new(grid, 3, None);
        // Rank 2 asks three times as often as the others.
        let got = drain(&mut s, &[0, 1, 2, 2, 2]);
        let mut all: Vec<u32> = got.concat();
        all.sort_unstable();
        assert_eq!(all, (0..grid.len() as u32).collect::<Vec<_>>());
        assert!(got[2].len() > got[0].len() && got[2].len() > got[1].len());
        assert!(s.next_batch(0, 8).is_empty());
        for (r, chunks) in got.iter().enumerate() {
            assert!(chunks.iter().all(|&c| s.owners()[c as usize] == r as u32));
        }
    }

    #[test]
    fn the_next_frame_starts_from_the_chunks_each_rank_had() {
        let grid = ChunkGrid {
            width: 512,
            height: 512,
            scale: 1,
        };
        let mut first = Schedule::new(grid, 2, None);
        let got = drain(&mut first, &[0, 1, 1]);
        let owners = first.owners().to_vec();
        // Same speeds: every rank gets back exactly its chunks.
        let mut second = Schedule::new(grid, 2, Some(&owners));
        let again = drain(&mut second, &[0, 1, 1]);
        let sorted = |v: &Vec<u32>| {
            let mut v = v.clone();
            v.sort_unstable();
            v
        };
        assert_eq!(sorted(&again[0]), sorted(&got[0]));
        assert_eq!(sorted(&again[1]), sorted(&got[1]));
        // A history of another size or naming a missing rank is ignored.
        let s = Schedule::new(grid, 1, Some(&owners));
        assert_eq!(s.queues[0].len(), grid.len());
        let s = Schedule::new(grid, 2, Some(&owners[1..]));
        assert_eq!(s.queues[0].len() + s.queues[1].len(), grid.len());
    }

    #[test]
    fn batches_shrink_as_the_frame_empties() {
        let grid = ChunkGrid {
            width: 1024,
            height: 1024,
            scale: 1,
        };
        let mut s = Schedule::new(grid, 2, None);
        let first = s.next_batch(0, usize::MAX).len();
        assert_eq!(first, 64); // 256 / (2·2)
        let mut last = first;
        while s.remaining() > 0 {
            let b = s.next_batch(1, usize::MAX).len();
            assert!(b <= last && b >= 1);
            last = b;
        }
        assert_eq!(last, 1);
        assert_eq!(
            Schedule::new(grid, 2, None).next_batch(0, 4).len(),
            4,
            "capped"
        );
    }
}

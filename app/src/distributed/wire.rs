//! What travels between the ranks: a frame's job (JSON: small, once per frame), batches of
//! chunk ids, and the pixels of rendered chunks (little-endian binary: RGBA8 and f32 depth,
//! the bulk of the traffic).
//!
//! Floats in the job survive the trip bit for bit (serde_json with `float_roundtrip`), so
//! every rank traces exactly the rays a single process would.

use serde::{Deserialize, Serialize};
use volume_core::intersect::Intersector;
use volume_core::render::{Camera, Frame, RenderSettings};

use super::schedule::ChunkGrid;

/// One frame as rank 0 asks it: everything a rank needs besides the data it opened.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FrameJob {
    /// Frame number, echoed in every answer.
    pub frame: u64,
    pub camera: Camera,
    pub settings: RenderSettings,
    /// Time step the frame shows.
    pub step: usize,
    /// The point array a mesh draws (`None`: the scene's current one, or not a mesh).
    pub field: Option<String>,
    pub intersector: Intersector,
    pub smooth_normals: bool,
    /// Out-of-core: rank 0's loaded levels; a rank first waits (at most `level_wait_ms`)
    /// until it has as many, so that every tile is drawn from the same level.
    pub levels: usize,
    pub level_wait_ms: u64,
}

impl FrameJob {
    pub fn grid(&self) -> ChunkGrid {
        ChunkGrid {
            width: self.settings.width,
            height: self.settings.height,
            scale: self.settings.scale.max(1),
        }
    }
}

/// Errors decoding a message (a bug or a mismatched build on some rank, never user input).
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum WireError {
    #[error("message of {len} bytes is too short for {what}")]
    Short { what: &'static str, len: usize },
    #[error("chunk {id} is outside the frame's {count} chunks")]
    Chunk { id: u32, count: usize },
    #[error("bad frame job: {0}")]
    Job(String),
}

pub fn encode_job(job: &FrameJob) -> Vec<u8> {
    serde_json::to_vec(job).expect("a frame job serializes")
}

pub fn decode_job(bytes: &[u8]) -> Result<FrameJob, WireError> {
    serde_json::from_slice(bytes).map_err(|e| WireError::Job(e.to_string()))
}

/// Frame number then chunk ids.
pub fn encode_batch(frame: u64, chunks: &[u32]) -> Vec<u8> {
    let mut out = Vec::with_capacity(8 + 4 * chunks.len());
    out.extend_from_slice(&frame.to_le_bytes());
    for c in chunks {
        out.extend_from_slice(&c.to_le_bytes());
    }
    out
}

pub fn decode_batch(bytes: &[u8]) -> Result<(u64, Vec<u32>), WireError> {
    if bytes.len() < 8 || !(bytes.len() - 8).is_multiple_of(4) {
        return Err(WireError::Short {
            what: "a batch",
            len: bytes.len(),
        });
    }
    let frame = u64::from_le_bytes(bytes[..8].try_into().expect("8 bytes"));
    let chunks = bytes[8..]
        .chunks_exact(4)
        .map(|c| u32::from_le_bytes(c.try_into().expect("4 bytes")))
        .collect();
    Ok((frame, chunks))
}

/// A frame number alone (`Ready`).
pub fn encode_frame(frame: u64) -> Vec<u8> {
    frame.to_le_bytes().to_vec()
}

pub fn decode_frame(bytes: &[u8]) -> Result<u64, WireError> {
    bytes
        .try_into()
        .map(u64::from_le_bytes)
        .map_err(|_| WireError::Short {
            what: "a frame number",
            len: bytes.len(),
        })
}

/// A rank's rendered batch: its pixels and what it cost.
#[derive(Debug, Clone, PartialEq)]
pub struct BatchResult {
    pub frame: u64,
    /// Time the rank spent rendering the batch.
    pub render_ns: u64,
    /// Primary, transparency and shadow rays traced.
    pub rays: [u64; 3],
    /// Chunk ids, and per chunk its region's RGBA8 rows then its f32 depths.
    pub chunks: Vec<u32>,
    pub rgba8: Vec<u8>,
    pub depth: Vec<f32>,
}

const RESULT_HEADER: usize = 8 + 8 + 24 + 4;

impl BatchResult {
    /// Copies `chunks`' regions out of `frame` (rendered at `grid`'s size).
    pub fn from_frame(
        frame_number: u64,
        grid: ChunkGrid,
        chunks: &[u32],
        frame: &Frame,
        render_ns: u64,
        rays: [u64; 3],
    ) -> Self {
        let mut rgba8 = Vec::new();
        let mut depth = Vec::new();
        let w = grid.width as usize;
        for &id in chunks {
            let r = grid.region(id);
            let (x0, x1) = (r.x[0] as usize, r.x[1] as usize);
            for y in r.y[0] as usize..r.y[1] as usize {
                rgba8.extend_from_slice(&frame.rgba8[4 * (y * w + x0)..4 * (y * w + x1)]);
                depth.extend_from_slice(&frame.depth[y * w + x0..y * w + x1]);
            }
        }
        Self {
            frame: frame_number,
            render_ns,
            rays,
            chunks: chunks.to_vec(),
            rgba8,
            depth,
        }
    }

    pub fn encode(&self) -> Vec<u8> {
        let mut out =
            Vec::with_capacity(RESULT_HEADER + 4 * self.chunks.len() + self.rgba8.len() * 2);
        out.extend_from_slice(&self.frame.to_le_bytes());
        out.extend_from_slice(&self.render_ns.to_le_bytes());
        for r in self.rays {
            out.extend_from_slice(&r.to_le_bytes());
        }
        out.extend_from_slice(&(self.chunks.len() as u32).to_le_bytes());
        for c in &self.chunks {
            out.extend_from_slice(&c.to_le_bytes());
        }
        out.extend_from_slice(&self.rgba8);
        for d in &self.depth {
            out.extend_from_slice(&d.to_le_bytes());
        }
        out
    }

    /// Decodes a result for a frame of `grid`, checking every length against it.
    pub fn decode(bytes: &[u8], grid: ChunkGrid) -> Result<Self, WireError> {
        let short = || WireError::Short {
            what: "a batch result",
            len: bytes.len(),
        };
        if bytes.len() < RESULT_HEADER {
            return Err(short());
        }
        let u64_at = |i: usize| u64::from_le_bytes(bytes[i..i + 8].try_into().expect("8 bytes"));
        let frame = u64_at(0);
        let render_ns = u64_at(8);
        let rays = [u64_at(16), u64_at(24), u64_at(32)];
        let n = u32::from_le_bytes(bytes[40..44].try_into().expect("4 bytes")) as usize;
        let ids_end = RESULT_HEADER
            .checked_add(n.checked_mul(4).ok_or_else(short)?)
            .ok_or_else(short)?;
        let ids = bytes.get(RESULT_HEADER..ids_end).ok_or_else(short)?;
        let chunks: Vec<u32> = ids
            .chunks_exact(4)
            .map(|c| u32::from_le_bytes(c.try_into().expect("4 bytes")))
            .collect();
        let mut pixels = 0usize;
        for &id in &chunks {
            if id as usize >= grid.len() {
                return Err(WireError::Chunk {
                    id,
                    count: grid.len(),
                });
            }
            pixels += grid.region(id).pixels();
        }
        let rgba_end = ids_end + 4 * pixels;
        if bytes.len() != rgba_end + 4 * pixels {
            return Err(short());
        }
        let depth = bytes[rgba_end..]
            .chunks_exact(4)
            .map(|c| f32::from_le_bytes(c.try_into().expect("4 bytes")))
            .collect();
        Ok(Self {
            frame,
            render_ns,
            rays,
            chunks,
            rgba8: bytes[ids_end..rgba_end].to_vec(),
            depth,
        })
    }

    /// Writes the chunks' pixels into `frame` (sized for `grid`).
    pub fn paste_into(&self, grid: ChunkGrid, frame: &mut Frame) {
        let w = grid.width as usize;
        let (mut rgba_at, mut depth_at) = (0, 0);
        for &id in &self.chunks {
            let r = grid.region(id);
            let (x0, x1) = (r.x[0] as usize, r.x[1] as usize);
            let n = x1 - x0;
            for y in r.y[0] as usize..r.y[1] as usize {
                frame.rgba8[4 * (y * w + x0)..4 * (y * w + x1)]
                    .copy_from_slice(&self.rgba8[rgba_at..rgba_at + 4 * n]);
                frame.depth[y * w + x0..y * w + x1]
                    .copy_from_slice(&self.depth[depth_at..depth_at + n]);
                rgba_at += 4 * n;
                depth_at += n;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use volume_core::render::Surface;

    #[test]
    fn jobs_round_trip_bit_for_bit() {
        let bounds = volume_core::math::Aabb::new(
            glam::Vec3::new(-1.3, 0.1, 2.0),
            glam::Vec3::new(0.7, 3.3, 5.1),
        );
        let job = FrameJob {
            frame: 7,
            camera: Camera::orbit(&bounds, 33.3, 17.1, 41.0),
            settings: RenderSettings {
                surfaces: vec![Surface::new(0.1 + 0.2, [0.3, 0.1, 0.7])],
                ..RenderSettings::default()
            },
            step: 3,
            field: Some("T".into()),
            intersector: Intersector::default(),
            smooth_normals: true,
            levels: 2,
            level_wait_ms: 500,
        };
        let back = decode_job(&encode_job(&job)).unwrap();
        assert_eq!(back, job);
        let bits = |c: &Camera| [c.eye, c.target, c.up].map(|v| v.to_array().map(f32::to_bits));
        assert_eq!(bits(&back.camera), bits(&job.camera));
        assert!(matches!(decode_job(b"{"), Err(WireError::Job(_))));
    }

    #[test]
    fn results_round_trip_and_paste_where_they_came_from() {
        let grid = ChunkGrid {
            width: 150,
            height: 70,
            scale: 1,
        };
        let pixels = (grid.width * grid.height) as usize;
        let source = Frame {
            width: grid.width,
            height: grid.height,
            rgba8: (0..pixels * 4).map(|i| (i * 7 % 251) as u8).collect(),
            depth: (0..pixels).map(|i| i as f32 * 0.5).collect(),
            ..Frame::default()
        };
        let chunks = [4, 0, 2];
        let r = BatchResult::from_frame(9, grid, &chunks, &source, 1234, [1, 2, 3]);
        let bytes = r.encode();
        let back = BatchResult::decode(&bytes, grid).unwrap();
        assert_eq!(back, r);
        let mut out = Frame {
            rgba8: vec![0; pixels * 4],
            depth: vec![-1.0; pixels],
            ..Frame::default()
        };
        back.paste_into(grid, &mut out);
        for id in 0..grid.len() as u32 {
            let reg = grid.region(id);
            for y in reg.y[0]..reg.y[1] {
                for x in reg.x[0]..reg.x[1] {
                    let p = (y * grid.width + x) as usize;
                    if chunks.contains(&id) {
                        assert_eq!(out.depth[p], source.depth[p]);
                        assert_eq!(out.rgba8[4 * p..4 * p + 4], source.rgba8[4 * p..4 * p + 4]);
                    } else {
                        assert_eq!(out.depth[p], -1.0);
                    }
                }
            }
        }
        // Truncated, padded or naming a chunk outside the frame: errors, not panics.
        assert!(BatchResult::decode(&bytes[..bytes.len() - 1], grid).is_err());
        let mut padded = bytes.clone();
        padded.push(0);
        assert!(BatchResult::decode(&padded, grid).is_err());
        let mut bad = bytes.clone();
        bad[44..48].copy_from_slice(&999u32.to_le_bytes());
        assert!(matches!(
            BatchResult::decode(&bad, grid),
            Err(WireError::Chunk { id: 999, .. })
        ));
        let mut huge = bytes;
        huge[40..44].copy_from_slice(&u32::MAX.to_le_bytes());
        assert!(BatchResult::decode(&huge, grid).is_err());
        assert_eq!(decode_batch(&encode_batch(5, &[1, 9])), Ok((5, vec![1, 9])));
        assert!(decode_batch(&[0; 9]).is_err());
        assert_eq!(decode_frame(&encode_frame(u64::MAX)), Ok(u64::MAX));
    }
}

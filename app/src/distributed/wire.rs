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
    /// The result of rendering `chunks`, each into its own frame (its region's pixels, as
    /// [`RenderSettings::region`] renders them).
    pub fn from_chunks(
        frame_number: u64,
        grid: ChunkGrid,
        chunks: &[(u32, Frame)],
        render_ns: u64,
    ) -> Self {
        let mut out = Self {
            frame: frame_number,
            render_ns,
            rays: [0; 3],
            chunks: Vec::with_capacity(chunks.len()),
            rgba8: Vec::new(),
            depth: Vec::new(),
        };
        for (id, f) in chunks {
            debug_assert_eq!(f.depth.len(), grid.region(*id).pixels());
            out.chunks.push(*id);
            out.rgba8.extend_from_slice(&f.rgba8);
            out.depth.extend_from_slice(&f.depth);
            out.rays[0] += f.rays.primary;
            out.rays[1] += f.rays.transparency;
            out.rays[2] += f.rays.shadow;
        }
        out
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

    /// Decodes a result for a frame of `grid`, checking every length against it. The pixels
    /// stay in `bytes` until pasted (one pass over them on rank 0).
    pub fn decode(bytes: &[u8], grid: ChunkGrid) -> Result<BatchView<'_>, WireError> {
        let short = || WireError::Short {
            what: "a batch result",
            len: bytes.len(),
        };
        if bytes.len() < RESULT_HEADER {
            return Err(short());
        }
        let u64_at = |i: usize| u64::from_le_bytes(bytes[i..i + 8].try_into().expect("8 bytes"));
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
        Ok(BatchView {
            frame: u64_at(0),
            render_ns: u64_at(8),
            rays: [u64_at(16), u64_at(24), u64_at(32)],
            chunks,
            rgba8: &bytes[ids_end..rgba_end],
            depth_le: &bytes[rgba_end..],
        })
    }
}

/// A received [`BatchResult`], its pixels still in the message.
#[derive(Debug, Clone, PartialEq)]
pub struct BatchView<'a> {
    pub frame: u64,
    pub render_ns: u64,
    pub rays: [u64; 3],
    pub chunks: Vec<u32>,
    rgba8: &'a [u8],
    /// Little-endian f32 depths.
    depth_le: &'a [u8],
}

impl BatchView<'_> {
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
                let row = &self.depth_le[depth_at..depth_at + 4 * n];
                for (d, b) in frame.depth[y * w + x0..y * w + x1]
                    .iter_mut()
                    .zip(row.chunks_exact(4))
                {
                    *d = f32::from_le_bytes(b.try_into().expect("4 bytes"));
                }
                rgba_at += 4 * n;
                depth_at += 4 * n;
            }
        }
    }
}

/// Writes one chunk's pixels (its region's rows, RGBA8 and depth) into `frame` (sized for
/// `grid`).
pub fn paste_chunk(grid: ChunkGrid, id: u32, rgba8: &[u8], depth: &[f32], frame: &mut Frame) {
    let w = grid.width as usize;
    let r = grid.region(id);
    let (x0, x1) = (r.x[0] as usize, r.x[1] as usize);
    let n = x1 - x0;
    for (k, y) in (r.y[0] as usize..r.y[1] as usize).enumerate() {
        frame.rgba8[4 * (y * w + x0)..4 * (y * w + x1)]
            .copy_from_slice(&rgba8[4 * k * n..4 * (k + 1) * n]);
        frame.depth[y * w + x0..y * w + x1].copy_from_slice(&depth[k * n..(k + 1) * n]);
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
        // Each chunk's frame: its region cut out of the source.
        let parts: Vec<(u32, Frame)> = chunks
            .iter()
            .map(|&id| {
                let r = grid.region(id);
                let mut f = Frame {
                    width: r.x[1] - r.x[0],
                    height: r.y[1] - r.y[0],
                    ..Frame::default()
                };
                f.rays.primary = 1;
                for y in r.y[0]..r.y[1] {
                    let row = (y * grid.width) as usize;
                    let (a, b) = (row + r.x[0] as usize, row + r.x[1] as usize);
                    f.rgba8.extend_from_slice(&source.rgba8[4 * a..4 * b]);
                    f.depth.extend_from_slice(&source.depth[a..b]);
                }
                (id, f)
            })
            .collect();
        let r = BatchResult::from_chunks(9, grid, &parts, 1234);
        assert_eq!(r.rays, [3, 0, 0]);
        let bytes = r.encode();
        let back = BatchResult::decode(&bytes, grid).unwrap();
        assert_eq!(
            (back.frame, back.render_ns, back.rays, &back.chunks),
            (r.frame, r.render_ns, r.rays, &r.chunks)
        );
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

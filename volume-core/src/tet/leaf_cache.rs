//! A per-thread cache of the isopolygons of recently visited BVH leaves.
//!
//! The large-packet traversal extracts a leaf's isopolygons on the fly (thesis 004 §8.2.4),
//! and neighbouring packets of a tile visit many of the same leaves, as do a round's shadow
//! packets, whose rays start on the surface the primary packets just found. Extraction
//! (the tets' corner gathers, the case test, the edge interpolations and the polygon's
//! bounds) was about a sixth of a frame: a second, discarded extraction pass made the
//! faceted frame of the real TetGen head 1.17× as long. The cache keeps each extracted leaf's polygons
//! with their bounds, so a later visit reads them instead.
//!
//! - Keyed by leaf node, in a direct-mapped table of [`SLOTS`] entries; the polygons live in
//!   a ring of [`RING`] entries that later leaves overwrite. An entry is valid while its
//!   span has not been overwritten, which one comparison of monotonic positions decides.
//! - Valid for one scene generation and one list of isovalues ([`LeafCache::begin`]): a new
//!   isovalue, a refit or a rebuild forgets everything in O(1).
//! - The polygons are those extraction makes (the same calls, the same order), so hits are
//!   bit-identical with or without the cache.

use glam::Vec3A;

use super::mt::IsoPoly;

/// Direct-mapped leaf slots (a power of two).
const SLOTS: usize = 8192;
/// Polygons kept (a power of two; 96 bytes each: 3 MiB). The renderer draws a band of 16×16
/// tiles at a time; this holds about a band's live leaves on a 1024-wide frame, so the band
/// below reads them (a quarter of that, 768 KiB, left 186 k extractions a frame on the
/// real TetGen head instead of 153 k, and a frame 1.02× as long).
const RING: usize = 32768;
/// Leaves that may hold more polygons than this (tets × isovalues) are not cached: they are
/// extracted into a buffer of their own at every visit.
pub(crate) const MAX_LEAF_POLYS: usize = 64;

/// An isopolygon of a leaf, with its bounds, tet (leaf order) and isovalue index.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct LeafPoly {
    pub lo: Vec3A,
    pub hi: Vec3A,
    pub poly: IsoPoly,
    pub tet: u32,
    pub surface: u32,
}

impl LeafPoly {
    pub(crate) fn new(tet: u32, surface: u32, poly: IsoPoly) -> Self {
        let (lo, hi) = poly.bounds();
        Self {
            lo: lo.into(),
            hi: hi.into(),
            poly,
            tet,
            surface,
        }
    }

    const EMPTY: Self = Self {
        lo: Vec3A::ZERO,
        hi: Vec3A::ZERO,
        poly: IsoPoly {
            v: [glam::Vec3::ZERO; 4],
            count: 0,
        },
        tet: 0,
        surface: 0,
    };
}

#[derive(Clone, Copy)]
struct Slot {
    node: u32,
    len: u32,
    /// Monotonic ring position of the first polygon.
    start: u64,
}

pub(crate) struct LeafCache {
    generation: u64,
    iso_bits: Vec<u32>,
    slots: Vec<Slot>,
    ring: Vec<LeafPoly>,
    /// Monotonic position of the next write; the ring index is `pos % RING`.
    pos: u64,
    /// The polygons of a leaf too large to cache (grown once, then reused).
    overflow: Vec<LeafPoly>,
}

impl LeafCache {
    /// An empty cache; its tables are allocated at the first [`LeafCache::begin`].
    pub(crate) const fn new() -> Self {
        Self {
            generation: 0,
            iso_bits: Vec::new(),
            slots: Vec::new(),
            ring: Vec::new(),
            pos: 0,
            overflow: Vec::new(),
        }
    }

    /// Starts a traversal of scene `generation` with isovalues `iso`: forgets every leaf
    /// unless both are those of the cached polygons.
    pub(crate) fn begin(&mut self, generation: u64, iso: &[f32]) {
        if self.ring.is_empty() {
            self.slots = vec![
                Slot {
                    node: u32::MAX,
                    len: 0,
                    start: 0,
                };
                SLOTS
            ];
            self.ring = vec![LeafPoly::EMPTY; RING];
            self.forget();
        }
        let same_iso = self.iso_bits.len() == iso.len()
            && self
                .iso_bits
                .iter()
                .zip(iso)
                .all(|(&b, c)| b == c.to_bits());
        if self.generation != generation || !same_iso {
            self.generation = generation;
            self.iso_bits.clear();
            self.iso_bits.extend(iso.iter().map(|c| c.to_bits()));
            self.forget();
        }
    }

    /// Moves the write position a whole ring on: every entry counts as overwritten.
    fn forget(&mut self) {
        self.pos = (self.pos / RING as u64 + 2) * RING as u64;
    }

    /// The polygons of leaf `node`: the cached ones, or those `extract` writes into the
    /// slice it is given (`max_len` long), returning how many. A leaf that may hold more
    /// than [`MAX_LEAF_POLYS`] (or any leaf before [`LeafCache::begin`]) is extracted at
    /// every call, into a buffer that is not kept.
    #[inline]
    pub(crate) fn leaf(
        &mut self,
        node: u32,
        max_len: usize,
        extract: impl FnOnce(&mut [LeafPoly]) -> usize,
    ) -> &[LeafPoly] {
        if max_len > MAX_LEAF_POLYS || self.ring.is_empty() {
            if self.overflow.len() < max_len {
                self.overflow.resize(max_len, LeafPoly::EMPTY);
            }
            let len = extract(&mut self.overflow[..max_len]).min(max_len);
            return &self.overflow[..len];
        }
        let slot = &mut self.slots[node as usize & (SLOTS - 1)];
        if slot.node == node && self.pos <= slot.start + RING as u64 {
            let base = (slot.start % RING as u64) as usize;
            return &self.ring[base..base + slot.len as usize];
        }
        // The leaf's span must not wrap: skip to the ring's start if it would.
        if (self.pos % RING as u64) as usize + max_len > RING {
            self.pos = (self.pos / RING as u64 + 1) * RING as u64;
        }
        let base = (self.pos % RING as u64) as usize;
        let len = extract(&mut self.ring[base..base + max_len]).min(max_len);
        *slot = Slot {
            node,
            len: len as u32,
            start: self.pos,
        };
        self.pos += len as u64;
        &self.ring[base..base + len]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    fn poly(k: u32) -> LeafPoly {
        let p = Vec3::splat(k as f32);
        LeafPoly::new(
            k,
            0,
            IsoPoly {
                v: [p, p + Vec3::X, p + Vec3::Y, Vec3::ZERO],
                count: 3,
            },
        )
    }

    /// Polygons `k * 10 ..` of leaf `k`, `k % 5 + 1` of them.
    fn fill(k: u32) -> impl FnOnce(&mut [LeafPoly]) -> usize {
        move |out| {
            let n = (k % 5 + 1) as usize;
            for (i, o) in out[..n].iter_mut().enumerate() {
                *o = poly(k * 10 + i as u32);
            }
            n
        }
    }

    /// Against a twin that extracts every time: every answer equals the extracted one, a
    /// working set that fits is mostly read from the cache, and a new key forgets.
    #[test]
    fn cached_leaves_equal_extracted_ones() {
        let mut c = LeafCache::new();
        c.begin(7, &[1.0]);
        let mut rng = crate::math::rng::Rng::new(5);
        let (mut extracted, mut visits) = (0usize, 0usize);
        for round in 0..40_000u32 {
            if round == 20_000 {
                c.begin(7, &[1.0]); // same key: keeps
            }
            // Mostly a working set that fits, sometimes far leaves that evict.
            let k = if rng.chance(0.9) {
                rng.below(600)
            } else {
                rng.below(1_000_000)
            };
            let mut called = false;
            let got = c
                .leaf(k, 8, |out| {
                    called = true;
                    fill(k)(out)
                })
                .to_vec();
            extracted += usize::from(called);
            visits += 1;
            let mut want = vec![LeafPoly::EMPTY; 8];
            let n = fill(k)(&mut want);
            assert_eq!(got, want[..n], "leaf {k}");
        }
        assert!(extracted * 4 < visits, "{extracted} of {visits}");
        // A new isovalue or generation forgets every leaf.
        for (g, iso) in [(7, 2.0), (8, 2.0)] {
            c.begin(g, &[iso]);
            let mut called = false;
            c.leaf(3, 8, |out| {
                called = true;
                fill(3)(out)
            });
            assert!(called);
        }
        // Too many polygons: extracted at every call, never cached.
        let big = MAX_LEAF_POLYS + 1;
        for _ in 0..2 {
            let mut called = false;
            let got = c
                .leaf(1, big, |out| {
                    called = true;
                    assert_eq!(out.len(), big);
                    fill(1)(out)
                })
                .to_vec();
            assert!(called);
            let mut want = vec![LeafPoly::EMPTY; big];
            let n = fill(1)(&mut want);
            assert_eq!(got, want[..n]);
        }
    }
}

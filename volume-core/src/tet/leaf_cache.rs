//! A per-thread cache of the isopolygons of visited BVH leaves.
//!
//! The large-packet traversal extracts a leaf's isopolygons on the fly (thesis 004 §8.2.4),
//! and neighbouring packets of a tile visit many of the same leaves, as do a round's shadow
//! packets, whose rays start on the surface the primary packets just found, and the next
//! frame at the same isovalues. Extraction (the tets' corner gathers, the case test, the
//! edge interpolations and the polygon's bounds) was about a sixth of a frame: a second,
//! discarded extraction pass made the faceted frame of the real TetGen head 1.17× as long.
//! The cache keeps each extracted leaf's polygons with their bounds, so a later visit reads
//! them instead.
//!
//! - Keyed by leaf node, in a direct-mapped table with a slot per node, up to twice as
//!   many slots as the ring holds polygons; the polygons live in a ring that later leaves
//!   overwrite once it is full. An entry is
//!   valid while its span has not been overwritten, which one comparison of monotonic
//!   positions decides.
//! - The ring grows on demand up to its capacity: [`RING_BUDGET`] polygons shared by the
//!   threads of the pool, each thread's at least [`MIN_RING`] and at most [`MAX_RING`]. On a
//!   mesh whose visible surface fits, a steady frame extracts nothing.
//! - Valid for one scene generation and one list of isovalues ([`LeafCache::begin`]): a new
//!   isovalue, a refit or a rebuild forgets everything in O(1).
//! - The polygons are those extraction makes (the same calls, the same order), so hits are
//!   bit-identical with or without the cache.

use glam::Vec3A;

use super::mt::IsoPoly;

/// Polygons (96 bytes each) kept by all threads of a pool together: 48 MiB. The real TetGen
/// head's view (663 k tets, 1024²) extracts about 140 k polygons, so with 2 threads each one
/// keeps the whole view and a steady frame extracts none; a ring of 32,768 polygons a
/// thread (3 MiB) left 150 k extractions a frame and made the faceted frame 1.08× as long,
/// and a quarter of that 1.02× longer still. A thread keeps its tables while it lives.
const RING_BUDGET: usize = 1 << 19;
/// Each thread's ring holds at least this many polygons (3 MiB: a band of 16×16 tiles'
/// live leaves on a 1024-wide frame, so the band below reads them) ...
const MIN_RING: usize = 1 << 15;
/// ... and at most this many (24 MiB). A thread's slots (16 bytes each) are at most twice
/// its ring's polygons, so its tables take at most 4/3 of its ring: 32 MiB.
const MAX_RING: usize = 1 << 18;
/// Leaves that may hold more polygons than this (tets × isovalues: 32-tet leaves and 16
/// isovalues) are not cached: they are extracted into a buffer of their own at every visit.
pub(crate) const MAX_LEAF_POLYS: usize = 512;

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

impl Slot {
    const NONE: Self = Self {
        node: u32::MAX,
        len: 0,
        start: 0,
    };
}

pub(crate) struct LeafCache {
    generation: u64,
    iso_bits: Vec<u32>,
    /// Direct-mapped by node (`node & (slots.len() - 1)`).
    slots: Vec<Slot>,
    /// Grown on demand up to `capacity`, then overwritten in order.
    ring: Vec<LeafPoly>,
    /// The ring's size once grown (a power of two).
    capacity: usize,
    /// Monotonic position of the next write; the ring index is `pos % capacity`.
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
            capacity: 0,
            pos: 0,
            overflow: Vec::new(),
        }
    }

    /// Starts a traversal of scene `generation`, whose BVH has `nodes` nodes, with
    /// isovalues `iso`: forgets every leaf unless both are those of the cached polygons.
    /// The ring's capacity is this thread's share of [`RING_BUDGET`] among `threads`.
    pub(crate) fn begin(&mut self, generation: u64, nodes: usize, iso: &[f32], threads: usize) {
        let capacity = (RING_BUDGET / threads.max(1))
            .next_power_of_two()
            .clamp(MIN_RING, MAX_RING);
        let slots = nodes.next_power_of_two().min(2 * capacity);
        let same_iso = self.iso_bits.len() == iso.len()
            && self
                .iso_bits
                .iter()
                .zip(iso)
                .all(|(&b, c)| b == c.to_bits());
        let resized = self.slots.len() < slots || self.capacity != capacity;
        if resized {
            // New tables: every slot names no node, so nothing in them is valid.
            self.slots = vec![Slot::NONE; slots];
            self.capacity = capacity;
            self.ring.clear();
            self.ring.shrink_to(capacity);
        }
        if resized || self.generation != generation || !same_iso {
            self.generation = generation;
            self.iso_bits.clear();
            self.iso_bits.extend(iso.iter().map(|c| c.to_bits()));
            self.forget();
        }
    }

    /// Moves the write position a whole ring on: every entry counts as overwritten.
    fn forget(&mut self) {
        let cap = self.capacity as u64;
        self.pos = (self.pos / cap + 2) * cap;
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
        if max_len > MAX_LEAF_POLYS || self.slots.is_empty() {
            if self.overflow.len() < max_len {
                self.overflow.resize(max_len, LeafPoly::EMPTY);
            }
            let len = extract(&mut self.overflow[..max_len]).min(max_len);
            return &self.overflow[..len];
        }
        let cap = self.capacity as u64;
        let mask = self.slots.len() - 1;
        let slot = &mut self.slots[node as usize & mask];
        if slot.node == node && self.pos <= slot.start + cap {
            let base = (slot.start % cap) as usize;
            return &self.ring[base..base + slot.len as usize];
        }
        // The leaf's span must not wrap: skip to the ring's start if it would.
        if (self.pos % cap) as usize + max_len > self.capacity {
            self.pos = (self.pos / cap + 1) * cap;
        }
        let base = (self.pos % cap) as usize;
        if base + max_len > self.ring.len() {
            // Still growing: the written part keeps its positions.
            let len = (base + max_len)
                .max(2 * self.ring.len())
                .max(MIN_RING)
                .min(self.capacity);
            self.ring.resize(len, LeafPoly::EMPTY);
        }
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

    /// Leaf `k` through the cache, checked against extracting it again; true when the
    /// cache had to extract it.
    fn visit(c: &mut LeafCache, k: u32) -> bool {
        let mut called = false;
        let got = c
            .leaf(k, 8, |out| {
                called = true;
                fill(k)(out)
            })
            .to_vec();
        let mut want = vec![LeafPoly::EMPTY; 8];
        let n = fill(k)(&mut want);
        assert_eq!(got, want[..n], "leaf {k}");
        called
    }

    /// Against a twin that extracts every time: every answer equals the extracted one, a
    /// working set that fits is mostly read from the cache, and a new key forgets.
    #[test]
    fn cached_leaves_equal_extracted_ones() {
        for threads in [1, 2, 64] {
            let mut c = LeafCache::new();
            c.begin(7, 1 << 20, &[1.0], threads);
            let mut rng = crate::math::rng::Rng::new(5);
            let (mut extracted, mut visits) = (0usize, 0usize);
            for round in 0..40_000u32 {
                if round == 20_000 {
                    c.begin(7, 1 << 20, &[1.0], threads); // same key: keeps
                }
                // Mostly a working set that fits, sometimes far leaves that evict.
                let k = if rng.chance(0.9) {
                    rng.below(600)
                } else {
                    rng.below(1_000_000)
                };
                extracted += usize::from(visit(&mut c, k));
                visits += 1;
            }
            assert!(extracted * 4 < visits, "{extracted} of {visits}");
            assert!(c.ring.len() <= c.capacity);
            // A new isovalue or generation forgets every leaf.
            for (g, iso) in [(7, 2.0), (8, 2.0)] {
                c.begin(g, 1 << 20, &[iso], threads);
                assert!(visit(&mut c, 3));
            }
        }
        // Too many polygons: extracted at every call, never cached.
        let mut c = LeafCache::new();
        c.begin(1, 16, &[1.0], 2);
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

    /// The ring grows to its capacity and no further; a sweep of leaves that fits is read
    /// from the cache in full the second time (a steady frame), and one that does not fit
    /// is overwritten in order and extracted again, with correct answers throughout.
    #[test]
    fn ring_grows_to_its_capacity_then_wraps() {
        for threads in [2, 64] {
            let mut c = LeafCache::new();
            c.begin(3, 1 << 19, &[1.0], threads);
            assert!(c.ring.is_empty(), "allocated before use");
            let cap = c.capacity;
            assert_eq!(cap, (RING_BUDGET / threads).clamp(MIN_RING, MAX_RING));
            assert_eq!(
                c.slots.len(),
                (1 << 19).min(2 * cap),
                "slots bounded by the ring"
            );
            // Leaves of 1–5 polygons (3 on average): a sixteenth of a ring's leaves.
            let fits = (cap / 16) as u32;
            for pass in 0..2 {
                let extracted = (0..fits).filter(|&k| visit(&mut c, k)).count();
                assert_eq!(extracted, if pass == 0 { fits as usize } else { 0 });
            }
            if cap > MIN_RING {
                assert!(c.ring.len() < cap, "grew past the polygons written");
            }
            // Twice the capacity: the ring fills, wraps, and the first leaves are gone.
            let many = (cap / 2) as u32 + fits;
            for k in fits..many {
                visit(&mut c, k);
            }
            assert_eq!(c.ring.len(), cap);
            assert!(visit(&mut c, 0), "leaf 0 was overwritten");
            assert!(!visit(&mut c, many - 1), "the last leaf is still cached");
        }
    }
}

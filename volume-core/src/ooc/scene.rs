//! Out-of-core rendering (thesis seed 004 §7.8.2–7.8.3): the loader thread, the bit table
//! of resident treelets, and [`OocScene`], the [`IsoScene`] render threads trace.
//!
//! [`OocVolume`] owns a [`TreeletStorage`] and a loader thread. The first treelet is loaded
//! before the thread starts (§7.8.2). For the current isovalues the thread sweeps the
//! treelet levels in order: from every resident treelet of level `L` it walks the nodes
//! whose quantized range passes an isovalue and collects the treelets of level `L + 1`
//! below them (index order), fetches the ones not yet resident, and *publishes* the level
//! once all are in: the "bit table" is the per-level set of resident treelet ids in an
//! immutable snapshot. Render threads never wait on loading: [`OocVolume::scene`] clones the
//! current snapshot (one short lock per frame), which is the thesis' "check the available
//! LODs before a new frame".
//!
//! New isovalues with the same quantized code bounds change nothing; otherwise loading
//! restarts from level 1, reusing resident treelets that are still needed; the others are
//! evicted (freed when the last frame holding an old snapshot ends). A memory budget stops
//! the sweep before a level would exceed it: rendering then stays at the last complete
//! level ([`OocVolume::budget_limited`]).
//!
//! Traversal (Listing 7.3) is the slim kd-tree traversal of [`crate::kdtree`] with node
//! ranges read from the current treelet: at the bottom of a treelet it continues in the
//! child treelet if its level is published and the treelet resident, and otherwise
//! intersects the cell of the current level's LOD voxels with the shared cell intersector
//! and normal code ([`intersect_cell`], [`crate::grid::hit`]) through a
//! treelet-local [`TraversalFrame`]. At the finest level the cells, voxels and positions are
//! the in-core ones, so hits equal [`crate::grid::GridScene`]'s; quantized ranges only
//! add visited nodes. Primary rays go as packets of 16 (`traverse_packet`, the twin of the
//! single-ray `traverse`, with the in-core packets' ray set-up and leaf test from
//! [`crate::kdtree`]): the packet enters a child treelet together, since the node, not the
//! ray, names it.

use std::cell::RefCell;
use std::collections::HashMap;
use std::hash::{BuildHasherDefault, Hasher};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Condvar, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use super::OocError;
use wide::f32x16;

use super::layout::linear_index;
use super::quantize::CodeQuery;
use super::treelet::{OocMeta, TreeletRecord, TreeletStorage};
use crate::grid::hit::{CellBlock, CellTrace, first_hit_with, first_hits_packet_with};
use crate::intersect::{
    CellHit, CellIntersector, INLINE_ISOVALUES, Intersector, IsoSet, LocalRay, TraversalFrame,
    intersect_cell,
};
use crate::kdtree::packet::{
    LaneNext, Lanes, PacketRays, any_lane, mask_bits, packet_leaf, packet_visit, splat,
};
use crate::kdtree::step::{Step, ray_step, take_step};
use crate::kdtree::{PACKET_WIDTH, packet_compatible};
use crate::math::{Aabb, Ray, union_of_cell_boxes};
use crate::render::{Hit, IsoScene, Normals, Stats};
use crate::voxel::Voxel;

/// A treelet in memory with its local frame (positions of its voxel block).
#[derive(Debug)]
pub struct ResidentTreelet<T: Voxel> {
    rec: TreeletRecord<T>,
    frame: TraversalFrame,
    /// The last frame ([`OocScene`] stamp) that entered this treelet; kept only for
    /// treelets of demand-paged levels (least-recently-used eviction).
    last_used: AtomicU64,
}

impl<T: Voxel> ResidentTreelet<T> {
    fn bytes(&self) -> u64 {
        (self.rec.nodes.len()
            + self.rec.voxels.len() * size_of::<T>()
            + self.frame.pos().iter().map(|p| p.len() * 4).sum::<usize>()
            + size_of::<Self>()) as u64
    }
}

/// Resident treelets of one level by index. Looked up at every treelet boundary a ray
/// crosses: the default SipHash took a tenth of the traversal's time.
type LevelMap<T> = HashMap<u64, Arc<ResidentTreelet<T>>, BuildHasherDefault<TreeletIdHasher>>;

/// A multiplicative hash of a treelet index (Fibonacci hashing, as FxHash): indices are
/// dense small integers, not attacker-chosen keys.
#[derive(Debug, Default, Clone, Copy)]
struct TreeletIdHasher(u64);

impl Hasher for TreeletIdHasher {
    fn finish(&self) -> u64 {
        self.0
    }

    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.write_u64(u64::from(b));
        }
    }

    fn write_u64(&mut self, i: u64) {
        self.0 = (self.0.rotate_left(5) ^ i).wrapping_mul(0x9e37_79b9_7f4a_7c15);
    }
}

/// What one frame renders with: the published levels (the bit table).
#[derive(Debug)]
struct Snapshot<T: Voxel> {
    /// Complete levels first; levels from `complete` on are demand-paged (only the
    /// treelets the frames asked for, within the budget).
    levels: Vec<Arc<LevelMap<T>>>,
    complete: usize,
    resident_bytes: u64,
}

/// Loader options.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct OocOptions {
    /// Resident treelet bytes the loader may hold.
    pub budget_bytes: u64,
}

/// The default budget is physical memory divided by this (half of RAM: the rest is left to
/// the page cache the treelet file is read through, the frame buffers and other programs).
pub const BUDGET_DIVISOR: u64 = 2;
/// The budget when physical memory is unknown (no `/proc/meminfo`).
pub const FALLBACK_BUDGET_BYTES: u64 = 2 << 30;

impl Default for OocOptions {
    /// Budget: [`physical_memory_bytes`] / [`BUDGET_DIVISOR`], else
    /// [`FALLBACK_BUDGET_BYTES`].
    fn default() -> Self {
        Self {
            budget_bytes: physical_memory_bytes()
                .map_or(FALLBACK_BUDGET_BYTES, |m| m / BUDGET_DIVISOR),
        }
    }
}

/// Physical memory (`MemTotal` of `/proc/meminfo`), where the system has it (Linux).
pub fn physical_memory_bytes() -> Option<u64> {
    parse_mem_total(&std::fs::read_to_string("/proc/meminfo").ok()?)
}

/// `MemTotal:  N kB` of a `/proc/meminfo` text, in bytes.
pub fn parse_mem_total(meminfo: &str) -> Option<u64> {
    let rest = meminfo.lines().find_map(|l| l.strip_prefix("MemTotal:"))?;
    let mut words = rest.split_whitespace();
    let n: u64 = words.next()?.parse().ok()?;
    match words.next() {
        Some("kB") => n.checked_mul(1024),
        None => Some(n),
        Some(_) => None,
    }
}

/// Loader progress for a GUI: poll [`OocVolume::progress`] (or the lock-free
/// [`OocVolume::generation`]) each frame, or receive it from [`OocVolume::on_level`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LoadProgress {
    /// Increases with every published level and every end of loading: redraw when it
    /// changes.
    pub generation: u64,
    /// Increases with every [`OocVolume::set_isovalues`] that changes the quantized bucket
    /// (a restart).
    pub request: u64,
    /// Levels the next frame renders with (1 = the top treelet only).
    pub loaded_levels: usize,
    pub level_count: usize,
    /// Treelets fetched and needed for the level being loaded now.
    pub level_fetched: u64,
    pub level_needed: u64,
    /// Bytes of the resident treelets the next frame renders with (the working set).
    pub resident_bytes: u64,
    /// The loader is idle for the current isovalues.
    pub finished: bool,
    /// The memory budget stopped loading before the finest level.
    pub budget_limited: bool,
}

type Listener = Arc<dyn Fn(&LoadProgress) + Send + Sync>;

#[derive(Debug)]
struct State<T: Voxel> {
    snapshot: Arc<Snapshot<T>>,
    wanted: Vec<CodeQuery>,
    all_pass: bool,
    finished: bool,
    budget_limited: bool,
    error: Option<OocError>,
    /// The budget stopped the sweep: the levels from `snapshot.complete` on are paged in on
    /// demand (treelets that frames missed) with least-recently-used eviction.
    demand: bool,
    /// A frame recorded misses since the last demand round.
    miss_pending: bool,
    /// A demand round is running.
    demand_busy: bool,
}

/// Slots of the lossy miss table render threads write (a collision drops a miss; the next
/// frame reports it again).
const MISS_SLOTS: usize = 4096;
/// Most treelets one demand round loads before it publishes.
const DEMAND_BATCH: usize = 1024;

fn miss_key(level: usize, index: u64) -> u64 {
    ((level as u64) << 56) | index
}

struct Shared<T: Voxel> {
    storage: Arc<dyn TreeletStorage>,
    meta: OocMeta,
    frame: TraversalFrame,
    /// `frame` without sample tables, cloned per treelet.
    template: TraversalFrame,
    options: OocOptions,
    request: AtomicU64,
    stop: AtomicBool,
    state: Mutex<State<T>>,
    changed: Condvar,
    generation: AtomicU64,
    level_fetched: AtomicU64,
    level_needed: AtomicU64,
    listener: Mutex<Option<Listener>>,
    /// Stamp of the newest frame ([`OocVolume::scene`] increments it).
    frame_clock: AtomicU64,
    /// `miss_key + 1` of demand-level treelets frames wanted and did not find (0: empty).
    misses: Box<[AtomicU64]>,
    missed: AtomicBool,
    evictions: AtomicU64,
}

/// An out-of-core volume: storage, loader thread and published levels.
pub struct OocVolume<T: Voxel> {
    shared: Arc<Shared<T>>,
    thread: Option<JoinHandle<()>>,
}

impl<T: Voxel> std::fmt::Debug for OocVolume<T> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("OocVolume")
            .field("dims", &self.shared.meta.layout.dims())
            .field("loaded_levels", &self.loaded_levels())
            .finish_non_exhaustive()
    }
}

/// Code bounds of physical `isovalues` (all-pass when there are more than fit inline).
fn queries_of(meta: &OocMeta, isovalues: &[f32]) -> (Vec<CodeQuery>, bool) {
    let q: Vec<CodeQuery> = isovalues
        .iter()
        .filter_map(|&c| meta.quantizer.query(meta.value_map.iso_to_stored(c)))
        .collect();
    let all = q.len() > INLINE_ISOVALUES;
    (if all { Vec::new() } else { q }, all)
}

impl<T: Voxel> Shared<T> {
    fn load(&self, level: usize, index: u64) -> Result<ResidentTreelet<T>, OocError> {
        let bytes = self.storage.fetch(level, index)?;
        let rec = TreeletRecord::<T>::decode(&self.meta, level, index, &bytes)?;
        let mut frame = self.template.clone();
        let layout = &self.meta.layout;
        frame.set_positions(std::array::from_fn(|a| {
            (0..rec.voxel_dims[a] as u64)
                .map(|i| {
                    self.frame.pos()[a]
                        [layout.lod_sample(level, a, rec.voxel_origin[a] + i) as usize]
                })
                .collect()
        }));
        Ok(ResidentTreelet {
            rec,
            frame,
            last_used: AtomicU64::new(self.frame_clock.load(Ordering::Acquire)),
        })
    }

    /// Records (lossily, lock-free) that a frame wanted treelet `(level, index)`.
    #[inline]
    fn record_miss(&self, level: usize, index: u64) {
        let key = miss_key(level, index) + 1;
        let slot = (key.wrapping_mul(0x9E37_79B9_7F4A_7C15) >> 52) as usize % MISS_SLOTS;
        let s = &self.misses[slot];
        if s.load(Ordering::Relaxed) != key {
            s.store(key, Ordering::Relaxed);
        }
        if !self.missed.load(Ordering::Relaxed) {
            self.missed.store(true, Ordering::Release);
        }
    }

    /// Indices of level `l + 1` treelets below the passing nodes of `map` (level `l`).
    fn needed_children(
        &self,
        map: &LevelMap<T>,
        l: usize,
        queries: &[CodeQuery],
        all: bool,
    ) -> Vec<u64> {
        let layout = &self.meta.layout;
        let q = &self.meta.quantizer;
        let lv = *layout.level(l);
        let next_roots = layout.level(l + 1).roots;
        let mut out = Vec::new();
        let mut ids: Vec<u64> = map.keys().copied().collect();
        ids.sort_unstable();
        let mut todo = Vec::new();
        for id in ids {
            let t = &map[&id];
            todo.push((lv.first, layout.root_of(l, id), 0usize));
            while let Some((level, node, h)) = todo.pop() {
                if level == lv.end {
                    out.push(linear_index(next_roots, node));
                    continue;
                }
                let c = q.get(&t.rec.nodes, h);
                if !(all || queries.iter().any(|x| x.passes(c[0], c[1]))) {
                    continue;
                }
                let a = layout.shape(level).axis;
                let mut left = node;
                left[a] *= 2;
                let mut right = left;
                right[a] += 1;
                if right[a] < layout.shape(level + 1).count[a] {
                    todo.push((level + 1, right, 2 * h + 2));
                }
                todo.push((level + 1, left, 2 * h + 1));
            }
        }
        out.sort_unstable();
        out
    }

    fn progress_of(&self, st: &State<T>) -> LoadProgress {
        LoadProgress {
            generation: self.generation.load(Ordering::Acquire),
            request: self.request.load(Ordering::Acquire),
            loaded_levels: st.snapshot.complete,
            level_count: self.meta.layout.level_count(),
            level_fetched: self.level_fetched.load(Ordering::Acquire),
            level_needed: self.level_needed.load(Ordering::Acquire),
            resident_bytes: st.snapshot.resident_bytes,
            finished: st.finished,
            budget_limited: st.budget_limited,
        }
    }

    /// Calls the listener (outside the state lock) with `progress`.
    fn notify(&self, progress: Option<LoadProgress>) {
        if let Some(p) = progress {
            let listener = self.listener.lock().expect("listener").clone();
            if let Some(f) = listener {
                f(&p);
            }
        }
    }

    /// Makes `levels` the snapshot of the next frames (the renderer's "loaded LODs"); the
    /// first `complete` are complete levels, the others demand-paged.
    fn publish(&self, request: u64, levels: &[Arc<LevelMap<T>>], complete: usize, bytes: u64) {
        let progress = {
            let mut st = self.state.lock().expect("loader state");
            if self.request.load(Ordering::Acquire) != request {
                return;
            }
            st.snapshot = Arc::new(Snapshot {
                levels: levels.to_vec(),
                complete,
                resident_bytes: bytes,
            });
            self.generation.fetch_add(1, Ordering::AcqRel);
            self.changed.notify_all();
            Some(self.progress_of(&st))
        };
        self.notify(progress);
    }

    /// One sweep for `queries`; `Ok(true)` when the budget stopped it.
    fn sweep(
        &self,
        request: u64,
        queries: &[CodeQuery],
        all: bool,
        old: &Snapshot<T>,
    ) -> Result<bool, OocError> {
        let n = self.meta.layout.level_count();
        let mut levels = vec![old.levels[0].clone()];
        let mut bytes: u64 = levels[0].values().map(|t| t.bytes()).sum();
        self.publish(request, &levels, 1, bytes);
        for l in 1..n {
            let needed = if queries.is_empty() && !all {
                Vec::new()
            } else {
                self.needed_children(&levels[l - 1], l - 1, queries, all)
            };
            let mut map =
                LevelMap::with_capacity_and_hasher(needed.len(), BuildHasherDefault::default());
            self.level_fetched.store(0, Ordering::Release);
            self.level_needed
                .store(needed.len() as u64, Ordering::Release);
            for idx in needed {
                if self.request.load(Ordering::Acquire) != request
                    || self.stop.load(Ordering::Acquire)
                {
                    return Ok(false);
                }
                let t = match old.levels.get(l).and_then(|m| m.get(&idx)) {
                    Some(t) => t.clone(),
                    None => Arc::new(self.load(l, idx)?),
                };
                if bytes + t.bytes() > self.options.budget_bytes {
                    // Level `l` does not fit: keep what does and page the rest of this
                    // level and the finer ones in as frames ask for them.
                    let complete = levels.len();
                    levels.push(Arc::new(map));
                    levels.extend((l + 1..n).map(|_| Arc::new(LevelMap::default())));
                    self.publish(request, &levels, complete, bytes);
                    return Ok(true);
                }
                bytes += t.bytes();
                map.insert(idx, t);
                self.level_fetched.fetch_add(1, Ordering::AcqRel);
            }
            levels.push(Arc::new(map));
            self.publish(request, &levels, levels.len(), bytes);
        }
        Ok(false)
    }

    /// One demand round: loads the treelets frames missed on the demand-paged levels,
    /// evicting the least recently used ones (never those of the newest frame) to stay
    /// within the budget, and publishes the result. Returns `Ok(())` also when the budget
    /// is full of treelets the newest frame used (those misses stay at the coarser level).
    fn demand_round(&self, request: u64, old: &Snapshot<T>) -> Result<(), OocError> {
        let complete = old.complete;
        let n = old.levels.len();
        let mut wanted: Vec<(usize, u64)> = self
            .misses
            .iter()
            .filter_map(|s| s.swap(0, Ordering::AcqRel).checked_sub(1))
            .map(|k| ((k >> 56) as usize, k & ((1 << 56) - 1)))
            .filter(|&(l, i)| {
                (complete..n).contains(&l)
                    && i < self.meta.layout.level(l).treelet_count()
                    && !old.levels[l].contains_key(&i)
            })
            .collect();
        wanted.sort_unstable();
        wanted.dedup();
        wanted.truncate(DEMAND_BATCH);
        if wanted.is_empty() {
            return Ok(());
        }
        // Treelets the newest frame entered (and the ones loaded now) are not evicted.
        let protect = self.frame_clock.load(Ordering::Acquire);
        let mut victims: Vec<(u64, usize, u64)> = (complete..n)
            .flat_map(|l| {
                old.levels[l]
                    .iter()
                    .map(move |(&i, t)| (t.last_used.load(Ordering::Relaxed), l, i))
            })
            .filter(|v| v.0 < protect)
            .collect();
        victims.sort_unstable();
        let mut victims = victims.into_iter().peekable();
        let mut maps: Vec<LevelMap<T>> = (complete..n).map(|l| (*old.levels[l]).clone()).collect();
        let mut bytes = old.resident_bytes;
        let mut changed = false;
        'load: for (l, idx) in wanted {
            if self.request.load(Ordering::Acquire) != request || self.stop.load(Ordering::Acquire)
            {
                return Ok(());
            }
            if bytes >= self.options.budget_bytes && victims.peek().is_none() {
                break;
            }
            let t = Arc::new(self.load(l, idx)?);
            t.last_used.store(protect, Ordering::Relaxed);
            while bytes + t.bytes() > self.options.budget_bytes {
                let Some((_, vl, vi)) = victims.next() else {
                    break 'load;
                };
                if let Some(v) = maps[vl - complete].remove(&vi) {
                    bytes -= v.bytes();
                    self.evictions.fetch_add(1, Ordering::AcqRel);
                    changed = true;
                }
            }
            bytes += t.bytes();
            maps[l - complete].insert(idx, t);
            changed = true;
        }
        if changed {
            let mut levels = old.levels[..complete].to_vec();
            levels.extend(maps.into_iter().map(Arc::new));
            self.publish(request, &levels, complete, bytes);
        }
        Ok(())
    }

    fn run(&self) {
        loop {
            let (queries, all, request, old, demand) = {
                let mut st = self.state.lock().expect("loader state");
                while st.finished
                    && !(st.demand && st.miss_pending)
                    && !self.stop.load(Ordering::Acquire)
                {
                    st = self.changed.wait(st).expect("loader state");
                }
                if self.stop.load(Ordering::Acquire) {
                    return;
                }
                let demand = st.finished;
                if demand {
                    st.miss_pending = false;
                    st.demand_busy = true;
                }
                (
                    st.wanted.clone(),
                    st.all_pass,
                    self.request.load(Ordering::Acquire),
                    st.snapshot.clone(),
                    demand,
                )
            };
            if demand {
                let result = self.demand_round(request, &old);
                drop(old);
                let mut st = self.state.lock().expect("loader state");
                st.demand_busy = false;
                if let Err(e) = result
                    && self.request.load(Ordering::Acquire) == request
                {
                    st.error = Some(e);
                    st.demand = false;
                }
                self.changed.notify_all();
                continue;
            }
            let result = self.sweep(request, &queries, all, &old);
            drop(old);
            let progress = {
                let mut st = self.state.lock().expect("loader state");
                if self.request.load(Ordering::Acquire) != request {
                    continue;
                }
                st.finished = true;
                match result {
                    Ok(limited) => {
                        st.budget_limited = limited;
                        st.demand = limited;
                    }
                    Err(e) => st.error = Some(e),
                }
                self.generation.fetch_add(1, Ordering::AcqRel);
                self.changed.notify_all();
                self.progress_of(&st)
            };
            self.notify(Some(progress));
        }
    }
}

impl<T: Voxel> OocVolume<T> {
    /// Loads the first treelet and starts the loader thread (no isovalues yet).
    pub fn open(storage: Arc<dyn TreeletStorage>, options: OocOptions) -> Result<Self, OocError> {
        let meta = storage.meta().clone();
        if meta.voxel_type != T::TYPE {
            return Err(OocError::Storage(format!(
                "stored voxel type {} opened as {}",
                meta.voxel_type.name(),
                T::TYPE.name()
            )));
        }
        let frame = TraversalFrame::new(&meta.grid);
        let mut template = frame.clone();
        template.set_positions(std::array::from_fn(|_| Box::default()));
        let shared = Shared {
            storage,
            meta,
            frame,
            template,
            options,
            request: AtomicU64::new(0),
            stop: AtomicBool::new(false),
            state: Mutex::new(State {
                snapshot: Arc::new(Snapshot {
                    levels: Vec::new(),
                    complete: 0,
                    resident_bytes: 0,
                }),
                wanted: Vec::new(),
                all_pass: false,
                finished: true,
                budget_limited: false,
                error: None,
                demand: false,
                miss_pending: false,
                demand_busy: false,
            }),
            changed: Condvar::new(),
            generation: AtomicU64::new(0),
            level_fetched: AtomicU64::new(0),
            level_needed: AtomicU64::new(0),
            listener: Mutex::new(None),
            frame_clock: AtomicU64::new(0),
            misses: (0..MISS_SLOTS).map(|_| AtomicU64::new(0)).collect(),
            missed: AtomicBool::new(false),
            evictions: AtomicU64::new(0),
        };
        let first = Arc::new(shared.load(0, 0)?);
        let bytes = first.bytes();
        let mut level0 = LevelMap::default();
        level0.insert(0, first);
        shared.state.lock().expect("loader state").snapshot = Arc::new(Snapshot {
            levels: vec![Arc::new(level0)],
            complete: 1,
            resident_bytes: bytes,
        });
        let shared = Arc::new(shared);
        let worker = shared.clone();
        let thread = std::thread::Builder::new()
            .name("isoscope-treelet-loader".into())
            .spawn(move || worker.run())
            .map_err(|e| OocError::Storage(format!("cannot start the loader thread: {e}")))?;
        Ok(Self {
            shared,
            thread: Some(thread),
        })
    }

    pub fn meta(&self) -> &OocMeta {
        &self.shared.meta
    }

    /// Asks the loader for the treelets of `isovalues`. Same quantized bounds: no reload.
    pub fn set_isovalues(&self, isovalues: &[f32]) {
        let (q, all) = queries_of(&self.shared.meta, isovalues);
        let mut st = self.shared.state.lock().expect("loader state");
        if st.wanted == q && st.all_pass == all && st.snapshot.levels.len() > 1 {
            return;
        }
        st.wanted = q;
        st.all_pass = all;
        st.finished = false;
        st.budget_limited = false;
        st.demand = false;
        st.miss_pending = false;
        st.error = None;
        self.shared.request.fetch_add(1, Ordering::AcqRel);
        self.shared.generation.fetch_add(1, Ordering::AcqRel);
        self.shared.changed.notify_all();
    }

    /// Calls `listener` from the loader thread after every published level (the thesis'
    /// "notify the render threads whenever a new LOD level is loaded", §7.8.2) and when
    /// loading ends. It must be quick (e.g. send on a channel, request a repaint).
    pub fn on_level(&self, listener: impl Fn(&LoadProgress) + Send + Sync + 'static) {
        *self.shared.listener.lock().expect("listener") = Some(Arc::new(listener));
    }

    /// Loader progress (one short lock).
    pub fn progress(&self) -> LoadProgress {
        let st = self.shared.state.lock().expect("loader state");
        self.shared.progress_of(&st)
    }

    /// Changes with every published level, end of loading and restart (lock-free; a GUI
    /// compares it with the value of its last frame).
    pub fn generation(&self) -> u64 {
        self.shared.generation.load(Ordering::Acquire)
    }

    /// The scene for the next frame (the levels published so far). When the budget put
    /// the loader in demand mode, the treelets this frame misses are paged in after it
    /// ends (a GUI re-renders on [`Self::generation`]).
    pub fn scene(&self, intersector: Intersector) -> OocScene<T> {
        let snap = self
            .shared
            .state
            .lock()
            .expect("loader state")
            .snapshot
            .clone();
        let stamp = self.shared.frame_clock.fetch_add(1, Ordering::AcqRel) + 1;
        OocScene {
            shared: self.shared.clone(),
            snap,
            intersector,
            normals: Normals::Smooth,
            stamp,
        }
    }

    /// Treelets evicted by demand paging so far (least recently used first).
    pub fn evictions(&self) -> u64 {
        self.shared.evictions.load(Ordering::Acquire)
    }

    /// Complete levels published for the current isovalues (1 = the top treelet only).
    pub fn loaded_levels(&self) -> usize {
        self.shared
            .state
            .lock()
            .expect("loader state")
            .snapshot
            .complete
    }

    pub fn level_count(&self) -> usize {
        self.shared.meta.layout.level_count()
    }

    /// Bytes of resident treelets in the current snapshot.
    pub fn resident_bytes(&self) -> u64 {
        self.shared
            .state
            .lock()
            .expect("loader state")
            .snapshot
            .resident_bytes
    }

    /// True when the loader is idle for the current isovalues.
    pub fn is_finished(&self) -> bool {
        self.shared.state.lock().expect("loader state").finished
    }

    pub fn budget_limited(&self) -> bool {
        self.shared
            .state
            .lock()
            .expect("loader state")
            .budget_limited
    }

    /// The error that stopped the last sweep (a damaged treelet, an I/O error).
    pub fn error(&self) -> Option<OocError> {
        self.shared
            .state
            .lock()
            .expect("loader state")
            .error
            .clone()
    }

    /// Waits (not from a render thread) until the loader is idle (including the demand
    /// round for the misses of frames that ended) or `timeout` passes; returns whether it
    /// finished.
    pub fn wait_until_finished(&self, timeout: Duration) -> bool {
        let deadline = Instant::now() + timeout;
        let mut st = self.shared.state.lock().expect("loader state");
        while !st.finished || (st.demand && st.miss_pending) || st.demand_busy {
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return false;
            }
            st = self
                .shared
                .changed
                .wait_timeout(st, left)
                .expect("loader state")
                .0;
        }
        true
    }
}

impl<T: Voxel> Drop for OocVolume<T> {
    fn drop(&mut self) {
        self.shared.stop.store(true, Ordering::Release);
        {
            let _st = self.shared.state.lock();
            self.shared.changed.notify_all();
        }
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// The isovalues of one frame as the out-of-core traversal reads them, prepared once per
/// frame ([`IsoScene::prepare`]): in the voxel type, and as quantized code queries for the
/// treelet node ranges (seed 004 §7.8.1).
#[derive(Debug, Clone)]
pub struct OocIsovalues<T: Voxel> {
    set: IsoSet<T>,
    queries: [CodeQuery; INLINE_ISOVALUES],
    count: usize,
    /// More queries than fit: every node passes (conservative).
    all: bool,
}

impl<T: Voxel> OocIsovalues<T> {
    fn new(meta: &OocMeta, isovalues: &[f32]) -> Self {
        let mut queries = [CodeQuery { a: 0, b: 0 }; INLINE_ISOVALUES];
        let mut count = 0;
        let mut all = false;
        for &c in isovalues {
            if let Some(q) = meta.quantizer.query(meta.value_map.iso_to_stored(c)) {
                if count == INLINE_ISOVALUES {
                    all = true;
                    break;
                }
                queries[count] = q;
                count += 1;
            }
        }
        Self {
            set: IsoSet::mapped(isovalues, meta.value_map),
            queries,
            count,
            all,
        }
    }
}

/// One frame's view of an [`OocVolume`]: immutable, shared by all render threads.
pub struct OocScene<T: Voxel> {
    shared: Arc<Shared<T>>,
    snap: Arc<Snapshot<T>>,
    intersector: Intersector,
    /// Shading normals of hits (smooth unless [`OocScene::with_normals`]).
    normals: Normals,
    /// This frame's use stamp (least-recently-used eviction of demand-paged treelets).
    stamp: u64,
}

impl<T: Voxel> Drop for OocScene<T> {
    /// The frame is over: hand its misses to the loader.
    fn drop(&mut self) {
        if self.shared.missed.swap(false, Ordering::AcqRel) {
            let mut st = self.shared.state.lock().expect("loader state");
            st.miss_pending = true;
            self.shared.changed.notify_all();
        }
    }
}

impl<T: Voxel> std::fmt::Debug for OocScene<T> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("OocScene")
            .field("level", &self.level())
            .finish_non_exhaustive()
    }
}

/// A far child to visit later: its node, tree level, slot in its treelet, the treelet
/// (level `tl`, index `ti`), and the interval (`f32` for a ray, lanes for a packet).
#[derive(Debug, Clone, Copy, Default)]
struct Entry<L> {
    node: [u32; 3],
    level: u32,
    h: u32,
    tl: u32,
    ti: u64,
    t_near: L,
    t_far: L,
}

thread_local! {
    /// The traversal stacks of this thread's rays and packets (one entry per level at most),
    /// made once per thread: zeroing 64 entries per ray showed in profiles.
    static STACK: RefCell<Vec<Entry<f32>>> = const { RefCell::new(Vec::new()) };
    /// Packets also keep their rays' lanes here, written in place per packet.
    static PACKET_STACK: RefCell<(Vec<Entry<Lanes>>, PacketRays)> =
        const { RefCell::new((Vec::new(), PacketRays::EMPTY)) };
}

/// The children of an inner node as both traversals read them.
#[derive(Debug, Clone, Copy)]
struct NodeSplit {
    axis: usize,
    /// One-hot `axis`.
    unit: [u32; 3],
    /// Split position (traversal units); `+inf` when the left child covers every real cell.
    split: f32,
    left: [u32; 3],
    right_real: bool,
}

/// The left (`right == false`) or right child of a node whose left child is `left` along the
/// one-hot axis `u`, with its heap slot in the treelet (parent slot `h`).
#[inline(always)]
fn child_of(left: [u32; 3], u: [u32; 3], h: usize, right: bool) -> ([u32; 3], usize) {
    let r = u32::from(right);
    (
        [left[0] + r * u[0], left[1] + r * u[1], left[2] + r * u[2]],
        2 * h + 1 + r as usize,
    )
}

/// Most nodes [`OocScene::live_cell_box`] looks at (as the in-core
/// [`crate::kdtree::LIVE_BOX_NODES`]).
const LIVE_BOX_NODES: usize = 1 << 15;

/// Most nodes [`OocScene::live_boxes`] looks at before the rest count whole: its boxes are
/// projected every frame (as the in-core [`crate::kdtree::LIVE_COVER_NODES`]).
const LIVE_COVER_NODES: usize = 1 << 12;

impl<T: Voxel> OocScene<T> {
    /// This frame with `normals` for its hits (smooth by default).
    pub fn with_normals(mut self, normals: Normals) -> Self {
        self.normals = normals;
        self
    }

    /// The inclusive finest-cell box around every cell this frame's traversal can find a
    /// crossing in (the in-core [`crate::kdtree::KdTree::live_cell_box`]), or `None` when
    /// there is none: the union of [`OocScene::live_cell_boxes`] at [`LIVE_BOX_NODES`].
    fn live_cell_box(&self, isos: &OocIsovalues<T>) -> Option<[[u64; 3]; 2]> {
        union_of_cell_boxes(|f| self.live_cell_boxes(isos, LIVE_BOX_NODES, f))
    }

    /// Calls `f` with inclusive finest-cell boxes, every cell this frame's traversal can
    /// find a crossing in lying in one of them. The walk follows the traversal's own rule
    /// through this frame's snapshot: nodes whose quantized range passes a query, into a
    /// child treelet exactly when the traversal would enter it (resident in the snapshot),
    /// else the node's LOD cell whole. Breadth first until `max_nodes` nodes were looked
    /// at; the passing nodes left then count whole. No side effects (no use stamps, no
    /// misses).
    fn live_cell_boxes(
        &self,
        isos: &OocIsovalues<T>,
        max_nodes: usize,
        mut f: impl FnMut([[u64; 3]; 2]),
    ) {
        if isos.set.is_empty() || isos.count == 0 {
            return;
        }
        let queries = &isos.queries[..isos.count];
        let layout = &self.shared.meta.layout;
        let q = &self.shared.meta.quantizer;
        let levels = &self.snap.levels;
        let Some(render) = levels.len().checked_sub(1) else {
            return;
        };
        let Some(root) = levels[0].get(&0) else {
            return;
        };
        let cells = layout.cells();
        let mut grow = |level: usize, node: [u32; 3]| {
            let e = layout.shape(level).extent;
            let n = node.map(u64::from);
            f([
                [0, 1, 2].map(|a| n[a] * e[a]),
                [0, 1, 2].map(|a| ((n[a] + 1) * e[a]).min(cells[a]) - 1),
            ]);
        };
        // (treelet level, treelet, tree level, node, heap slot in the treelet)
        let mut todo = std::collections::VecDeque::new();
        todo.push_back((0usize, root, 0usize, [0u32; 3], 0usize));
        let mut looked = 0usize;
        while let Some((tl, cur, level, node, h)) = todo.pop_front() {
            if level == layout.level(tl).end {
                let child = (tl < render)
                    .then(|| linear_index(layout.level(tl + 1).roots, node.map(u64::from)))
                    .and_then(|idx| levels[tl + 1].get(&idx));
                match child {
                    Some(child) => todo.push_back((tl + 1, child, level, node, 0)),
                    None => grow(level, node),
                }
                continue;
            }
            let c = q.get(&cur.rec.nodes, h);
            if !(isos.all || queries.iter().any(|x| x.passes(c[0], c[1]))) {
                continue;
            }
            looked += 1;
            if looked + todo.len() >= max_nodes {
                grow(level, node);
                continue;
            }
            let ns = self.split_of(level, node);
            for right in [false, true] {
                if right && !ns.right_real {
                    continue;
                }
                let (child, ch) = child_of(ns.left, ns.unit, h, right);
                todo.push_back((tl, cur, level + 1, child, ch));
            }
        }
    }

    /// The finest complete level of this frame (0 = coarsest); demand-paged treelets of
    /// finer levels refine it where they are resident.
    pub fn level(&self) -> usize {
        self.snap.complete.saturating_sub(1)
    }

    pub fn resident_bytes(&self) -> u64 {
        self.snap.resident_bytes
    }

    /// The prepared isovalues as the traversal reads them: an empty set or no quantized
    /// query means no hit.
    #[inline]
    fn cell_hit_in<C: CellIntersector, S: Stats>(
        &self,
        ray: &LocalRay,
        t_min: f32,
        t_max: f32,
        isos: &OocIsovalues<T>,
        intersector: C,
        stats: &mut S,
    ) -> Option<(CellHit, &ResidentTreelet<T>)> {
        if isos.set.is_empty() || isos.count == 0 {
            return None;
        }
        let (t0, t1) = self.shared.frame.clip(ray, t_min, t_max)?;
        let queries = &isos.queries[..isos.count];
        let depth = self.shared.meta.layout.depth();
        // One stack per thread, not per ray (zeroing 64 entries per ray showed in profiles).
        STACK.with_borrow_mut(|stack| {
            if stack.len() <= depth {
                stack.resize(depth + 1, Entry::default());
            }
            self.traverse(
                ray,
                t0,
                t1,
                &isos.set,
                queries,
                isos.all,
                intersector,
                stats,
                stack,
            )
        })
    }

    /// At the bottom of a treelet of level `tl` (below the finest published level), at
    /// `node`: the child treelet and its index if it is resident (stamped as used), else
    /// `None` with the miss recorded for the loader.
    #[inline(always)]
    fn child_treelet(&self, tl: usize, node: [u32; 3]) -> Option<(&ResidentTreelet<T>, u64)> {
        let layout = &self.shared.meta.layout;
        let idx = linear_index(layout.level(tl + 1).roots, node.map(u64::from));
        let paged = tl + 1 >= self.snap.complete;
        if let Some(child) = self.snap.levels[tl + 1].get(&idx) {
            if paged && child.last_used.load(Ordering::Relaxed) != self.stamp {
                child.last_used.store(self.stamp, Ordering::Relaxed);
            }
            return Some((child, idx));
        }
        if paged {
            self.shared.record_miss(tl + 1, idx);
        }
        None
    }

    /// The split of inner node `node` at tree `level` and its children. One-hot axis
    /// arithmetic keeps the node in registers (as `KdTree::children`): indexing a `[u32; 3]`
    /// by the axis and reading it back whole stalled store forwarding on every step.
    #[inline(always)]
    fn split_of(&self, level: usize, node: [u32; 3]) -> NodeSplit {
        let layout = &self.shared.meta.layout;
        let shapes = layout.shapes();
        let sh = &shapes[level];
        let a = sh.axis;
        let u = [0, 1, 2].map(|i| u32::from(a == i));
        let na = node[0] * u[0] + node[1] * u[1] + node[2] * u[2];
        let m = u64::from(na) * sh.extent[a] + sh.extent[a] / 2;
        let split = if m < layout.cells()[a] {
            self.shared.frame.pos()[a][m as usize]
        } else {
            f32::INFINITY
        };
        NodeSplit {
            axis: a,
            unit: u,
            split,
            left: [node[0] << u[0], node[1] << u[1], node[2] << u[2]],
            right_real: u64::from(2 * na + 1) < shapes[level + 1].count[a],
        }
    }

    #[inline(always)]
    fn traverse<'s, C: CellIntersector, S: Stats>(
        &'s self,
        ray: &LocalRay,
        t0: f32,
        t1: f32,
        isos: &IsoSet<T>,
        queries: &[CodeQuery],
        all: bool,
        intersector: C,
        stats: &mut S,
        stack: &mut [Entry<f32>],
    ) -> Option<(CellHit, &'s ResidentTreelet<T>)> {
        let meta = &self.shared.meta;
        let layout = &meta.layout;
        let q = &meta.quantizer;
        let levels = &self.snap.levels;
        let render = levels.len().checked_sub(1)?;
        let mut cur: &ResidentTreelet<T> = levels[0].get(&0)?;
        let (mut tl, mut ti) = (0usize, 0u64);
        let mut end = layout.level(0).end;
        let mut node = [0u32; 3];
        let mut level = 0usize;
        let mut h = 0usize;
        let (mut ta, mut tb) = (t0, t1);
        let mut sp = 0usize;
        let mut best: Option<(CellHit, &ResidentTreelet<T>)> = None;
        'outer: loop {
            loop {
                if level == end {
                    if tl < render
                        && let Some((child, idx)) = self.child_treelet(tl, node)
                    {
                        cur = child;
                        tl += 1;
                        ti = idx;
                        end = layout.level(tl).end;
                        h = 0;
                        continue;
                    }
                    // Intersect the cell of this level's LOD voxels (Listing 7.3).
                    let o = cur.rec.voxel_origin;
                    let cell = [0, 1, 2].map(|a| (u64::from(node[a]) - o[a]) as usize);
                    if let Some(hit) = intersect_cell(
                        &cur.frame,
                        &cur.rec.voxels,
                        cur.rec.voxel_dims,
                        ray,
                        cell,
                        t0,
                        t1,
                        isos,
                        intersector,
                        stats,
                    ) && best.is_none_or(|b| hit.t < b.0.t)
                    {
                        best = Some((hit, cur));
                    }
                    break;
                }
                let c = q.get(&cur.rec.nodes, h);
                if !(all || queries.iter().any(|x| x.passes(c[0], c[1]))) {
                    break;
                }
                stats.node();
                let ns = self.split_of(level, node);
                let (a, u, left) = (ns.axis, ns.unit, ns.left);
                level += 1;
                let step = ray_step(ray.origin[a], ray.dir[a], ray.inv_dir[a], ns.split, ta, tb);
                // Children as `false` (left) / `true` (right): no node tuples through memory.
                // The left child is always real; culling happens when a node is entered.
                let (next, far) = take_step(step, false, true, true, ns.right_real, &mut tb);
                if let Some((f, t_near, t_far)) = far {
                    let (node, h) = child_of(left, u, h, f);
                    stack[sp] = Entry {
                        node,
                        level: level as u32,
                        h: h as u32,
                        tl: tl as u32,
                        ti,
                        t_near,
                        t_far,
                    };
                    sp += 1;
                }
                match next {
                    Some(right) => (node, h) = child_of(left, u, h, right),
                    None => break,
                }
            }
            loop {
                if sp == 0 {
                    break 'outer;
                }
                sp -= 1;
                let e = stack[sp];
                let limit = best.map_or(f32::INFINITY, |b| b.0.t);
                if e.t_near <= limit {
                    node = e.node;
                    level = e.level as usize;
                    h = e.h as usize;
                    if e.tl as usize != tl || e.ti != ti {
                        tl = e.tl as usize;
                        ti = e.ti;
                        cur = levels[tl].get(&ti)?;
                        end = layout.level(tl).end;
                    }
                    ta = e.t_near;
                    tb = e.t_far.min(limit);
                    continue 'outer;
                }
            }
        }
        best
    }

    /// The packet twin of [`Self::traverse`] (as [`crate::kdtree`]'s packet traversal is of
    /// its single-ray one): up to [`PACKET_WIDTH`] [`packet_compatible`] rays walk the
    /// treelets together with per-ray intervals in lanes, and enter a child treelet together
    /// (it is chosen by the node, not the ray); leaves test the active rays at once
    /// ([`packet_leaf`]) in the current treelet's voxel block. Same hits as ray by ray.
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn traverse_packet<'s, C: CellIntersector, S: Stats>(
        &'s self,
        rays: &[LocalRay],
        t0: &[f32],
        t1: &[f32],
        isos: &IsoSet<T>,
        queries: &[CodeQuery],
        all: bool,
        intersector: C,
        stats: &mut S,
        stack: &mut [Entry<Lanes>],
        p: &mut PacketRays,
        out: &mut [Option<(CellHit, CellBlock<'s, T>)>],
    ) {
        let meta = &self.shared.meta;
        let layout = &meta.layout;
        let q = &meta.quantizer;
        let levels = &self.snap.levels;
        let Some(render) = levels.len().checked_sub(1) else {
            return;
        };
        let Some(mut cur) = levels[0].get(&0).map(|t| &**t) else {
            return;
        };
        let n = rays.len().min(PACKET_WIDTH);
        debug_assert!(packet_compatible(&rays[..n]));
        p.set(&rays[..n], &t0[..n], &t1[..n]);
        let (mut tn, mut tf) = (p.t_near, p.t_far);
        let (mut tl, mut ti) = (0usize, 0u64);
        let mut end = layout.level(0).end;
        let mut node = [0u32; 3];
        let mut level = 0usize;
        let mut h = 0usize;
        let mut sp = 0usize;
        let mut best = [f32::INFINITY; PACKET_WIDTH];
        let mut best_v = splat(f32::INFINITY);
        'outer: loop {
            loop {
                let active = tn.simd_le(tf);
                if !any_lane(&active) {
                    break;
                }
                if level == end {
                    if tl < render
                        && let Some((child, idx)) = self.child_treelet(tl, node)
                    {
                        cur = child;
                        tl += 1;
                        ti = idx;
                        end = layout.level(tl).end;
                        h = 0;
                        continue;
                    }
                    // The cell of this level's LOD voxels (Listing 7.3), for every active ray.
                    let o = cur.rec.voxel_origin;
                    let cell = [0, 1, 2].map(|a| (u64::from(node[a]) - o[a]) as usize);
                    let block = CellBlock {
                        frame: &cur.frame,
                        voxels: &cur.rec.voxels,
                        dims: cur.rec.voxel_dims,
                    };
                    best_v = packet_leaf(
                        block.frame,
                        block.voxels,
                        block.dims,
                        cell,
                        p,
                        mask_bits(&active),
                        isos,
                        intersector,
                        stats,
                        &mut best,
                        // Treelet cells come from several blocks, some paged out by the end
                        // of the walk: roots are found as the cells are met.
                        None,
                        |k, hit| {
                            out[k] = Some((hit, block));
                            LaneNext::Stop(hit.t)
                        },
                    );
                    break;
                }
                let c = q.get(&cur.rec.nodes, h);
                if !(all || queries.iter().any(|x| x.passes(c[0], c[1]))) {
                    break;
                }
                stats.node();
                let ns = self.split_of(level, node);
                let (a, u, left) = (ns.axis, ns.unit, ns.left);
                level += 1;
                let ts = (f32x16::splat(ns.split) - p.org[a]) * p.inv[a];
                // The packet enters one child when every active ray does (as in-core).
                let step = Step {
                    near_is_left: p.dir_pos[a],
                    visit: packet_visit(&active, &ts, &tn, &tf),
                };
                let (next, far) = take_step(step, false, true, true, ns.right_real, &mut tf);
                if let Some((f, t_near, t_far)) = far {
                    let (node, h) = child_of(left, u, h, f);
                    stack[sp] = Entry {
                        node,
                        level: level as u32,
                        h: h as u32,
                        tl: tl as u32,
                        ti,
                        t_near,
                        t_far,
                    };
                    sp += 1;
                }
                match next {
                    Some(right) => (node, h) = child_of(left, u, h, right),
                    None => break,
                }
            }
            loop {
                if sp == 0 {
                    break 'outer;
                }
                sp -= 1;
                let e = stack[sp];
                let e_tf = e.t_far.min(best_v);
                if any_lane(&e.t_near.simd_le(e_tf)) {
                    node = e.node;
                    level = e.level as usize;
                    h = e.h as usize;
                    if e.tl as usize != tl || e.ti != ti {
                        tl = e.tl as usize;
                        ti = e.ti;
                        match levels[tl].get(&ti) {
                            Some(t) => cur = t,
                            None => break 'outer,
                        }
                        end = layout.level(tl).end;
                    }
                    tn = e.t_near;
                    tf = e_tf;
                    continue 'outer;
                }
            }
        }
    }
}

impl<T: Voxel> CellTrace<T> for OocScene<T> {
    type Isovalues = OocIsovalues<T>;

    fn frame(&self) -> &TraversalFrame {
        &self.shared.frame
    }

    fn normals(isos: &Self::Isovalues) -> Option<Normals> {
        isos.set.normals()
    }

    #[inline]
    fn cell_hit<C: CellIntersector, S: Stats>(
        &self,
        ray: &LocalRay,
        t_min: f32,
        t_max: f32,
        isos: &OocIsovalues<T>,
        intersector: C,
        stats: &mut S,
    ) -> Option<(CellHit, CellBlock<'_, T>)> {
        let (h, t) = self.cell_hit_in(ray, t_min, t_max, isos, intersector, stats)?;
        let block = CellBlock {
            frame: &t.frame,
            voxels: &t.rec.voxels,
            dims: t.rec.voxel_dims,
        };
        Some((h, block))
    }

    #[inline]
    fn cell_hits_packet<'s, C: CellIntersector, S: Stats>(
        &'s self,
        rays: &[LocalRay],
        t0: &[f32],
        t1: &[f32],
        isos: &OocIsovalues<T>,
        intersector: C,
        stats: &mut S,
        out: &mut [Option<(CellHit, CellBlock<'s, T>)>],
    ) {
        let n = rays.len().min(PACKET_WIDTH);
        for o in &mut out[..n] {
            *o = None;
        }
        if isos.set.is_empty() || isos.count == 0 || n == 0 {
            return;
        }
        let depth = self.shared.meta.layout.depth();
        PACKET_STACK.with_borrow_mut(|(stack, p)| {
            if stack.len() <= depth {
                stack.resize(depth + 1, Entry::default());
            }
            self.traverse_packet(
                &rays[..n],
                t0,
                t1,
                &isos.set,
                &isos.queries[..isos.count],
                isos.all,
                intersector,
                stats,
                stack,
                p,
                out,
            );
        });
    }
}

impl<T: Voxel> IsoScene for OocScene<T> {
    type Isovalues = OocIsovalues<T>;

    fn prepare(&self, isovalues: &[f32]) -> OocIsovalues<T> {
        let mut isos = OocIsovalues::new(&self.shared.meta, isovalues);
        isos.set = isos.set.with_normals(self.normals);
        isos
    }

    fn prepare_distances(&self, isovalues: &[f32]) -> OocIsovalues<T> {
        let mut isos = self.prepare(isovalues);
        isos.set = isos.set.without_normals();
        isos
    }

    fn world_bounds(&self) -> Aabb {
        self.shared.frame.world_bounds()
    }

    /// The finest cells the traversal can find a crossing in (the passing nodes of a walk
    /// through this frame's resident treelets, as the traversal walks them), in world
    /// units, a cell wider on every side ([`TraversalFrame::world_bounds_of_cells`]).
    fn live_bounds(&self, isos: &OocIsovalues<T>) -> Aabb {
        match self.live_cell_box(isos) {
            Some([lo, hi]) => self
                .shared
                .frame
                .world_bounds_of_cells(lo.map(|x| x as usize), hi.map(|x| x as usize)),
            None => Aabb::EMPTY,
        }
    }

    /// The boxes of the walk of [`IsoScene::live_bounds`] stopped after 2¹² nodes, in
    /// world units, each a cell wider on every side.
    fn live_boxes(&self, isos: &OocIsovalues<T>, out: &mut Vec<Aabb>) {
        let frame = &self.shared.frame;
        self.live_cell_boxes(isos, LIVE_COVER_NODES, |[lo, hi]| {
            out.push(frame.world_bounds_of_cells(lo.map(|x| x as usize), hi.map(|x| x as usize)));
        });
    }

    #[inline]
    fn first_hit_prepared<S: Stats>(
        &self,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
        isos: &OocIsovalues<T>,
        stats: &mut S,
    ) -> Option<Hit> {
        crate::dispatch_intersector!(self.intersector, c => first_hit_with(self, ray, t_min, t_max, isos, c, stats))
    }

    fn first_hit_packet_prepared<S: Stats>(
        &self,
        rays: &[Ray],
        t_min: &[f32],
        t_max: &[f32],
        isos: &OocIsovalues<T>,
        out: &mut [Option<Hit>],
        stats: &mut S,
    ) {
        crate::dispatch_intersector!(self.intersector, c => {
            for (start, chunk) in rays.chunks(PACKET_WIDTH).enumerate() {
                let base = start * PACKET_WIDTH;
                first_hits_packet_with(self, chunk, &t_min[base..], &t_max[base..], isos, c, &mut out[base..], stats);
            }
        });
    }
}

crate::voxel_enum! {
    /// An [`OocVolume`] of whichever voxel type the storage holds.
    #[derive(Debug)]
    pub enum AnyOocVolume(OocVolume)
}

/// [`crate::match_voxel!`] for [`AnyOocVolume`].
macro_rules! dispatch_ooc {
    ($v:expr, $s:ident => $body:expr) => {
        crate::match_voxel!(AnyOocVolume, $v, $s => $body)
    };
}

impl AnyOocVolume {
    /// Opens `storage` with the voxel type it records.
    pub fn open(storage: Arc<dyn TreeletStorage>, options: OocOptions) -> Result<Self, OocError> {
        Ok(crate::match_voxel_type!(storage.meta().voxel_type, V => {
            OocVolume::<V>::open(storage, options)?.into()
        }))
    }

    pub fn meta(&self) -> &OocMeta {
        dispatch_ooc!(self, v => v.meta())
    }

    pub fn set_isovalues(&self, isovalues: &[f32]) {
        dispatch_ooc!(self, v => v.set_isovalues(isovalues));
    }

    pub fn loaded_levels(&self) -> usize {
        dispatch_ooc!(self, v => v.loaded_levels())
    }

    pub fn level_count(&self) -> usize {
        dispatch_ooc!(self, v => v.level_count())
    }

    pub fn resident_bytes(&self) -> u64 {
        dispatch_ooc!(self, v => v.resident_bytes())
    }

    pub fn is_finished(&self) -> bool {
        dispatch_ooc!(self, v => v.is_finished())
    }

    pub fn budget_limited(&self) -> bool {
        dispatch_ooc!(self, v => v.budget_limited())
    }

    pub fn error(&self) -> Option<OocError> {
        dispatch_ooc!(self, v => v.error())
    }

    pub fn wait_until_finished(&self, timeout: Duration) -> bool {
        dispatch_ooc!(self, v => v.wait_until_finished(timeout))
    }

    pub fn on_level(&self, listener: impl Fn(&LoadProgress) + Send + Sync + 'static) {
        dispatch_ooc!(self, v => v.on_level(listener));
    }

    pub fn progress(&self) -> LoadProgress {
        dispatch_ooc!(self, v => v.progress())
    }

    pub fn generation(&self) -> u64 {
        dispatch_ooc!(self, v => v.generation())
    }

    /// Hands this frame's typed [`OocScene`] to `visitor` (monomorphized rendering, as
    /// [`crate::grid::AnyGridScene::visit`]).
    pub fn visit_scene<V: crate::render::SceneVisitor>(
        &self,
        intersector: Intersector,
        normals: Normals,
        visitor: V,
    ) -> V::Output {
        dispatch_ooc!(self, v => visitor.visit(&v.scene(intersector).with_normals(normals)))
    }

    /// The finest level a frame rendered now could reach (what
    /// [`Self::render_with_level`] reports), without rendering.
    pub fn current_level(&self, intersector: Intersector) -> usize {
        dispatch_ooc!(self, v => v.scene(intersector).level())
    }

    /// Renders one frame with the levels loaded now and returns it with the finest level
    /// that frame could reach (0 = coarsest); `None` if `cancel` was set. The caller
    /// requests the frame's isovalues first ([`Self::set_isovalues`]).
    pub fn render_with_level(
        &self,
        intersector: Intersector,
        normals: Normals,
        camera: &crate::render::Camera,
        settings: &crate::render::RenderSettings,
        cancel: &AtomicBool,
    ) -> Option<(crate::render::Frame, usize)> {
        dispatch_ooc!(self, v => {
            let scene = v.scene(intersector).with_normals(normals);
            let frame = crate::render::render(&scene, camera, settings, cancel)?;
            Some((frame, scene.level()))
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::grid::GridScene;
    use crate::kdtree::KdTreeConfig;
    use crate::ooc::build::build_treelets;
    use crate::ooc::layout::TreeletLayout;
    use crate::ooc::treelet::MemoryStorage;
    use crate::render::NoStats;
    use crate::volume::{Grid, VoxelBuffer};
    use glam::Vec3;

    /// Two blobs (distance-like fields) on an anisotropic grid.
    fn blobs(dims: [usize; 3]) -> Vec<f32> {
        let mut v = Vec::new();
        for k in 0..dims[2] {
            for j in 0..dims[1] {
                for i in 0..dims[0] {
                    let p = Vec3::new(i as f32, j as f32, k as f32);
                    let a = (p - Vec3::new(9.0, 8.0, 6.0)).length();
                    let b = (p - Vec3::new(22.0, 14.0, 10.0)).length() * 1.3;
                    v.push(a.min(b) + 0.3 * (i as f32 * 0.7).sin());
                }
            }
        }
        v
    }

    fn rays(bounds: Aabb, n: usize) -> Vec<Ray> {
        let mut rng = crate::math::rng::Rng::new(12_345);
        let mut rnd = || rng.unit_f32();
        let c = (bounds.min + bounds.max) * 0.5;
        let ext = bounds.max - bounds.min;
        let mut out = Vec::new();
        for i in 0..n {
            let target = bounds.min + Vec3::new(rnd(), rnd(), rnd()) * ext;
            if i % 7 == 0 {
                // Axis-aligned rays through sample planes (split-plane robustness).
                let mut o = target.round();
                o.z = bounds.min.z - 5.0;
                out.push(Ray::new(o, Vec3::Z));
                continue;
            }
            let origin =
                c + Vec3::new(rnd() - 0.5, rnd() - 0.5, rnd() - 0.5).normalize() * ext.length();
            out.push(Ray::new(origin, (target - origin).normalize()));
        }
        out
    }

    fn setup(dims: [usize; 3], h: u32, budget: u64) -> (Grid, Vec<f32>, OocVolume<f32>) {
        let grid = Grid::uniform(dims, [-3.0, 1.0, 2.0], [1.0, 0.75, 1.5]).unwrap();
        let voxels = blobs(dims);
        // Split as the in-core tree is (in world space: these cells are not cubes).
        let layout = TreeletLayout::for_grid(&grid, h).unwrap();
        assert_ne!(
            layout.split_axes(),
            TreeletLayout::new(dims.map(|d| d as u64), h)
                .unwrap()
                .split_axes()
        );
        let mut store = MemoryStorage::new();
        build_treelets(&grid, &voxels, layout, &mut store, &mut |_, _| {}).unwrap();
        let vol = OocVolume::<f32>::open(
            Arc::new(store),
            OocOptions {
                budget_bytes: budget,
            },
        )
        .unwrap();
        (grid, voxels, vol)
    }

    /// Packets of 16 rays: 4×4 fans from random eyes (one packet each, as a camera's tiles
    /// are), then the random rays of [`rays`] in groups of 16 (mixed directions: groups of 8
    /// or one by one), some with a finite `t_max`.
    fn packets(bounds: Aabb, fans: usize) -> (Vec<Ray>, Vec<f32>) {
        let mut rng = crate::math::rng::Rng::new(777);
        let mut rnd = || rng.unit_f32();
        let c = (bounds.min + bounds.max) * 0.5;
        let ext = bounds.max - bounds.min;
        let mut out = Vec::new();
        for _ in 0..fans {
            let eye =
                c + Vec3::new(rnd() - 0.5, rnd() - 0.5, rnd() - 0.5).normalize() * ext.length();
            let target = bounds.min + Vec3::new(rnd(), rnd(), rnd()) * ext;
            let spread = 0.05 + 0.6 * rnd();
            for j in 0..4 {
                for i in 0..4 {
                    let off = Vec3::new(i as f32 - 1.5, j as f32 - 1.5, 0.3 * (i as f32)) * spread;
                    out.push(Ray::new(eye, (target + off - eye).normalize()));
                }
            }
        }
        out.extend(rays(bounds, 16 * fans));
        let t_max = (0..out.len())
            .map(|i| {
                if i % 5 == 3 {
                    ext.length() * 0.9
                } else {
                    f32::INFINITY
                }
            })
            .collect();
        (out, t_max)
    }

    /// Every packet hit equals the ray's single-ray hit (bit for bit), whichever treelets
    /// are resident.
    fn assert_packets_equal_single_rays(scene: &OocScene<f32>, isos: &[f32]) -> usize {
        let (all, t_max) = packets(scene.world_bounds(), 300);
        let t_min = vec![0.0; all.len()];
        let mut packet = vec![None; all.len()];
        scene.first_hit_packet(&all, &t_min, &t_max, isos, &mut packet, &mut NoStats);
        let mut hits = 0;
        for (i, r) in all.iter().enumerate() {
            let single = scene.first_hit(r, t_min[i], t_max[i], isos, &mut NoStats);
            assert_eq!(packet[i], single, "ray {i}: {r:?}");
            hits += usize::from(single.is_some());
        }
        hits
    }

    #[test]
    fn packets_hit_as_single_rays_at_every_level_and_when_paged() {
        let dims = [31, 23, 17];
        let isos = [4.0f32, 6.5];
        let (_, _, vol) = setup(dims, 4, u64::MAX);
        // Only the top treelet (level 0), then every level.
        let coarse = vol.scene(Intersector::Exact);
        assert_eq!(coarse.level(), 0);
        let n: usize = [[4.0f32], [8.0], [12.0], [16.0]]
            .iter()
            .map(|iso| assert_packets_equal_single_rays(&coarse, iso))
            .sum();
        assert!(n > 100, "{n}");
        drop(coarse);
        vol.set_isovalues(&isos);
        assert!(vol.wait_until_finished(Duration::from_secs(30)));
        assert_eq!(vol.loaded_levels(), vol.level_count());
        for intersector in [Intersector::Exact, Intersector::Linear] {
            let fine = vol.scene(intersector);
            assert!(assert_packets_equal_single_rays(&fine, &isos) > 500);
        }
        // A budget below the finest level: it is paged in as frames ask for it, so child
        // treelets are missing under some nodes and resident under others.
        let (_, _, paged) = setup(dims, 4, vol.resident_bytes() / 2);
        paged.set_isovalues(&isos);
        assert!(paged.wait_until_finished(Duration::from_secs(30)));
        assert!(paged.budget_limited());
        assert!(paged.loaded_levels() < paged.level_count());
        let first = paged.scene(Intersector::Exact);
        assert!(assert_packets_equal_single_rays(&first, &isos) > 500);
        drop(first);
        assert!(paged.wait_until_finished(Duration::from_secs(30)));
        let scene = paged.scene(Intersector::Exact);
        assert!(assert_packets_equal_single_rays(&scene, &isos) > 500);
    }

    /// [`OocScene::live_bounds`] against the scene itself: each ray cut to them finds the
    /// hit it finds uncut, and frames equal the whole-bounds twin's bit for bit; returns
    /// the hits and whether the frame traced fewer rays.
    fn assert_live_bounds_keep_hits(scene: &OocScene<f32>, isos: &[f32]) -> (usize, bool) {
        use crate::render::{Camera, RenderSettings, Surface, WholeBounds, render};
        let live = scene.live_bounds(&scene.prepare(isos));
        let whole = scene.world_bounds();
        let mut hits = 0;
        // Cut as the renderer cuts them: to the data's box, or to the live bounds.
        let cut = |b: &Aabb, r: &Ray| {
            b.intersect(r, 0.0, f32::INFINITY)
                .and_then(|(lo, hi)| scene.first_hit(r, lo, hi, isos, &mut NoStats))
        };
        for r in rays(whole, 1500) {
            let (a, b) = (cut(&whole, &r), cut(&live, &r));
            assert_eq!(a, b, "{r:?}, live bounds {live:?}");
            hits += usize::from(a.is_some());
        }
        let settings = RenderSettings {
            width: 64,
            height: 48,
            surfaces: isos.iter().map(|&c| Surface::new(c, [0.8; 3])).collect(),
            collect_stats: true,
            ..RenderSettings::default()
        };
        let cam = Camera::orbit(&whole, 30.0, 20.0, 40.0);
        let go = AtomicBool::new(false);
        let cut = render(scene, &cam, &settings, &go).unwrap();
        let full = render(&WholeBounds(scene), &cam, &settings, &go).unwrap();
        assert_eq!(cut.rgba8, full.rgba8);
        let bits = |d: &[f32]| d.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&cut.depth), bits(&full.depth));
        assert!(cut.counts.rays <= full.counts.rays);
        // Hits without normals (`prepare_distances`): the same depth map.
        let flat = RenderSettings {
            depth_only: true,
            ..settings.clone()
        };
        assert!(scene.prepare_distances(isos).set.normals().is_none());
        let flat = render(scene, &cam, &flat, &go).unwrap();
        assert_eq!(bits(&flat.depth), bits(&full.depth));
        (hits, cut.counts.rays < full.counts.rays)
    }

    #[test]
    fn live_bounds_keep_every_hit_at_every_level_and_when_paged() {
        let dims = [31, 23, 17];
        let isos = [2.5f32, 4.0];
        let (_, _, vol) = setup(dims, 4, u64::MAX);
        // Only the top treelet: its coarse nodes bound the box.
        let coarse = vol.scene(Intersector::Exact);
        assert_eq!(coarse.level(), 0);
        let coarse_hits: usize = [[4.0f32], [8.0], [12.0]]
            .iter()
            .map(|iso| assert_live_bounds_keep_hits(&coarse, iso).0)
            .sum();
        assert!(coarse_hits > 100, "{coarse_hits}");
        assert!(coarse.live_bounds(&coarse.prepare(&[1e6])).is_empty());
        drop(coarse);
        vol.set_isovalues(&isos);
        assert!(vol.wait_until_finished(Duration::from_secs(30)));
        let fine = vol.scene(Intersector::Exact);
        let (hits, fewer) = assert_live_bounds_keep_hits(&fine, &isos);
        assert!(hits > 100 && fewer, "{hits} hits, fewer rays: {fewer}");
        drop(fine);
        // Paged: child treelets resident under some nodes only.
        let (_, _, paged) = setup(dims, 4, vol.resident_bytes() / 2);
        paged.set_isovalues(&isos);
        assert!(paged.wait_until_finished(Duration::from_secs(30)));
        assert!(paged.budget_limited());
        let first = paged.scene(Intersector::Exact);
        assert!(assert_live_bounds_keep_hits(&first, &isos).0 > 100);
        drop(first);
        assert!(paged.wait_until_finished(Duration::from_secs(30)));
        let scene = paged.scene(Intersector::Exact);
        assert!(assert_live_bounds_keep_hits(&scene, &isos).0 > 100);
    }

    #[test]
    fn finest_level_hits_equal_the_in_core_scene() {
        let dims = [31, 23, 17];
        let (grid, voxels, vol) = setup(dims, 4, u64::MAX);
        assert!(vol.level_count() >= 3);
        let isos = [4.0f32, 6.5];
        vol.set_isovalues(&isos);
        assert!(vol.wait_until_finished(Duration::from_secs(30)));
        assert_eq!(vol.error(), None);
        assert_eq!(vol.loaded_levels(), vol.level_count());
        let ooc = vol.scene(Intersector::Exact);
        assert_eq!(ooc.level(), vol.level_count() - 1);
        let incore = GridScene::new(
            &grid,
            VoxelBuffer::from_vec(voxels),
            Intersector::Exact,
            KdTreeConfig::default(),
        )
        .unwrap();
        assert_eq!(ooc.world_bounds(), incore.world_bounds());
        let mut hits = 0;
        for r in rays(incore.world_bounds(), 3000) {
            let a = incore.first_hit(&r, 0.0, f32::INFINITY, &isos, &mut NoStats);
            let b = ooc.first_hit(&r, 0.0, f32::INFINITY, &isos, &mut NoStats);
            assert_eq!(a, b, "{r:?}");
            hits += usize::from(a.is_some());
        }
        assert!(hits > 500, "{hits}");
        assert!(vol.resident_bytes() > 0);
    }

    #[test]
    fn physical_isovalues_through_a_value_map_hit_as_in_core() {
        // A reversing map (slope −2, intercept 10): physical 2 and −3 are stored 4 and 6.5.
        let dims = [31, 23, 17];
        let grid = Grid::uniform(dims, [-3.0, 1.0, 2.0], [1.0, 0.75, 1.5]).unwrap();
        let voxels = blobs(dims);
        let layout = TreeletLayout::new(dims.map(|d| d as u64), 4).unwrap();
        let mut store = MemoryStorage::new();
        build_treelets(&grid, &voxels, layout, &mut store, &mut |_, _| {}).unwrap();
        let map = crate::volume::ValueMap::new(-2.0, 10.0).unwrap();
        store.set_value_map(map);
        let vol = OocVolume::<f32>::open(Arc::new(store), OocOptions::default()).unwrap();
        let isos = [2.0f32, -3.0];
        vol.set_isovalues(&isos);
        assert!(vol.wait_until_finished(Duration::from_secs(30)));
        assert_eq!(vol.loaded_levels(), vol.level_count());
        let ooc = vol.scene(Intersector::Exact);
        let mut incore = GridScene::new(
            &grid,
            VoxelBuffer::from_vec(voxels),
            Intersector::Exact,
            KdTreeConfig::default(),
        )
        .unwrap();
        incore.set_value_map(map);
        let mut hits = 0;
        for r in rays(incore.world_bounds(), 2000) {
            let a = incore.first_hit(&r, 0.0, f32::INFINITY, &isos, &mut NoStats);
            let b = ooc.first_hit(&r, 0.0, f32::INFINITY, &isos, &mut NoStats);
            assert_eq!(a, b, "{r:?}");
            hits += usize::from(a.is_some());
        }
        assert!(hits > 300, "{hits}");
    }

    #[test]
    fn coarse_levels_render_at_once_and_refine() {
        let dims = [31, 23, 17];
        let (grid, voxels, vol) = setup(dims, 4, u64::MAX);
        // Before any isovalue: only the top treelet, and it already renders the blobs.
        let coarse = vol.scene(Intersector::Exact);
        assert_eq!(coarse.level(), 0);
        let bounds = coarse.world_bounds();
        let incore = GridScene::new(
            &grid,
            VoxelBuffer::from_vec(voxels),
            Intersector::Exact,
            KdTreeConfig::default(),
        )
        .unwrap();
        let all = rays(bounds, 2000);
        let count = |s: &dyn Fn(&Ray) -> Option<Hit>| all.iter().filter(|r| s(r).is_some()).count();
        let mut n_coarse = 0;
        for c in [4.0f32, 8.0, 12.0, 16.0] {
            let iso = [c];
            n_coarse += count(&|r| coarse.first_hit(r, 0.0, f32::INFINITY, &iso, &mut NoStats));
        }
        assert!(n_coarse > 0, "the top treelet renders on its own");
        let iso = [5.0f32];
        let n_fine = count(&|r| incore.first_hit(r, 0.0, f32::INFINITY, &iso, &mut NoStats));
        assert!(n_fine > 0);
        vol.set_isovalues(&iso);
        assert!(vol.wait_until_finished(Duration::from_secs(30)));
        assert_eq!(vol.loaded_levels(), vol.level_count());
        let fine = vol.scene(Intersector::Exact);
        let n_ooc = count(&|r| fine.first_hit(r, 0.0, f32::INFINITY, &iso, &mut NoStats));
        assert_eq!(n_ooc, n_fine);
        // An isovalue in the same quantized bucket keeps everything; another reloads
        // and evicts what it does not need.
        let before = vol.resident_bytes();
        vol.set_isovalues(&[5.0]);
        assert!(vol.is_finished());
        vol.set_isovalues(&[1.0]);
        assert!(vol.wait_until_finished(Duration::from_secs(30)));
        assert_eq!(vol.loaded_levels(), vol.level_count());
        assert_ne!(vol.resident_bytes(), before);
    }

    #[test]
    fn budget_stops_at_a_coarser_level_and_damage_is_reported() {
        let dims = [31, 23, 17];
        let (_, _, vol) = setup(dims, 4, 1);
        vol.set_isovalues(&[5.0]);
        assert!(vol.wait_until_finished(Duration::from_secs(30)));
        assert!(vol.budget_limited());
        assert_eq!(vol.loaded_levels(), 1);

        let grid = Grid::uniform(dims, [0.0; 3], [1.0; 3]).unwrap();
        let voxels = blobs(dims);
        let layout = TreeletLayout::new(dims.map(|d| d as u64), 4).unwrap();
        let mut store = MemoryStorage::new();
        build_treelets(&grid, &voxels, layout.clone(), &mut store, &mut |_, _| {}).unwrap();
        // Damage every treelet of the finest level.
        let last = layout.level_count() - 1;
        for i in 0..layout.level(last).treelet_count() {
            store.record_mut(last, i).unwrap()[3] ^= 1;
        }
        let vol = OocVolume::<f32>::open(Arc::new(store), OocOptions::default()).unwrap();
        vol.set_isovalues(&[5.0]);
        assert!(vol.wait_until_finished(Duration::from_secs(30)));
        let e = vol.error().expect("damaged treelet reported");
        assert!(e.to_string().contains("level"), "{e}");
        assert!(vol.loaded_levels() < vol.level_count());
        // Wrong type: an error, not garbage.
        let mut store = MemoryStorage::new();
        build_treelets(&grid, &voxels, layout, &mut store, &mut |_, _| {}).unwrap();
        assert!(OocVolume::<u8>::open(Arc::new(store), OocOptions::default()).is_err());
    }

    #[test]
    fn levels_are_notified_in_order_and_a_new_bucket_restarts_loading() {
        let dims = [31, 23, 17];
        let (_, _, vol) = setup(dims, 4, u64::MAX);
        let n = vol.level_count();
        assert!(n >= 3);
        let (tx, rx) = std::sync::mpsc::channel::<LoadProgress>();
        let tx = Mutex::new(tx);
        vol.on_level(move |p| {
            let _ = tx.lock().unwrap().send(*p);
        });
        let g0 = vol.generation();
        // The listener runs on the loader thread: collect up to the end-of-loading event.
        let until_finished = || {
            let mut events = Vec::new();
            while let Ok(e) = rx.recv_timeout(Duration::from_secs(30)) {
                events.push(e);
                if e.finished {
                    break;
                }
            }
            events
        };
        vol.set_isovalues(&[5.0]);
        let events = until_finished();
        // One event per published level 1..=n, then the end of loading.
        let levels: Vec<usize> = events.iter().map(|e| e.loaded_levels).collect();
        assert_eq!(levels, (1..=n).chain([n]).collect::<Vec<_>>(), "{events:?}");
        assert!(events.windows(2).all(|w| w[0].generation < w[1].generation));
        assert!(events[0].generation > g0);
        let last = *events.last().unwrap();
        assert!(last.finished && !last.budget_limited);
        assert_eq!(last.level_count, n);
        assert_eq!(last.level_fetched, last.level_needed);
        assert_eq!(last.resident_bytes, vol.resident_bytes());
        assert_eq!(vol.progress(), last);
        // Same quantized bucket: nothing reloads, nobody is notified.
        let q = vol.meta().quantizer;
        let b5 = q.query(5.0).unwrap();
        let same = (1..100_000u32)
            .flat_map(|i| [5.0f32.to_bits() + i, 5.0f32.to_bits() - i])
            .map(f32::from_bits)
            .find(|&c| q.query(c) == Some(b5))
            .expect("a neighbour in the bucket");
        let g1 = vol.generation();
        vol.set_isovalues(&[same]);
        assert!(vol.is_finished());
        assert_eq!(vol.generation(), g1);
        assert_eq!(rx.try_iter().count(), 0);
        // Outside the bucket: loading restarts at the top level and refines again.
        let other = 14.0f32;
        assert_ne!(q.query(other), Some(b5));
        vol.set_isovalues(&[other]);
        let events = until_finished();
        assert_eq!(events[0].loaded_levels, 1, "{events:?}");
        assert!(events[0].request > last.request);
        assert_eq!(events.last().unwrap().loaded_levels, n);
    }

    #[test]
    fn a_budget_below_the_finest_level_pages_the_view_in_and_evicts_lru() {
        let dims = [31, 23, 17];
        let iso = [5.0f32];
        // The working set without a budget, and the bytes of the coarser levels alone.
        let (grid, voxels, full) = setup(dims, 4, u64::MAX);
        let n = full.level_count();
        let (tx, rx) = std::sync::mpsc::channel::<LoadProgress>();
        let tx = Mutex::new(tx);
        full.on_level(move |p| {
            let _ = tx.lock().unwrap().send(*p);
        });
        full.set_isovalues(&iso);
        assert!(full.wait_until_finished(Duration::from_secs(30)));
        let coarse_bytes = rx
            .try_iter()
            .find(|p| p.loaded_levels == n - 1)
            .expect("level n-1 published")
            .resident_bytes;
        let full_bytes = full.resident_bytes();
        drop(full);
        // A quarter of the finest level fits: it is paged in as frames ask for it.
        let budget = coarse_bytes + (full_bytes - coarse_bytes) / 4;
        let (_, _, vol) = setup(dims, 4, budget);
        vol.set_isovalues(&iso);
        assert!(vol.wait_until_finished(Duration::from_secs(30)));
        assert!(vol.budget_limited());
        assert_eq!(vol.loaded_levels(), n - 1);
        assert!(vol.resident_bytes() <= budget);
        let incore = GridScene::new(
            &grid,
            VoxelBuffer::from_vec(voxels),
            Intersector::Exact,
            KdTreeConfig::default(),
        )
        .unwrap();
        // Renders `rays` frame after frame until a frame pages nothing in.
        let converge = |rays: &[Ray]| {
            for frame in 1..=100 {
                let g = vol.generation();
                let hits: Vec<Option<Hit>> = {
                    let scene = vol.scene(Intersector::Exact);
                    rays.iter()
                        .map(|r| scene.first_hit(r, 0.0, f32::INFINITY, &iso, &mut NoStats))
                        .collect()
                };
                assert!(vol.wait_until_finished(Duration::from_secs(30)));
                assert_eq!(vol.error(), None);
                assert!(
                    vol.resident_bytes() <= budget,
                    "{} > {budget}",
                    vol.resident_bytes()
                );
                if vol.generation() == g {
                    return (hits, frame);
                }
            }
            panic!("demand paging did not settle in 100 frames");
        };
        // Two views down z: a patch over each blob (world: origin (-3, 1, 2), spacing
        // (1, 0.75, 1.5); blobs at samples (9, 8, 6) and (22, 14, 10)).
        let patch = |cx: f32, cy: f32| -> Vec<Ray> {
            (0..81)
                .map(|k| {
                    let o = Vec3::new(
                        cx + 0.5 * (k % 9) as f32 - 2.0,
                        cy + 0.5 * (k / 9) as f32 - 2.0,
                        -5.0,
                    );
                    Ray::new(o, Vec3::Z)
                })
                .collect()
        };
        let mut frames_b = 0;
        for (cx, cy) in [(6.0, 7.0), (19.0, 11.5), (6.0, 7.0)] {
            let rays = patch(cx, cy);
            let (hits, frames) = converge(&rays);
            let want: Vec<Option<Hit>> = rays
                .iter()
                .map(|r| incore.first_hit(r, 0.0, f32::INFINITY, &iso, &mut NoStats))
                .collect();
            assert!(want.iter().filter(|h| h.is_some()).count() > 20);
            assert_eq!(hits, want, "view at ({cx}, {cy})");
            if cx > 10.0 {
                frames_b = frames;
            }
        }
        // The second view needed treelets the first did not: paged in over frames, with
        // least-recently-used treelets evicted to stay within the budget.
        assert!(frames_b > 1, "view B was resident from the start");
        assert!(vol.evictions() > 0);
        assert_eq!(vol.loaded_levels(), n - 1);
    }

    #[test]
    fn default_budget_is_half_of_physical_memory() {
        let text = "MemTotal:       24593312 kB\nMemFree:        1 kB\n";
        assert_eq!(parse_mem_total(text), Some(24_593_312 * 1024));
        assert_eq!(parse_mem_total("MemFree: 1 kB\n"), None);
        assert_eq!(parse_mem_total("MemTotal: x kB\n"), None);
        let want = physical_memory_bytes().map_or(FALLBACK_BUDGET_BYTES, |m| m / BUDGET_DIVISOR);
        assert_eq!(OocOptions::default().budget_bytes, want);
        if cfg!(target_os = "linux") {
            assert!(physical_memory_bytes().is_some_and(|m| m > 1 << 20));
        }
    }
}

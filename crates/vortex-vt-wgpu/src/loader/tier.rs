//! The memory tier: tiles kept in RAM in their stored (compressed) form, up to a byte budget,
//! least recently used out first, between the source and the GPU's page cache. A page the cache
//! evicted and the view wants again is decoded from RAM instead of read from the pack (or the
//! disk, or the network behind it): id Tech 5 kept such a system-memory cache in front of its
//! disk. Stored bytes are what is worth keeping: a JPEG tile is a tenth of its texels or less,
//! and decoding it is cheap next to a slow read.
//!
//! Inclusive: every tile read through the tier is kept (a page's own tile, or the ancestor an
//! absent page is magnified from, and the answer "absent" itself), whether or not the GPU still
//! holds its page. The workers share it behind one lock, held only to find, add or drop an entry:
//! never to read or decode. What a page decodes to does not depend on whether its bytes came from
//! the tier or from the source; only the counters (hits, misses, bytes read) do.

use std::collections::{BTreeMap, HashMap};
use std::hash::Hash;
use std::sync::{Mutex, PoisonError};

use vortex_vt::page::PageId;

use super::RetryPolicy;
use super::decode::Tally;
use crate::page_cache::CacheFormat;
use crate::source::{PageSource, ReadError, ReadErrorKind, SourceTile, StoredRead, StoredTile, tile_id};

/// The runtime's default budget: 64 MiB, some 3000 JPEG tiles of 136² texels, or five full
/// 16²-slot caches of them, for about as much RAM as one 16²-slot RGBA8 cache takes on the GPU.
pub const DEFAULT_MEMORY_TIER_BYTES: u64 = 64 << 20;

/// What the budget charges each tile beyond its stored bytes: its key, its place in the LRU order
/// and the shared buffer's header. Keeps "absent" answers (no bytes) from costing nothing.
pub const TIER_ENTRY_OVERHEAD: u64 = 64;

/// What a tier holds now.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct TierUsage {
    /// The budget in bytes (0: the tier is off).
    pub budget: u64,
    /// Bytes charged against it: stored bytes plus [`TIER_ENTRY_OVERHEAD`] per tile.
    pub bytes: u64,
    /// Tiles held.
    pub tiles: usize,
}

/// Stored tiles by page (texture, LOD, x, y), shared by the loader's workers.
pub(super) struct Tier {
    lru: Mutex<Lru<PageId, StoredTile>>,
}

impl Tier {
    pub(super) fn new(budget: u64) -> Tier {
        Tier { lru: Mutex::new(Lru::new(budget)) }
    }

    /// Changes the budget; a smaller one drops the least recently used tiles at once.
    pub(super) fn set_budget(&self, budget: u64) {
        self.lock().set_budget(budget);
    }

    pub(super) fn usage(&self) -> TierUsage {
        let lru = self.lock();
        TierUsage { budget: lru.budget, bytes: lru.bytes, tiles: lru.entries.len() }
    }

    /// Whether it keeps anything (a budget above 0).
    fn is_on(&self) -> bool {
        self.lock().budget > 0
    }

    /// A held tile (a shared handle: no copy of its bytes), now the most recently used.
    fn get(&self, tile: PageId) -> Option<StoredTile> {
        self.lock().get(&tile).cloned()
    }

    fn insert(&self, tile: PageId, stored: StoredTile) {
        let cost = match &stored {
            StoredTile::Absent => 0,
            StoredTile::Stored { bytes, .. } => bytes.len() as u64,
        };
        self.lock().insert(tile, stored, cost.saturating_add(TIER_ENTRY_OVERHEAD));
    }

    /// Nothing that can panic runs under the lock, so a poisoned one still holds consistent data.
    fn lock(&self) -> std::sync::MutexGuard<'_, Lru<PageId, StoredTile>> {
        self.lru.lock().unwrap_or_else(PoisonError::into_inner)
    }
}

/// Tile `tile` of `source` in `format`, `None` if it is absent: decoded from the tier's copy of its
/// stored bytes when the tier holds one (a hit: nothing read), else read from the source (a miss)
/// and kept. With the tier off, or for a source with no stored form, the tile is read whole every
/// time (a miss): no copy of its stored bytes is made. Bytes read are tallied even when the read
/// fails.
pub(super) fn read(
    tier: &Tier,
    source: &dyn PageSource,
    tile: PageId,
    format: CacheFormat,
    retry: RetryPolicy,
    tally: &mut Tally,
) -> Result<Option<Vec<u8>>, ReadError> {
    let id = tile_id(tile);
    let retry = source.retry_policy(retry);
    let read_whole = |tally: &mut Tally| match with_retries(retry, tally, || source.read_tile(id, format))? {
        SourceTile::Absent => Ok(None),
        SourceTile::Texels { texels, bytes_read } => {
            tally.bytes_read += bytes_read;
            Ok(Some(texels))
        }
    };
    let on = tier.is_on();
    let held = if on { tier.get(tile) } else { None };
    let stored = match held {
        Some(stored) => {
            tally.tier_hits += 1;
            stored
        }
        None => {
            tally.tier_misses += 1;
            if !on {
                return read_whole(tally);
            }
            let read = with_retries(retry, tally, || source.read_stored(id))?;
            let Some(StoredRead { tile: stored, bytes_read }) = read else { return read_whole(tally) };
            tally.bytes_read += bytes_read;
            tier.insert(tile, stored.clone());
            stored
        }
    };
    match stored {
        StoredTile::Absent => Ok(None),
        StoredTile::Stored { kind, bytes } => source.decode(id, kind, &bytes, format).map(Some),
    }
}

/// Whether a loader may wait to read again. Not in the browser: nothing there may block (a
/// thread sleep panics on wasm32), and a web source's reads were fetched, with its own retries,
/// before the loader reads them, so a read again would answer the same.
const CAN_WAIT: bool = cfg!(not(target_arch = "wasm32"));

/// `read`, tried again while it fails with an I/O error, up to `retry.attempts` times in all,
/// waiting `retry.backoff` before the first retry and twice as long before each next one. The
/// bytes every attempt read are tallied, failed ones included.
fn with_retries<T>(
    retry: RetryPolicy,
    tally: &mut Tally,
    read: impl Fn() -> Result<T, ReadError>,
) -> Result<T, ReadError> {
    let mut wait = retry.backoff;
    let mut tries = 1;
    loop {
        match read() {
            Err(e) if CAN_WAIT && e.kind == ReadErrorKind::Io && tries < retry.attempts => {
                tally.bytes_read += e.bytes_read;
                tally.read_retries += 1;
                std::thread::sleep(wait);
                wait = wait.saturating_mul(2);
                tries += 1;
            }
            result => return result.inspect_err(|e| tally.bytes_read += e.bytes_read),
        }
    }
}

/// A least-recently-used map whose entries each cost some bytes, kept within a budget. Plain and
/// single-threaded: [`Tier`] puts it behind its lock.
struct Lru<K, V> {
    budget: u64,
    /// The sum of the entries' costs, never over `budget`.
    bytes: u64,
    /// Stamps uses: the larger, the more recent.
    clock: u64,
    /// Each entry's value, cost and last use.
    entries: HashMap<K, (V, u64, u64)>,
    /// Every entry's key by its last use (the stamp in `entries`), oldest first.
    order: BTreeMap<u64, K>,
}

impl<K: Copy + Eq + Hash, V> Lru<K, V> {
    fn new(budget: u64) -> Lru<K, V> {
        Lru { budget, bytes: 0, clock: 0, entries: HashMap::new(), order: BTreeMap::new() }
    }

    fn get(&mut self, key: &K) -> Option<&V> {
        let stamp = self.tick();
        let (value, _, used) = self.entries.get_mut(key)?;
        self.order.remove(used);
        *used = stamp;
        self.order.insert(stamp, *key);
        Some(value)
    }

    /// Keeps `value` as the most recently used, dropping the least recently used entries until
    /// the budget holds it; a value that costs more than the whole budget is not kept (and any
    /// older value of `key` goes).
    fn insert(&mut self, key: K, value: V, cost: u64) {
        self.remove(&key);
        if cost > self.budget {
            return;
        }
        self.evict_to(self.budget - cost);
        let stamp = self.tick();
        self.order.insert(stamp, key);
        self.entries.insert(key, (value, cost, stamp));
        self.bytes += cost;
    }

    fn remove(&mut self, key: &K) {
        if let Some((_, cost, used)) = self.entries.remove(key) {
            self.order.remove(&used);
            self.bytes -= cost;
        }
    }

    fn set_budget(&mut self, budget: u64) {
        self.budget = budget;
        self.evict_to(budget);
    }

    /// Drops the least recently used entries until they cost at most `bytes`.
    fn evict_to(&mut self, bytes: u64) {
        while self.bytes > bytes {
            let Some((_, oldest)) = self.order.pop_first() else { break };
            if let Some((_, cost, _)) = self.entries.remove(&oldest) {
                self.bytes -= cost;
            }
        }
    }

    fn tick(&mut self) -> u64 {
        self.clock += 1;
        self.clock
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn keys(lru: &Lru<u32, &str>) -> Vec<u32> {
        lru.order.values().copied().collect()
    }

    #[test]
    fn the_least_recently_used_go_first_and_the_budget_holds() {
        let mut lru = Lru::new(100);
        for key in 0..4 {
            lru.insert(key, "v", 30);
        }
        assert_eq!((keys(&lru), lru.bytes), (vec![1, 2, 3], 90), "0 went to make room for 3");
        assert_eq!(lru.get(&1), Some(&"v"));
        lru.insert(4, "v", 30);
        assert_eq!(keys(&lru), vec![3, 1, 4], "2, not the just used 1");
        assert_eq!(lru.get(&2), None);
        lru.insert(5, "v", 70);
        assert_eq!((keys(&lru), lru.bytes), (vec![4, 5], 100));
    }

    #[test]
    fn an_entry_over_the_budget_is_not_kept_and_replaces_nothing() {
        let mut lru = Lru::new(100);
        lru.insert(1, "small", 40);
        lru.insert(2, "huge", 101);
        assert_eq!((keys(&lru), lru.bytes), (vec![1], 40));
        // A new value for a key replaces the old one, whose cost is given back.
        lru.insert(1, "again", 60);
        assert_eq!(lru.bytes, 60);
        assert_eq!(lru.get(&1), Some(&"again"));
        lru.insert(1, "too big", 200);
        assert_eq!((lru.bytes, lru.entries.len()), (0, 0));
        assert_eq!(lru.get(&1), None);
    }

    #[test]
    fn a_zero_budget_keeps_nothing_and_shrinking_drops_the_oldest() {
        let mut off = Lru::new(0);
        off.insert(1, "v", 1);
        assert!(off.entries.is_empty() && off.order.is_empty());
        let mut lru = Lru::new(100);
        for key in 0..5 {
            lru.insert(key, "v", 20);
        }
        lru.get(&0);
        lru.set_budget(50);
        assert_eq!((keys(&lru), lru.bytes), (vec![4, 0], 40));
        lru.set_budget(0);
        assert_eq!((lru.entries.len(), lru.order.len(), lru.bytes), (0, 0, 0));
    }

    #[test]
    fn tiles_are_charged_their_bytes_and_the_overhead() {
        let tier = Tier::new(1000);
        let bytes: std::sync::Arc<[u8]> = vec![7u8; 300].into();
        tier.insert(PageId::new(0, 1, 2, 3), StoredTile::Stored { kind: crate::source::TileKind::Jpeg, bytes });
        tier.insert(PageId::new(1, 1, 2, 3), StoredTile::Absent);
        let usage = tier.usage();
        assert_eq!(usage, TierUsage { budget: 1000, bytes: 300 + 2 * TIER_ENTRY_OVERHEAD, tiles: 2 });
        assert_eq!(tier.get(PageId::new(1, 1, 2, 3)), Some(StoredTile::Absent));
        assert_eq!(tier.get(PageId::new(2, 1, 2, 3)), None, "keyed by texture too");
    }
}

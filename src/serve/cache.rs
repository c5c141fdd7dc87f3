//! The re-encoded tiles kept in memory: a least-recently-used cache bounded by bytes (`--cache`).
//!
//! Only tiles that cost a decode and an encode are kept; stored tiles come straight from the
//! pack's memory map and would only be copied. The bound counts each tile's bytes and its key.
//! A capacity of 0 turns the cache off; a tile larger than the whole capacity is not kept.

use std::collections::{BTreeMap, HashMap};
use std::sync::Mutex;

use bytes::Bytes;

/// A byte-bounded LRU map from a tile's key to its encoded bytes; `&self` methods, shared by
/// every request.
pub struct TileCache {
    capacity: u64,
    inner: Mutex<Lru>,
}

#[derive(Default)]
struct Lru {
    /// Key -> (bytes, last use).
    map: HashMap<String, (Bytes, u64)>,
    /// Last use -> key, oldest first.
    order: BTreeMap<u64, String>,
    tick: u64,
    bytes: u64,
}

fn cost(key: &str, value: &Bytes) -> u64 {
    (key.len() + value.len()) as u64
}

impl TileCache {
    pub fn new(capacity: u64) -> TileCache {
        TileCache { capacity, inner: Mutex::new(Lru::default()) }
    }

    /// The tile under `key`, now the most recently used.
    pub fn get(&self, key: &str) -> Option<Bytes> {
        if self.capacity == 0 {
            return None;
        }
        let mut lru = self.lock();
        lru.tick += 1;
        let tick = lru.tick;
        let (value, used) = lru.map.get_mut(key)?;
        let (value, old) = (value.clone(), std::mem::replace(used, tick));
        if let Some(k) = lru.order.remove(&old) {
            lru.order.insert(tick, k);
        }
        Some(value)
    }

    /// Keeps `value` under `key`, evicting the least recently used tiles until it fits.
    pub fn insert(&self, key: String, value: Bytes) {
        let size = cost(&key, &value);
        if size > self.capacity {
            return;
        }
        let mut lru = self.lock();
        if let Some((old, used)) = lru.map.remove(&key) {
            lru.order.remove(&used);
            lru.bytes -= cost(&key, &old);
        }
        while lru.bytes + size > self.capacity {
            let Some((_, oldest)) = lru.order.pop_first() else { break };
            if let Some((old, _)) = lru.map.remove(&oldest) {
                lru.bytes -= cost(&oldest, &old);
            }
        }
        lru.tick += 1;
        let tick = lru.tick;
        lru.order.insert(tick, key.clone());
        lru.map.insert(key, (value, tick));
        lru.bytes += size;
    }

    // What the tests observe; the server only gets and inserts.
    /// Bytes held (tiles and keys).
    #[cfg(test)]
    pub fn bytes(&self) -> u64 {
        self.lock().bytes
    }

    /// Tiles held.
    #[cfg(test)]
    pub fn len(&self) -> usize {
        self.lock().map.len()
    }

    #[cfg(test)]
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The map; a panic while holding it cannot leave it inconsistent in a way that matters
    /// for a cache (at worst a stale count), so a poisoned lock is taken over.
    fn lock(&self) -> std::sync::MutexGuard<'_, Lru> {
        self.inner.lock().unwrap_or_else(|poisoned| poisoned.into_inner())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tile(n: usize) -> Bytes {
        Bytes::from(vec![7u8; n])
    }

    #[test]
    fn evicts_the_least_recently_used_first() {
        // Keys of 1 byte + 9 bytes of tile: 10 bytes each, 3 fit in 30.
        let cache = TileCache::new(30);
        cache.insert("a".into(), tile(9));
        cache.insert("b".into(), tile(9));
        cache.insert("c".into(), tile(9));
        assert_eq!((cache.len(), cache.bytes()), (3, 30));
        // Using "a" makes "b" the oldest.
        assert!(cache.get("a").is_some());
        cache.insert("d".into(), tile(9));
        assert!(cache.get("b").is_none());
        assert!(cache.get("a").is_some() && cache.get("c").is_some() && cache.get("d").is_some());
        assert_eq!(cache.bytes(), 30);
    }

    #[test]
    fn a_large_tile_evicts_several_and_a_huge_one_is_not_kept() {
        let cache = TileCache::new(30);
        for k in ["a", "b", "c"] {
            cache.insert(k.into(), tile(9));
        }
        cache.insert("e".into(), tile(19));
        assert_eq!((cache.len(), cache.bytes()), (2, 30));
        assert!(cache.get("c").is_some() && cache.get("e").is_some());
        cache.insert("huge".into(), tile(100));
        assert!(cache.get("huge").is_none());
        assert_eq!(cache.len(), 2);
    }

    #[test]
    fn replacing_a_key_recounts_its_bytes_and_zero_capacity_keeps_nothing() {
        let cache = TileCache::new(100);
        cache.insert("a".into(), tile(9));
        cache.insert("a".into(), tile(19));
        assert_eq!((cache.len(), cache.bytes()), (1, 20));
        assert_eq!(cache.get("a").map(|b| b.len()), Some(19));
        let off = TileCache::new(0);
        off.insert("a".into(), tile(1));
        assert!(off.get("a").is_none() && off.is_empty());
    }
}

//! Where the layers of a page meet: each layer has its own loader, so a page's layers land one
//! by one, in any order; the runtime uploads and maps a page only once all of them are here, so
//! that no page-table entry is ever valid for one layer and not another.

use std::collections::HashMap;

use vortex_vt::page::PageId;
use vortex_vt::residency::Slot;

use crate::loader::LoadedPage;

/// A page whose every layer has landed, layer 0 first.
#[derive(Debug)]
pub(crate) struct Landed {
    pub(crate) page: PageId,
    pub(crate) slot: Slot,
    pub(crate) layers: Vec<LoadedPage>,
}

impl Landed {
    /// The bytes the page's layers take in the caches.
    pub(crate) fn bytes(&self) -> u64 {
        self.layers.iter().map(|l| l.texels.len() as u64).sum()
    }
}

/// The layers of pages that have partly landed.
#[derive(Debug)]
pub(crate) struct Arrivals {
    layers: usize,
    partial: HashMap<(PageId, Slot), Vec<Option<LoadedPage>>>,
}

impl Arrivals {
    pub(crate) fn new(layers: usize) -> Arrivals {
        Arrivals { layers, partial: HashMap::new() }
    }

    /// Layer `layer` of a page has landed: the whole page if that was its last layer.
    pub(crate) fn add(&mut self, layer: usize, page: LoadedPage) -> Option<Landed> {
        let key = (page.page, page.slot);
        let layers = self.partial.entry(key).or_insert_with(|| vec![None; self.layers]);
        layers[layer] = Some(page);
        if layers.iter().any(Option::is_none) {
            return None;
        }
        let layers = self.partial.remove(&key)?.into_iter().flatten().collect();
        Some(Landed { page: key.0, slot: key.1, layers })
    }

    /// Drops what has landed of `page` in `slot` (evicted before it was complete, or uploaded).
    pub(crate) fn forget(&mut self, page: PageId, slot: Slot) {
        self.partial.remove(&(page, slot));
    }

    /// Pages with some layers landed and some not.
    #[cfg(test)]
    pub(crate) fn len(&self) -> usize {
        self.partial.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn loaded(page: PageId, slot: Slot, byte: u8) -> LoadedPage {
        LoadedPage { page, slot, texels: vec![byte; 4], bytes_read: 1, tier_hits: 0, tier_misses: 1, error: None }
    }

    #[test]
    fn a_page_lands_once_every_layer_has_in_layer_order() {
        let (a, b) = (PageId::new(0, 1, 0, 0), PageId::new(0, 1, 1, 0));
        let mut arrivals = Arrivals::new(3);
        assert!(arrivals.add(2, loaded(a, 5, 2)).is_none());
        assert!(arrivals.add(0, loaded(b, 6, 0)).is_none());
        assert!(arrivals.add(0, loaded(a, 5, 0)).is_none());
        assert_eq!(arrivals.len(), 2);
        let landed = arrivals.add(1, loaded(a, 5, 1)).expect("every layer of a");
        assert_eq!((landed.page, landed.slot, landed.bytes()), (a, 5, 12));
        assert_eq!(landed.layers.iter().map(|l| l.texels[0]).collect::<Vec<_>>(), [0, 1, 2]);
        arrivals.forget(b, 6);
        assert_eq!(arrivals.len(), 0);
    }

    #[test]
    fn one_layer_lands_at_once_and_slots_keep_pages_apart() {
        let a = PageId::new(0, 0, 0, 0);
        assert!(Arrivals::new(1).add(0, loaded(a, 1, 9)).is_some());
        let mut two = Arrivals::new(2);
        assert!(two.add(0, loaded(a, 1, 0)).is_none());
        assert!(two.add(1, loaded(a, 2, 1)).is_none(), "another slot is another load");
    }
}

//! Spatial index over instance bounding boxes: a wrapper over parry's `Bvh` whose leaves are dense
//! slots of the store.
//!
//! Design: the exact box of every slot is kept next to the tree (`boxes`), so the index can
//! answer [`SpatialIndex::get`], filter query hits exactly and rebuild itself. The tree holds
//! *loose* boxes (`loose`: the exact box grown by [`LOOSE_MARGIN`] on every side, the "fat AABB" of
//! dynamic trees): an update whose new exact box still fits in the slot's loose box leaves the
//! tree alone (most merges move an instance by centimetres), and query hits are filtered by the
//! exact boxes, so answers are exactly those of the exact boxes. Other updates go through
//! `Bvh::insert`, which sets the leaf box and only *grows* ancestors; removals go through
//! `Bvh::remove`, which leaves unreachable wide nodes behind until the next rebuild. Both are
//! correct for queries (ancestors always enclose their leaves) but degrade the tree over time, so
//! the tree is rebuilt from the loose boxes (binned SAH build) once the number of removals and
//! shrinking updates since the last build exceeds half the live leaves (amortised O(log N) per
//! operation). `Bvh::optimize_incremental` is deliberately not used (parry PR #409: it can act on
//! orphaned nodes left by `remove`).

use parry2d_f64::bounding_volume::{Aabb, BoundingVolume};
use parry2d_f64::partitioning::{Bvh, BvhBuildStrategy};

/// Rebuild when `stale > max(REBUILD_MIN, live / 2)`.
const REBUILD_MIN: usize = 64;
/// How far (metres) a slot's box in the tree reaches beyond its exact box on every side.
const LOOSE_MARGIN: f64 = 1.0;

/// `aabb` grown by [`LOOSE_MARGIN`] on every side.
fn loosen(aabb: Aabb) -> Aabb {
    aabb.loosened(LOOSE_MARGIN)
}

/// A dynamic bounding-box index: insert / update / remove a slot's box, query all slots whose box
/// intersects a box in O(log N + k).
#[derive(Debug, Clone, Default)]
pub struct SpatialIndex {
    /// The tree; leaf data are slots.
    bvh: Bvh,
    /// Exact box of each slot (`None`: slot not in the index).
    boxes: Vec<Option<Aabb>>,
    /// The slot's box in the tree: its exact box when last (re)inserted, loosened by
    /// [`LOOSE_MARGIN`]; it contains the exact box at all times.
    loose: Vec<Option<Aabb>>,
    /// Number of `Some` entries in `boxes`.
    live: usize,
    /// Removals and shrinking updates since the last (re)build.
    stale: usize,
}

impl SpatialIndex {
    /// An empty index.
    pub fn new() -> Self {
        Self::default()
    }

    /// Builds an index from `(slot, box)` pairs in one pass (a later pair for the same slot wins).
    pub fn from_boxes(items: impl IntoIterator<Item = (u32, Aabb)>) -> Self {
        let mut index = SpatialIndex::new();
        for (slot, aabb) in items {
            let s = slot as usize;
            if s >= index.boxes.len() {
                index.boxes.resize(s + 1, None);
            }
            if index.boxes[s].replace(aabb).is_none() {
                index.live += 1;
            }
        }
        index.loose = index.boxes.iter().map(|b| b.map(loosen)).collect();
        index.rebuild();
        index
    }

    /// Number of slots in the index.
    pub fn len(&self) -> usize {
        self.live
    }

    /// Whether the index holds no slot.
    pub fn is_empty(&self) -> bool {
        self.live == 0
    }

    /// The stored box of `slot`, if present.
    pub fn get(&self, slot: u32) -> Option<&Aabb> {
        self.boxes.get(slot as usize).and_then(Option::as_ref)
    }

    /// Inserts or replaces the box of `slot`.
    pub fn upsert(&mut self, slot: u32, aabb: Aabb) {
        let s = slot as usize;
        if s >= self.boxes.len() {
            self.boxes.resize(s + 1, None);
            self.loose.resize(s + 1, None);
        }
        if self.boxes[s].replace(aabb).is_none() {
            self.live += 1;
        }
        // Still inside the tree's loose box: the tree needs no change.
        if self.loose[s].is_some_and(|l| l.contains(&aabb)) {
            return;
        }
        let new = loosen(aabb);
        if let Some(old) = self.loose[s].replace(new) {
            if !new.contains(&old) {
                // The leaf shrank somewhere: ancestors stay loose until the next rebuild.
                self.stale += 1;
            }
        }
        // Sets the leaf box and grows the ancestors as needed (new leaf: SAH descent).
        self.bvh.insert(new, slot);
        self.maybe_rebuild();
    }

    /// Removes `slot` (no-op if absent).
    pub fn remove(&mut self, slot: u32) {
        let s = slot as usize;
        if let Some(entry) = self.boxes.get_mut(s) {
            if entry.take().is_some() {
                self.loose[s] = None;
                self.live -= 1;
                self.stale += 1;
                self.bvh.remove(slot);
                while matches!(self.boxes.last(), Some(None)) {
                    self.boxes.pop();
                    self.loose.pop();
                }
                self.maybe_rebuild();
            }
        }
    }

    /// Removes every slot.
    pub fn clear(&mut self) {
        *self = SpatialIndex::new();
    }

    /// Slots whose box intersects `aabb` (boundary contact counts), in any order.
    pub fn query(&self, aabb: &Aabb) -> Vec<u32> {
        if self.live == 0 {
            return Vec::new();
        }
        // The tree answers for the loose boxes; the exact boxes decide.
        self.bvh
            .intersect_aabb(aabb)
            .filter(|&s| {
                self.boxes
                    .get(s as usize)
                    .and_then(Option::as_ref)
                    .is_some_and(|b| b.intersects(aabb))
            })
            .collect()
    }

    /// Rebuilds the tree from the stored boxes (compacts it and restores tight ancestors).
    pub fn rebuild(&mut self) {
        self.stale = 0;
        if self.live == 0 {
            self.bvh = Bvh::new();
            return;
        }
        let items = self
            .loose
            .iter()
            .enumerate()
            .filter_map(|(s, b)| b.map(|b| (s, b)));
        if self.live <= 2 {
            // parry 0.25.3's `Bvh::from_iter` special-cases 1 and 2 leaves assuming their ids are
            // 0 and 1 (it panics with "key not present" otherwise): insert them one by one.
            self.bvh = Bvh::new();
            for (s, b) in items {
                self.bvh.insert(b, s as u32);
            }
        } else {
            self.bvh = Bvh::from_iter(BvhBuildStrategy::Binned, items);
        }
    }

    fn maybe_rebuild(&mut self) {
        if self.stale > REBUILD_MIN.max(self.live / 2) {
            self.rebuild();
        }
    }

    /// Brute-force reference of [`SpatialIndex::query`] (ascending slots); for tests and checks.
    pub fn query_brute_force(&self, aabb: &Aabb) -> Vec<u32> {
        self.boxes
            .iter()
            .enumerate()
            .filter_map(|(s, b)| match b {
                Some(b) if b.intersects(aabb) => Some(s as u32),
                _ => None,
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_util::query_boxes;
    use crate::types::Point;
    use proptest::prelude::*;

    fn bx(x0: f64, y0: f64, w: f64, h: f64) -> Aabb {
        Aabb::new(Point::new(x0, y0), Point::new(x0 + w, y0 + h))
    }

    fn sorted(mut v: Vec<u32>) -> Vec<u32> {
        v.sort_unstable();
        v
    }

    #[test]
    fn empty_and_single() {
        let mut idx = SpatialIndex::new();
        assert!(idx.query(&bx(-1e9, -1e9, 2e9, 2e9)).is_empty());
        idx.upsert(3, bx(0.0, 0.0, 1.0, 1.0));
        assert_eq!(idx.query(&bx(0.5, 0.5, 0.1, 0.1)), vec![3]);
        assert!(idx.query(&bx(2.0, 2.0, 1.0, 1.0)).is_empty());
        // Touching boundaries count.
        assert_eq!(idx.query(&bx(1.0, 1.0, 1.0, 1.0)), vec![3]);
        idx.remove(3);
        idx.remove(3);
        assert!(idx.is_empty());
        assert!(idx.query(&bx(0.5, 0.5, 0.1, 0.1)).is_empty());
    }

    /// Small updates stay inside the tree's loose box (no tree change), yet queries answer for
    /// the exact boxes: a shrunk box is no longer hit where it left, a grown one is hit where it
    /// went.
    #[test]
    fn small_updates_answer_exactly() {
        let mut idx = SpatialIndex::new();
        for s in 0..20 {
            idx.upsert(s, bx(s as f64 * 10.0, 0.0, 4.0, 4.0));
        }
        idx.upsert(5, bx(50.5, 0.5, 3.0, 3.0)); // shrink by 0.5 m on every side
        assert!(idx.query(&bx(50.0, 0.0, 0.2, 0.2)).is_empty());
        assert_eq!(idx.query(&bx(51.0, 1.0, 0.2, 0.2)), vec![5]);
        idx.upsert(6, bx(59.6, 0.0, 4.8, 4.0)); // grow by 0.4 m to both sides in x
        assert_eq!(idx.query(&bx(59.5, 1.0, 0.2, 0.2)), vec![6]);
        assert_eq!(idx.query(&bx(64.3, 1.0, 0.05, 0.05)), vec![6]);
        assert_eq!(idx.get(5), Some(&bx(50.5, 0.5, 3.0, 3.0)));
        for q in [
            bx(49.0, -1.0, 2.0, 2.0),
            bx(58.0, 0.0, 2.0, 5.0),
            bx(0.0, 0.0, 300.0, 1.0),
        ] {
            assert_eq!(sorted(idx.query(&q)), idx.query_brute_force(&q));
        }
    }

    #[test]
    fn update_moves_box() {
        let mut idx = SpatialIndex::new();
        for s in 0..10 {
            idx.upsert(s, bx(s as f64 * 10.0, 0.0, 1.0, 1.0));
        }
        idx.upsert(4, bx(500.0, 500.0, 1.0, 1.0));
        assert!(idx.query(&bx(40.0, 0.0, 1.0, 1.0)).is_empty());
        assert_eq!(idx.query(&bx(499.0, 499.0, 1.5, 1.5)), vec![4]);
        assert_eq!(idx.len(), 10);
    }

    #[test]
    fn rebuild_with_few_high_slots() {
        // Regression: parry's from_iter mishandles 1 or 2 leaves whose ids are not 0 and 1.
        for n in 1..4u32 {
            let idx =
                SpatialIndex::from_boxes((0..n).map(|i| (10 + i, bx(i as f64, 0.0, 0.5, 0.5))));
            assert_eq!(
                sorted(idx.query(&bx(-1.0, -1.0, 10.0, 10.0))),
                (10..10 + n).collect::<Vec<_>>()
            );
        }
    }

    #[test]
    fn huge_coordinates_do_not_panic() {
        // Box volumes overflow to inf (and inf * 0 = NaN in the SAH costs): quality may suffer but
        // the answers stay exact.
        let mut idx = SpatialIndex::new();
        for s in 0..200u32 {
            let x: f64 = if s % 2 == 0 { -1e308 } else { 1e308 };
            let w: f64 = if s % 3 == 0 { 0.0 } else { 1.7e308 };
            idx.upsert(s, bx(x.min(x + w), (s as f64) * 1e306, w.min(1e308), 0.0));
        }
        for s in (0..200u32).step_by(3) {
            idx.remove(s);
        }
        idx.rebuild();
        let q = bx(-1e308, -1e308, 1.7e308, 1.7e308);
        assert_eq!(sorted(idx.query(&q)), idx.query_brute_force(&q));
    }

    #[test]
    fn identical_boxes_rebuild() {
        let items = (0..300u32).map(|s| (s, bx(1.0, 1.0, 0.0, 0.0)));
        let idx = SpatialIndex::from_boxes(items);
        assert_eq!(sorted(idx.query(&bx(0.0, 0.0, 2.0, 2.0))).len(), 300);
    }

    #[derive(Debug, Clone)]
    enum Op {
        Upsert(u32, f64, f64, f64, f64),
        Remove(u32),
        Rebuild,
    }

    fn op() -> impl Strategy<Value = Op> {
        prop_oneof![
            6 => (0u32..80, -100.0..100.0f64, -100.0..100.0f64, 0.0..30.0f64, 0.0..30.0f64)
                .prop_map(|(s, x, y, w, h)| Op::Upsert(s, x, y, w, h)),
            3 => (0u32..80).prop_map(Op::Remove),
            1 => Just(Op::Rebuild),
        ]
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]
        #[test]
        fn query_equals_brute_force(ops in prop::collection::vec(op(), 1..400),
                                    queries in query_boxes(120.0, 60.0, 8)) {
            let mut idx = SpatialIndex::new();
            for (i, o) in ops.iter().enumerate() {
                match *o {
                    Op::Upsert(s, x, y, w, h) => idx.upsert(s, bx(x, y, w, h)),
                    Op::Remove(s) => idx.remove(s),
                    Op::Rebuild => idx.rebuild(),
                }
                if i % 7 == 0 {
                    for &(x, y, w, h) in &queries {
                        let q = bx(x, y, w, h);
                        prop_assert_eq!(sorted(idx.query(&q)), idx.query_brute_force(&q));
                    }
                }
            }
            for &(x, y, w, h) in &queries {
                let q = bx(x, y, w, h);
                prop_assert_eq!(sorted(idx.query(&q)), idx.query_brute_force(&q));
            }
            let all = bx(-1e6, -1e6, 2e6, 2e6);
            prop_assert_eq!(sorted(idx.query(&all)).len(), idx.len());
        }
    }
}

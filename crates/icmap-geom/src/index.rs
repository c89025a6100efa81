//! Spatial index over instance bounding boxes: a wrapper over parry's `Bvh` whose leaves are dense
//! slots of the store.

use parry2d_f64::bounding_volume::Aabb;

/// A dynamic bounding-box index: insert / update / remove a slot's box, query all slots whose box
/// intersects a box in O(log N + k).
#[derive(Debug, Clone, Default)]
pub struct SpatialIndex {
    // built on parry2d_f64::partitioning::Bvh (filled in by index.rs's implementer)
}

impl SpatialIndex {
    /// An empty index.
    pub fn new() -> Self {
        todo!("index.rs: new")
    }
    /// Inserts or replaces the box of `slot`.
    pub fn upsert(&mut self, slot: u32, aabb: Aabb) {
        let _ = (slot, aabb);
        todo!("index.rs: upsert")
    }
    /// Removes `slot` (no-op if absent).
    pub fn remove(&mut self, slot: u32) {
        let _ = slot;
        todo!("index.rs: remove")
    }
    /// Slots whose box intersects `aabb`, in any order.
    pub fn query(&self, aabb: &Aabb) -> Vec<u32> {
        let _ = aabb;
        todo!("index.rs: query")
    }
}

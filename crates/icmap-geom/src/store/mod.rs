//! The global map store: instances with bookkeeping, kept in dense slots and indexed spatially.
//!
//! Layout: `slots: Vec<Option<Instance>>` (dense, freed slots are recycled through a free list),
//! `id -> slot` hash map, and a [`SpatialIndex`] over each live slot's bounding box. Ids are
//! assigned increasingly from 0 and never reused (`next_id` only grows).

use crate::error::{GeomError, Result};
use crate::index::SpatialIndex;
use crate::types::{
    check_non_negative, check_positive, points_aabb, validate_points, MapClass, Point,
};
use parry2d_f64::bounding_volume::Aabb;
use std::collections::HashMap;

mod query;
mod update;

pub use update::wake_merge_workers;

/// Points closer than this (metres) to the previous one are dropped before storing a crossing ring
/// (this also removes a repeated closing point).
const DEDUP_EPS: f64 = 1e-9;

/// The most points [`GlobalMap::sample_patch`] samples per instance.
pub const MAX_PATCH_POINTS: usize = 1_000_000;

/// Tunables of the store.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MapConfig {
    /// Smoothing `s` of the curve fit on merge (scipy `splprep` semantics); paper: 0.1 .. 1.
    pub smoothing: f64,
    /// Spacing of the stored dense points, metres.
    pub spacing: f64,
}

impl Default for MapConfig {
    fn default() -> Self {
        MapConfig {
            smoothing: 0.5,
            spacing: 1.0,
        }
    }
}

impl MapConfig {
    /// Checks `smoothing >= 0` and `spacing > 0`, both finite.
    pub fn validate(&self) -> Result<()> {
        check_non_negative("smoothing", self.smoothing)?;
        check_positive("spacing", self.spacing)?;
        Ok(())
    }
}

/// One global map instance (world frame).
#[derive(Debug, Clone, PartialEq)]
pub struct Instance {
    pub id: u64,
    pub class: MapClass,
    /// Dense points about `spacing` apart; for a closed crossing the ring without a repeated point.
    pub points: Vec<Point>,
    pub closed: bool,
    pub first_frame: i64,
    pub last_frame: i64,
    /// How many times the instance was inserted or merged into.
    pub observations: u32,
}

impl Instance {
    /// Checks the invariants of a stored instance: `closed == class.is_closed()`, finite points,
    /// at least 2 points (3 for a closed ring), `first_frame <= last_frame`, `observations >= 1`.
    pub fn validate(&self) -> Result<()> {
        if self.closed != self.class.is_closed() {
            return Err(GeomError::InvalidParameter {
                name: "closed",
                reason: format!(
                    "instance {}: class {} requires closed = {}",
                    self.id,
                    self.class.name(),
                    self.class.is_closed()
                ),
            });
        }
        let what = format!("instance {} points", self.id);
        validate_points(&self.points, if self.closed { 3 } else { 2 }, &what)?;
        if self.first_frame > self.last_frame {
            return Err(GeomError::InvalidParameter {
                name: "first_frame",
                reason: format!(
                    "instance {}: first_frame {} > last_frame {}",
                    self.id, self.first_frame, self.last_frame
                ),
            });
        }
        if self.observations == 0 {
            return Err(GeomError::InvalidParameter {
                name: "observations",
                reason: format!("instance {}: must be >= 1", self.id),
            });
        }
        Ok(())
    }

    /// The world-axis-aligned bounding box of the points (`points` must be non-empty).
    pub fn aabb(&self) -> Aabb {
        points_aabb(&self.points)
    }
}

/// The result of [`GlobalMap::sample_patch`]: `k` instances that intersect the patch.
#[derive(Debug, Clone, PartialEq)]
pub struct PatchSample {
    /// Instance ids, ascending.
    pub ids: Vec<u64>,
    pub classes: Vec<MapClass>,
    /// `k * n_points` points in the EGO frame of the patch, row-major.
    pub points: Vec<Point>,
    /// `k * n_points` connectivity flags (see [`crate::clip::sample_pieces`]).
    pub mask: Vec<bool>,
    pub n_points: usize,
}

impl PatchSample {
    /// Number of instances `k`.
    pub fn len(&self) -> usize {
        self.ids.len()
    }

    /// Whether no instance was sampled.
    pub fn is_empty(&self) -> bool {
        self.ids.is_empty()
    }
}

/// The global vector map.
#[derive(Debug, Clone)]
pub struct GlobalMap {
    config: MapConfig,
    /// Dense slots; `None` marks a free slot (listed in `free`).
    slots: Vec<Option<Instance>>,
    id_to_slot: HashMap<u64, u32>,
    free: Vec<u32>,
    /// The next automatic id; every id in the map is below it.
    next_id: u64,
    index: SpatialIndex,
    /// Provenance: the sorted, distinct drives that observed each instance (absent: none); see
    /// `provenance.rs`.
    pub(crate) drives: HashMap<u64, Box<[u32]>>,
}

impl GlobalMap {
    /// An empty map.
    pub fn new(config: MapConfig) -> Result<Self> {
        config.validate()?;
        Ok(GlobalMap {
            config,
            slots: Vec::new(),
            id_to_slot: HashMap::new(),
            free: Vec::new(),
            next_id: 0,
            index: SpatialIndex::new(),
            drives: HashMap::new(),
        })
    }

    /// A map from stored parts (used by loading): every instance is validated, ids must be unique
    /// and below `next_id`. Points are taken as they are (not resampled).
    pub fn from_parts(config: MapConfig, next_id: u64, instances: Vec<Instance>) -> Result<Self> {
        let mut map = GlobalMap::new(config)?;
        if instances.len() > u32::MAX as usize {
            return Err(GeomError::InvalidParameter {
                name: "instances",
                reason: "more than 2^32 - 1 instances".into(),
            });
        }
        map.slots.reserve(instances.len());
        map.id_to_slot.reserve(instances.len());
        for inst in instances {
            inst.validate()?;
            if inst.id >= next_id {
                return Err(GeomError::InvalidParameter {
                    name: "next_id",
                    reason: format!("instance id {} is not below next_id {next_id}", inst.id),
                });
            }
            let slot = map.slots.len() as u32;
            if map.id_to_slot.insert(inst.id, slot).is_some() {
                return Err(GeomError::DuplicateId(inst.id));
            }
            map.slots.push(Some(inst));
        }
        map.next_id = next_id;
        map.index = SpatialIndex::from_boxes(
            map.slots
                .iter()
                .enumerate()
                .filter_map(|(s, i)| i.as_ref().map(|i| (s as u32, i.aabb()))),
        );
        Ok(map)
    }

    /// [`Self::from_parts`] for `n` instances the caller has validated (`Instance::validate`),
    /// each with its bounding box (crate use: loading, which does both in parallel); ids are
    /// still checked here (unique, below `next_id`).
    pub(crate) fn from_checked_parts(
        config: MapConfig,
        next_id: u64,
        n: usize,
        items: impl IntoIterator<Item = (Instance, Aabb)>,
    ) -> Result<Self> {
        let mut map = GlobalMap::new(config)?;
        if n > u32::MAX as usize {
            return Err(GeomError::InvalidParameter {
                name: "instances",
                reason: "more than 2^32 - 1 instances".into(),
            });
        }
        map.slots.reserve(n);
        let mut boxes = Vec::with_capacity(n);
        for (inst, aabb) in items {
            if inst.id >= next_id {
                return Err(GeomError::InvalidParameter {
                    name: "next_id",
                    reason: format!("instance id {} is not below next_id {next_id}", inst.id),
                });
            }
            let slot = map.slots.len() as u32;
            if slot == u32::MAX {
                return Err(GeomError::InvalidParameter {
                    name: "instances",
                    reason: "more than 2^32 - 1 instances".into(),
                });
            }
            map.slots.push(Some(inst));
            boxes.push((slot, aabb));
        }
        // The id map and the spatial index are built at the same time.
        let slots = &map.slots;
        let (index, ids) = rayon::join(
            || SpatialIndex::from_boxes(boxes),
            || {
                let mut ids: HashMap<u64, u32> = HashMap::with_capacity(slots.len());
                for (slot, inst) in slots.iter().enumerate() {
                    let id = inst.as_ref().map_or(u64::MAX, |i| i.id);
                    if ids.insert(id, slot as u32).is_some() {
                        return Err(GeomError::DuplicateId(id));
                    }
                }
                Ok(ids)
            },
        );
        map.id_to_slot = ids?;
        map.index = index;
        map.next_id = next_id;
        Ok(map)
    }

    pub fn config(&self) -> MapConfig {
        self.config
    }

    /// Replaces the tunables (used by later inserts and merges; stored points are not touched).
    pub fn set_config(&mut self, config: MapConfig) -> Result<()> {
        config.validate()?;
        self.config = config;
        Ok(())
    }

    /// Number of instances.
    pub fn len(&self) -> usize {
        self.id_to_slot.len()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The id the next [`GlobalMap::insert`] will assign (every id in the map is below it).
    pub fn next_id(&self) -> u64 {
        self.next_id
    }

    /// Whether instance `id` is in the map.
    pub fn contains(&self, id: u64) -> bool {
        self.id_to_slot.contains_key(&id)
    }

    pub(crate) fn alloc_slot(&mut self, inst: Instance) -> Result<u32> {
        let slot = match self.free.pop() {
            Some(s) => s,
            None => {
                if self.slots.len() >= u32::MAX as usize {
                    return Err(GeomError::InvalidParameter {
                        name: "id",
                        reason: "the map is full (2^32 - 1 slots)".into(),
                    });
                }
                self.slots.push(None);
                (self.slots.len() - 1) as u32
            }
        };
        let aabb = inst.aabb();
        self.id_to_slot.insert(inst.id, slot);
        self.slots[slot as usize] = Some(inst);
        self.index.upsert(slot, aabb);
        Ok(slot)
    }

    /// Replaces instance `inst.id` whole (geometry and bookkeeping, taken as they are: not
    /// resampled) and updates the index; its provenance is kept. Errors on an unknown id or an
    /// invalid instance (the map is then unchanged). For whole-map operations (`merge_map`).
    pub(crate) fn put(&mut self, inst: Instance) -> Result<()> {
        let slot = *self
            .id_to_slot
            .get(&inst.id)
            .ok_or(GeomError::UnknownId(inst.id))?;
        inst.validate()?;
        let aabb = inst.aabb();
        self.slots[slot as usize] = Some(inst);
        self.index.upsert(slot, aabb);
        Ok(())
    }

    /// Inserts `inst` (points and bookkeeping taken as they are) under the next automatic id,
    /// which it returns; `inst.id` is ignored. For whole-map operations (`merge_map`).
    pub(crate) fn insert_instance(&mut self, mut inst: Instance) -> Result<u64> {
        let id = self.next_id;
        if id == u64::MAX {
            return Err(GeomError::InvalidParameter {
                name: "id",
                reason: "the map has used every id (2^64 - 1)".into(),
            });
        }
        inst.id = id;
        inst.validate()?;
        self.alloc_slot(inst)?;
        self.next_id = id + 1;
        Ok(id)
    }

    /// Removes and returns instance `id`.
    pub fn remove(&mut self, id: u64) -> Result<Instance> {
        let slot = self
            .id_to_slot
            .remove(&id)
            .ok_or(GeomError::UnknownId(id))?;
        let inst = self.slots[slot as usize]
            .take()
            .ok_or(GeomError::UnknownId(id))?;
        self.index.remove(slot);
        self.free.push(slot);
        self.drives.remove(&id);
        Ok(inst)
    }

    /// Removes every instance (`next_id` is kept, so ids are still never reused).
    pub fn clear(&mut self) {
        self.slots.clear();
        self.id_to_slot.clear();
        self.free.clear();
        self.index.clear();
        self.drives.clear();
    }

    pub fn get(&self, id: u64) -> Option<&Instance> {
        let slot = *self.id_to_slot.get(&id)?;
        self.slots.get(slot as usize)?.as_ref()
    }

    /// All instances in ascending id order.
    pub fn instances(&self) -> Vec<&Instance> {
        let mut v: Vec<&Instance> = self.instances_iter().collect();
        v.sort_unstable_by_key(|i| i.id);
        v
    }

    /// All instances in storage (slot) order, without sorting.
    pub fn instances_iter(&self) -> impl Iterator<Item = &Instance> + '_ {
        self.slots.iter().filter_map(Option::as_ref)
    }

    /// All ids, ascending.
    pub fn ids(&self) -> Vec<u64> {
        let mut v: Vec<u64> = self.id_to_slot.keys().copied().collect();
        v.sort_unstable();
        v
    }

    /// The bounding box of instance `id` as held by the spatial index.
    pub fn bbox(&self, id: u64) -> Option<Aabb> {
        let slot = *self.id_to_slot.get(&id)?;
        self.index.get(slot).copied()
    }

    /// Checks the internal bookkeeping (slots, id map, free list, index boxes); for tests.
    #[doc(hidden)]
    pub fn check_invariants(&self) -> std::result::Result<(), String> {
        let mut live = 0usize;
        for (s, inst) in self.slots.iter().enumerate() {
            match inst {
                Some(i) => {
                    live += 1;
                    if self.id_to_slot.get(&i.id) != Some(&(s as u32)) {
                        return Err(format!("id {} not mapped to slot {s}", i.id));
                    }
                    if i.id >= self.next_id {
                        return Err(format!("id {} >= next_id {}", i.id, self.next_id));
                    }
                    if self.index.get(s as u32) != Some(&i.aabb()) {
                        return Err(format!(
                            "index box of slot {s} differs from the instance box"
                        ));
                    }
                    i.validate().map_err(|e| e.to_string())?;
                }
                None => {
                    if !self.free.contains(&(s as u32)) {
                        return Err(format!("empty slot {s} not in the free list"));
                    }
                    if self.index.get(s as u32).is_some() {
                        return Err(format!("empty slot {s} still indexed"));
                    }
                }
            }
        }
        if live != self.id_to_slot.len() || live != self.index.len() {
            return Err(format!(
                "{live} live slots, {} ids, {} indexed",
                self.id_to_slot.len(),
                self.index.len()
            ));
        }
        if self.free.len() + live != self.slots.len() {
            return Err("free list size mismatch".into());
        }
        for (id, drives) in &self.drives {
            if !self.id_to_slot.contains_key(id) {
                return Err(format!("provenance of the absent instance {id}"));
            }
            if drives.is_empty() || drives.windows(2).any(|w| w[0] >= w[1]) {
                return Err(format!("drives of instance {id} not sorted and distinct"));
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_util::{add, p, query_boxes};
    use crate::types::{Patch, Pose2};
    use proptest::prelude::*;

    fn line(x0: f64, y0: f64, x1: f64, y1: f64) -> Vec<Point> {
        vec![p(x0, y0), p(x1, y1)]
    }

    fn square(cx: f64, cy: f64, h: f64) -> Vec<Point> {
        vec![
            p(cx - h, cy - h),
            p(cx + h, cy - h),
            p(cx + h, cy + h),
            p(cx - h, cy + h),
        ]
    }

    fn map() -> GlobalMap {
        GlobalMap::new(MapConfig::default()).unwrap()
    }

    /// `merge_many` gives exactly the map of sequential `merge` calls, with the same per-item
    /// errors: several items per instance, unknown ids, bad geometry, both classes.
    #[test]
    fn merge_many_equals_sequential_merges() {
        let mut a = map();
        let mut ids = Vec::new();
        for k in 0..12 {
            let y = 10.0 * k as f64;
            if k % 3 == 0 {
                ids.push(add(&mut a, MapClass::PedCrossing, &square(0.0, y, 2.0), 0));
            } else {
                let pts: Vec<Point> = (0..30)
                    .map(|i| p(i as f64, y + 0.1 * (i as f64).sin()))
                    .collect();
                let class = if k % 2 == 0 {
                    MapClass::Divider
                } else {
                    MapClass::Boundary
                };
                ids.push(a.insert(class, &pts, 0).unwrap());
            }
        }
        let mut b = a.clone();
        let mut items: Vec<(u64, Vec<Point>)> = Vec::new();
        for (j, &id) in ids.iter().enumerate().chain(ids.iter().enumerate().take(5)) {
            let y = 10.0 * j as f64;
            let det = if j % 3 == 0 {
                square(1.0, y + 0.3, 2.0)
            } else {
                (0..20)
                    .map(|i| p(10.0 + i as f64, y + 0.2 + 0.05 * (i % 3) as f64))
                    .collect()
            };
            items.push((id, det));
        }
        items.push((999, square(0.0, 0.0, 1.0))); // unknown id
        items.push((ids[1], vec![p(f64::NAN, 0.0), p(1.0, 1.0)])); // non-finite
        items.push((ids[2], vec![p(1.0, 1.0)])); // one point
        items.push((ids[0], vec![p(0.0, 0.0), p(1.0, 1.0)])); // a ring of two points
        items.push((ids[4], line(3.0, 40.0, 8.0, 40.5)));
        let sequential: Vec<Result<()>> = items.iter().map(|(id, q)| a.merge(*id, q, 7)).collect();
        let refs: Vec<(u64, &[Point])> = items.iter().map(|(id, q)| (*id, q.as_slice())).collect();
        let batched = b.merge_many(&refs, 7);
        assert_eq!(sequential.len(), batched.len());
        for (i, (x, y)) in sequential.iter().zip(&batched).enumerate() {
            assert_eq!(x.is_ok(), y.is_ok(), "item {i}: {x:?} vs {y:?}");
            if let (Err(x), Err(y)) = (x, y) {
                assert_eq!(x.to_string(), y.to_string());
            }
        }
        assert!(batched.iter().filter(|r| r.is_err()).count() >= 4);
        for &id in &ids {
            let (x, y) = (a.get(id).unwrap(), b.get(id).unwrap());
            assert_eq!(x.points, y.points, "instance {id}");
            assert_eq!(x.observations, y.observations);
            assert_eq!((x.first_frame, x.last_frame), (y.first_frame, y.last_frame));
        }
        // The index follows the merged geometry.
        let patch = Patch::new(Pose2::new(15.0, 40.0, 0.0).unwrap(), 20.0, 60.0, 0.0).unwrap();
        let hits = a.query(&patch);
        assert!(!hits.is_empty());
        assert_eq!(hits, b.query(&patch));
    }

    #[test]
    fn config_validation() {
        for (s, d) in [
            (-1.0, 1.0),
            (f64::NAN, 1.0),
            (0.5, 0.0),
            (0.5, -1.0),
            (0.5, f64::INFINITY),
        ] {
            assert!(
                GlobalMap::new(MapConfig {
                    smoothing: s,
                    spacing: d
                })
                .is_err(),
                "{s} {d}"
            );
        }
        let mut m = map();
        assert!(m
            .set_config(MapConfig {
                smoothing: 0.0,
                spacing: f64::NAN
            })
            .is_err());
        assert_eq!(m.config(), MapConfig::default());
        m.set_config(MapConfig {
            smoothing: 0.0,
            spacing: 2.0,
        })
        .unwrap();
        assert_eq!(m.config().spacing, 2.0);
    }

    #[test]
    fn insert_assigns_increasing_ids_and_resamples() {
        let mut m = map();
        let a = add(&mut m, MapClass::Divider, &line(0.0, 0.0, 10.0, 0.0), 3);
        let b = add(&mut m, MapClass::PedCrossing, &square(50.0, 0.0, 2.0), 4);
        assert_eq!((a, b), (0, 1));
        let ia = m.get(a).unwrap();
        assert_eq!(ia.points.len(), 11);
        assert!(!ia.closed);
        assert_eq!((ia.first_frame, ia.last_frame, ia.observations), (3, 3, 1));
        let ib = m.get(b).unwrap();
        assert!(ib.closed);
        assert_eq!(ib.points.len(), 16);
        assert_eq!(m.len(), 2);
        m.check_invariants().unwrap();
    }

    #[test]
    fn crossing_with_repeated_closing_point() {
        let mut m = map();
        let mut ring = square(0.0, 0.0, 1.0);
        ring.push(ring[0]);
        let id = add(&mut m, MapClass::PedCrossing, &ring, 0);
        assert_eq!(m.get(id).unwrap().points.len(), 8);
        // Three points of which one repeats: not a ring.
        assert!(matches!(
            m.insert(
                MapClass::PedCrossing,
                &[p(0.0, 0.0), p(1.0, 0.0), p(0.0, 0.0)],
                0
            ),
            Err(GeomError::TooFewPoints { .. })
        ));
    }

    #[test]
    fn insert_with_id_and_remove() {
        let mut m = map();
        m.insert_with_id(10, MapClass::Boundary, &line(0.0, 0.0, 1.0, 1.0), 0)
            .unwrap();
        assert!(matches!(
            m.insert_with_id(10, MapClass::Boundary, &line(0.0, 0.0, 1.0, 1.0), 0),
            Err(GeomError::DuplicateId(10))
        ));
        assert!(m
            .insert_with_id(u64::MAX, MapClass::Boundary, &line(0.0, 0.0, 1.0, 1.0), 0)
            .is_err());
        assert_eq!(
            add(&mut m, MapClass::Divider, &line(0.0, 0.0, 2.0, 0.0), 1),
            11
        );
        m.insert_with_id(3, MapClass::Divider, &line(0.0, 5.0, 2.0, 5.0), 1)
            .unwrap();
        assert_eq!(m.next_id(), 12);
        assert_eq!(m.ids(), vec![3, 10, 11]);
        assert_eq!(
            m.instances().iter().map(|i| i.id).collect::<Vec<_>>(),
            vec![3, 10, 11]
        );
        let r = m.remove(10).unwrap();
        assert_eq!(r.id, 10);
        assert!(matches!(m.remove(10), Err(GeomError::UnknownId(10))));
        assert!(m.get(10).is_none());
        assert!(!m.contains(10));
        // Ids are never reused.
        assert_eq!(
            add(&mut m, MapClass::Divider, &line(0.0, 0.0, 2.0, 0.0), 1),
            12
        );
        m.check_invariants().unwrap();
        m.clear();
        assert!(m.is_empty());
        assert_eq!(
            add(&mut m, MapClass::Divider, &line(0.0, 0.0, 2.0, 0.0), 1),
            13
        );
        m.check_invariants().unwrap();
    }

    #[test]
    fn bad_inputs_are_errors() {
        let mut m = map();
        assert!(m.insert(MapClass::Divider, &[], 0).is_err());
        assert!(m.insert(MapClass::Divider, &[p(0.0, 0.0)], 0).is_err());
        assert!(m
            .insert(MapClass::Divider, &[p(0.0, 0.0), p(0.0, 0.0)], 0)
            .is_err());
        assert!(m
            .insert(MapClass::Divider, &[p(0.0, 0.0), p(f64::NAN, 0.0)], 0)
            .is_err());
        assert!(m
            .insert(MapClass::Divider, &[p(-1e308, 0.0), p(1e308, 0.0)], 0)
            .is_err());
        assert!(m
            .insert(MapClass::PedCrossing, &[p(0.0, 0.0), p(1.0, 0.0)], 0)
            .is_err());
        assert!(
            m.insert(MapClass::Divider, &[p(0.0, 0.0), p(1e12, 0.0)], 0)
                .is_err(),
            "too many points"
        );
        assert!(m.is_empty());
        assert_eq!(m.next_id(), 0, "failed inserts do not consume ids");
        assert!(matches!(
            m.merge(5, &line(0.0, 0.0, 1.0, 0.0), 0),
            Err(GeomError::UnknownId(5))
        ));
        let id = add(&mut m, MapClass::Divider, &line(0.0, 0.0, 4.0, 0.0), 0);
        let before = m.get(id).unwrap().clone();
        assert!(m.merge(id, &[p(0.0, 0.0)], 1).is_err());
        assert!(m
            .merge(id, &[p(0.0, 0.0), p(f64::INFINITY, 1.0)], 1)
            .is_err());
        assert_eq!(
            m.get(id).unwrap(),
            &before,
            "a failed merge leaves the instance unchanged"
        );
        let patch = Patch {
            pose: Pose2 {
                x: f64::NAN,
                y: 0.0,
                yaw: 0.0,
            },
            half_extents: [1.0, 1.0].into(),
        };
        assert!(m.query(&patch).is_empty());
        assert!(m.sample_patch(&patch, 20).is_err());
        let ok = Patch::new(Pose2::new(0.0, 0.0, 0.0).unwrap(), 5.0, 5.0, 0.0).unwrap();
        assert!(m.sample_patch(&ok, 1).is_err());
        assert!(m.sample_patch(&ok, usize::MAX).is_err());
        m.check_invariants().unwrap();
    }

    #[test]
    fn from_parts_validates() {
        let inst = |id: u64, class: MapClass, closed: bool| Instance {
            id,
            class,
            points: square(0.0, 0.0, 1.0),
            closed,
            first_frame: 0,
            last_frame: 1,
            observations: 2,
        };
        let cfg = MapConfig::default();
        let m = GlobalMap::from_parts(
            cfg,
            5,
            vec![
                inst(0, MapClass::PedCrossing, true),
                inst(4, MapClass::Divider, false),
            ],
        )
        .unwrap();
        m.check_invariants().unwrap();
        assert_eq!(m.ids(), vec![0, 4]);
        assert!(GlobalMap::from_parts(cfg, 4, vec![inst(4, MapClass::Divider, false)]).is_err());
        assert!(GlobalMap::from_parts(cfg, 9, vec![inst(1, MapClass::Divider, true)]).is_err());
        assert!(matches!(
            GlobalMap::from_parts(
                cfg,
                9,
                vec![
                    inst(1, MapClass::Divider, false),
                    inst(1, MapClass::Boundary, false)
                ]
            ),
            Err(GeomError::DuplicateId(1))
        ));
    }

    #[test]
    fn query_and_sample_patch() {
        let mut m = map();
        let a = add(&mut m, MapClass::Divider, &line(-20.0, 1.0, 20.0, 1.0), 0);
        let b = add(&mut m, MapClass::PedCrossing, &square(3.0, -3.0, 1.0), 0);
        let _far = add(
            &mut m,
            MapClass::Boundary,
            &line(100.0, 100.0, 120.0, 100.0),
            0,
        );
        // Bounding box overlaps the patch but the geometry does not (diagonal away from it).
        let _diag = add(&mut m, MapClass::Boundary, &line(6.0, 30.0, 30.0, 6.0), 0);
        let pose = Pose2::new(0.0, 0.0, std::f64::consts::FRAC_PI_2).unwrap();
        let patch = Patch::new(pose, 10.0, 10.0, 0.0).unwrap();
        assert_eq!(m.query(&patch), vec![a, b]);
        let s = m.sample_patch(&patch, 20).unwrap();
        assert_eq!(s.ids, vec![a, b]);
        assert_eq!(s.classes, vec![MapClass::Divider, MapClass::PedCrossing]);
        assert_eq!(s.points.len(), 40);
        assert_eq!(s.mask.len(), 40);
        // Ego frame of a pose rotated by +90 degrees: world (x, 1) -> ego (1, -x).
        for q in &s.points[..20] {
            assert!(
                (q.x - 1.0).abs() < 1e-9 && q.y.abs() <= 10.0 + 1e-9,
                "{q:?}"
            );
        }
        assert!(s.mask[..19].iter().all(|&c| c));
        assert!(!s.mask[19], "end of an open polyline does not connect");
        // The crossing centred at world (3, -3) lies at ego (-3, -3).
        let c = s.points[20..]
            .iter()
            .fold(Point::origin(), |acc, q| acc + q.coords / 20.0);
        assert!((c.x + 3.0).abs() < 0.2 && (c.y + 3.0).abs() < 0.2, "{c:?}");
        assert!(s.mask[39], "a ring connects back");
        assert!(
            m.sample_patch(&patch, 2).is_err(),
            "a crossing needs 3 points"
        );
    }

    #[test]
    fn merge_updates_bookkeeping_and_index() {
        let mut m = map();
        let a = add(&mut m, MapClass::Divider, &line(0.0, 0.0, 10.0, 0.0), 2);
        m.merge(a, &line(5.0, 0.0, 30.0, 0.0), 5).unwrap();
        let i = m.get(a).unwrap();
        assert_eq!((i.first_frame, i.last_frame, i.observations), (2, 5, 2));
        assert!(m.bbox(a).unwrap().maxs.x > 25.0);
        let pose = Pose2::new(27.0, 0.0, 0.0).unwrap();
        assert_eq!(m.query(&Patch::new(pose, 1.0, 1.0, 0.0).unwrap()), vec![a]);
        let c = add(&mut m, MapClass::PedCrossing, &square(50.0, 0.0, 1.0), 1);
        m.merge(c, &square(51.0, 0.0, 1.0), 0).unwrap();
        let i = m.get(c).unwrap();
        assert_eq!((i.first_frame, i.last_frame, i.observations), (0, 1, 2));
        assert!(m.bbox(c).unwrap().maxs.x > 51.9);
        m.check_invariants().unwrap();
    }

    #[derive(Debug, Clone)]
    enum Op {
        Insert(u8, f64, f64, f64, f64),
        Merge(usize, f64, f64, f64, f64),
        Remove(usize),
    }

    fn op() -> impl Strategy<Value = Op> {
        let c = -200.0..200.0f64;
        prop_oneof![
            5 => (0u8..3, c.clone(), c.clone(), -15.0..15.0f64, -15.0..15.0f64)
                .prop_map(|(k, x, y, dx, dy)| Op::Insert(k, x, y, dx, dy)),
            3 => (any::<usize>(), -5.0..5.0f64, -5.0..5.0f64, -15.0..15.0f64, -15.0..15.0f64)
                .prop_map(|(i, x, y, dx, dy)| Op::Merge(i, x, y, dx, dy)),
            2 => any::<usize>().prop_map(Op::Remove),
        ]
    }

    fn geometry(class: MapClass, x: f64, y: f64, dx: f64, dy: f64) -> Vec<Point> {
        if class.is_closed() {
            let h = 0.5 + dx.abs() / 4.0;
            square(x, y, h)
        } else {
            vec![
                p(x, y),
                p(x + dx / 2.0, y + dy / 2.0 + 0.3),
                p(x + dx + 0.5, y + dy),
            ]
        }
    }

    fn check_queries(
        m: &GlobalMap,
        queries: &[(f64, f64, f64, f64)],
    ) -> std::result::Result<(), TestCaseError> {
        if let Err(e) = m.check_invariants() {
            return Err(TestCaseError::fail(e));
        }
        for &(x, y, w, h) in queries {
            let q = Aabb::new(p(x, y), p(x + w, y + h));
            let mut brute: Vec<u64> = m
                .instances_iter()
                .filter(|i| i.aabb().intersects(&q))
                .map(|i| i.id)
                .collect();
            brute.sort_unstable();
            prop_assert_eq!(m.query_aabb(&q), brute);
        }
        Ok(())
    }

    fn run_ops(
        ops: &[Op],
        queries: &[(f64, f64, f64, f64)],
        with_merge: bool,
    ) -> std::result::Result<(), TestCaseError> {
        let mut m = map();
        for (step, o) in ops.iter().enumerate() {
            let ids = m.ids();
            match *o {
                Op::Insert(k, x, y, dx, dy) => {
                    let class = MapClass::ALL[k as usize];
                    let _ = m.insert(class, &geometry(class, x, y, dx, dy), step as i64);
                }
                Op::Merge(i, x, y, dx, dy) if with_merge && !ids.is_empty() => {
                    let id = ids[i % ids.len()];
                    let inst = m.get(id).unwrap().clone();
                    let anchor = inst.points[inst.points.len() / 2];
                    let det = geometry(inst.class, anchor.x + x, anchor.y + y, dx, dy);
                    if m.merge(id, &det, step as i64).is_err() {
                        prop_assert_eq!(m.get(id).unwrap(), &inst);
                    }
                }
                Op::Remove(i) if !ids.is_empty() => {
                    m.remove(ids[i % ids.len()]).unwrap();
                }
                _ => {}
            }
            if step % 10 == 0 {
                check_queries(&m, queries)?;
            }
        }
        check_queries(&m, queries)
    }

    use parry2d_f64::bounding_volume::BoundingVolume;

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(48))]
        /// The spatial index answers like brute force after random insert / remove.
        #[test]
        fn index_matches_brute_force_insert_remove(ops in prop::collection::vec(op(), 1..150),
                                                   queries in query_boxes(220.0, 120.0, 6)) {
            run_ops(&ops, &queries, false)?;
        }

        /// The spatial index answers like brute force after random insert / merge / remove
        /// (needs merge.rs).
        #[test]
        fn index_matches_brute_force_with_merge(ops in prop::collection::vec(op(), 1..150),
                                                queries in query_boxes(220.0, 120.0, 6)) {
            run_ops(&ops, &queries, true)?;
        }

        /// Arbitrary coordinates (NaN, inf, huge) give errors or a valid map, never a panic.
        #[test]
        fn arbitrary_floats_never_panic(xs in prop::collection::vec(prop_oneof![
                                            4 => -1e3..1e3f64,
                                            1 => Just(f64::NAN),
                                            1 => Just(f64::INFINITY),
                                            1 => Just(-f64::INFINITY),
                                            1 => Just(1e308),
                                            1 => any::<f64>(),
                                        ], 0..24),
                                        k in 0u8..3, n in 0usize..40,
                                        pose in (any::<f64>(), any::<f64>(), any::<f64>(), any::<f64>())) {
            let class = MapClass::ALL[k as usize];
            let pts: Vec<Point> = xs.chunks_exact(2).map(|c| p(c[0], c[1])).collect();
            let mut m = map();
            let base = m.insert(class, &geometry(class, 0.0, 0.0, 5.0, 3.0), 0).unwrap();
            let _ = m.insert(class, &pts, 1);
            let _ = m.merge(base, &pts, 2);
            let patch = Patch { pose: Pose2 { x: pose.0, y: pose.1, yaw: pose.2 }, half_extents: [pose.3, pose.3.abs()].into() };
            let _ = m.query(&patch);
            let _ = m.sample_patch(&patch, n);
            if let Ok(patch) = Patch::new(Pose2 { x: 0.0, y: 0.0, yaw: 0.0 }, 30.0, 15.0, 1.0) {
                let _ = m.sample_patch(&patch, n);
            }
            if let Err(e) = m.check_invariants() {
                return Err(TestCaseError::fail(e));
            }
        }
    }

    #[test]
    fn trim_cuts_a_line_and_keeps_its_bookkeeping() {
        let mut m = GlobalMap::new(MapConfig::default()).unwrap();
        let line: Vec<Point> = (0..=20).map(|i| Point::new(i as f64, 0.0)).collect();
        let id = m.insert(MapClass::Divider, &line, 3).unwrap();
        m.replace(id, &line, 5).unwrap();
        let before = m.get(id).unwrap().clone();
        m.trim(id, 2, 15).unwrap();
        let inst = m.get(id).unwrap();
        assert_eq!(inst.points, before.points[2..15].to_vec());
        assert_eq!(
            (inst.first_frame, inst.last_frame, inst.observations),
            (before.first_frame, before.last_frame, before.observations)
        );
        let cut = Patch::new(Pose2::new(19.0, 0.0, 0.0).unwrap(), 0.5, 0.5, 0.0).unwrap();
        assert!(m.query(&cut).is_empty());
        for (a, b) in [(0, 1), (5, 5), (3, 99)] {
            assert!(matches!(
                m.trim(id, a, b),
                Err(GeomError::InvalidParameter { .. })
            ));
        }
        assert_eq!(m.get(id).unwrap().points.len(), 13);
        let ring = [
            Point::new(0.0, 0.0),
            Point::new(4.0, 0.0),
            Point::new(4.0, 4.0),
            Point::new(0.0, 4.0),
        ];
        let crossing = m.insert(MapClass::PedCrossing, &ring, 0).unwrap();
        assert!(m.trim(crossing, 0, 3).is_err());
        assert!(matches!(m.trim(999, 0, 2), Err(GeomError::UnknownId(999))));
    }

    #[test]
    fn replace_keeps_bookkeeping_and_index() {
        let mut m = GlobalMap::new(MapConfig::default()).unwrap();
        let id = m
            .insert(
                MapClass::Divider,
                &[Point::new(0.0, 0.0), Point::new(10.0, 0.0)],
                3,
            )
            .unwrap();
        let far = [Point::new(100.0, 50.0), Point::new(120.0, 50.0)];
        m.replace(id, &far, 7).unwrap();
        let inst = m.get(id).unwrap();
        assert_eq!(
            (inst.first_frame, inst.last_frame, inst.observations),
            (3, 7, 2)
        );
        assert!((inst.points[0] - far[0]).norm() < 1e-12);
        let old_patch = Patch::new(Pose2::new(5.0, 0.0, 0.0).unwrap(), 5.0, 5.0, 0.0).unwrap();
        let new_patch = Patch::new(Pose2::new(110.0, 50.0, 0.0).unwrap(), 5.0, 5.0, 0.0).unwrap();
        assert!(m.query(&old_patch).is_empty());
        assert_eq!(m.query(&new_patch), vec![id]);
        assert!(matches!(
            m.replace(id, &[far[0]], 8),
            Err(GeomError::TooFewPoints { .. })
        ));
        assert_eq!(m.get(id).unwrap().last_frame, 7); // unchanged on error
        assert!(matches!(
            m.replace(99, &far, 8),
            Err(GeomError::UnknownId(99))
        ));
    }
}

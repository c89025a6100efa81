//! The global map store: instances with bookkeeping, kept in dense slots and indexed spatially.

use crate::error::Result;
use crate::types::{MapClass, Patch, Point};

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
        MapConfig { smoothing: 0.5, spacing: 1.0 }
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

/// The global vector map.
#[derive(Debug, Clone)]
pub struct GlobalMap {
    // filled in by store.rs's implementer: config, slots, id -> slot map, free list, next id,
    // crate::index::SpatialIndex
    _private: (),
}

impl GlobalMap {
    /// An empty map.
    pub fn new(config: MapConfig) -> Result<Self> {
        let _ = config;
        todo!("store.rs: new")
    }
    pub fn config(&self) -> MapConfig {
        todo!()
    }
    /// Number of instances.
    pub fn len(&self) -> usize {
        todo!()
    }
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// Inserts a new instance (points resampled at `spacing`) observed at `frame`; returns its id
    /// (ids are assigned increasingly from 0 and never reused).
    pub fn insert(&mut self, class: MapClass, points: &[Point], frame: i64) -> Result<u64> {
        let _ = (class, points, frame);
        todo!()
    }
    /// Inserts with a caller-chosen id (errors on a duplicate id); later automatic ids stay above it.
    pub fn insert_with_id(&mut self, id: u64, class: MapClass, points: &[Point], frame: i64) -> Result<()> {
        let _ = (id, class, points, frame);
        todo!()
    }
    /// Merges a detection into instance `id` by its class rule (curve fit or polygon union) and
    /// updates the index and bookkeeping. On error the instance is unchanged.
    pub fn merge(&mut self, id: u64, points: &[Point], frame: i64) -> Result<()> {
        let _ = (id, points, frame);
        todo!()
    }
    /// Removes and returns instance `id`.
    pub fn remove(&mut self, id: u64) -> Result<Instance> {
        let _ = id;
        todo!()
    }
    pub fn get(&self, id: u64) -> Option<&Instance> {
        let _ = id;
        todo!()
    }
    /// All instances in ascending id order.
    pub fn instances(&self) -> Vec<&Instance> {
        todo!()
    }
    /// Ids (ascending) of the instances whose geometry intersects the patch (exact test after the
    /// bounding-box query).
    pub fn query(&self, patch: &Patch) -> Vec<u64> {
        let _ = patch;
        todo!()
    }
    /// Every instance in the patch clipped to it and sampled evenly to `n_points` in the ego frame.
    pub fn sample_patch(&self, patch: &Patch, n_points: usize) -> Result<PatchSample> {
        let _ = (patch, n_points);
        todo!()
    }
}

//! Changing the map one instance at a time: inserts, merges by the class rules (also many at
//! once, in parallel), replaces and splices, with the bookkeeping they update.

use super::{GlobalMap, Instance, MapConfig, DEDUP_EPS};
use crate::error::{GeomError, Result};
use crate::merge::{merge_line, merge_polygon, merge_polyline};
use crate::resample::{dedup_cow, resample_spacing};
use crate::types::points_aabb;
use crate::types::{validate_points, MapClass, Point};
use std::collections::HashMap;

/// The threads [`GlobalMap::merge_many`] shares its work with: a pool of its own, one thread fewer
/// than rayon's global pool (the calling thread works too; `RAYON_NUM_THREADS` sets both), so
/// that long jobs on the global pool (e.g. a big `chamfer_matrix` in another thread) never hold up
/// a frame's merges. `None` on a single thread.
fn merge_pool() -> Option<&'static rayon::ThreadPool> {
    static POOL: std::sync::OnceLock<Option<rayon::ThreadPool>> = std::sync::OnceLock::new();
    POOL.get_or_init(|| {
        let helpers = rayon::current_num_threads().saturating_sub(1);
        if helpers == 0 {
            return None;
        }
        rayon::ThreadPoolBuilder::new()
            .num_threads(helpers)
            .thread_name(|i| format!("icmap-merge-{i}"))
            .build()
            .ok()
    })
    .as_ref()
}

/// Wakes the threads that [`GlobalMap::merge_many`] shares its work with, ahead of a call: a
/// sleeping thread takes tens of microseconds to wake, a good part of a frame's merges, so a
/// caller that first converts its input (the Python binding) starts the wake-up before. Optional;
/// without it the merges start on the calling thread and the others join when awake.
pub fn wake_merge_workers() {
    if let Some(pool) = merge_pool() {
        for _ in 0..pool.current_num_threads() {
            pool.spawn(|| ());
        }
    }
}

/// The class rule of a merge: the detection `points` (world frame) merged into the current
/// geometry `current` of an instance (polygon union for a closed crossing ring, curve-fit merge for
/// a polyline; for a line class one that does not fold onto itself, [`merge_line`] with the
/// class's [`MapClass::fold`]), checked to keep
/// the store's invariants.
fn merge_rule(
    class: MapClass,
    current: &[Point],
    points: &[Point],
    config: &MapConfig,
) -> Result<Vec<Point>> {
    let closed = class.is_closed();
    let merged = if closed {
        let what = "detected crossing ring";
        validate_points(points, 2, what)?;
        let ring = dedup_cow(points, DEDUP_EPS, true);
        validate_points(&ring, 3, what)?;
        merge_polygon(current, &ring, config.spacing)?
    } else {
        validate_points(points, 2, "detected polyline")?;
        match class.fold() {
            Some(fold) => merge_line(current, points, config.smoothing, config.spacing, fold)?,
            None => merge_polyline(current, points, config.smoothing, config.spacing)?,
        }
    };
    validate_points(&merged, if closed { 3 } else { 2 }, "merged geometry")?;
    Ok(merged)
}

impl GlobalMap {
    /// Validates a detection for `class` and returns the points to store (resampled at spacing).
    fn prepare(&self, class: MapClass, points: &[Point]) -> Result<Vec<Point>> {
        let closed = class.is_closed();
        let what = if closed { "crossing ring" } else { "polyline" };
        validate_points(points, 2, what)?;
        if closed {
            let ring = dedup_cow(points, DEDUP_EPS, true);
            validate_points(&ring, 3, what)?;
            resample_spacing(&ring, self.config.spacing, true)
        } else {
            resample_spacing(points, self.config.spacing, false)
        }
    }

    /// Inserts a new instance (points resampled at `spacing`) observed at `frame`; returns its id
    /// (ids are assigned increasingly from 0 and never reused).
    pub fn insert(&mut self, class: MapClass, points: &[Point], frame: i64) -> Result<u64> {
        let id = self.next_id;
        self.insert_with_id(id, class, points, frame)?;
        Ok(id)
    }

    /// Inserts with a caller-chosen id (errors on a duplicate id); later automatic ids stay above it.
    pub fn insert_with_id(
        &mut self,
        id: u64,
        class: MapClass,
        points: &[Point],
        frame: i64,
    ) -> Result<()> {
        if id == u64::MAX {
            return Err(GeomError::InvalidParameter {
                name: "id",
                reason: "id 2^64 - 1 is reserved".into(),
            });
        }
        if self.id_to_slot.contains_key(&id) {
            return Err(GeomError::DuplicateId(id));
        }
        let stored = self.prepare(class, points)?;
        let inst = Instance {
            id,
            class,
            points: stored,
            closed: class.is_closed(),
            first_frame: frame,
            last_frame: frame,
            observations: 1,
        };
        self.alloc_slot(inst)?;
        self.next_id = self.next_id.max(id + 1);
        Ok(())
    }

    /// Merges a detection into instance `id` by its class rule (curve fit or polygon union) and
    /// updates the index and bookkeeping. On error the instance is unchanged.
    pub fn merge(&mut self, id: u64, points: &[Point], frame: i64) -> Result<()> {
        let slot = *self.id_to_slot.get(&id).ok_or(GeomError::UnknownId(id))?;
        let inst = self.slots[slot as usize]
            .as_ref()
            .ok_or(GeomError::UnknownId(id))?;
        let merged = merge_rule(inst.class, &inst.points, points, &self.config)?;
        self.commit(slot, id, merged, 1, frame)
    }

    /// Merges many detections at `frame`: `items[i] = (id, points)`. The result is exactly that of
    /// calling [`Self::merge`] on each item in order (items for the same instance are applied in
    /// their order, each to the result of the previous one); the merges of different instances
    /// are computed in parallel (a pool of their own) and then committed. Returns one result per item:
    /// an item that fails (unknown id, bad geometry) leaves the instance as the items before it
    /// made it, and does not affect the others.
    pub fn merge_many(&mut self, items: &[(u64, &[Point])], frame: i64) -> Vec<Result<()>> {
        use std::sync::atomic::{AtomicUsize, Ordering};
        use std::sync::OnceLock;
        let mut results: Vec<Result<()>> = (0..items.len()).map(|_| Ok(())).collect();
        // Group the items by instance, in order of first appearance.
        let mut group_of: HashMap<u64, usize> = HashMap::new();
        let mut groups: Vec<(u32, Vec<usize>)> = Vec::new();
        for (i, (id, _)) in items.iter().enumerate() {
            match self.id_to_slot.get(id) {
                None => results[i] = Err(GeomError::UnknownId(*id)),
                Some(&slot) => {
                    let g = *group_of.entry(*id).or_insert_with(|| {
                        groups.push((slot, Vec::new()));
                        groups.len() - 1
                    });
                    groups[g].1.push(i);
                }
            }
        }
        let config = &self.config;
        let slots = &self.slots;
        // Per group: the final geometry (None when every item failed) and the per-item errors.
        type GroupOutcome = (Option<Vec<Point>>, u32, Vec<(usize, GeomError)>);
        let outcome = |(slot, members): &(u32, Vec<usize>)| -> GroupOutcome {
            let Some(inst) = slots[*slot as usize].as_ref() else {
                let errs = members
                    .iter()
                    .map(|&i| (i, GeomError::UnknownId(items[i].0)))
                    .collect();
                return (None, 0, errs);
            };
            let mut current: Option<Vec<Point>> = None;
            let mut merged = 0u32;
            let mut errs = Vec::new();
            for &i in members {
                let base = current.as_deref().unwrap_or(&inst.points);
                match merge_rule(inst.class, base, items[i].1, config) {
                    Ok(next) => {
                        current = Some(next);
                        merged += 1;
                    }
                    Err(e) => errs.push((i, e)),
                }
            }
            (current, merged, errs)
        };
        // The calling thread works through the groups (largest first) and the merge pool's
        // threads join in as they wake up, taking the next group from a shared counter: no wait for a
        // pool wake-up before the first merge (which costs as much as several merges).
        let mut order: Vec<usize> = (0..groups.len()).collect();
        let cost = |g: usize| -> usize {
            let (slot, members) = &groups[g];
            let own = slots[*slot as usize]
                .as_ref()
                .map_or(0, |inst| inst.points.len());
            own + members.iter().map(|&i| items[i].1.len()).sum::<usize>()
        };
        order.sort_by_key(|&g| std::cmp::Reverse(cost(g)));
        let done: Vec<OnceLock<GroupOutcome>> =
            (0..groups.len()).map(|_| OnceLock::new()).collect();
        let next = AtomicUsize::new(0);
        let work = || loop {
            let k = next.fetch_add(1, Ordering::Relaxed);
            let Some(&g) = order.get(k) else { break };
            let _ = done[g].set(outcome(&groups[g]));
        };
        match merge_pool().filter(|_| groups.len() >= 4) {
            Some(pool) => pool.in_place_scope(|scope| {
                for _ in 0..pool.current_num_threads().min(groups.len() - 1) {
                    scope.spawn(|_| work());
                }
                work();
            }),
            None => work(),
        }
        // (Every group is done once the scope ends; one left undone would be computed here.)
        let outcomes: Vec<GroupOutcome> = done
            .into_iter()
            .zip(&groups)
            .map(|(cell, group)| cell.into_inner().unwrap_or_else(|| outcome(group)))
            .collect();
        for ((slot, members), (geometry, merged, errs)) in groups.iter().zip(outcomes) {
            for (i, e) in errs {
                results[i] = Err(e);
            }
            if let Some(points) = geometry {
                let id = items[members[0]].0;
                // (Cannot fail: the instance was present above and nothing removed it since.)
                if let Err(e) = self.commit(*slot, id, points, merged, frame) {
                    results[members[0]] = Err(e);
                }
            }
        }
        results
    }

    /// Replaces the geometry of instance `id` with `points` (resampled at `spacing` as on insert)
    /// as a new observation at `frame`: the bookkeeping continues (first frame kept, last frame
    /// and observation count updated) — for merge rules implemented outside the store, e.g. the
    /// VMA and PolyMerge baselines. On error the instance is unchanged.
    pub fn replace(&mut self, id: u64, points: &[Point], frame: i64) -> Result<()> {
        let slot = *self.id_to_slot.get(&id).ok_or(GeomError::UnknownId(id))?;
        let class = self.slots[slot as usize]
            .as_ref()
            .ok_or(GeomError::UnknownId(id))?
            .class;
        let stored = self.prepare(class, points)?;
        self.commit(slot, id, stored, 1, frame)
    }

    /// The slot and instance of polyline `id`; errors on an unknown id or a crossing (`doing`
    /// names the operation in the error).
    fn polyline(&self, id: u64, doing: &str) -> Result<(u32, &Instance)> {
        let slot = *self.id_to_slot.get(&id).ok_or(GeomError::UnknownId(id))?;
        let inst = self.slots[slot as usize]
            .as_ref()
            .ok_or(GeomError::UnknownId(id))?;
        if inst.closed {
            return Err(GeomError::InvalidParameter {
                name: "id",
                reason: format!("instance {id} is a crossing; {doing} applies to polylines"),
            });
        }
        Ok((slot, inst))
    }

    /// Cuts the polyline instance `id` to its stored points `start..stop` (no resampling), its
    /// bookkeeping unchanged (no new observation): a clean-up of a finished map cutting off
    /// ends the drive did not back. Errors on an unknown id, a crossing (closed) instance, or a
    /// range out of bounds or of fewer than 2 points; the instance is then unchanged.
    pub fn trim(&mut self, id: u64, start: usize, stop: usize) -> Result<()> {
        let (slot, inst) = self.polyline(id, "trimming")?;
        let n = inst.points.len();
        if stop > n || start + 2 > stop {
            return Err(GeomError::InvalidParameter {
                name: "start, stop",
                reason: format!(
                    "{start}..{stop} must keep at least 2 of the instance's {n} points"
                ),
            });
        }
        let points = inst.points[start..stop].to_vec();
        let last = inst.last_frame;
        self.commit(slot, id, points, 0, last)
    }

    /// Splices the open polyline `points` into instance `id` ([`crate::splice::splice_polyline`]
    /// with `overlap` metres: the stretch it covers is replaced, the rest kept on either side; a
    /// lane line or kerb by [`crate::splice::splice_line`], which does not fold onto itself),
    /// then resamples at `spacing` as [`Self::replace`] does, as a new observation at `frame`.
    /// Errors on an unknown id, a crossing (closed) instance, bad geometry or a bad `overlap`; the
    /// instance is then unchanged.
    pub fn splice(&mut self, id: u64, points: &[Point], overlap: f64, frame: i64) -> Result<()> {
        let (slot, inst) = self.polyline(id, "splicing")?;
        let spliced = match inst.class.fold() {
            Some(fold) => crate::splice::splice_line(&inst.points, points, overlap, fold)?,
            None => crate::splice::splice_polyline(&inst.points, points, overlap)?,
        };
        let stored = self.prepare(inst.class, &spliced)?;
        self.commit(slot, id, stored, 1, frame)
    }

    /// Stores new geometry of the instance in `slot` as `observed` more observations at `frame`.
    fn commit(
        &mut self,
        slot: u32,
        id: u64,
        points: Vec<Point>,
        observed: u32,
        frame: i64,
    ) -> Result<()> {
        let aabb = points_aabb(&points);
        let inst = self.slots[slot as usize]
            .as_mut()
            .ok_or(GeomError::UnknownId(id))?;
        inst.points = points;
        inst.first_frame = inst.first_frame.min(frame);
        inst.last_frame = inst.last_frame.max(frame);
        inst.observations = inst.observations.saturating_add(observed);
        self.index.upsert(slot, aabb);
        Ok(())
    }
}

//! Absorbing duplicates inside one map: an instance that lies on a neighbour of its class over
//! most of its length becomes part of it.
//!
//! An online mapper inserts a new instance when a detection is not associated with the one
//! already stored (a track lost and found again, a skeleton piece of the same line); merges then
//! grow both until they lie on each other. [`GlobalMap::absorb`] finds such pairs around the
//! instances a step touched and joins them:
//!
//! 1. **Candidates** of an instance `A` of `ids` (in the order given): the instances of its
//!    class whose bounding box meets `A`'s grown by `gate` (the spatial index).
//! 2. **Overlap test**, the one of [`GlobalMap::merge_map`]: `A` and `B` overlap when
//!    `max(s(A, B), s(B, A)) >= min_overlap`, with `s(A, B)` the share of `A`'s points within
//!    `gate` of `B`. For crossings the gate is 0: only points inside (or on) the other's ring
//!    count, so a crossing drawn twice is absorbed and two crossings that meet at an
//!    intersection's corner, within the gate of each other's outline, are not (absorbing those
//!    joined distinct crossings of real intersections: av2-mini, CD_ped 0.15 -> 0.48 m).
//!    Candidates are tried by larger share, then smaller mean distance, then lower id.
//! 3. **Merge**: of the pair, the instance with more points keeps its id (ties: the lower id)
//!    and takes the other's geometry by the class rule of `merge_map` (a polyline merge only
//!    when it is faithful within `tolerance` and the gate, a crossing by polygon union);
//!    observations add up, first / last frames span both, drives are the union. The other
//!    instance is removed. A pair whose merge fails stays apart (and is not tried again in this
//!    call).
//! 4. The keeper is checked again (it may now overlap another instance).
//!
//! Returns the `(absorbed, into)` pairs in the order they happened (an id absorbed into one that
//! is absorbed later: follow the chain). Deterministic: no threads, no hash order.

use crate::error::Result;
use crate::merge_map::{merge_geometry, overlap, MergeMapParams, Outline};
use crate::provenance::union_sorted;
use crate::store::GlobalMap;
use parry2d_f64::bounding_volume::BoundingVolume;
use std::collections::{HashSet, VecDeque};

/// The unordered key of a pair of ids.
fn pair(a: u64, b: u64) -> (u64, u64) {
    (a.min(b), a.max(b))
}

impl GlobalMap {
    /// The overlapping neighbours of instance `id` (see the module docs, steps 1-2), best first,
    /// leaving out pairs in `failed`.
    fn overlapping(
        &self,
        id: u64,
        params: &MergeMapParams,
        failed: &HashSet<(u64, u64)>,
    ) -> Vec<u64> {
        let Some(a) = self.get(id) else {
            return Vec::new();
        };
        let oa = Outline::new(a);
        let mut found: Vec<(u64, f64, f64)> = self
            .query_aabb(&a.aabb().loosened(params.gate))
            .into_iter()
            .filter(|&k| k != id && !failed.contains(&pair(id, k)))
            .filter_map(|k| {
                let b = self.get(k)?;
                if b.class != a.class {
                    return None;
                }
                // crossings: only points inside (or on) the other ring count; two crossings side
                // by side at an intersection lie within the gate of each other's outline
                let gate = if a.closed { 0.0 } else { params.gate };
                let (share, mean) = overlap(&oa, &Outline::new(b), gate);
                (share >= params.min_overlap).then_some((k, share, mean))
            })
            .collect();
        found.sort_by(|x, y| {
            y.1.total_cmp(&x.1)
                .then(x.2.total_cmp(&y.2))
                .then(x.0.cmp(&y.0))
        });
        found.into_iter().map(|f| f.0).collect()
    }

    /// Joins instance `a` and `b` (see the module docs, step 3): `Some((absorbed, into))`, or
    /// `None` when their merge fails (the map is then unchanged).
    fn join(&mut self, a: u64, b: u64, params: &MergeMapParams) -> Result<Option<(u64, u64)>> {
        let (ia, ib) = match (self.get(a), self.get(b)) {
            (Some(x), Some(y)) => (x, y),
            _ => return Ok(None),
        };
        let (keep, gone) =
            if ib.points.len() > ia.points.len() || (ib.points.len() == ia.points.len() && b < a) {
                (ib, ia)
            } else {
                (ia, ib)
            };
        let config = self.config();
        let Ok(points) = merge_geometry(keep.closed, &keep.points, &gone.points, &config, params)
        else {
            return Ok(None);
        };
        let mut merged = keep.clone();
        merged.points = points;
        merged.first_frame = keep.first_frame.min(gone.first_frame);
        merged.last_frame = keep.last_frame.max(gone.last_frame);
        merged.observations = keep.observations.saturating_add(gone.observations);
        let drives = union_sorted(self.drives(keep.id), self.drives(gone.id));
        let (kid, gid) = (keep.id, gone.id);
        if merged.validate().is_err() {
            return Ok(None);
        }
        self.put(merged)?;
        self.remove(gid)?;
        self.set_drives(kid, &drives)?;
        Ok(Some((gid, kid)))
    }

    /// Absorbs the duplicates around the instances `ids` (see the module docs): returns the
    /// `(absorbed, into)` pairs. Unknown ids are skipped. Errors only on bad parameters (the map
    /// is then unchanged).
    pub fn absorb(&mut self, ids: &[u64], params: MergeMapParams) -> Result<Vec<(u64, u64)>> {
        params.validate()?;
        let mut out = Vec::new();
        let mut failed: HashSet<(u64, u64)> = HashSet::new();
        let mut queue: VecDeque<u64> = ids.iter().copied().collect();
        while let Some(id) = queue.pop_front() {
            for k in self.overlapping(id, &params, &failed) {
                match self.join(id, k, &params)? {
                    Some((gone, into)) => {
                        out.push((gone, into));
                        queue.push_back(into);
                        break;
                    }
                    None => {
                        failed.insert(pair(id, k));
                    }
                }
            }
        }
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_util::{add, map, rect};
    use crate::types::{MapClass, Point};

    fn line(x0: f64, x1: f64, y: f64) -> Vec<Point> {
        let n = ((x1 - x0).abs().ceil() as usize).max(1);
        (0..=n)
            .map(|i| Point::new(x0 + (x1 - x0) * i as f64 / n as f64, y))
            .collect()
    }

    fn params_of(gate: f64, min_overlap: f64, tolerance: f64) -> MergeMapParams {
        MergeMapParams {
            gate,
            min_overlap,
            tolerance,
        }
    }

    fn params() -> MergeMapParams {
        params_of(1.0, 0.5, 3.0)
    }

    #[test]
    fn a_stub_on_a_long_line_is_absorbed_into_it() {
        let mut m = map();
        let long = add(&mut m, MapClass::Divider, &line(0.0, 50.0, 0.0), 0);
        let stub = add(&mut m, MapClass::Divider, &line(20.0, 26.0, 0.3), 3);
        let out = m.absorb(&[stub], params()).unwrap();
        assert_eq!(out, vec![(stub, long)]);
        assert!(!m.contains(stub));
        let kept = m.get(long).unwrap();
        assert_eq!(kept.observations, 2);
        assert_eq!((kept.first_frame, kept.last_frame), (0, 3));
        // the merged line still runs from 0 to 50 m, within the tolerance of both
        let xs: Vec<f64> = kept.points.iter().map(|p| p.x).collect();
        assert!(xs[0].min(*xs.last().unwrap()) < 0.5);
        assert!(xs[0].max(*xs.last().unwrap()) > 49.5);
        assert!(kept.points.iter().all(|p| p.y.abs() <= 0.3 + 1e-9));
    }

    #[test]
    fn neighbours_beyond_the_gate_or_of_another_class_stay() {
        let mut m = map();
        let a = add(&mut m, MapClass::Divider, &line(0.0, 50.0, 0.0), 0);
        let b = add(&mut m, MapClass::Divider, &line(0.0, 50.0, 3.5), 0); // next lane
        let c = add(&mut m, MapClass::Boundary, &line(0.0, 50.0, 0.2), 0);
        let out = m.absorb(&[a, b, c], params()).unwrap();
        assert!(out.is_empty());
        assert_eq!(m.len(), 3);
    }

    #[test]
    fn pieces_overlapping_over_most_of_one_join() {
        let mut m = map();
        let a = add(&mut m, MapClass::Boundary, &line(0.0, 20.0, 0.0), 0);
        let b = add(&mut m, MapClass::Boundary, &line(8.0, 26.0, 0.1), 1); // 13 of 19 on `a`
        let out = m.absorb(&[b], params()).unwrap();
        assert_eq!(out.len(), 1);
        assert_eq!(m.len(), 1);
        let (_, into) = out[0];
        assert_eq!(into, a); // 21 points against 19: `a` keeps its id
        let pts = &m.get(a).unwrap().points;
        let (lo, hi) = pts
            .iter()
            .fold((f64::MAX, f64::MIN), |(l, h), p| (l.min(p.x), h.max(p.x)));
        assert!(lo < 0.5 && hi > 25.5, "joined extent {lo}..{hi}");
    }

    #[test]
    fn chains_are_followed_and_overlapping_crossings_union() {
        let mut m = map();
        let big = add(&mut m, MapClass::PedCrossing, &rect(0.0, 0.0, 6.0, 2.0), 0);
        let small = add(&mut m, MapClass::PedCrossing, &rect(1.0, 0.0, 2.0, 1.5), 1);
        let far = add(&mut m, MapClass::PedCrossing, &rect(30.0, 0.0, 6.0, 2.0), 1);
        // a crossing overlapping `big`'s edge by 5 cm (a neighbour at an intersection): more
        // than half of its outline within the gate of `big`'s, less than half inside it
        let beside = add(&mut m, MapClass::PedCrossing, &rect(0.0, 2.7, 6.0, 0.75), 1);
        let out = m.absorb(&[small, far, beside], params()).unwrap();
        assert_eq!(out, vec![(small, big)]);
        assert!(m.contains(far) && m.contains(big) && m.contains(beside));
        assert!(!m.contains(small));
        // three stubs along one line end in one instance
        let mut m = map();
        let ids: Vec<u64> = (0..3)
            .map(|i| {
                let x = 5.0 * i as f64; // 8 of 13 points on the neighbour
                add(
                    &mut m,
                    MapClass::Divider,
                    &line(x, x + 12.0, 0.05 * i as f64),
                    0,
                )
            })
            .collect();
        let out = m.absorb(&ids, params()).unwrap();
        assert_eq!(out.len(), 2);
        assert_eq!(m.len(), 1);
    }

    #[test]
    fn an_unfaithful_merge_keeps_both_and_bad_parameters_are_errors() {
        let mut m = map();
        // an L: the short leg overlaps the long leg's corner only over the gate's reach
        let a = add(&mut m, MapClass::Boundary, &line(0.0, 30.0, 0.0), 0);
        let leg: Vec<Point> = (0..=20).map(|i| Point::new(30.0, i as f64)).collect();
        let b = add(&mut m, MapClass::Boundary, &leg, 0);
        let out = m.absorb(&[a, b], params_of(1.0, 0.04, 0.2)).unwrap();
        assert!(out.is_empty(), "{out:?}");
        assert_eq!(m.len(), 2);
        assert!(m.absorb(&[a], params_of(f64::NAN, 0.5, 3.0)).is_err());
        assert!(m.absorb(&[12345], params()).unwrap().is_empty());
    }
}

//! Merging a whole map into another: the city map from drive maps.
//!
//! [`GlobalMap::merge_map`] merges every instance of `other` into `self` by the store's class rules
//! (curve-fit merge of polylines, polygon union of crossings), keeping provenance. It works in
//! four steps:
//!
//! 1. **Candidates.** For each instance `B` of `other` (ascending id), the instances `A` of `self`
//!    *as it was before the call* whose bounding box meets `B`'s box grown by `gate` (the spatial
//!    index), of the same class.
//! 2. **Overlap test.** With `d(p, X)` the distance from a point `p` to the geometry of `X` (its
//!    polyline; for a crossing its ring, 0 inside the ring), the share of `B`'s points within
//!    `gate` of `A` is `s(B, A) = |{p in B : d(p, A) <= gate}| / |B|`. `A` and `B` *overlap* when
//!    `max(s(B, A), s(A, B)) >= min_overlap` (the larger share: a short piece lying along a long
//!    instance overlaps it). Stored points are dense (about `spacing` apart), so a share of
//!    points is a share of length. The mean distance `D` of the points within the gate (both
//!    directions together) ranks equal shares.
//! 3. **Groups.** Overlapping pairs are edges of a graph between the instances of `self` and of
//!    `other`; each connected group with an edge becomes one instance. (So an instance of `other`
//!    that bridges two instances of `self` joins them, and two instances of `other` are joined
//!    only through an instance of `self`: the instances of one map are taken as distinct, as that
//!    map's own mapper decided.) The group's geometry starts from its member with the most
//!    points (ties: the instance of `self`, then the lowest id) and takes the others in
//!    breadth-first order over the edges, neighbours by overlap (larger share first, then smaller
//!    `D`, then lower id), each merged by the class rule: `merge_polyline` with `self`'s
//!    smoothing and spacing for dividers and boundaries, `merge_polygon` (union, resampled at
//!    spacing) for crossings. The curve-fit merge splices one polyline into the other where it
//!    projects and keeps the rest of the base, so two long polylines that overlap only in part
//!    (a block's boundary seen by two drives as two U shapes, a piece that runs along a
//!    boundary and turns away from it) could lose whole sides or be joined across a gap; a
//!    polyline merge is therefore kept only when it is *faithful* within
//!    [`MergeMapParams::tolerance`]: every vertex of both members within the tolerance of the
//!    result, every vertex of the result within the tolerance of a member, and at most
//!    [`LOST_SLACK`] metres of either member farther than the gate from the result (what
//!    overlapped within the gate stays within it: the two sides of a median island, 2-3 m
//!    apart, are not merged into one line). The merge of the
//!    member into the group's geometry is tried first, then the reverse. A member whose merge
//!    fails (no faithful merge, or invalid geometry) is left out: an instance of `self` stays
//!    as it was, one of `other` is inserted. The group keeps
//!    the lowest id of its instances of `self`; the other instances of `self` in it are removed
//!    ("absorbed").
//! 4. **Inserts.** The instances of `other` in no group are inserted with fresh ids of `self` (in
//!    ascending id order of `other`), geometry and bookkeeping copied.
//!
//! Provenance and bookkeeping of a group: the union of the members' drives, the sum of their
//! observations, the min of their first frames and the max of their last frames.
//!
//! The result is deterministic (no dependence on threads or hash order; the overlap tests and the
//! groups' merges run in parallel and are committed in a fixed order). It depends on the order in
//! which maps are merged only through the curve fits of the overlapping parts and through which
//! pieces meet the overlap threshold; `tests` bounds it by the Chamfer distance between the maps
//! built in different orders (see `order_of_merges_changes_little`).

use crate::error::{GeomError, Result};
use crate::store::{GlobalMap, Instance};
use crate::types::{check_non_negative, check_positive};
use rayon::prelude::*;

mod graph;
mod outline;
mod rule;

use graph::{groups, overlap_edges, Node};
pub use outline::instance_overlap;
pub(crate) use outline::{overlap, Outline};
pub(crate) use rule::merge_geometry;
pub use rule::LOST_SLACK;
use rule::{merge_group, GroupOutcome, Members};

/// Default gate of [`MergeMapParams`], metres.
pub const DEFAULT_GATE: f64 = 1.5;
/// Default share of points that makes two instances overlap ([`MergeMapParams`]).
pub const DEFAULT_MIN_OVERLAP: f64 = 0.5;
/// Default largest deviation of a polyline merge ([`MergeMapParams::tolerance`]), metres.
pub const DEFAULT_TOLERANCE: f64 = 3.0;

/// The tunables of [`GlobalMap::merge_map`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MergeMapParams {
    /// Distance (metres) within which a point counts as lying on the other instance; also how far
    /// candidates are looked for. Finite, >= 0.
    pub gate: f64,
    /// The share of points (in (0, 1]) within the gate that makes two instances overlap.
    pub min_overlap: f64,
    /// Largest deviation (metres, finite, > 0) of a polyline merge: the merge of two polylines is
    /// kept only when every vertex of both lies within `tolerance` of the result (nothing of
    /// either is lost) and every vertex of the result within `tolerance` of one of them (nothing
    /// invented, such as a jump between far-apart pieces), and at most [`LOST_SLACK`] metres of
    /// either lie farther than `gate` from it; otherwise the member stays a separate instance
    /// (see the module docs, step 3).
    pub tolerance: f64,
}

impl Default for MergeMapParams {
    fn default() -> Self {
        MergeMapParams {
            gate: DEFAULT_GATE,
            min_overlap: DEFAULT_MIN_OVERLAP,
            tolerance: DEFAULT_TOLERANCE,
        }
    }
}

impl MergeMapParams {
    /// Checks `gate` finite and >= 0, `min_overlap` in (0, 1], `tolerance` finite and > 0.
    pub fn validate(&self) -> Result<()> {
        check_positive("tolerance", self.tolerance)?;
        check_non_negative("gate", self.gate)?;
        if !(self.min_overlap > 0.0 && self.min_overlap <= 1.0) {
            return Err(GeomError::InvalidParameter {
                name: "min_overlap",
                reason: format!("must be in (0, 1], got {}", self.min_overlap),
            });
        }
        Ok(())
    }
}

/// What [`GlobalMap::merge_map`] did.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct MergeMapStats {
    /// Instances of `other` merged into instances of `self`.
    pub merged: usize,
    /// Instances of `other` inserted with fresh ids.
    pub inserted: usize,
    /// Instances of `self` joined into another instance of `self` (and removed) because an
    /// instance of `other` overlapped both.
    pub absorbed: usize,
}

impl GlobalMap {
    /// Merges every instance of `other` into this map (see the module docs for the overlap test
    /// and the rules); `other` is unchanged. Errors only on bad parameters or when the map cannot
    /// hold `other`'s instances (ids or slots exhausted); the map is then unchanged.
    pub fn merge_map(
        &mut self,
        other: &GlobalMap,
        params: MergeMapParams,
    ) -> Result<MergeMapStats> {
        params.validate()?;
        self.check_room_for(other)?;
        let theirs: Vec<&Instance> = other.instances();
        // 1-2. Candidates from the index and the overlap test, against the map as it is now.
        let edges = overlap_edges(self, &theirs, &params);
        // 3. Groups: connected parts of the overlap graph, merged in parallel.
        let members = Members {
            this: self,
            other,
            theirs: &theirs,
        };
        let groups = groups(theirs.len(), &edges, |n| members.n_points(n));
        let config = self.config();
        let outcomes: Vec<GroupOutcome> = groups
            .par_iter()
            .map(|g| merge_group(g, members, &config, &params))
            .collect();
        // 4. Commit: the groups, then the inserts (ascending id of `other`).
        let mut stats = MergeMapStats::default();
        let mut placed = vec![false; theirs.len()];
        for out in outcomes {
            self.commit_group(out, &mut placed, &mut stats)?;
        }
        for (j, b) in theirs.iter().enumerate() {
            if !placed[j] {
                let id = self.insert_instance((*b).clone())?;
                self.set_drives(id, other.drives(b.id))?;
                stats.inserted += 1;
            }
        }
        Ok(stats)
    }

    /// Errors when this map cannot take `other`'s instances (ids or slots exhausted).
    fn check_room_for(&self, other: &GlobalMap) -> Result<()> {
        if self.len().saturating_add(other.len()) >= u32::MAX as usize
            || self.next_id().saturating_add(other.len() as u64) == u64::MAX
        {
            return Err(GeomError::InvalidParameter {
                name: "other",
                reason: format!(
                    "the map cannot take {} more instances (ids or slots exhausted)",
                    other.len()
                ),
            });
        }
        Ok(())
    }

    /// Commits a merged group: under the lowest id of its instances of `self` (the others of
    /// `self` are removed, "absorbed"), or as a new instance when it has none; marks its members
    /// of `other` as placed and counts them in `stats`.
    fn commit_group(
        &mut self,
        out: GroupOutcome,
        placed: &mut [bool],
        stats: &mut MergeMapStats,
    ) -> Result<()> {
        let holder = out
            .members
            .iter()
            .filter_map(|n| match n {
                Node::Mine(id) => Some(*id),
                Node::Theirs(_) => None,
            })
            .min();
        let id = match holder {
            Some(id) => {
                let mut inst = out.merged;
                inst.id = id;
                self.put(inst)?;
                id
            }
            None => self.insert_instance(out.merged)?,
        };
        for n in &out.members {
            match *n {
                Node::Theirs(j) => {
                    placed[j] = true;
                    if holder.is_some() {
                        stats.merged += 1;
                    }
                }
                Node::Mine(m) if m != id => {
                    self.remove(m)?;
                    stats.absorbed += 1;
                }
                Node::Mine(_) => {}
            }
        }
        if holder.is_none() {
            stats.inserted += 1;
            // (The other members of such a group, all of `other`, count as merged into it.)
            stats.merged += out.members.len() - 1;
        }
        self.set_drives(id, &out.drives)
    }
}

#[cfg(test)]
mod tests {
    use super::outline::{segment_count, segment_distance2};
    use super::*;
    use crate::test_util::{add, map, p, rect};
    use crate::types::{MapClass, Point};
    use proptest::prelude::*;

    /// Merges `b` into `a` with the default parameters: (merged, inserted, absorbed).
    fn merge_counts(a: &mut GlobalMap, b: &GlobalMap) -> (usize, usize, usize) {
        let s = a.merge_map(b, MergeMapParams::default()).unwrap();
        (s.merged, s.inserted, s.absorbed)
    }

    /// A gently curved polyline along x from `x0` to `x1` at height `y`.
    fn curve(x0: f64, x1: f64, y: f64) -> Vec<Point> {
        let n = ((x1 - x0) / 0.5).ceil() as usize + 1;
        (0..n)
            .map(|i| {
                let x = x0 + (x1 - x0) * i as f64 / (n - 1) as f64;
                p(x, y + 2.0 * (x / 40.0).sin())
            })
            .collect()
    }

    /// Distance from `q` to the polyline / ring boundary `pts`.
    fn boundary_distance(q: &Point, pts: &[Point], closed: bool) -> f64 {
        let n = pts.len();
        (0..segment_count(n, closed))
            .map(|i| segment_distance2(q, &pts[i], &pts[(i + 1) % n]))
            .fold(f64::INFINITY, f64::min)
            .sqrt()
    }

    /// The map Chamfer distance of one class: (mean distance of `a`'s points to `b`'s geometry +
    /// the same from `b` to `a`) / 2, over all instances of the class (0 if both have none,
    /// infinite if only one has some).
    fn map_chamfer(a: &GlobalMap, b: &GlobalMap, class: MapClass) -> f64 {
        let of = |m: &GlobalMap| -> Vec<Instance> {
            m.instances()
                .into_iter()
                .filter(|i| i.class == class)
                .cloned()
                .collect()
        };
        let (ia, ib) = (of(a), of(b));
        if ia.is_empty() && ib.is_empty() {
            return 0.0;
        }
        if ia.is_empty() || ib.is_empty() {
            return f64::INFINITY;
        }
        let directed = |x: &[Instance], y: &[Instance]| {
            let (mut sum, mut n) = (0.0, 0usize);
            for inst in x {
                for q in &inst.points {
                    sum += y
                        .iter()
                        .map(|j| boundary_distance(q, &j.points, j.closed))
                        .fold(f64::INFINITY, f64::min);
                    n += 1;
                }
            }
            sum / n as f64
        };
        (directed(&ia, &ib) + directed(&ib, &ia)) / 2.0
    }

    #[test]
    fn parameters_are_checked() {
        let mut m = map();
        let o = map();
        for (gate, share) in [
            (-1.0, 0.5),
            (f64::NAN, 0.5),
            (f64::INFINITY, 0.5),
            (1.0, 0.0),
            (1.0, 1.5),
            (1.0, f64::NAN),
        ] {
            let params = MergeMapParams {
                gate,
                min_overlap: share,
                ..MergeMapParams::default()
            };
            assert!(
                matches!(
                    m.merge_map(&o, params),
                    Err(GeomError::InvalidParameter { .. })
                ),
                "{gate} {share}"
            );
        }
        assert_eq!(
            m.merge_map(&o, MergeMapParams::default()).unwrap(),
            MergeMapStats::default()
        );
    }

    #[test]
    fn disjoint_maps_give_the_union() {
        let mut a = map();
        add(&mut a, MapClass::Divider, &curve(0.0, 50.0, 0.0), 3);
        add(
            &mut a,
            MapClass::PedCrossing,
            &rect(10.0, 20.0, 2.0, 4.0),
            4,
        );
        a.tag_drive(1);
        let mut b = map();
        b.insert_with_id(7, MapClass::Boundary, &curve(0.0, 50.0, 30.0), 1)
            .unwrap();
        // Same place as a's divider but another class: not merged.
        b.insert_with_id(9, MapClass::Boundary, &curve(0.0, 50.0, 0.0), 2)
            .unwrap();
        b.tag_drive(4);
        let before = b.clone();
        assert_eq!(merge_counts(&mut a, &b), (0, 2, 0));
        assert_eq!(a.ids(), vec![0, 1, 2, 3]);
        assert_eq!(a.get(2).unwrap().points, b.get(7).unwrap().points);
        assert_eq!(a.get(3).unwrap().points, b.get(9).unwrap().points);
        let i = a.get(3).unwrap();
        assert_eq!((i.first_frame, i.last_frame, i.observations), (2, 2, 1));
        assert_eq!(a.drives(0), &[1]);
        assert_eq!(a.drives(3), &[4]);
        assert_eq!(b.instances(), before.instances(), "other is unchanged");
        a.check_invariants().unwrap();
    }

    #[test]
    fn identical_maps_merge_one_to_one() {
        let mut a = map();
        for k in 0..4 {
            add(
                &mut a,
                MapClass::Divider,
                &curve(0.0, 60.0, 10.0 * k as f64),
                k,
            );
        }
        add(
            &mut a,
            MapClass::PedCrossing,
            &rect(5.0, -20.0, 2.0, 4.0),
            0,
        );
        a.tag_drive(0);
        let mut b = a.clone();
        b.set_drives(0, &[3]).unwrap();
        let original = a.clone();
        assert_eq!(merge_counts(&mut a, &b), (5, 0, 0));
        assert_eq!(a.ids(), original.ids());
        for class in MapClass::ALL {
            let cd = map_chamfer(&a, &original, class);
            assert!(cd < 0.02, "{class:?}: {cd}");
        }
        let i = a.get(0).unwrap();
        assert_eq!(i.observations, 2);
        assert_eq!(a.drives(0), &[0, 3]);
        assert_eq!(a.drives(1), &[0]);
        a.check_invariants().unwrap();
    }

    #[test]
    fn pieces_join_and_bookkeeping_adds_up() {
        let mut a = map();
        let a1 = add(&mut a, MapClass::Divider, &curve(0.0, 40.0, 0.0), 5);
        let a2 = add(&mut a, MapClass::Divider, &curve(60.0, 100.0, 0.0), 2);
        let far = add(&mut a, MapClass::Divider, &curve(0.0, 100.0, 20.0), 1);
        a.set_drives(a1, &[1]).unwrap();
        a.set_drives(a2, &[2]).unwrap();
        let mut b = map();
        // Spans both pieces: each lies along it entirely (share 1), so all three join.
        add(&mut b, MapClass::Divider, &curve(-5.0, 105.0, 0.1), 9);
        // Crossings: union.
        let c = add(&mut a, MapClass::PedCrossing, &rect(0.0, 50.0, 2.0, 4.0), 0);
        add(&mut b, MapClass::PedCrossing, &rect(1.0, 51.0, 2.0, 4.0), 3);
        b.tag_drive(7);
        assert_eq!(merge_counts(&mut a, &b), (2, 0, 1));
        assert_eq!(a.ids(), vec![a1, far, c]);
        let i = a.get(a1).unwrap();
        assert_eq!((i.first_frame, i.last_frame, i.observations), (2, 9, 3));
        assert_eq!(a.drives(a1), &[1, 2, 7]);
        assert!(a.drives(far).is_empty());
        let xs: Vec<f64> = i.points.iter().map(|q| q.x).collect();
        let (lo, hi) = xs
            .iter()
            .fold((f64::INFINITY, -f64::INFINITY), |(l, h), &x| {
                (l.min(x), h.max(x))
            });
        assert!(lo < -4.0 && hi > 104.0, "{lo} {hi}");
        let cr = a.get(c).unwrap();
        let (lo, hi) = cr
            .points
            .iter()
            .fold((f64::INFINITY, -f64::INFINITY), |(l, h), q| {
                (l.min(q.x), h.max(q.x))
            });
        assert!(
            (lo + 2.0).abs() < 1e-6 && (hi - 3.0).abs() < 1e-6,
            "union: {lo} {hi}"
        );
        assert_eq!(a.get(c).unwrap().observations, 2);
        a.check_invariants().unwrap();
    }

    #[test]
    fn small_overlap_is_not_merged_and_threshold_decides() {
        let mut a = map();
        add(&mut a, MapClass::Boundary, &curve(0.0, 40.0, 0.0), 0);
        let mut b = map();
        add(&mut b, MapClass::Boundary, &curve(30.0, 70.0, 0.0), 0);
        let mut a2 = a.clone();
        let s = a.merge_map(&b, MergeMapParams::default()).unwrap();
        assert_eq!((s.merged, s.inserted), (0, 1), "an overlap of a quarter");
        let s = a2
            .merge_map(
                &b,
                MergeMapParams {
                    gate: 1.5,
                    min_overlap: 0.2,
                    ..MergeMapParams::default()
                },
            )
            .unwrap();
        assert_eq!((s.merged, s.inserted), (1, 0));
        assert_eq!(a2.len(), 1);
        // Shares, computed directly: about 12 of 41 points each way.
        let (share, mean) = instance_overlap(a.get(0).unwrap(), b.get(0).unwrap(), 1.5);
        assert!((0.2..0.4).contains(&share) && mean < 0.1, "{share} {mean}");
        // Parallel at 2 m: outside a 1.5 m gate, inside a 2.5 m one.
        let mut c = map();
        add(&mut c, MapClass::Boundary, &curve(0.0, 40.0, 2.0), 0);
        let (share, _) = instance_overlap(a.get(0).unwrap(), c.get(0).unwrap(), 1.5);
        assert_eq!(share, 0.0);
        let (share, mean) = instance_overlap(a.get(0).unwrap(), c.get(0).unwrap(), 2.5);
        assert!(share > 0.95 && (mean - 2.0).abs() < 0.1, "{share} {mean}");
    }

    /// Points every 0.5 m along the polyline through `corners`.
    fn dense(corners: &[(f64, f64)]) -> Vec<Point> {
        let mut out = vec![p(corners[0].0, corners[0].1)];
        for w in corners.windows(2) {
            let (a, b) = (p(w[0].0, w[0].1), p(w[1].0, w[1].1));
            let n = ((b - a).norm() / 0.5).ceil() as usize;
            out.extend((1..=n).map(|k| a + (b - a) * (k as f64 / n as f64)));
        }
        out
    }

    /// The largest distance from a vertex of `from` to the nearest instance of `to` (any class).
    fn worst_gap(from: &[&[Point]], to: &[&[Point]]) -> f64 {
        from.iter()
            .flat_map(|pts| pts.iter())
            .map(|q| {
                to.iter()
                    .map(|t| boundary_distance(q, t, false))
                    .fold(f64::INFINITY, f64::min)
            })
            .fold(0.0, f64::max)
    }

    /// Regression (AV2 city maps, issue 16): two drives' pieces of a block's boundary that
    /// overlap at both ends (the ring closes) or in a T were spliced so that a whole side was
    /// dropped, or far-apart pieces joined. With the tolerance check nothing of either map is
    /// lost and nothing is invented; without it (a tolerance too large to refuse anything) the
    /// same merges lose geometry.
    #[test]
    fn polyline_merges_lose_nothing_and_invent_nothing() {
        let cases: [(Vec<Point>, Vec<Point>); 2] = [
            // Three sides of a 40 x 20 m block, and the three sides across (a ring closes).
            (
                dense(&[(0.0, 20.0), (0.0, 0.0), (40.0, 0.0), (40.0, 20.0)]),
                dense(&[(40.0, 0.0), (40.0, 20.0), (0.0, 20.0), (0.0, 0.0)]),
            ),
            // More than half of the piece lies along the middle of the long boundary, then it
            // turns away (a T with an L-shaped stem).
            (
                dense(&[(0.0, 0.0), (100.0, 0.0)]),
                dense(&[(10.0, 0.2), (60.0, 0.2), (60.0, 20.0), (80.0, 20.0)]),
            ),
        ];
        for (k, (pa, pb)) in cases.iter().enumerate() {
            let run = |tolerance: f64, gate: f64| {
                let mut a = map();
                add(&mut a, MapClass::Boundary, pa, 0);
                let mut b = map();
                add(&mut b, MapClass::Boundary, pb, 1);
                let params = MergeMapParams {
                    tolerance,
                    gate,
                    ..MergeMapParams::default()
                };
                a.merge_map(&b, params).unwrap();
                a.check_invariants().unwrap();
                let out: Vec<Vec<Point>> = a.instances().iter().map(|i| i.points.clone()).collect();
                out
            };
            let inputs: [&[Point]; 2] = [pa, pb];
            let out = run(DEFAULT_TOLERANCE, DEFAULT_GATE);
            let outs: Vec<&[Point]> = out.iter().map(|v| &v[..]).collect();
            let (lost, invented) = (worst_gap(&inputs, &outs), worst_gap(&outs, &inputs));
            assert!(
                lost <= DEFAULT_TOLERANCE && invented <= DEFAULT_TOLERANCE,
                "case {k}: lost {lost} invented {invented}"
            );
            // unchecked: every merge passes the tolerance, and the gate (LOST_SLACK)
            let old = run(1e9, 1e9);
            let olds: Vec<&[Point]> = old.iter().map(|v| &v[..]).collect();
            let (lost, invented) = (worst_gap(&inputs, &olds), worst_gap(&olds, &inputs));
            assert!(
                lost.max(invented) > 2.0 * DEFAULT_TOLERANCE,
                "case {k}: the unchecked merge was faithful ({lost}, {invented}): the test shows nothing"
            );
        }
        // The tolerance is checked.
        for tolerance in [0.0, -1.0, f64::NAN, f64::INFINITY] {
            let params = MergeMapParams {
                tolerance,
                ..MergeMapParams::default()
            };
            assert!(matches!(
                map().merge_map(&map(), params),
                Err(GeomError::InvalidParameter {
                    name: "tolerance",
                    ..
                })
            ));
        }
    }

    #[test]
    fn deterministic() {
        let mut base = map();
        let mut other = map();
        for k in 0..30 {
            let x = 15.0 * (k % 6) as f64;
            let y = 12.0 * (k / 6) as f64;
            add(
                &mut base,
                MapClass::ALL[k % 3],
                &curve(x, x + 30.0, y),
                k as i64,
            );
            add(
                &mut other,
                MapClass::ALL[k % 3],
                &curve(x + 10.0, x + 35.0, y + 0.3),
                0,
            );
        }
        let mut a = base.clone();
        let mut b = base.clone();
        let sa = a.merge_map(&other, MergeMapParams::default()).unwrap();
        let sb = b.merge_map(&other, MergeMapParams::default()).unwrap();
        assert_eq!(sa, sb);
        assert_eq!(a.instances(), b.instances());
        a.check_invariants().unwrap();
    }

    /// A random world of well-separated instances and drives that each see random pieces of it.
    #[derive(Debug, Clone)]
    struct World {
        /// Per world instance: class, geometry.
        instances: Vec<(MapClass, Vec<Point>)>,
    }

    fn world() -> impl Strategy<Value = World> {
        (
            prop::collection::vec((-3.0..3.0f64, 20.0..80.0f64, 0.0..1.0f64), 1..5),
            prop::collection::vec((1.0..3.0f64, 1.5..4.0f64), 0..3),
        )
            .prop_map(|(lines, crossings)| {
                let mut instances = Vec::new();
                for (k, (amp, wave, cls)) in lines.into_iter().enumerate() {
                    let y0 = 12.0 * k as f64;
                    let class = if cls < 0.5 {
                        MapClass::Divider
                    } else {
                        MapClass::Boundary
                    };
                    let pts = (0..=200)
                        .map(|i| {
                            let x = i as f64 * 0.5;
                            p(x, y0 + amp * (x / wave).sin())
                        })
                        .collect();
                    instances.push((class, pts));
                }
                for (k, (hx, hy)) in crossings.into_iter().enumerate() {
                    instances.push((
                        MapClass::PedCrossing,
                        rect(20.0 + 30.0 * k as f64, -20.0, hx, hy),
                    ));
                }
                World { instances }
            })
    }

    /// One drive's view of the world: per instance, whether it is seen, which part, its offset.
    type View = Vec<(bool, f64, f64, f64, f64)>;

    fn view() -> impl Strategy<Value = View> {
        prop::collection::vec(
            (
                prop::bool::weighted(0.8),
                0.0..0.5f64,
                0.5..1.0f64,
                -0.1..0.1f64,
                -0.1..0.1f64,
            ),
            8,
        )
    }

    fn drive_map(world: &World, view: &View, drive: u32) -> GlobalMap {
        let mut m = map();
        for ((class, pts), &(seen, t0, t1, dx, dy)) in world.instances.iter().zip(view) {
            if !seen {
                continue;
            }
            let piece: Vec<Point> = if class.is_closed() {
                pts.iter().map(|q| p(q.x + dx, q.y + dy)).collect()
            } else {
                let (i0, i1) = ((t0 * 200.0) as usize, (t1 * 200.0) as usize);
                pts[i0..=i1]
                    .iter()
                    .enumerate()
                    .map(|(i, q)| p(q.x + dx, q.y + dy + 0.03 * ((i * 7 % 5) as f64 - 2.0)))
                    .collect()
            };
            m.insert(*class, &piece, drive as i64).unwrap();
        }
        m.tag_drive(drive);
        m
    }

    /// Merges the maps in `order`: one after another, or by a pairwise tree reduction.
    fn reduce(maps: &[GlobalMap], order: &[usize], tree: bool) -> GlobalMap {
        let mut level: Vec<GlobalMap> = order.iter().map(|&k| maps[k].clone()).collect();
        if !tree {
            let mut acc = level.remove(0);
            for m in &level {
                acc.merge_map(m, MergeMapParams::default()).unwrap();
            }
            return acc;
        }
        while level.len() > 1 {
            let mut next = Vec::new();
            let mut it = level.into_iter();
            while let Some(mut a) = it.next() {
                if let Some(b) = it.next() {
                    a.merge_map(&b, MergeMapParams::default()).unwrap();
                }
                next.push(a);
            }
            level = next;
        }
        level.pop().unwrap()
    }

    /// The documented order tolerance: per class, the map Chamfer distance between the city maps
    /// built in two orders (drive maps offset by up to 0.14 m and jittered by 0.06 m).
    const ORDER_TOLERANCE: f64 = 0.25;

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(32))]
        /// The city map hardly depends on the order of the merges (sequential or tree reduction,
        /// any permutation of the drives): map Chamfer per class within ORDER_TOLERANCE, every
        /// drive recorded, observations summed.
        #[test]
        fn order_of_merges_changes_little(world in world(),
                                          views in prop::collection::vec(view(), 3..6),
                                          perm_seed in any::<u64>(), tree in any::<bool>()) {
            let maps: Vec<GlobalMap> = views.iter().enumerate()
                .map(|(k, v)| drive_map(&world, v, k as u32)).collect();
            let identity: Vec<usize> = (0..maps.len()).collect();
            let mut perm = identity.clone();
            let mut s = perm_seed;
            for i in (1..perm.len()).rev() {
                s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                perm.swap(i, (s >> 33) as usize % (i + 1));
            }
            let a = reduce(&maps, &identity, false);
            let b = reduce(&maps, &perm, tree);
            a.check_invariants().map_err(TestCaseError::fail)?;
            b.check_invariants().map_err(TestCaseError::fail)?;
            for class in MapClass::ALL {
                let cd = map_chamfer(&a, &b, class);
                prop_assert!(cd <= ORDER_TOLERANCE, "{:?}: map Chamfer {} (perm {:?}, tree {})", class, cd, perm, tree);
            }
            let obs = |m: &GlobalMap| m.instances().iter().map(|i| i.observations as usize).sum::<usize>();
            let total: usize = maps.iter().map(|m| m.len()).sum();
            prop_assert_eq!(obs(&a), total);
            prop_assert_eq!(obs(&b), total);
            for m in [&a, &b] {
                let mut seen: Vec<u32> = m.instances().iter().flat_map(|i| m.drives(i.id).to_vec()).collect();
                seen.sort_unstable();
                seen.dedup();
                let expect: Vec<u32> = (0..maps.len() as u32).filter(|&k| !maps[k as usize].is_empty()).collect();
                prop_assert_eq!(seen, expect);
            }
        }
    }
}

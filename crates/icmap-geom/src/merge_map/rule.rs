//! The class rule of a whole-instance merge (a polyline merge kept only when faithful) and the
//! merge of one group of overlapping instances into one instance (step 3 of the module doc).

use super::graph::{Group, Node};
use super::outline::Outline;
use super::MergeMapParams;
use crate::error::{GeomError, Result};
use crate::merge::{merge_polygon, merge_polyline};
use crate::provenance::union_sorted;
use crate::store::{GlobalMap, Instance, MapConfig};
use crate::types::{validate_points, Point};

/// The merged geometry of a group and which of its members made it in.
pub(super) struct GroupOutcome {
    /// The merged instance (its id is decided on commit).
    pub(super) merged: Instance,
    pub(super) drives: Vec<u32>,
    /// Members whose merge succeeded (the start included).
    pub(super) members: Vec<Node>,
}

/// The instances of both maps by node: `self` as it was before the call, `other`'s instances in
/// ascending id order.
#[derive(Clone, Copy)]
pub(super) struct Members<'a> {
    pub(super) this: &'a GlobalMap,
    pub(super) other: &'a GlobalMap,
    pub(super) theirs: &'a [&'a Instance],
}

impl<'a> Members<'a> {
    pub(super) fn instance(&self, n: Node) -> &'a Instance {
        match n {
            Node::Theirs(j) => self.theirs[j],
            Node::Mine(id) => self.this.get(id).expect("an instance of self in a group"),
        }
    }

    pub(super) fn drives(&self, n: Node) -> &'a [u32] {
        match n {
            Node::Theirs(j) => self.other.drives(self.theirs[j].id),
            Node::Mine(id) => self.this.drives(id),
        }
    }

    pub(super) fn n_points(&self, n: Node) -> usize {
        match n {
            Node::Theirs(j) => self.theirs[j].points.len(),
            Node::Mine(id) => self.this.get(id).map_or(0, |i| i.points.len()),
        }
    }
}

/// Merges a group's members in its order into its start by the class rule ([`merge_geometry`]);
/// a member whose merge fails is left out. Bookkeeping: frames' min and max, observations
/// summed, drives united.
pub(super) fn merge_group(
    g: &Group,
    members: Members<'_>,
    config: &MapConfig,
    params: &MergeMapParams,
) -> GroupOutcome {
    let start = members.instance(g.order[0]);
    let mut merged = start.clone();
    let mut drives = members.drives(g.order[0]).to_vec();
    let mut ok = vec![g.order[0]];
    for &n in &g.order[1..] {
        let inst = members.instance(n);
        if let Ok(points) =
            merge_geometry(merged.closed, &merged.points, &inst.points, config, params)
        {
            merged.points = points;
            merged.first_frame = merged.first_frame.min(inst.first_frame);
            merged.last_frame = merged.last_frame.max(inst.last_frame);
            merged.observations = merged.observations.saturating_add(inst.observations);
            drives = union_sorted(&drives, members.drives(n));
            ok.push(n);
        }
    }
    GroupOutcome {
        merged,
        drives,
        members: ok,
    }
}

/// Metres of either polyline that a faithful merge may leave farther than the gate from the
/// result: a hook or a spur that the fit smooths away. Two sides of a median island 2-3 m apart,
/// found to overlap within the kerbs' gate and merged into one line, lost one side over its
/// length, and the tolerance (3 m) let that pass (sim:val:32: the islands' kerbs were covered
/// 0.56 m on average, the other kerbs 0.40 m; docs/mapping.md, "A merge keeps both sides of an
/// island").
pub const LOST_SLACK: f64 = 6.0;

/// The distance (metres) of each vertex of `pts` to `outline`; `None` farther than `cutoff`.
fn distances(pts: &[Point], outline: &Outline<'_>, cutoff: f64) -> Vec<Option<f64>> {
    pts.iter()
        .map(|p| outline.distance_within(p, cutoff))
        .collect()
}

/// The length (metres) of the stretches of the polyline `pts` farther than `gate` from a line,
/// given its vertices' distances `dist` to it (`None`: farther than any gate): its segments with
/// an end farther than that.
fn lost_length(pts: &[Point], dist: &[Option<f64>], gate: f64) -> f64 {
    let off = |d: &Option<f64>| d.is_none_or(|d| d > gate);
    pts.windows(2)
        .zip(dist.windows(2))
        .filter(|(_, d)| off(&d[0]) || off(&d[1]))
        .map(|(w, _)| (w[1] - w[0]).norm())
        .sum()
}

/// Whether `merged` is a faithful merge of the polylines `a` and `b`: every vertex of `a` and
/// `b` within the tolerance of it, every vertex of it within the tolerance of `a` or `b`, and at
/// most [`LOST_SLACK`] metres of either farther than the gate from it (what was found to overlap
/// within the gate stays within it). Each vertex's distance is measured once.
fn faithful(merged: &[Point], a: &[Point], b: &[Point], params: &MergeMapParams) -> bool {
    let tol = params.tolerance;
    let (om, oa, ob) = (
        Outline::of(merged, false),
        Outline::of(a, false),
        Outline::of(b, false),
    );
    // every vertex within the tolerance, and at most the slack of it beyond the gate
    let kept = |pts: &[Point]| {
        let d = distances(pts, &om, tol);
        d.iter().all(Option::is_some) && lost_length(pts, &d, params.gate) <= LOST_SLACK
    };
    kept(a)
        && kept(b)
        && merged
            .iter()
            .all(|p| oa.distance_within(p, tol).is_some() || ob.distance_within(p, tol).is_some())
}

/// The class rule of a whole-instance merge: `detected` merged into `current`. Polylines: the
/// curve-fit merge of `detected` into `current`, else of `current` into `detected` (the splice
/// keeps the base's parts outside the other's projection, so the roles matter when the two only
/// partly overlap), the first that is [`faithful`] by `params`; neither is an error (the member
/// is left out of the group).
pub(crate) fn merge_geometry(
    closed: bool,
    current: &[Point],
    detected: &[Point],
    config: &MapConfig,
    params: &MergeMapParams,
) -> Result<Vec<Point>> {
    if closed {
        let merged = merge_polygon(current, detected, config.spacing)?;
        validate_points(&merged, 3, "merged geometry")?;
        return Ok(merged);
    }
    for (base, other) in [(current, detected), (detected, current)] {
        let merged = merge_polyline(base, other, config.smoothing, config.spacing)?;
        validate_points(&merged, 2, "merged geometry")?;
        if faithful(&merged, current, detected, params) {
            return Ok(merged);
        }
    }
    Err(GeomError::Degenerate {
        what: "polyline merge".into(),
        reason: format!(
            "no merge keeps both polylines within {} m with at most {LOST_SLACK} m of either \
             farther than {} m",
            params.tolerance, params.gate
        ),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_util::p;

    /// Points every 0.5 m from (`x0`, `y`) to (`x1`, `y`).
    fn line(x0: f64, x1: f64, y: f64) -> Vec<Point> {
        let n = ((x1 - x0).abs() / 0.5).round() as usize;
        (0..=n)
            .map(|i| p(x0 + (x1 - x0) * i as f64 / n as f64, y))
            .collect()
    }

    #[test]
    fn a_merge_that_loses_a_side_of_an_island_is_not_faithful() {
        // a kerb round a median island 2.5 m wide: up one side, round the nose, down the other
        let nose: Vec<Point> = (1..8)
            .map(|k| {
                let t = std::f64::consts::PI * (0.5 + k as f64 / 8.0);
                p(1.25 * t.cos(), 1.25 + 1.25 * t.sin())
            })
            .collect();
        let u: Vec<Point> = [line(30.0, 0.0, 2.5), nose, line(0.0, 30.0, 0.0)].concat();
        let side = line(0.0, 30.0, 0.0);
        let params = MergeMapParams {
            gate: 1.5,
            ..MergeMapParams::default()
        };
        // the merged line kept one side: every vertex lies within the 3 m tolerance ...
        let d = distances(&u, &Outline::of(&side, false), params.tolerance);
        assert!(d.iter().all(Option::is_some));
        // ... but 30 m of the U lie farther than the gate from it
        assert!(lost_length(&u, &d, params.gate) > 29.0);
        assert!(!faithful(&side, &u, &side, &params));
        assert!(faithful(&u, &u, &side, &params));
        // a hook of 2 m smoothed away is a faithful merge
        let hooked: Vec<Point> = [
            line(0.0, 30.0, 0.0),
            vec![p(30.5, 1.0), p(31.0, 2.0), p(31.0, 2.8)],
        ]
        .concat();
        let d = distances(&hooked, &Outline::of(&side, false), params.tolerance);
        let lost = lost_length(&hooked, &d, params.gate);
        assert!((lost - (1.25f64.sqrt() + 0.8)).abs() < 1e-9, "{lost}");
        assert!(faithful(&side, &hooked, &side, &params));
        // with no slack left for it, the gate decides: a merge 1 m off everywhere
        let off = line(0.0, 30.0, 1.0);
        assert!(faithful(&off, &side, &off, &params));
        let narrow = MergeMapParams {
            gate: 0.5,
            ..params
        };
        assert!(!faithful(&off, &side, &off, &narrow));
    }
}

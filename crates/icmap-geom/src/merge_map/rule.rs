//! The class rule of a whole-instance merge (a polyline merge kept only when faithful) and the
//! merge of one group of overlapping instances into one instance (step 3 of the module doc).

use super::graph::{Group, Node};
use super::outline::Outline;
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
    tolerance: f64,
) -> GroupOutcome {
    let start = members.instance(g.order[0]);
    let mut merged = start.clone();
    let mut drives = members.drives(g.order[0]).to_vec();
    let mut ok = vec![g.order[0]];
    for &n in &g.order[1..] {
        let inst = members.instance(n);
        if let Ok(points) = merge_geometry(
            merged.closed,
            &merged.points,
            &inst.points,
            config,
            tolerance,
        ) {
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

/// Whether every vertex of `pts` lies within `tol` of `outline`.
fn within(pts: &[Point], outline: &Outline<'_>, tol: f64) -> bool {
    pts.iter()
        .all(|p| outline.distance_within(p, tol).is_some())
}

/// Whether `merged` is a faithful merge of the polylines `a` and `b`: every vertex of `a` and
/// `b` within `tol` of it, every vertex of it within `tol` of `a` or `b`.
fn faithful(merged: &[Point], a: &[Point], b: &[Point], tol: f64) -> bool {
    let (om, oa, ob) = (
        Outline::of(merged, false),
        Outline::of(a, false),
        Outline::of(b, false),
    );
    within(a, &om, tol)
        && within(b, &om, tol)
        && merged
            .iter()
            .all(|p| oa.distance_within(p, tol).is_some() || ob.distance_within(p, tol).is_some())
}

/// The class rule of a whole-instance merge: `detected` merged into `current`. Polylines: the
/// curve-fit merge of `detected` into `current`, else of `current` into `detected` (the splice
/// keeps the base's parts outside the other's projection, so the roles matter when the two only
/// partly overlap), the first that is [`faithful`] within `tolerance`; neither is an error
/// (the member is left out of the group).
pub(crate) fn merge_geometry(
    closed: bool,
    current: &[Point],
    detected: &[Point],
    config: &MapConfig,
    tolerance: f64,
) -> Result<Vec<Point>> {
    if closed {
        let merged = merge_polygon(current, detected, config.spacing)?;
        validate_points(&merged, 3, "merged geometry")?;
        return Ok(merged);
    }
    for (base, other) in [(current, detected), (detected, current)] {
        let merged = merge_polyline(base, other, config.smoothing, config.spacing)?;
        validate_points(&merged, 2, "merged geometry")?;
        if faithful(&merged, current, detected, tolerance) {
            return Ok(merged);
        }
    }
    Err(GeomError::Degenerate {
        what: "polyline merge".into(),
        reason: format!("no merge keeps both polylines within {tolerance} m"),
    })
}

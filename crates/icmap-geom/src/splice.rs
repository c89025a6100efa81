//! Splicing a new observation into a stored polyline by projection: the stretch of the stored
//! polyline that the new one covers is replaced by it, the rest is kept on either side.
//!
//! The rule of IC-Mapper's fused polylines (a fused detection already combines the current view
//! with the instance's history, so it replaces what it covers instead of being averaged into it
//! again) and of the VMA- and PolyMerge-style baselines. It was numpy code in the Python package
//! (`icmapper.mapping.splice`); this is the same algorithm, step for step:
//!
//! 1. `new` is oriented like `stored` ([`orient_like`]);
//! 2. stored points within `overlap` metres of `new` are dropped (they are covered);
//! 3. the result is the stored points before the projection of `new`'s start onto `stored`, then
//!    `new`, then the stored points after the projection of its end (arc lengths along `stored`).
//!
//! With the store's rule for kerbs ([`splice_line`], [`Fold::loops`]) a new observation that
//! spans a seam of the stored line (its end come back to its start, a kerb around a block) is
//! spliced piece by piece ([`seam_runs`]); [`splice_polyline`], the VMA and PolyMerge rule, keeps
//! the plain algorithm.
//!
//! A line does not fold onto itself ([`splice_line`], the store's rule for lane lines and kerbs):
//! there the kept stored points on either side end where the stored line comes back beside `new`
//! ([`Unfold`]), by the class's [`Fold`] ([`crate::types::MapClass::fold`]).

use crate::error::Result;
use crate::resample::polyline_length;
use crate::types::{check_non_negative, validate_points, Point};

/// The nearest point of the open polyline `poly` (at least one point) to `p`: its distance and
/// its arc length (metres from `poly[0]`). Among segments at the same (smallest) distance the
/// first is taken. A one-point polyline is that point (arc length 0).
pub fn project_onto_polyline(p: &Point, poly: &[Point]) -> (f64, f64) {
    if poly.len() == 1 {
        return ((p - poly[0]).norm(), 0.0);
    }
    let (mut best_d, mut best_s) = (f64::INFINITY, 0.0);
    let mut s0 = 0.0;
    for w in poly.windows(2) {
        let (a, ab) = (w[0], w[1] - w[0]);
        let seg_len = ab.norm();
        let denom = (seg_len * seg_len).max(1e-18);
        let t = ((p - a).dot(&ab) / denom).clamp(0.0, 1.0);
        let d = (p - (a + ab * t)).norm();
        if d < best_d {
            best_d = d;
            best_s = s0 + t * seg_len;
        }
        s0 += seg_len;
    }
    (best_d, best_s)
}

/// Metres: consecutive points of a new observation whose projections onto the stored line lie
/// this much farther apart along it than the two points lie apart are on two stretches of it
/// that meet only across a seam: a kerb around a block whose end has come back to its start.
/// Spliced or merged whole, the observation replaced the stretch between its ends' projections,
/// the whole loop (sim:val:32, `sim-10082-27`: a kerb of 360 m cut to 38 m in one frame).
pub const SEAM_GAP: f64 = 10.0;

/// The pieces of `new` between its seams on `stored` ([`SEAM_GAP`]), each of at least 2 points
/// (a lone point between two seams is dropped); `None` when it has no seam.
pub fn seam_runs(stored: &[Point], new: &[Point]) -> Option<Vec<Vec<Point>>> {
    let s: Vec<f64> = new
        .iter()
        .map(|p| project_onto_polyline(p, stored).1)
        .collect();
    let cuts: Vec<usize> = (1..new.len())
        .filter(|&i| (s[i] - s[i - 1]).abs() > (new[i] - new[i - 1]).norm() + SEAM_GAP)
        .collect();
    if cuts.is_empty() {
        return None;
    }
    let bounds: Vec<usize> = std::iter::once(0)
        .chain(cuts)
        .chain(std::iter::once(new.len()))
        .collect();
    Some(
        bounds
            .windows(2)
            .filter(|w| w[1] - w[0] >= 2)
            .map(|w| new[w[0]..w[1]].to_vec())
            .collect(),
    )
}

/// `new` in the direction of `stored`: reversed when its end projects before its start along
/// `stored`. When both ends project to the same place (`new` lies beyond one end of `stored`),
/// the end of `new` nearer to the end of `stored` it continues comes first (after the end) or
/// last (before the start).
pub fn orient_like(stored: &[Point], new: &[Point]) -> Vec<Point> {
    let s: Vec<f64> = new
        .iter()
        .map(|p| project_onto_polyline(p, stored).1)
        .collect();
    let total = polyline_length(stored, false);
    let tol = 1e-6 * total.max(1.0);
    let (first, last) = (s[0], s[s.len() - 1]);
    let forward = if last - first > tol {
        true
    } else if first - last > tol {
        false
    } else if s.iter().sum::<f64>() / s.len() as f64 >= total / 2.0 {
        let end = stored[stored.len() - 1];
        (new[0] - end).norm() <= (new[new.len() - 1] - end).norm()
    } else {
        let start = stored[0];
        (new[new.len() - 1] - start).norm() <= (new[0] - start).norm()
    };
    if forward {
        new.to_vec()
    } else {
        new.iter().rev().copied().collect()
    }
}

/// Metres: a stored point of a lane line this near the interior of a new observation lies on the
/// stretch the observation replaced. Neighbouring lane lines lie further apart.
pub const LANE_FOLD: f64 = 1.5;

/// Metres: the same for a kerb. A kerb may turn around a median island (1.5-4 m wide in the
/// synthetic cities), whose other side lies further than this; a kerb folded onto itself by the
/// merges (validation drives: a quarter to two fifths of IC-Mapper's map kerbs) lies nearer.
pub const KERB_FOLD: f64 = 1.0;

/// How a class's lines are kept from folding onto themselves ([`Unfold`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Fold {
    /// Metres: a stored point this near the interior of a new observation lies on the stretch
    /// the observation replaced ([`LANE_FOLD`], [`KERB_FOLD`]).
    pub gap: f64,
    /// Metres of what a cut drops that may lie off the line ([`Unfold::trim`]; infinite: the cut
    /// is unbounded). Kerbs ([`KERB_SLACK`]): a view rounding a corner can meet a long kerb twice,
    /// and the unbounded cut dropped 120 m of it (sim:test:4, docs/mapping.md). Lane lines keep
    /// the unbounded cut of the sixteenth round: bounded, more of their folds stayed (validation
    /// drives: divider GAP 77.1 -> 75.0).
    pub slack: f64,
    /// Whether the line may close around a block (kerbs): a view across the seam where its end
    /// has come back to its start is merged piece by piece ([`seam_runs`]). Lane lines do not
    /// loop; cut there too, their views lost on the synthetic test drives (sim:test:12 CD_div
    /// 0.979 -> 1.012 m, docs/mapping.md).
    pub loops: bool,
}

impl Fold {
    /// Errors on a gap that is not finite and >= 0 or a slack that is not >= 0 (infinite allowed).
    pub fn check(&self) -> Result<()> {
        check_non_negative("gap", self.gap)?;
        if self.slack.is_nan() || self.slack < 0.0 {
            return Err(crate::error::GeomError::InvalidParameter {
                name: "slack",
                reason: format!("must be >= 0, got {}", self.slack),
            });
        }
        Ok(())
    }
}

/// Metres of a kerb's cut that may lie off the line: a kerb the detector drew a few metres past
/// a corner, and a view that turns the corner, left that overshoot joined behind the view's end,
/// a fold that every later view along the new side drew longer (sim:val:12: 143 m on
/// `sim-10016-7`; docs/mapping.md); a kerb that goes on elsewhere is longer.
pub const KERB_SLACK: f64 = 8.0;

/// Metres: a stored point beside an observation nearer than this to one of its ends is not
/// beside its interior (there the two lines part).
pub const END_MARGIN: f64 = 1.5;

/// Where a stored line turns back along a new observation `q` (oriented like it). A stored line
/// whose end hooks off (a skeleton's end bending toward a neighbour) and a view that runs on past
/// that end: the view's end projects onto the hook, so the hook's tip counts as lying after the
/// view and, kept, it was joined behind the view's end, a line that turns back on itself; each
/// later view that reached past it drew the fold longer (validation drives: 17 % of IC-Mapper's
/// map dividers lay on themselves, `eval.fragmentation`'s `folded`; docs/mapping.md). A stored
/// point comes back when it lies within the fold gap of the observation's interior
/// ([`Unfold::beside`]). Only an observation that runs along the line is a reason to cut it
/// ([`Unfold::along`]); a view across it (a stub) cuts nothing.
pub struct Unfold<'a> {
    q: &'a [Point],
    len: f64,
    fold: Fold,
}

impl<'a> Unfold<'a> {
    /// The rule for the new observation `q` (open, at least 2 points, oriented like the stored
    /// line) and the class's `fold`.
    pub fn new(q: &'a [Point], fold: Fold) -> Self {
        Unfold {
            q,
            len: polyline_length(q, false),
            fold,
        }
    }

    /// Whether an observation whose ends project `span` metres apart along the stored line runs
    /// along it: at least half its length.
    pub fn along(&self, span: f64) -> bool {
        span >= 0.5 * self.len
    }

    /// Whether `p` lies within the fold gap of the observation's interior: its nearest point on
    /// the observation more than [`END_MARGIN`] from either end (a point just past an end, where
    /// the two lines part, is not beside it).
    pub fn beside(&self, p: &Point) -> bool {
        let (d, t) = project_onto_polyline(p, self.q);
        d <= self.fold.gap && t > END_MARGIN && t < self.len - END_MARGIN
    }

    /// Of the stored line `points` (arc lengths `arc` along it), which are kept when it ends
    /// where it first comes back beside the observation: after `s_end`, every point from the
    /// first one beside it on is dropped; before `s_start`, every point up to the last one. All
    /// are kept when the observation does not run along the line. A side is cut only when at most
    /// the fold's slack of what its cut drops lies off the line (farther than twice the gap from
    /// the observation and from the stored points kept before it): a fold, or a fold and a short
    /// overshoot. Where the stored line goes on elsewhere after meeting the view (a kerb that a
    /// view rounding a corner meets twice), that side is kept whole.
    pub fn trim(&self, points: &[Point], arc: &[f64], s_start: f64, s_end: f64) -> Vec<bool> {
        let n = points.len();
        if !self.along(s_end - s_start) || n == 0 {
            return vec![true; n];
        }
        let beside: Vec<bool> = points.iter().map(|p| self.beside(p)).collect();
        // whether stored point i lies back on the line: near the view or the stored `part`
        let on_line = |i: usize, part: &[Point]| {
            let near = 2.0 * self.fold.gap;
            project_onto_polyline(&points[i], self.q).0 <= near
                || (!part.is_empty() && project_onto_polyline(&points[i], part).0 <= near)
        };
        // whether the cut of the points `cut` (a run) drops at most the slack off the line: the
        // length of its segments with an end off it
        let within_slack = |cut: std::ops::Range<usize>, part: &[Point]| {
            if self.fold.slack == f64::INFINITY {
                return true;
            }
            let off: Vec<bool> = cut.clone().map(|i| !on_line(i, part)).collect();
            let dropped: f64 = (cut.start..cut.end.saturating_sub(1))
                .filter(|&i| off[i - cut.start] || off[i + 1 - cut.start])
                .map(|i| (points[i + 1] - points[i]).norm())
                .sum();
            !off.iter().any(|&o| o) || dropped <= self.fold.slack
        };
        let first_after = (0..n)
            .find(|&i| arc[i] > s_end && beside[i])
            .filter(|&f| within_slack(f..n, &points[..f]));
        let last_before = (0..n)
            .rev()
            .find(|&i| arc[i] <= s_start && beside[i])
            .filter(|&l| within_slack(0..l + 1, &points[l + 1..]));
        (0..n)
            .map(|i| !(first_after.is_some_and(|f| i >= f) || last_before.is_some_and(|l| i <= l)))
            .collect()
    }
}

/// Splices `new` into `stored` (both open polylines of at least 2 points): see the module
/// documentation. `overlap` is in metres (finite, >= 0). Errors on too few points, non-finite or
/// out-of-domain coordinates and a bad `overlap`.
pub fn splice_polyline(stored: &[Point], new: &[Point], overlap: f64) -> Result<Vec<Point>> {
    splice(stored, new, overlap, None)
}

/// [`splice_polyline`] for a line that does not fold onto itself: the stored line is cut where it
/// comes back beside `new` by the class's `fold` ([`Unfold`]).
pub fn splice_line(
    stored: &[Point],
    new: &[Point],
    overlap: f64,
    fold: Fold,
) -> Result<Vec<Point>> {
    fold.check()?;
    splice(stored, new, overlap, Some(fold))
}

fn splice(
    stored: &[Point],
    new: &[Point],
    overlap: f64,
    unfold: Option<Fold>,
) -> Result<Vec<Point>> {
    validate_points(stored, 2, "stored polyline")?;
    validate_points(new, 2, "new polyline")?;
    check_non_negative("overlap", overlap)?;
    if let Some(runs) = unfold
        .filter(|f| f.loops)
        .and_then(|_| seam_runs(stored, new))
    {
        // each piece on its own stretch, in order
        let mut out = stored.to_vec();
        for run in &runs {
            out = splice(&out, run, overlap, unfold)?;
        }
        return Ok(out);
    }
    let q = orient_like(stored, new);
    let (_, s_start) = project_onto_polyline(&q[0], stored);
    let (_, s_end) = project_onto_polyline(&q[q.len() - 1], stored);
    let mut arc = Vec::with_capacity(stored.len());
    let mut s_p = 0.0;
    for (i, p) in stored.iter().enumerate() {
        if i > 0 {
            s_p += (*p - stored[i - 1]).norm();
        }
        arc.push(s_p);
    }
    let kept = unfold.map(|fold| Unfold::new(&q, fold).trim(stored, &arc, s_start, s_end));
    let mut before = Vec::new();
    let mut after = Vec::new();
    for (i, p) in stored.iter().enumerate() {
        if kept.as_ref().is_some_and(|k| !k[i]) || project_onto_polyline(p, &q).0 <= overlap {
            continue; // covered by the new observation, or where the line turned back
        }
        if arc[i] <= s_start {
            before.push(*p);
        }
        if arc[i] > s_end {
            after.push(*p);
        }
    }
    let mut out = before;
    out.reserve(q.len() + after.len());
    out.extend_from_slice(&q);
    out.extend_from_slice(&after);
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    const LANE: Fold = Fold {
        gap: LANE_FOLD,
        slack: f64::INFINITY,
        loops: false,
    };
    const KERB: Fold = Fold {
        gap: KERB_FOLD,
        slack: KERB_SLACK,
        loops: true,
    };

    fn pts(v: &[(f64, f64)]) -> Vec<Point> {
        v.iter().map(|&(x, y)| Point::new(x, y)).collect()
    }

    #[test]
    fn projection_distance_and_arc_length() {
        let poly = pts(&[(0.0, 0.0), (10.0, 0.0), (10.0, 10.0)]);
        let (d, s) = project_onto_polyline(&Point::new(4.0, 3.0), &poly);
        assert!((d - 3.0).abs() < 1e-12 && (s - 4.0).abs() < 1e-12);
        let (d, s) = project_onto_polyline(&Point::new(12.0, 5.0), &poly);
        assert!((d - 2.0).abs() < 1e-12 && (s - 15.0).abs() < 1e-12);
        let (d, s) = project_onto_polyline(&Point::new(-3.0, -4.0), &poly);
        assert!((d - 5.0).abs() < 1e-12 && s == 0.0);
        // equidistant from both segments: the first one wins
        let (_, s) = project_onto_polyline(&Point::new(11.0, -1.0), &poly);
        assert!((s - 10.0).abs() < 1e-12);
        let one = pts(&[(1.0, 1.0)]);
        assert_eq!(
            project_onto_polyline(&Point::new(4.0, 5.0), &one),
            (5.0, 0.0)
        );
    }

    #[test]
    fn orientation_follows_the_stored_polyline() {
        let stored = pts(&[(0.0, 0.0), (10.0, 0.0)]);
        let along = pts(&[(2.0, 0.5), (6.0, 0.5)]);
        assert_eq!(orient_like(&stored, &along), along);
        let back: Vec<Point> = along.iter().rev().copied().collect();
        assert_eq!(orient_like(&stored, &back), along);
        // beyond the end, pointing away from it: kept; pointing back at it: reversed
        let beyond = pts(&[(12.0, 3.0), (12.0, 8.0)]);
        assert_eq!(orient_like(&stored, &beyond), beyond);
        let beyond_back: Vec<Point> = beyond.iter().rev().copied().collect();
        assert_eq!(orient_like(&stored, &beyond_back), beyond);
        // before the start: the end nearer to the start comes last
        let before = pts(&[(-2.0, 8.0), (-2.0, 3.0)]);
        assert_eq!(orient_like(&stored, &before), before);
    }

    #[test]
    fn splice_replaces_the_covered_stretch() {
        let stored: Vec<Point> = (0..=10).map(|i| Point::new(i as f64, 0.0)).collect();
        let new = pts(&[(7.5, 0.2), (5.5, 0.2), (3.5, 0.2)]); // reversed, covers x 3.5..7.5
        let out = splice_polyline(&stored, &new, 0.5).unwrap();
        let xs: Vec<f64> = out.iter().map(|p| p.x).collect();
        // x = 3 and 8 lie 0.54 m from the new polyline's ends: kept
        assert_eq!(xs, vec![0.0, 1.0, 2.0, 3.0, 3.5, 5.5, 7.5, 8.0, 9.0, 10.0]);
        assert!(out[4..7].iter().all(|p| p.y == 0.2));
        // an extension beyond the end is appended
        let ext = pts(&[(10.5, 0.0), (14.0, 0.0)]);
        let out = splice_polyline(&stored, &ext, 0.3).unwrap();
        assert_eq!(out.len(), 13);
        assert_eq!(out[out.len() - 1], Point::new(14.0, 0.0));
        // stored points within the overlap of an extension are replaced by it
        let out = splice_polyline(&stored, &ext, 0.6).unwrap();
        assert_eq!(out.len(), 12);
    }

    #[test]
    fn a_line_does_not_turn_back() {
        // the stored line ends in a 0.9 m hook; the new view runs on past it
        let stored = pts(&[(0.0, 0.0), (10.0, 0.0), (20.0, 0.0), (20.0, -0.9)]);
        let new = pts(&[(26.0, 0.1), (18.0, 0.1), (12.0, 0.1)]);
        let hooked = splice_polyline(&stored, &new, 0.5).unwrap();
        assert_eq!(hooked[hooked.len() - 1], Point::new(20.0, -0.9)); // joined behind the view
        let out = splice_line(&stored, &new, 0.5, LANE).unwrap();
        assert_eq!(
            out,
            pts(&[
                (0.0, 0.0),
                (10.0, 0.0),
                (12.0, 0.1),
                (18.0, 0.1),
                (26.0, 0.1)
            ])
        );
        // a line that already turned back: everything from where it comes back beside is dropped
        let folded = pts(&[
            (0.0, 0.0),
            (20.0, 0.0),
            (20.5, 0.5),
            (14.0, 0.8),
            (4.0, 0.8),
        ]);
        let out = splice_line(&folded, &pts(&[(12.0, 0.0), (24.0, 0.0)]), 0.3, LANE).unwrap();
        assert_eq!(out, pts(&[(0.0, 0.0), (12.0, 0.0), (24.0, 0.0)]));
        // at the start too; a stretch further than LANE_FOLD from the view is kept
        let rev: Vec<Point> = folded.iter().rev().copied().collect();
        let out = splice_line(&rev, &pts(&[(24.0, 0.0), (12.0, 0.0)]), 0.3, LANE).unwrap();
        assert_eq!(out, pts(&[(24.0, 0.0), (12.0, 0.0), (0.0, 0.0)]));
        // a view across the line (a stub) cuts nothing
        let line = pts(&[(0.0, 0.0), (10.0, 0.0), (20.0, 0.0)]);
        let stub = pts(&[(19.0, -3.0), (19.0, 3.0)]);
        assert_eq!(
            splice_line(&line, &stub, 0.5, LANE).unwrap(),
            splice_polyline(&line, &stub, 0.5).unwrap()
        );
        let u_turn = pts(&[(0.0, 0.0), (20.0, 0.0), (20.0, -3.0), (8.0, -3.0)]);
        let out = splice_line(&u_turn, &pts(&[(4.0, 0.1), (16.0, 0.1)]), 0.5, LANE).unwrap();
        assert_eq!(out[out.len() - 1], Point::new(8.0, -3.0));
    }

    #[test]
    fn a_kerb_folds_within_its_own_gap_only() {
        // a kerb around a median 1.4 m wide: its other side is kept with the kerb's gap
        let median = pts(&[
            (0.0, 0.0),
            (20.0, 0.0),
            (20.5, -0.7),
            (20.0, -1.4),
            (8.0, -1.4),
        ]);
        let view = pts(&[(4.0, 0.0), (16.0, 0.0)]);
        let far_side = |out: &[Point], y: f64| out.contains(&Point::new(8.0, y));
        assert!(far_side(
            &splice_line(&median, &view, 0.5, KERB).unwrap(),
            -1.4
        ));
        // the lane lines' gap would cut it
        assert!(!far_side(
            &splice_line(&median, &view, 0.5, LANE).unwrap(),
            -1.4
        ));
        // a kerb the merges folded 0.8 m onto itself is cut
        let folded = pts(&[
            (0.0, 0.0),
            (20.0, 0.0),
            (20.4, -0.4),
            (20.0, -0.8),
            (8.0, -0.8),
        ]);
        assert!(!far_side(
            &splice_line(&folded, &view, 0.5, KERB).unwrap(),
            -0.8
        ));
        assert!(splice_line(&folded, &view, 0.5, Fold { gap: -1.0, ..KERB }).is_err());
        // a line that meets the view again and then goes on far (more than a fold along the
        // view can hold) is kept whole on that side
        let onward = pts(&[
            (0.0, 0.0),
            (20.0, 0.0),
            (20.4, -0.4),
            (14.0, -0.8),
            (14.0, -60.0),
        ]);
        let out = splice_line(&onward, &view, 0.5, KERB).unwrap();
        assert_eq!(out[out.len() - 1], Point::new(14.0, -60.0));
        assert!(splice_line(
            &folded,
            &view,
            0.5,
            Fold {
                slack: f64::NAN,
                ..KERB
            }
        )
        .is_err());
    }

    #[test]
    fn a_view_across_the_seam_of_a_loop_is_spliced_piece_by_piece() {
        // a kerb around a 40 x 20 m block, drawn from (0, 2) round to (2, 0): its end has come
        // back to its start; a view around the corner (0, 0) spans the seam
        let ring = pts(&[
            (0.0, 2.0),
            (0.0, 20.0),
            (40.0, 20.0),
            (40.0, 0.0),
            (2.0, 0.0),
        ]);
        let view = pts(&[(6.0, 0.1), (3.0, 0.1), (0.1, 0.1), (0.1, 3.0), (0.1, 6.0)]);
        let runs = seam_runs(&ring, &view).unwrap();
        assert_eq!(runs.len(), 2);
        assert!(seam_runs(&ring, &pts(&[(0.1, 4.0), (0.1, 9.0)])).is_none());
        let out = splice_line(&ring, &view, 0.5, KERB).unwrap();
        let len = polyline_length(&out, false);
        assert!(len > 100.0, "the loop was cut to {len} m"); // 114 m of kerb stay
        assert!(out.iter().any(|p| (p.y - 20.0).abs() < 1e-9)); // the far side is kept
                                                                // the plain algorithm (VMA, PolyMerge) and a lane line's rule replace the stretch between
                                                                // the ends' projections
        let plain = splice_polyline(&ring, &view, 0.5).unwrap();
        assert!(polyline_length(&plain, false) < 20.0);
        let lane = splice_line(&ring, &view, 0.5, LANE).unwrap();
        assert!(polyline_length(&lane, false) < 20.0);
    }

    #[test]
    fn a_kerb_drawn_past_a_corner_is_cut_where_a_view_turns_it() {
        // the kerb was drawn 6 m past the corner at x = 20; the view turns the corner north
        let stored = pts(&[
            (0.0, 0.0),
            (10.0, 0.0),
            (20.0, 0.0),
            (20.8, 0.0),
            (23.0, 0.0),
            (26.0, 0.0),
        ]);
        let view = pts(&[
            (4.0, 0.1),
            (12.0, 0.1),
            (20.2, 0.2),
            (20.4, 5.0),
            (20.4, 15.0),
        ]);
        let out = splice_line(&stored, &view, 0.5, KERB).unwrap();
        assert_eq!(out[out.len() - 1], Point::new(20.4, 15.0)); // ends where the view does
        assert!(out.iter().all(|p| p.x <= 20.4));
        // with no slack the overshoot stays, joined behind the view's end: a fold
        let strict = Fold { slack: 0.0, ..KERB };
        let out = splice_line(&stored, &view, 0.5, strict).unwrap();
        assert_eq!(out[out.len() - 1], Point::new(26.0, 0.0));
    }

    #[test]
    fn splice_rejects_bad_input() {
        let stored = pts(&[(0.0, 0.0), (10.0, 0.0)]);
        let new = pts(&[(1.0, 0.0), (2.0, 0.0)]);
        assert!(splice_polyline(&stored[..1], &new, 0.5).is_err());
        assert!(splice_polyline(&stored, &new[..1], 0.5).is_err());
        assert!(splice_polyline(&stored, &pts(&[(f64::NAN, 0.0), (1.0, 1.0)]), 0.5).is_err());
        assert!(splice_polyline(&stored, &pts(&[(1e9, 0.0), (1.0, 1.0)]), 0.5).is_err());
        assert!(splice_polyline(&stored, &new, -1.0).is_err());
        assert!(splice_polyline(&stored, &new, f64::NAN).is_err());
    }
}

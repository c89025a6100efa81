//! Lines the ridge finds along the front and back edges of the grid.
//!
//! The ridge's Gaussian reads zeros past the grid (scipy's `mode="constant"`), so wherever a
//! divider's probabilities are high at the front or back edge (lane lines entering or leaving the
//! range) the smoothed probabilities fall off across the edge and the Hessian reports a ridge
//! along it: a line across the lanes, one per frame, moving with the car (on the 12 validation
//! drives 39 of 42 detected dividers lying along those edges were on no true line). Lines along
//! the side edges are left: lane lines run there (docs/mapping.md, "Clean maps").

/// Share of a line's points that must lie within the margin of the front or back edge.
pub const EDGE_SHARE: f64 = 0.8;

/// Whether a line of ego points (`x` along the driving direction) lies along the front or back
/// edge of a grid `[-half_x, half_x]`: more than [`EDGE_SHARE`] of its points within `margin`
/// metres of the edge (|x| > half_x - margin) and spanning more than `span` metres across it (in
/// y). `margin <= 0` never holds. Computed in float64, as the reference.
pub fn along_front_or_back_edge(points: &[[f32; 2]], half_x: f64, margin: f64, span: f64) -> bool {
    if margin <= 0.0 || points.is_empty() {
        return false;
    }
    let limit = half_x - margin;
    let near = points
        .iter()
        .filter(|p| (p[0] as f64).abs() > limit)
        .count();
    if near as f64 / points.len() as f64 <= EDGE_SHARE {
        return false;
    }
    let (lo, hi) = points
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), p| {
            (lo.min(p[1] as f64), hi.max(p[1] as f64))
        });
    hi - lo > span
}

#[cfg(test)]
mod tests {
    use super::*;

    fn line(x0: f32, y0: f32, x1: f32, y1: f32) -> Vec<[f32; 2]> {
        (0..20)
            .map(|i| {
                let t = i as f32 / 19.0;
                [x0 + t * (x1 - x0), y0 + t * (y1 - y0)]
            })
            .collect()
    }

    #[test]
    fn a_line_across_the_front_edge_is_found() {
        assert!(along_front_or_back_edge(
            &line(29.2, 1.0, 29.4, 9.0),
            30.0,
            1.5,
            3.0
        ));
        assert!(along_front_or_back_edge(
            &line(-29.0, -6.0, -29.5, 2.0),
            30.0,
            1.5,
            3.0
        ));
    }

    #[test]
    fn lane_lines_entering_the_range_and_side_edges_are_kept() {
        // a short piece of a lane line entering the range: along x, not across
        assert!(!along_front_or_back_edge(
            &line(28.6, 3.0, 30.0, 3.2),
            30.0,
            1.5,
            3.0
        ));
        // a lane line along the side edge
        assert!(!along_front_or_back_edge(
            &line(-20.0, 14.5, 20.0, 14.6),
            30.0,
            1.5,
            3.0
        ));
        // a line crossing the whole range
        assert!(!along_front_or_back_edge(
            &line(-25.0, 2.0, 29.0, 2.0),
            30.0,
            1.5,
            3.0
        ));
        // the rule off
        assert!(!along_front_or_back_edge(
            &line(29.2, 1.0, 29.4, 9.0),
            30.0,
            0.0,
            3.0
        ));
        assert!(!along_front_or_back_edge(&[], 30.0, 1.5, 3.0));
    }
}

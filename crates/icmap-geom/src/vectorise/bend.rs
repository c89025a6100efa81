//! Lane lines cut where they bend sharply.
//!
//! A painted lane line curves gently: turning 45 degrees within 1.5 m on either side of a point
//! needs a radius under 4 m. Where a vectorised lane line turns that sharply, its skeleton ran
//! from one line into another or across the lanes (a ridge that smears across the lanes near the
//! range edge, joined to the line it leaves; docs/mapping.md, "Lane lines bend gently"). Merged
//! into the map such a view leaves a stub across the lanes inside the instance. The line is cut
//! there: each side is a line of its own (shorter than the minimum length: dropped), scored by
//! its own cells.

use crate::resample::cumulative_lengths;
use crate::types::Point;

/// Metres of the line on either side of a vertex over which its turn is measured.
pub const BEND_ARC: f64 = 1.5;

/// The point at arc length `t` along `line` (cumulative lengths `cum`), clamped to its ends.
fn at(line: &[Point], cum: &[f64], t: f64) -> Point {
    let last = cum.len() - 1;
    if t <= 0.0 {
        return line[0];
    }
    if t >= cum[last] {
        return line[last];
    }
    // the segment [cum[j], cum[j + 1]] holding t (the first such, as numpy's interp)
    let j = cum
        .partition_point(|&c| c <= t)
        .saturating_sub(1)
        .min(last - 1);
    let len = cum[j + 1] - cum[j];
    if len <= 0.0 {
        return line[j];
    }
    let u = (t - cum[j]) / len;
    Point::new(
        line[j].x + u * (line[j + 1].x - line[j].x),
        line[j].y + u * (line[j + 1].y - line[j].y),
    )
}

/// Degrees the line turns at interior vertex `i`: the angle between the chord from the point
/// [`BEND_ARC`] metres before it to the vertex and the chord from the vertex to the point
/// [`BEND_ARC`] metres after it (clamped at the line's ends); 0 where a chord has no length.
fn turn_at(line: &[Point], cum: &[f64], i: usize) -> f64 {
    let v = line[i];
    let a = v - at(line, cum, cum[i] - BEND_ARC);
    let b = at(line, cum, cum[i] + BEND_ARC) - v;
    let (na, nb) = (a.norm(), b.norm());
    if na <= 0.0 || nb <= 0.0 {
        return 0.0;
    }
    (a.dot(&b) / (na * nb)).clamp(-1.0, 1.0).acos().to_degrees()
}

/// The pieces of a polyline cut at every vertex where it turns by more than `bend` degrees
/// (`bend <= 0`: never), as spans `(first, last)` of vertex indices (inclusive; pieces share
/// their cut vertex, in order along the line): the sharpest such vertex first (the first of
/// equals), then each side again. A piece shorter than `min_length` metres is left out (a line
/// with no such vertex comes back whole, whatever its length).
pub fn cut_at_bends(line: &[Point], bend: f64, min_length: f64) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    if !line.is_empty() {
        cut_into(line, 0, bend, min_length, &mut out);
    }
    out
}

fn cut_into(
    line: &[Point],
    offset: usize,
    bend: f64,
    min_length: f64,
    out: &mut Vec<(usize, usize)>,
) {
    let cum = cumulative_lengths(line);
    let mut best: Option<(usize, f64)> = None;
    if bend > 0.0 {
        for i in 1..line.len().saturating_sub(1) {
            let turn = turn_at(line, &cum, i);
            if turn > bend && best.is_none_or(|(_, t)| turn > t) {
                best = Some((i, turn));
            }
        }
    }
    let Some((i, _)) = best else {
        out.push((offset, offset + line.len() - 1));
        return;
    };
    if cum[i] >= min_length {
        cut_into(&line[..=i], offset, bend, min_length, out);
    }
    if cum[cum.len() - 1] - cum[i] >= min_length {
        cut_into(&line[i..], offset + i, bend, min_length, out);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pts(xy: &[(f64, f64)]) -> Vec<Point> {
        xy.iter().map(|&(x, y)| Point::new(x, y)).collect()
    }

    #[test]
    fn an_l_is_cut_at_its_corner() {
        let l = pts(&[(0.0, 0.0), (10.0, 0.0), (10.0, 6.0)]);
        assert_eq!(cut_at_bends(&l, 45.0, 2.0), vec![(0, 1), (1, 2)]);
    }

    #[test]
    fn a_short_hook_is_dropped_and_gentle_curves_kept() {
        let hook = pts(&[(0.0, 0.0), (20.0, 0.0), (20.0, 1.0)]);
        assert_eq!(cut_at_bends(&hook, 45.0, 2.0), vec![(0, 1)]);
        // a 20 m radius arc in 1 m chords turns ~8.6 degrees over 3 m
        let arc: Vec<Point> = (0..=30)
            .map(|k| {
                let t = k as f64 / 20.0;
                Point::new(20.0 * t.sin(), 20.0 * (1.0 - t.cos()))
            })
            .collect();
        assert_eq!(cut_at_bends(&arc, 45.0, 2.0), vec![(0, 30)]);
        // off
        assert_eq!(cut_at_bends(&hook, 0.0, 2.0), vec![(0, 2)]);
        // a line with no bend comes back whole, however short
        let short = pts(&[(0.0, 0.0), (1.0, 0.0)]);
        assert_eq!(cut_at_bends(&short, 45.0, 2.0), vec![(0, 1)]);
        assert!(cut_at_bends(&[], 45.0, 2.0).is_empty());
    }

    #[test]
    fn a_zigzag_is_cut_at_every_sharp_vertex() {
        let z = pts(&[(0.0, 0.0), (10.0, 0.0), (4.0, 5.0), (14.0, 5.0)]);
        assert_eq!(cut_at_bends(&z, 45.0, 2.0), vec![(0, 1), (1, 2), (2, 3)]);
        // degenerate input: repeated points do not panic
        let same = pts(&[(1.0, 1.0), (1.0, 1.0), (1.0, 1.0)]);
        assert!(cut_at_bends(&same, 45.0, 0.0).len() == 1);
    }
}

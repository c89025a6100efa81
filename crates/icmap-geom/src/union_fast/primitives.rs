//! Geometry primitives of the fast union: a plain 2-D vector in the local frame, bounding boxes,
//! signed area and the exact "closer than tol" test of a point and a segment (ray casting:
//! `crate::clip::inside_ring`).

use crate::clip::Xy;
use crate::types::Point;

#[derive(Clone, Copy, Debug)]
pub(super) struct V {
    pub(super) x: f64,
    pub(super) y: f64,
}

impl V {
    #[inline]
    pub(super) fn sub(self, o: V) -> V {
        V {
            x: self.x - o.x,
            y: self.y - o.y,
        }
    }
    #[inline]
    pub(super) fn dot(self, o: V) -> f64 {
        self.x * o.x + self.y * o.y
    }
    #[inline]
    pub(super) fn cross(self, o: V) -> f64 {
        self.x * o.y - self.y * o.x
    }
}

/// The larger side of the points' bounding box and whether it is the x side; `None` when it is
/// not finite and positive.
pub(super) fn extent_of<'a>(points: impl Iterator<Item = &'a V>) -> Option<(f64, bool)> {
    let (mut x0, mut x1, mut y0, mut y1) = (
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
    );
    for p in points {
        x0 = x0.min(p.x);
        x1 = x1.max(p.x);
        y0 = y0.min(p.y);
        y1 = y1.max(p.y);
    }
    let extent = (x1 - x0).max(y1 - y0);
    (extent.is_finite() && extent > 0.0).then_some((extent, x1 - x0 >= y1 - y0))
}

/// An axis-aligned bounding box.
#[derive(Clone, Copy)]
pub(super) struct BBox {
    pub(super) x0: f64,
    pub(super) x1: f64,
    pub(super) y0: f64,
    pub(super) y1: f64,
}

impl BBox {
    pub(super) fn join(&self, o: &BBox) -> BBox {
        BBox {
            x0: self.x0.min(o.x0),
            x1: self.x1.max(o.x1),
            y0: self.y0.min(o.y0),
            y1: self.y1.max(o.y1),
        }
    }

    /// The larger side and whether it is the x side; `None` when it is not finite and positive.
    pub(super) fn extent(&self) -> Option<(f64, bool)> {
        let (w, h) = (self.x1 - self.x0, self.y1 - self.y0);
        let extent = w.max(h);
        (extent.is_finite() && extent > 0.0).then_some((extent, w >= h))
    }
}

/// Writes `ring` in the frame centred at `origin` into `out`; returns its bounding box there and
/// twice its signed area (as [`area2`] computes it). Comparisons ignore NaN in the box; a NaN
/// coordinate still makes the area NaN.
pub(super) fn load_ring(ring: &[Point], origin: Point, out: &mut Vec<V>) -> (BBox, f64) {
    let to_local = |p: &Point| V {
        x: p.x - origin.x,
        y: p.y - origin.y,
    };
    out.clear();
    let mut bb = BBox {
        x0: f64::INFINITY,
        x1: f64::NEG_INFINITY,
        y0: f64::INFINITY,
        y1: f64::NEG_INFINITY,
    };
    let Some(last) = ring.last() else {
        return (bb, 0.0);
    };
    let mut prev = to_local(last);
    let mut s = 0.0;
    for p in ring {
        let v = to_local(p);
        s += prev.cross(v);
        prev = v;
        bb.x0 = if v.x < bb.x0 { v.x } else { bb.x0 };
        bb.x1 = if v.x > bb.x1 { v.x } else { bb.x1 };
        bb.y0 = if v.y < bb.y0 { v.y } else { bb.y0 };
        bb.y1 = if v.y > bb.y1 { v.y } else { bb.y1 };
        out.push(v);
    }
    (bb, s)
}

/// Twice the signed area of a ring.
pub(super) fn area2(r: &[V]) -> f64 {
    let Some(&last) = r.last() else {
        return 0.0;
    };
    let mut s = 0.0;
    let mut prev = last;
    for &p in r {
        s += prev.cross(p);
        prev = p;
    }
    s
}

/// Whether `p` is closer than `sqrt(tol2)` to the segment `a`-`b` (`a != b`).
#[inline]
pub(super) fn near(p: V, a: V, b: V, tol2: f64) -> bool {
    let ab = b.sub(a);
    let ap = p.sub(a);
    let t = (ap.dot(ab) / ab.dot(ab)).clamp(0.0, 1.0);
    let d = V {
        x: ap.x - ab.x * t,
        y: ap.y - ab.y * t,
    };
    d.dot(d) < tol2
}

impl Xy for V {
    #[inline]
    fn xy(self) -> (f64, f64) {
        (self.x, self.y)
    }
}

#[cfg(test)]
mod tests {
    use super::super::test_util::{seg_dist, star, Rng};
    use super::*;
    use crate::clip::inside_ring;

    fn v(x: f64, y: f64) -> V {
        V { x, y }
    }

    #[test]
    fn near_is_the_segment_distance_test() {
        let mut rng = Rng(3);
        for _ in 0..2000 {
            let [p, a, b] = [0; 3].map(|_| v(rng.uniform(-2.0, 2.0), rng.uniform(-2.0, 2.0)));
            let tol = rng.uniform(0.0, 1.5);
            let d = seg_dist(
                Point::new(p.x, p.y),
                Point::new(a.x, a.y),
                Point::new(b.x, b.y),
            );
            if (d - tol).abs() > 1e-12 {
                assert_eq!(near(p, a, b, tol * tol), d < tol);
            }
        }
    }

    #[test]
    fn load_ring_area_and_box_and_inside() {
        let mut rng = Rng(9);
        for _ in 0..50 {
            let ring = star(&mut rng, 3.0, -2.0, 12, 4.0);
            let origin = Point::new(1.0, 1.0);
            let mut local = Vec::new();
            let (bb, a2) = load_ring(&ring, origin, &mut local);
            assert_eq!(local.len(), ring.len());
            assert!((a2 - area2(&local)).abs() < 1e-12 * a2.abs());
            assert!(a2 > 0.0, "stars are counter-clockwise");
            let xs = ring.iter().map(|p| p.x - origin.x);
            assert_eq!(bb.x0, xs.clone().fold(f64::INFINITY, f64::min));
            assert_eq!(bb.x1, xs.fold(f64::NEG_INFINITY, f64::max));
            // The star's centre is inside, a point beyond its outer radius is not.
            assert!(inside_ring(v(2.0, -3.0), &local));
            assert!(!inside_ring(v(2.0 + 4.5, -3.0), &local));
        }
        let (_, a2) = load_ring(&[], Point::new(0.0, 0.0), &mut Vec::new());
        assert_eq!(a2, 0.0);
        assert_eq!(extent_of([v(0.0, 0.0), v(0.0, 0.0)].iter()), None);
        assert_eq!(
            extent_of([v(0.0, 0.0), v(1.0, 3.0)].iter()),
            Some((3.0, false))
        );
    }
}

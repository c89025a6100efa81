//! The crossings in order along each ring (step 3 of the module doc, first half).

use super::crossings::Cross;
use super::primitives::V;

/// Fills `order[ring]` with the crossing ids in order along `ring` (by edge, then by parameter
/// along the edge) and `rank[ring][id]` with each crossing's place in that order. `None`
/// (decline) when two crossings on one edge are closer than `sqrt(tol2)` or exits and entries
/// do not alternate along a ring.
pub(super) fn order_along_rings(
    rings: &[&[V]; 2],
    crosses: &[Cross],
    tol2: f64,
    order: &mut [Vec<u32>; 2],
    rank: &mut [Vec<u32>; 2],
    keys: &mut Vec<u128>,
) -> Option<()> {
    // The crossings in order along each ring (by edge, then by parameter along the edge); two
    // crossings on one edge must be at least tol apart, and exits and entries must alternate.
    let nc = crosses.len();
    for ring in 0..2 {
        let (ord, rk) = (&mut order[ring], &mut rank[ring]);
        let key = |c: &Cross| {
            if ring == 0 {
                (c.ea, c.ta)
            } else {
                (c.eb, c.tb)
            }
        };
        // Sort keys `(edge, t, id)` packed in one integer: `t` lies in (0, 1), where the bits of
        // a positive f64 sort as the number does.
        keys.clear();
        keys.extend(crosses.iter().enumerate().map(|(id, c)| {
            let (e, t) = key(c);
            (u128::from(e) << 96) | (u128::from(t.to_bits()) << 32) | id as u128
        }));
        keys.sort_unstable();
        ord.clear();
        ord.extend(keys.iter().map(|&k| k as u32));
        rk.clear();
        rk.resize(nc, 0);
        let r = rings[ring];
        for (k, w) in ord.windows(2).enumerate() {
            let (c0, c1) = (&crosses[w[0] as usize], &crosses[w[1] as usize]);
            let ((e0, t0), (e1, t1)) = (key(c0), key(c1));
            if e0 == e1 {
                let iu = e0 as usize;
                let q = if iu + 1 == r.len() { r[0] } else { r[iu + 1] };
                let d = q.sub(r[iu]);
                if (t1 - t0) * (t1 - t0) * d.dot(d) < tol2 {
                    return None;
                }
            }
            if c0.a_exits == c1.a_exits {
                return None;
            }
            rk[w[1] as usize] = k as u32 + 1;
        }
    }
    Some(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cross(ea: u32, ta: f64, eb: u32, tb: f64, a_exits: bool) -> Cross {
        let p = V { x: 0.0, y: 0.0 };
        Cross {
            ea,
            ta,
            eb,
            tb,
            p,
            pw: crate::types::Point::new(0.0, 0.0),
            a_exits,
        }
    }

    fn square() -> Vec<V> {
        [(0.0, 0.0), (4.0, 0.0), (4.0, 4.0), (0.0, 4.0)]
            .iter()
            .map(|&(x, y)| V { x, y })
            .collect()
    }

    #[test]
    fn crossings_are_ordered_by_edge_then_parameter() {
        let (ra, rb) = (square(), square());
        let crosses = [
            cross(2, 0.5, 0, 0.3, true),
            cross(0, 0.7, 3, 0.1, false),
            cross(0, 0.2, 1, 0.9, true),
            cross(3, 0.1, 0, 0.8, false),
        ];
        let (mut order, mut rank, mut keys) = (Default::default(), Default::default(), Vec::new());
        order_along_rings(
            &[&ra, &rb],
            &crosses,
            1e-12,
            &mut order,
            &mut rank,
            &mut keys,
        )
        .unwrap();
        assert_eq!(order[0], vec![2, 1, 0, 3]);
        assert_eq!(order[1], vec![0, 3, 2, 1]);
        for ring in 0..2 {
            for (k, &id) in order[ring].iter().enumerate() {
                assert_eq!(rank[ring][id as usize] as usize, k);
            }
        }
    }

    #[test]
    fn close_or_non_alternating_crossings_are_declined() {
        let (ra, rb) = (square(), square());
        let mut order = Default::default();
        let mut rank = Default::default();
        let mut keys = Vec::new();
        // Two exits in a row along ring 0.
        let same = [cross(0, 0.2, 0, 0.5, true), cross(1, 0.5, 2, 0.5, true)];
        assert!(
            order_along_rings(&[&ra, &rb], &same, 1e-12, &mut order, &mut rank, &mut keys)
                .is_none()
        );
        // Two crossings 4e-4 m apart on one 4 m edge, with tol = 1e-3.
        let close = [cross(0, 0.5, 0, 0.2, true), cross(0, 0.5001, 2, 0.5, false)];
        assert!(
            order_along_rings(&[&ra, &rb], &close, 1e-6, &mut order, &mut rank, &mut keys)
                .is_none()
        );
        assert!(
            order_along_rings(&[&ra, &rb], &close, 1e-8, &mut order, &mut rank, &mut keys)
                .is_some()
        );
    }
}

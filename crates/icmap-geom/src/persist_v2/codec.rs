//! The format's primitive codecs: the checksum, LEB128 varints, zigzag, Hilbert keys of the
//! blocks' order, and the quantisation of coordinates.

use super::MAX_QUANTISED;
use crate::types::Point;
use parry2d_f64::bounding_volume::Aabb;

/// A fast 64-bit checksum: the 8-byte little-endian words (the tail zero-padded) are dealt to 4
/// lanes in turn, each folding its words by `h = xorshift((h ^ w) * P)`; the lanes, the length
/// and a final mix give the sum. Each step is a bijection of the lane for a fixed word and of the
/// word for a fixed lane, and the lanes are combined by xor of bijections, so any change confined
/// to one word is always detected.
pub fn hash64(bytes: &[u8]) -> u64 {
    const P: u64 = 0x0000_0100_0000_01b3;
    #[inline(always)]
    fn step(h: u64, w: u64) -> u64 {
        let h = (h ^ w).wrapping_mul(P);
        h ^ (h >> 29)
    }
    let word = |c: &[u8]| u64::from_le_bytes(c.try_into().expect("8 bytes"));
    let mut lanes: [u64; 4] = [
        0xcbf2_9ce4_8422_2325,
        0x9e37_79b9_7f4a_7c15,
        0xbf58_476d_1ce4_e5b9,
        0x94d0_49bb_1331_11eb,
    ];
    let mut quads = bytes.chunks_exact(32);
    for q in &mut quads {
        for (k, lane) in lanes.iter_mut().enumerate() {
            *lane = step(*lane, word(&q[8 * k..8 * k + 8]));
        }
    }
    let rest = quads.remainder();
    let mut words = rest.chunks_exact(8);
    let mut k = 0;
    for c in &mut words {
        lanes[k] = step(lanes[k], word(c));
        k += 1;
    }
    if !words.remainder().is_empty() {
        let mut last = [0u8; 8];
        last[..words.remainder().len()].copy_from_slice(words.remainder());
        lanes[k] = step(lanes[k], u64::from_le_bytes(last));
    }
    let mut h = step(0x2545_f491_4f6c_dd1d, bytes.len() as u64);
    for (k, lane) in lanes.iter().enumerate() {
        h ^= step(*lane, k as u64).rotate_left(16 * k as u32);
    }
    step(h, 0)
}

#[inline]
pub(super) fn put_varint(out: &mut Vec<u8>, mut v: u64) {
    if v < 0x80 {
        out.push(v as u8);
        return;
    }
    while v >= 0x80 {
        out.push((v as u8) | 0x80);
        v >>= 7;
    }
    out.push(v as u8);
}

pub(super) fn zigzag(v: i64) -> u64 {
    ((v << 1) ^ (v >> 63)) as u64
}

pub(super) fn unzigzag(v: u64) -> i64 {
    ((v >> 1) as i64) ^ -((v & 1) as i64)
}

/// The prediction of the quantised coordinates of a point from the points before it, the same
/// in the writer and the reader (each point is stored as its zigzag residual): the first from
/// (0, 0), the second from the first, every later one by linear extrapolation of the two before.
#[derive(Default)]
pub(super) struct Predictor {
    i: usize,
    x1: i64,
    y1: i64,
    x2: i64,
    y2: i64,
}

impl Predictor {
    /// The prediction of the next point.
    #[inline]
    pub(super) fn predict(&self) -> (i64, i64) {
        match self.i {
            0 => (0, 0),
            1 => (self.x1, self.y1),
            _ => (
                self.x1.wrapping_mul(2).wrapping_sub(self.x2),
                self.y1.wrapping_mul(2).wrapping_sub(self.y2),
            ),
        }
    }

    /// Records the next point.
    #[inline]
    pub(super) fn push(&mut self, x: i64, y: i64) {
        (self.x2, self.y2, self.x1, self.y1) = (self.x1, self.y1, x, y);
        self.i += 1;
    }
}

/// The point's Hilbert index on a 2^16 x 2^16 grid over `extent`.
pub(super) fn hilbert_key(p: &Point, extent: &Aabb) -> u64 {
    const N: u32 = 1 << 16;
    let cell = |v: f64, lo: f64, hi: f64| -> u32 {
        let t = if hi > lo { (v - lo) / (hi - lo) } else { 0.0 };
        ((t * N as f64) as i64).clamp(0, N as i64 - 1) as u32
    };
    let (mut x, mut y) = (
        cell(p.x, extent.mins.x, extent.maxs.x),
        cell(p.y, extent.mins.y, extent.maxs.y),
    );
    let mut d: u64 = 0;
    let mut s = N / 2;
    while s > 0 {
        let rx = u32::from(x & s > 0);
        let ry = u32::from(y & s > 0);
        d += u64::from(s) * u64::from(s) * u64::from((3 * rx) ^ ry);
        if ry == 0 {
            if rx == 1 {
                x = N - 1 - x;
                y = N - 1 - y;
            }
            std::mem::swap(&mut x, &mut y);
        }
        s /= 2;
    }
    d
}

pub(super) fn quantisable(points: &[Point]) -> bool {
    points
        .iter()
        .all(|p| p.x.abs() < MAX_QUANTISED && p.y.abs() < MAX_QUANTISED)
}

/// `v` rounded to the nearest integer, halves away from zero (`f64::round`, without the libm
/// call), for `|v| < 2^52`.
#[inline]
pub(super) fn round_i64(v: f64) -> i64 {
    let t = v as i64;
    let r = v - t as f64;
    t + i64::from(r >= 0.5) - i64::from(r <= -0.5)
}

//! The native map file, format version 2: compact records, provenance, spatial blocks with an
//! index (region loading), per-block checksums; still atomic. Version 1 files (`persist.rs`) are
//! read as before.
//!
//! Layout (integers and floats little-endian):
//!
//! ```text
//! magic        8 bytes  b"ICMAPGM\0"
//! version      u32      2
//! header       64 bytes
//!   smoothing    f64      MapConfig::smoothing
//!   spacing      f64      MapConfig::spacing
//!   next_id      u64
//!   count        u64      number of instances
//!   quantum      f64      metres per unit of quantised coordinates (0: every instance exact)
//!   n_blocks     u64
//!   body_len     u64      bytes of all blocks together
//!   reserved     u64      0
//! index        n_blocks * 64 bytes, per block:
//!   xmin ymin xmax ymax  4 f64   the union of its instances' bounding boxes
//!   offset       u64      from the start of the body (blocks are contiguous, in index order)
//!   len          u64      bytes
//!   count        u64      instances
//!   checksum     u64      hash64 of the block's bytes
//! head_sum     u64      hash64 of every byte before it (magic .. index)
//! body         the blocks: records of `count` instances each
//! ```
//!
//! The file is exactly `12 + 64 + 64 * n_blocks + 8 + body_len` bytes. An instance record
//! (varint = LEB128 unsigned, at most 10 bytes; zigzag for signed values):
//!
//! ```text
//! id           varint
//! flags        u8       bits 0-1 class (0, 1, 2), bit 2 closed, bit 3 exact coordinates; others 0
//! first_frame  zigzag varint
//! frame_span   varint   last_frame - first_frame
//! observations varint   (< 2^32)
//! n_drives     varint, then the drives ascending: the first as a varint, then each gap - 1
//! n_points     varint
//! coordinates  exact: n * (f64 x, f64 y); quantised: zigzag varints, x then y per point, of
//!              X_0 = round(x_0 / quantum), then X_1 - X_0, then for i >= 2 the residual of the
//!              linear prediction, X_i - (2 X_{i-1} - X_{i-2}) (integers, wrapping mod 2^64)
//! ```
//!
//! **Encodings.** [`Encoding::Exact`] stores coordinates as they are (the map loads bit for bit);
//! [`Encoding::Compact`] rounds them to a grid of [`QUANTUM`] = 0.1 mm, so a loaded coordinate
//! differs from the saved one by at most 0.05 mm (plus float rounding, < 1e-9 m for coordinates
//! below 10^5 m): densely sampled smooth polylines then take 2-3 bytes per point instead of 16.
//! (An instance with a coordinate beyond 10^9 m is stored exactly in either encoding.)
//! Loading a compact file and saving it compact again gives the same bytes.
//!
//! **Blocks.** Instances are ordered along a Hilbert curve of their middle points (ties by id) and cut into blocks of [`BLOCK_INSTANCES`]; [`load_region`] reads the header, the index
//! and only the blocks whose box meets the region, and keeps the instances whose own box meets
//! it.
//!
//! **Checks.** Every byte is covered by a checksum (the head's or a block's), then the structure
//! is checked (contiguous blocks, counts, lengths, varints, flags; no allocation larger than the
//! bytes that are there), then the values (the store's instance invariants, unique ids). Every
//! problem is a [`GeomError::Format`] naming the file.

use crate::error::{GeomError, Result};
use crate::persist::{write_atomic_parts, MAGIC};
use crate::store::{GlobalMap, Instance, MapConfig};
use crate::types::{MapClass, Point};
use parry2d_f64::bounding_volume::{Aabb, BoundingVolume};
use rayon::prelude::*;
use std::fs::File;
use std::io::Read;
use std::path::Path;

/// The format version this module writes.
pub const FORMAT_VERSION_2: u32 = 2;
/// Grid of [`Encoding::Compact`] coordinates, metres (0.1 mm).
pub const QUANTUM: f64 = 1e-4;
/// `1 / QUANTUM`: encoding multiplies by it.
const INV_QUANTUM: f64 = 1e4;
/// Instances per block (the granularity of region loading).
pub const BLOCK_INSTANCES: usize = 256;

const PREFIX: usize = 12;
const HEADER: usize = 64;
const INDEX_ENTRY: usize = 64;
/// Largest |coordinate| (metres) stored quantised: 10^13 quanta, far inside the exact integers
/// of f64, so rounding, decoding and re-encoding are exact to a fraction of a quantum.
const MAX_QUANTISED: f64 = 1e9;

/// How coordinates are stored.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Encoding {
    /// As they are (bit for bit).
    #[default]
    Exact,
    /// Rounded to [`QUANTUM`] and delta-coded (at most 0.05 mm off).
    Compact,
}

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

// ------------------------------------------------------------------------------------ writing

#[inline]
fn put_varint(out: &mut Vec<u8>, mut v: u64) {
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

fn zigzag(v: i64) -> u64 {
    ((v << 1) ^ (v >> 63)) as u64
}

fn unzigzag(v: u64) -> i64 {
    ((v >> 1) as i64) ^ -((v & 1) as i64)
}

/// The point's Hilbert index on a 2^16 x 2^16 grid over `extent`.
fn hilbert_key(p: &Point, extent: &Aabb) -> u64 {
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

fn quantisable(points: &[Point]) -> bool {
    points
        .iter()
        .all(|p| p.x.abs() < MAX_QUANTISED && p.y.abs() < MAX_QUANTISED)
}

/// `v` rounded to the nearest integer, halves away from zero (`f64::round`, without the libm
/// call), for `|v| < 2^52`.
#[inline]
fn round_i64(v: f64) -> i64 {
    let t = v as i64;
    let r = v - t as f64;
    t + i64::from(r >= 0.5) - i64::from(r <= -0.5)
}

/// Appends the record of `inst`; returns the bounding box of its coordinates as they will be
/// decoded (quantised or not).
fn encode_instance(out: &mut Vec<u8>, inst: &Instance, drives: &[u32], encoding: Encoding) -> Aabb {
    let quantised = encoding == Encoding::Compact && quantisable(&inst.points);
    put_varint(out, inst.id);
    out.push(inst.class.index() | (u8::from(inst.closed) << 2) | (u8::from(!quantised) << 3));
    put_varint(out, zigzag(inst.first_frame));
    put_varint(out, inst.last_frame.wrapping_sub(inst.first_frame) as u64);
    put_varint(out, u64::from(inst.observations));
    put_varint(out, drives.len() as u64);
    let mut prev: Option<u32> = None;
    for &d in drives {
        put_varint(out, u64::from(prev.map_or(d, |p| d - p - 1)));
        prev = Some(d);
    }
    put_varint(out, inst.points.len() as u64);
    out.reserve(if quantised { 6 } else { 16 } * inst.points.len());
    if !quantised {
        for p in &inst.points {
            out.extend_from_slice(&p.x.to_le_bytes());
            out.extend_from_slice(&p.y.to_le_bytes());
        }
        return inst.aabb();
    }
    let (mut lo, mut hi) = (
        Point::new(f64::INFINITY, f64::INFINITY),
        Point::new(-f64::INFINITY, -f64::INFINITY),
    );
    let (mut x1, mut y1, mut x2, mut y2) = (0i64, 0i64, 0i64, 0i64);
    for (i, p) in inst.points.iter().enumerate() {
        let (x, y) = (round_i64(p.x * INV_QUANTUM), round_i64(p.y * INV_QUANTUM));
        let (px, py) = match i {
            0 => (0, 0),
            1 => (x1, y1),
            _ => (
                x1.wrapping_mul(2).wrapping_sub(x2),
                y1.wrapping_mul(2).wrapping_sub(y2),
            ),
        };
        put_varint(out, zigzag(x.wrapping_sub(px)));
        put_varint(out, zigzag(y.wrapping_sub(py)));
        (x2, y2, x1, y1) = (x1, y1, x, y);
        let q = Point::new(x as f64 * QUANTUM, y as f64 * QUANTUM);
        lo = lo.inf(&q);
        hi = hi.sup(&q);
    }
    Aabb::new(lo, hi)
}

/// The map file contents of `map` in format version 2.
pub fn to_bytes(map: &GlobalMap, encoding: Encoding) -> Vec<u8> {
    let (mut out, blocks) = encode(map, encoding);
    out.reserve_exact(blocks.iter().map(Vec::len).sum());
    for bytes in &blocks {
        out.extend_from_slice(bytes);
    }
    out
}

/// The file of `map` in two parts: the head (magic .. head checksum) and the blocks, in file
/// order (their concatenation is [`to_bytes`]).
fn encode(map: &GlobalMap, encoding: Encoding) -> (Vec<u8>, Vec<Vec<u8>>) {
    // Instances in storage order (their data is read in memory order where possible).
    let insts: Vec<&Instance> = map.instances_iter().collect();
    // Each instance's drives: a merge join of (id, position) and the provenance table, both
    // sorted by id (no hash lookups, no visits to the instances' points).
    let mut by_id: Vec<(u64, usize)> = insts.iter().enumerate().map(|(k, i)| (i.id, k)).collect();
    by_id.par_sort_unstable();
    let mut drive_lists: Vec<(u64, &[u32])> =
        map.drives.iter().map(|(&id, d)| (id, &d[..])).collect();
    drive_lists.par_sort_unstable_by_key(|x| x.0);
    let mut drives_of: Vec<&[u32]> = vec![&[]; insts.len()];
    let mut lists = drive_lists.iter().peekable();
    for &(id, k) in &by_id {
        while lists.next_if(|x| x.0 < id).is_some() {}
        if let Some(x) = lists.next_if(|x| x.0 == id) {
            drives_of[k] = x.1;
        }
    }
    drop((by_id, drive_lists));
    // Hilbert order of a middle point of each instance (ties by id).
    let anchors: Vec<Point> = insts.iter().map(|i| i.points[i.points.len() / 2]).collect();
    let extent = anchors
        .iter()
        .fold(None, |acc: Option<Aabb>, q| {
            Some(acc.map_or(Aabb::new(*q, *q), |b| {
                Aabb::new(b.mins.inf(q), b.maxs.sup(q))
            }))
        })
        .unwrap_or_else(|| Aabb::new(Point::origin(), Point::origin()));
    let mut keyed: Vec<(u64, u64, usize)> = anchors
        .par_iter()
        .zip(&insts)
        .enumerate()
        .map(|(k, (q, i))| (hilbert_key(q, &extent), i.id, k))
        .collect();
    keyed.par_sort_unstable();
    let order: Vec<(&Instance, &[u32])> = keyed
        .iter()
        .map(|&(_, _, k)| (insts[k], drives_of[k]))
        .collect();
    drop((insts, drives_of, anchors, keyed));
    // Blocks, encoded in parallel: (bytes, box, count).
    let blocks: Vec<(Vec<u8>, Aabb, usize)> = order
        .par_chunks(BLOCK_INSTANCES)
        .map(|chunk| {
            let mut out = Vec::with_capacity(chunk.len() * 64);
            let mut bbox: Option<Aabb> = None;
            for (inst, drives) in chunk {
                let b = encode_instance(&mut out, inst, drives, encoding);
                bbox = Some(bbox.map_or(b, |x| x.merged(&b)));
            }
            let bbox = bbox.expect("a block has instances");
            (out, bbox, chunk.len())
        })
        .collect();
    let body_len: usize = blocks.iter().map(|b| b.0.len()).sum();
    let head_len = PREFIX + HEADER + blocks.len() * INDEX_ENTRY;
    let mut out = Vec::with_capacity(head_len + 8);
    out.extend_from_slice(MAGIC);
    out.extend_from_slice(&FORMAT_VERSION_2.to_le_bytes());
    let cfg = map.config();
    let quantum = if encoding == Encoding::Compact {
        QUANTUM
    } else {
        0.0
    };
    for v in [cfg.smoothing, cfg.spacing] {
        out.extend_from_slice(&v.to_le_bytes());
    }
    out.extend_from_slice(&map.next_id().to_le_bytes());
    out.extend_from_slice(&(map.len() as u64).to_le_bytes());
    out.extend_from_slice(&quantum.to_le_bytes());
    out.extend_from_slice(&(blocks.len() as u64).to_le_bytes());
    out.extend_from_slice(&(body_len as u64).to_le_bytes());
    out.extend_from_slice(&0u64.to_le_bytes());
    let mut offset = 0u64;
    let sums: Vec<u64> = blocks.par_iter().map(|b| hash64(&b.0)).collect();
    for ((bytes, bbox, count), sum) in blocks.iter().zip(&sums) {
        for v in [bbox.mins.x, bbox.mins.y, bbox.maxs.x, bbox.maxs.y] {
            out.extend_from_slice(&v.to_le_bytes());
        }
        for v in [offset, bytes.len() as u64, *count as u64, *sum] {
            out.extend_from_slice(&v.to_le_bytes());
        }
        offset += bytes.len() as u64;
    }
    let head_sum = hash64(&out);
    out.extend_from_slice(&head_sum.to_le_bytes());
    (out, blocks.into_iter().map(|b| b.0).collect())
}

/// Writes `map` to `path` atomically (temp file in the same folder, fsync, rename) in format 2:
/// the head and the blocks are written one after the other (the bytes of [`to_bytes`], without
/// joining them in memory).
pub fn save(map: &GlobalMap, path: &Path, encoding: Encoding) -> Result<()> {
    let (head, blocks) = encode(map, encoding);
    let parts: Vec<&[u8]> = std::iter::once(&head[..])
        .chain(blocks.iter().map(|b| &b[..]))
        .collect();
    write_atomic_parts(path, &parts)
}

// ------------------------------------------------------------------------------------ reading

type Parse<T> = std::result::Result<T, String>;

/// A bounds-checked reader over one block or the head.
struct Cursor<'a> {
    bytes: &'a [u8],
    pos: usize,
}

impl<'a> Cursor<'a> {
    fn remaining(&self) -> usize {
        self.bytes.len() - self.pos
    }
    fn take(&mut self, n: usize, what: &str) -> Parse<&'a [u8]> {
        if self.remaining() < n {
            return Err(format!(
                "truncated: {what} needs {n} byte(s) at offset {} of a section of {}",
                self.pos,
                self.bytes.len()
            ));
        }
        let s = &self.bytes[self.pos..self.pos + n];
        self.pos += n;
        Ok(s)
    }
    #[inline]
    fn u8(&mut self, what: &str) -> Parse<u8> {
        match self.bytes.get(self.pos) {
            Some(&b) => {
                self.pos += 1;
                Ok(b)
            }
            None => Err(self.take(1, what).err().unwrap_or_default()),
        }
    }
    fn u64(&mut self, what: &str) -> Parse<u64> {
        Ok(u64::from_le_bytes(
            self.take(8, what)?.try_into().expect("8 bytes"),
        ))
    }
    fn f64(&mut self, what: &str) -> Parse<f64> {
        Ok(f64::from_le_bytes(
            self.take(8, what)?.try_into().expect("8 bytes"),
        ))
    }
    #[inline]
    fn varint(&mut self, what: &str) -> Parse<u64> {
        match self.bytes.get(self.pos..self.pos + 2) {
            Some(&[b0, _]) if b0 < 0x80 => {
                self.pos += 1;
                Ok(u64::from(b0))
            }
            Some(&[b0, b1]) if b1 < 0x80 => {
                self.pos += 2;
                Ok(u64::from(b0 & 0x7f) | (u64::from(b1) << 7))
            }
            _ => self.varint_long(what),
        }
    }
    fn varint_long(&mut self, what: &str) -> Parse<u64> {
        let mut v: u64 = 0;
        for k in 0..10 {
            let b = self.u8(what)?;
            if k == 9 && b > 1 {
                break;
            }
            v |= u64::from(b & 0x7f) << (7 * k);
            if b & 0x80 == 0 {
                return Ok(v);
            }
        }
        Err(format!("corrupt: {what} is not a valid varint"))
    }
    /// A count of items of at least `min_bytes` each that must fit in the rest of the section.
    fn count(&mut self, what: &str, min_bytes: usize) -> Parse<usize> {
        let n = self.varint(what)?;
        if n > (self.remaining() / min_bytes.max(1)) as u64 {
            return Err(format!(
                "truncated or corrupt: {n} {what} declared but only {} bytes remain in the block",
                self.remaining()
            ));
        }
        Ok(n as usize)
    }
}

/// The head of a version-2 file: config, counts and the block index.
struct Head {
    config: MapConfig,
    next_id: u64,
    count: u64,
    quantum: f64,
    body_len: u64,
    blocks: Vec<BlockEntry>,
}

#[derive(Debug, Clone, Copy)]
struct BlockEntry {
    bbox: [f64; 4],
    offset: u64,
    len: u64,
    count: u64,
    sum: u64,
}

impl Head {
    /// Bytes of the head (magic .. head checksum).
    fn len(&self) -> u64 {
        (PREFIX + HEADER + 8) as u64 + (self.blocks.len() * INDEX_ENTRY) as u64
    }
}

/// Reads the fixed header after magic and version (`bytes` = the first PREFIX + HEADER bytes):
/// returns the header fields and the number of blocks, checked against `file_len`.
fn parse_header(bytes: &[u8], file_len: u64) -> Parse<(Head, usize)> {
    let mut c = Cursor {
        bytes: &bytes[PREFIX..],
        pos: 0,
    };
    let smoothing = c.f64("smoothing")?;
    let spacing = c.f64("spacing")?;
    let next_id = c.u64("next_id")?;
    let count = c.u64("instance count")?;
    let quantum = c.f64("quantum")?;
    let n_blocks = c.u64("block count")?;
    let body_len = c.u64("body length")?;
    let reserved = c.u64("reserved")?;
    let room = file_len.saturating_sub((PREFIX + HEADER + 8) as u64);
    if n_blocks > room / INDEX_ENTRY as u64 {
        return Err(format!(
            "truncated or corrupt: {n_blocks} blocks declared but the file has {file_len} bytes"
        ));
    }
    let expected = (PREFIX + HEADER + 8) as u64 + n_blocks * INDEX_ENTRY as u64;
    if body_len > file_len.saturating_sub(expected) {
        return Err(format!(
            "truncated: the header declares {} bytes but the file has {file_len}",
            expected.saturating_add(body_len)
        ));
    }
    if file_len != expected + body_len {
        return Err(format!(
            "{} unexpected trailing byte(s) after the last block",
            file_len - expected - body_len
        ));
    }
    if reserved != 0 {
        return Err("corrupt: reserved header field is not 0".into());
    }
    Ok((
        Head {
            config: MapConfig { smoothing, spacing },
            next_id,
            count,
            quantum,
            body_len,
            blocks: Vec::new(),
        },
        n_blocks as usize,
    ))
}

/// Reads the index and the head checksum (`head` = magic .. head checksum) and checks them.
fn parse_index(head_bytes: &[u8], mut head: Head, n_blocks: usize) -> Parse<Head> {
    let body = head_bytes.len() - 8;
    let stored = u64::from_le_bytes(head_bytes[body..].try_into().expect("8 bytes"));
    let computed = hash64(&head_bytes[..body]);
    if stored != computed {
        return Err(format!(
            "header checksum mismatch (stored {stored:#018x}, computed {computed:#018x}): the file is corrupt"
        ));
    }
    let mut c = Cursor {
        bytes: &head_bytes[PREFIX + HEADER..body],
        pos: 0,
    };
    let mut blocks = Vec::with_capacity(n_blocks);
    let (mut offset, mut count) = (0u64, 0u64);
    for k in 0..n_blocks {
        let mut bbox = [0.0; 4];
        for v in &mut bbox {
            *v = c.f64("block box")?;
        }
        let e = BlockEntry {
            bbox,
            offset: c.u64("block offset")?,
            len: c.u64("block length")?,
            count: c.u64("block count")?,
            sum: c.u64("block checksum")?,
        };
        if e.offset != offset || e.len > head.body_len - offset {
            return Err(format!("corrupt index: block {k} is out of place"));
        }
        if bbox.iter().any(|v| v.is_nan()) || bbox[0] > bbox[2] || bbox[1] > bbox[3] {
            return Err(format!("corrupt index: block {k} has an invalid box"));
        }
        offset += e.len;
        count = count.saturating_add(e.count);
        blocks.push(e);
    }
    if offset != head.body_len || count != head.count {
        return Err(format!(
            "corrupt index: blocks hold {offset} bytes and {count} instances, the header says {} and {}",
            head.body_len, head.count
        ));
    }
    let q = head.quantum;
    if !(q == 0.0 || (q.is_finite() && (1e-9..=1.0).contains(&q))) {
        return Err(format!("invalid quantum {q}"));
    }
    head.blocks = blocks;
    Ok(head)
}

/// The head of `bytes` (a whole version-2 file).
fn parse_head(bytes: &[u8]) -> Parse<Head> {
    if bytes.len() < PREFIX + HEADER {
        return Err(format!(
            "truncated: the header needs {} bytes but the file has {}",
            PREFIX + HEADER,
            bytes.len()
        ));
    }
    let (head, n_blocks) = parse_header(&bytes[..PREFIX + HEADER], bytes.len() as u64)?;
    let head_len = PREFIX + HEADER + n_blocks * INDEX_ENTRY + 8;
    parse_index(&bytes[..head_len], head, n_blocks)
}

/// An instance as decoded, with its drives (and, once checked, its bounding box).
type Decoded = (Instance, Vec<u32>);
/// A decoded block after the checks: the instances with their boxes, and the drive lists.
type Checked = (Vec<(Instance, Aabb)>, Vec<(u64, Box<[u32]>)>);

fn decode_instance(c: &mut Cursor<'_>, quantum: f64) -> Parse<Decoded> {
    let id = c.varint("instance id")?;
    let flags = c.u8("flags")?;
    if flags & !0b1111 != 0 || flags & 0b11 == 3 {
        return Err(format!("invalid flags {flags:#04x} for instance {id}"));
    }
    let class = MapClass::try_from(i64::from(flags & 0b11)).map_err(|e| e.to_string())?;
    let closed = flags & 0b100 != 0;
    let exact = flags & 0b1000 != 0;
    let first_frame = unzigzag(c.varint("first_frame")?);
    let last_frame = first_frame.wrapping_add(c.varint("frame span")? as i64);
    let observations = u32::try_from(c.varint("observations")?)
        .map_err(|_| format!("observations of instance {id} exceed 2^32 - 1"))?;
    let n_drives = c.count("drives", 1)?;
    let mut drives = Vec::with_capacity(n_drives);
    let mut prev: Option<u32> = None;
    for _ in 0..n_drives {
        let v = c.varint("drive")?;
        let d = match prev {
            None => u32::try_from(v).ok(),
            Some(p) => u32::try_from(v)
                .ok()
                .and_then(|g| p.checked_add(1)?.checked_add(g)),
        }
        .ok_or_else(|| format!("invalid drive list of instance {id}"))?;
        drives.push(d);
        prev = Some(d);
    }
    let n = c.count("points", if exact { 16 } else { 2 })?;
    let mut points = Vec::with_capacity(n);
    if exact {
        for _ in 0..n {
            let x = c.f64("coordinate")?;
            let y = c.f64("coordinate")?;
            points.push(Point::new(x, y));
        }
    } else {
        if quantum == 0.0 {
            return Err(format!(
                "instance {id} is quantised but the file has no quantum"
            ));
        }
        let (mut x1, mut y1, mut x2, mut y2) = (0i64, 0i64, 0i64, 0i64);
        for i in 0..n {
            let rx = unzigzag(c.varint("coordinate")?);
            let ry = unzigzag(c.varint("coordinate")?);
            let (px, py) = match i {
                0 => (0, 0),
                1 => (x1, y1),
                _ => (
                    x1.wrapping_mul(2).wrapping_sub(x2),
                    y1.wrapping_mul(2).wrapping_sub(y2),
                ),
            };
            let (x, y) = (px.wrapping_add(rx), py.wrapping_add(ry));
            points.push(Point::new(x as f64 * quantum, y as f64 * quantum));
            (x2, y2, x1, y1) = (x1, y1, x, y);
        }
    }
    if points.iter().any(|p| !(p.x.is_finite() && p.y.is_finite())) {
        return Err(format!("non-finite coordinate in instance {id}"));
    }
    Ok((
        Instance {
            id,
            class,
            points,
            closed,
            first_frame,
            last_frame,
            observations,
        },
        drives,
    ))
}

/// Decodes one block (its checksum checked first); keeps the instances whose box meets `region`.
fn decode_block(
    k: usize,
    e: &BlockEntry,
    bytes: &[u8],
    quantum: f64,
    region: Option<&Aabb>,
) -> Parse<Checked> {
    let computed = hash64(bytes);
    if computed != e.sum {
        return Err(format!(
            "checksum mismatch in block {k} (stored {:#018x}, computed {computed:#018x}): the file is corrupt",
            e.sum
        ));
    }
    let mut c = Cursor { bytes, pos: 0 };
    let mut out = Vec::with_capacity((e.count as usize).min(bytes.len()));
    let mut drive_lists = Vec::new();
    let bbox = Aabb::new(
        Point::new(e.bbox[0], e.bbox[1]),
        Point::new(e.bbox[2], e.bbox[3]),
    );
    for _ in 0..e.count {
        let (inst, drives) =
            decode_instance(&mut c, quantum).map_err(|m| format!("block {k}: {m}"))?;
        inst.validate().map_err(|e| format!("block {k}: {e}"))?;
        let b = inst.aabb();
        if !bbox.contains(&b) {
            return Err(format!(
                "corrupt index: block {k}'s box does not contain instance {}",
                inst.id
            ));
        }
        if region.is_none_or(|r| r.intersects(&b)) {
            if !drives.is_empty() {
                drive_lists.push((inst.id, drives.into_boxed_slice()));
            }
            out.push((inst, b));
        }
    }
    if c.remaining() != 0 {
        return Err(format!(
            "block {k}: {} unexpected byte(s) after its {} instances",
            c.remaining(),
            e.count
        ));
    }
    Ok((out, drive_lists))
}

/// Builds the map from decoded instances (the store's checks: invariants, unique ids, ids below
/// next_id).
fn assemble(head: &Head, blocks: Vec<Checked>) -> Parse<GlobalMap> {
    head.config
        .validate()
        .map_err(|e| format!("bad config: {e}"))?;
    let (instances, drive_lists): (Vec<_>, Vec<_>) = blocks.into_iter().unzip();
    let n = instances.iter().map(Vec::len).sum();
    // The store and the provenance table are built at the same time.
    let (map, drives) = rayon::join(
        || {
            GlobalMap::from_checked_parts(
                head.config,
                head.next_id,
                n,
                instances.into_iter().flatten(),
            )
        },
        || {
            let mut table =
                std::collections::HashMap::with_capacity(drive_lists.iter().map(Vec::len).sum());
            table.extend(drive_lists.into_iter().flatten());
            table
        },
    );
    let mut map = map.map_err(|e| e.to_string())?;
    map.drives = drives;
    Ok(map)
}

fn format_error(path: &str) -> impl Fn(String) -> GeomError + '_ {
    move |reason| GeomError::Format {
        path: path.to_string(),
        reason,
    }
}

/// The format version of a file that starts with `prefix` (at least the magic and the version),
/// or the error for a foreign / truncated start.
fn version_of(prefix: &[u8]) -> Parse<u32> {
    let head = &prefix[..prefix.len().min(MAGIC.len())];
    if head.is_empty() {
        return Err("not an icmapper map file (empty file)".into());
    }
    if head != &MAGIC[..head.len()] {
        return Err("not an icmapper map file (wrong magic bytes)".into());
    }
    if prefix.len() < PREFIX {
        return Err(format!(
            "truncated: the file ends at {} inside the magic bytes and version",
            prefix.len()
        ));
    }
    Ok(u32::from_le_bytes(
        prefix[8..12].try_into().expect("4 bytes"),
    ))
}

/// Re-labels a version-1 parse error (named `<bytes>`) with `path`.
fn with_path(e: GeomError, path: &str) -> GeomError {
    match e {
        GeomError::Format { reason, .. } => GeomError::Format {
            path: path.to_string(),
            reason,
        },
        other => other,
    }
}

/// A file's contents decoded: a map (version 1) or the head and the decoded blocks (version 2,
/// assembled once the file's bytes are dropped).
enum Parsed {
    Map(Box<GlobalMap>),
    Blocks(Head, Vec<Checked>),
}

fn decode_any(bytes: &[u8], path: &str, region: Option<&Aabb>) -> Result<Parsed> {
    let fmt = format_error(path);
    match version_of(bytes).map_err(&fmt)? {
        1 => {
            let map = crate::persist::from_bytes(bytes).map_err(|e| with_path(e, path))?;
            Ok(Parsed::Map(Box::new(match region {
                None => map,
                Some(r) => filter_region(map, r),
            })))
        }
        FORMAT_VERSION_2 => {
            let head = parse_head(bytes).map_err(&fmt)?;
            let start = head.len() as usize;
            let decoded: Parse<Vec<Checked>> = head
                .blocks
                .par_iter()
                .enumerate()
                .filter(|(_, e)| region.is_none_or(|r| r.intersects(&entry_box(e))))
                .map(|(k, e)| {
                    let at = start + e.offset as usize;
                    decode_block(k, e, &bytes[at..at + e.len as usize], head.quantum, region)
                })
                .collect();
            Ok(Parsed::Blocks(head, decoded.map_err(&fmt)?))
        }
        v => Err(fmt(format!(
            "unsupported format version {v} (this build reads versions 1 and 2; the file may come from a newer icmapper)"
        ))),
    }
}

fn finish(parsed: Parsed, path: &str) -> Result<GlobalMap> {
    match parsed {
        Parsed::Map(map) => Ok(*map),
        Parsed::Blocks(head, blocks) => assemble(&head, blocks).map_err(format_error(path)),
    }
}

fn parse_any(bytes: &[u8], path: &str, region: Option<&Aabb>) -> Result<GlobalMap> {
    finish(decode_any(bytes, path, region)?, path)
}

fn entry_box(e: &BlockEntry) -> Aabb {
    Aabb::new(
        Point::new(e.bbox[0], e.bbox[1]),
        Point::new(e.bbox[2], e.bbox[3]),
    )
}

/// The map of the instances of `map` whose box meets `region` (same config and next id).
fn filter_region(map: GlobalMap, region: &Aabb) -> GlobalMap {
    let mut out = map;
    let drop: Vec<u64> = out
        .instances_iter()
        .filter(|i| !region.intersects(&i.aabb()))
        .map(|i| i.id)
        .collect();
    for id in drop {
        let _ = out.remove(id);
    }
    out
}

/// Parses map file contents of version 1 or 2; errors name `<bytes>` as the path.
pub fn from_bytes(bytes: &[u8]) -> Result<GlobalMap> {
    parse_any(bytes, "<bytes>", None)
}

/// Reads a map file of version 1 or 2; a foreign, truncated or corrupt file gives
/// `GeomError::Format`, a missing or unreadable one `GeomError::Io`. A version-2 file is read
/// block by block (in parallel, into reused buffers), not into one buffer of its size.
pub fn load(path: &Path) -> Result<GlobalMap> {
    load_file(path, None)
}

/// Reads `buf.len()` bytes of `f` at offset `at` (a positioned read: threads share the file).
#[cfg(unix)]
fn read_block(f: &File, at: u64, buf: &mut [u8]) -> std::io::Result<()> {
    use std::os::unix::fs::FileExt;
    f.read_exact_at(buf, at)
}

#[cfg(not(unix))]
fn read_block(f: &File, at: u64, buf: &mut [u8]) -> std::io::Result<()> {
    use std::io::{Seek, SeekFrom};
    let mut f = f;
    f.seek(SeekFrom::Start(at))?;
    f.read_exact(buf)
}

/// [`load`] (`region` None) and [`load_region`]: a version-2 file's header and index, then the
/// blocks that meet the region, read and decoded in parallel; other versions are read whole.
fn load_file(path: &Path, region: Option<Aabb>) -> Result<GlobalMap> {
    let name = path.display().to_string();
    let io = |source| GeomError::Io {
        path: name.clone(),
        source,
    };
    let fmt = format_error(&name);
    let mut f = File::open(path).map_err(io)?;
    let file_len = f.metadata().map_err(io)?.len();
    let mut prefix = vec![0u8; (PREFIX + HEADER).min(file_len as usize)];
    f.read_exact(&mut prefix).map_err(io)?;
    if version_of(&prefix).map_err(&fmt)? != FORMAT_VERSION_2 {
        drop(f);
        let bytes = std::fs::read(path).map_err(io)?;
        let parsed = decode_any(&bytes, &name, region.as_ref())?;
        drop(bytes);
        return finish(parsed, &name);
    }
    if prefix.len() < PREFIX + HEADER {
        return Err(fmt(format!(
            "truncated: the header needs {} bytes but the file has {file_len}",
            PREFIX + HEADER
        )));
    }
    let (head, n_blocks) = parse_header(&prefix, file_len).map_err(&fmt)?;
    let head_len = PREFIX + HEADER + n_blocks * INDEX_ENTRY + 8;
    let mut head_bytes = prefix;
    head_bytes.resize(head_len, 0);
    f.read_exact(&mut head_bytes[PREFIX + HEADER..])
        .map_err(io)?;
    let head = parse_index(&head_bytes, head, n_blocks).map_err(&fmt)?;
    drop(head_bytes);
    let start = head.len();
    let f = &f;
    let results: Vec<Result<Checked>> = head
        .blocks
        .par_iter()
        .enumerate()
        .filter(|(_, e)| region.is_none_or(|r| r.intersects(&entry_box(e))))
        .map_init(Vec::new, |buf, (k, e)| {
            buf.resize(e.len as usize, 0);
            read_block(f, start + e.offset, buf).map_err(io)?;
            decode_block(k, e, buf, head.quantum, region.as_ref()).map_err(&fmt)
        })
        .collect();
    let blocks = results.into_iter().collect::<Result<Vec<_>>>()?;
    assemble(&head, blocks).map_err(&fmt)
}

/// A region `(xmin, ymin, xmax, ymax)` as a box: no NaN, `xmin <= xmax`, `ymin <= ymax`
/// (infinite bounds allowed: an unbounded side).
pub fn region_box(region: [f64; 4]) -> Result<Aabb> {
    let [x0, y0, x1, y1] = region;
    if region.iter().any(|v| v.is_nan()) {
        return Err(GeomError::NonFinite {
            what: "bbox (xmin, ymin, xmax, ymax)".into(),
        });
    }
    if x0 > x1 || y0 > y1 {
        return Err(GeomError::InvalidParameter {
            name: "bbox",
            reason: format!(
                "(xmin, ymin, xmax, ymax) needs xmin <= xmax and ymin <= ymax, got ({x0}, {y0}, {x1}, {y1})"
            ),
        });
    }
    Ok(Aabb::new(Point::new(x0, y0), Point::new(x1, y1)))
}

/// Reads the instances of a map file whose bounding box meets `region` = `(xmin, ymin, xmax,
/// ymax)` (boundary contact counts). For a version-2 file only the header, the index and the
/// blocks whose box meets the region are read (and checked); a version-1 file has no index and
/// is read whole. The map keeps the file's config and next id.
pub fn load_region(path: &Path, region: [f64; 4]) -> Result<GlobalMap> {
    load_file(path, Some(region_box(region)?))
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn p(x: f64, y: f64) -> Point {
        Point::new(x, y)
    }

    fn inst(
        id: u64,
        class: MapClass,
        points: Vec<Point>,
        frames: (i64, i64),
        obs: u32,
    ) -> Instance {
        Instance {
            id,
            class,
            points,
            closed: class.is_closed(),
            first_frame: frames.0,
            last_frame: frames.1,
            observations: obs,
        }
    }

    /// A map with gaps in the ids, extreme bookkeeping, provenance and far coordinates.
    fn sample_map() -> GlobalMap {
        let cfg = MapConfig {
            smoothing: 0.25,
            spacing: 0.75,
        };
        let wave: Vec<Point> = (0..40)
            .map(|i| p(1000.0 + i as f64 * 0.75, -250.0 + (i as f64 / 5.0).sin()))
            .collect();
        let instances = vec![
            inst(
                0,
                MapClass::PedCrossing,
                vec![p(0.0, 0.0), p(2.0, 0.0), p(2.0, 1.5), p(0.0, 1.5)],
                (-3, 7),
                4,
            ),
            inst(5, MapClass::Divider, wave, (2, 2), 1),
            inst(
                2,
                MapClass::Boundary,
                vec![p(-1e6, 3.0), p(1e6, 3.0 + f64::EPSILON)],
                (i64::MIN, i64::MAX),
                u32::MAX,
            ),
            // At the edge of the coordinate domain (|x| <= 1e7 m, issue 14.3).
            inst(
                7,
                MapClass::Boundary,
                vec![p(9.999_999e6, 0.0), p(-9.999_999e6, 1.0)],
                (0, 1),
                2,
            ),
        ];
        let mut m = GlobalMap::from_parts(cfg, 9, instances).unwrap();
        m.set_drives(0, &[0, 3, u32::MAX]).unwrap();
        m.set_drives(5, &[7]).unwrap();
        m
    }

    fn same(a: &GlobalMap, b: &GlobalMap) {
        assert_eq!(a.config(), b.config());
        assert_eq!(a.next_id(), b.next_id());
        assert_eq!(a.instances(), b.instances());
        for i in a.instances() {
            assert_eq!(a.drives(i.id), b.drives(i.id));
        }
        b.check_invariants().unwrap();
    }

    fn reason(e: GeomError) -> String {
        match e {
            GeomError::Format { reason, .. } => reason,
            other => panic!("expected a Format error, got {other:?}"),
        }
    }

    /// A grid of `n` dividers 10 m apart (for blocks and regions).
    fn grid_map(n: usize, encoding_noise: f64) -> GlobalMap {
        let mut m = GlobalMap::new(MapConfig::default()).unwrap();
        let side = (n as f64).sqrt().ceil() as usize;
        for k in 0..n {
            let (x, y) = ((k % side) as f64 * 10.0, (k / side) as f64 * 10.0);
            let class = MapClass::ALL[k % 3];
            let pts = if class.is_closed() {
                vec![p(x, y), p(x + 3.0, y), p(x + 3.0, y + 2.0), p(x, y + 2.0)]
            } else {
                (0..8)
                    .map(|i| p(x + i as f64, y + encoding_noise * (i as f64 * 1.7).sin()))
                    .collect()
            };
            m.insert(class, &pts, k as i64).unwrap();
        }
        m.tag_drive(3);
        m
    }

    #[test]
    fn hash_detects_single_word_changes() {
        let a = hash64(b"0123456789abcdef!");
        assert_ne!(a, hash64(b"0123456789abcdeg!"));
        assert_ne!(a, hash64(b"0123456789abcdef!\0"), "length is mixed in");
        assert_ne!(hash64(b""), hash64(b"\0"));
    }

    #[test]
    fn varints_round_trip() {
        for v in [0u64, 1, 127, 128, 300, u32::MAX as u64, u64::MAX] {
            let mut out = Vec::new();
            put_varint(&mut out, v);
            assert!(out.len() <= 10);
            let mut c = Cursor {
                bytes: &out,
                pos: 0,
            };
            assert_eq!(c.varint("v").unwrap(), v);
        }
        for v in [0i64, -1, 1, i64::MIN, i64::MAX] {
            assert_eq!(unzigzag(zigzag(v)), v);
        }
        let bad = [0xffu8; 11];
        assert!(Cursor {
            bytes: &bad,
            pos: 0
        }
        .varint("v")
        .is_err());
    }

    #[test]
    fn exact_round_trip_with_provenance() {
        let m = sample_map();
        let bytes = to_bytes(&m, Encoding::Exact);
        let back = from_bytes(&bytes).unwrap();
        same(&m, &back);
        assert_eq!(
            to_bytes(&back, Encoding::Exact),
            bytes,
            "deterministic bytes"
        );
        let empty = GlobalMap::new(MapConfig::default()).unwrap();
        same(
            &empty,
            &from_bytes(&to_bytes(&empty, Encoding::Exact)).unwrap(),
        );
        same(
            &empty,
            &from_bytes(&to_bytes(&empty, Encoding::Compact)).unwrap(),
        );
    }

    #[test]
    fn compact_round_trip_within_tolerance() {
        let m = sample_map();
        let bytes = to_bytes(&m, Encoding::Compact);
        let back = from_bytes(&bytes).unwrap();
        back.check_invariants().unwrap();
        assert_eq!(back.ids(), m.ids());
        for a in m.instances() {
            let b = back.get(a.id).unwrap();
            assert_eq!(
                (
                    a.class,
                    a.closed,
                    a.first_frame,
                    a.last_frame,
                    a.observations
                ),
                (
                    b.class,
                    b.closed,
                    b.first_frame,
                    b.last_frame,
                    b.observations
                )
            );
            assert_eq!(m.drives(a.id), back.drives(a.id));
            assert_eq!(a.points.len(), b.points.len());
            for (q, r) in a.points.iter().zip(&b.points) {
                if a.id == 7 {
                    assert_eq!(q, r, "out of the quantised range: exact");
                } else {
                    let tol = QUANTUM / 2.0 + 1e-9;
                    assert!(
                        (q.x - r.x).abs() <= tol && (q.y - r.y).abs() <= tol,
                        "{q:?} {r:?}"
                    );
                }
            }
        }
        assert_eq!(
            to_bytes(&back, Encoding::Compact),
            bytes,
            "compact is idempotent"
        );
        // Smooth dense polylines: far fewer bytes than exact coordinates.
        let g = grid_map(2000, 0.3);
        let (exact, compact) = (
            to_bytes(&g, Encoding::Exact).len(),
            to_bytes(&g, Encoding::Compact).len(),
        );
        let v1 = crate::persist::to_bytes(&g).len();
        assert!(exact < v1, "{exact} vs v1 {v1}");
        assert!(compact * 3 < v1, "{compact} vs v1 {v1}");
    }

    #[test]
    fn version_1_still_loads() {
        let m = sample_map();
        let v1 = crate::persist::to_bytes(&m);
        let back = from_bytes(&v1).unwrap();
        assert_eq!(back.instances(), m.instances());
        assert!(back.drives(0).is_empty(), "version 1 has no provenance");
        let mut bad = v1.clone();
        let n = bad.len();
        bad[n - 1] ^= 1;
        assert!(reason(from_bytes(&bad).unwrap_err()).contains("checksum"));
    }

    #[test]
    fn files_round_trip_and_regions() {
        let dir = std::env::temp_dir().join(format!("icmap-persist2-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("city.icmap");
        let m = grid_map(3000, 0.2);
        // The file written in parts is byte for byte the joined bytes, in both encodings.
        for encoding in [Encoding::Compact, Encoding::Exact] {
            save(&m, &path, encoding).unwrap();
            assert_eq!(std::fs::read(&path).unwrap(), to_bytes(&m, encoding));
        }
        same(&m, &load(&path).unwrap());
        let regions = [
            [0.0, 0.0, 40.0, 40.0],
            [-1e9, -1e9, 1e9, 1e9],
            [f64::NEG_INFINITY, 100.0, f64::INFINITY, 100.0],
            [5000.0, 5000.0, 6000.0, 6000.0],
            [123.4, 77.0, 301.0, 250.5],
        ];
        for r in regions {
            let region = region_box(r).unwrap();
            let got = load_region(&path, r).unwrap();
            got.check_invariants().unwrap();
            let want: Vec<&Instance> = m
                .instances()
                .into_iter()
                .filter(|i| region.intersects(&i.aabb()))
                .collect();
            assert_eq!(got.instances(), want, "{r:?}");
            assert_eq!(got.next_id(), m.next_id());
            for i in got.instances() {
                assert_eq!(got.drives(i.id), &[3]);
            }
        }
        // Compact files and version-1 files give the same regions (v1: read whole).
        save(&m, &path, Encoding::Compact).unwrap();
        let r = [123.4, 77.0, 301.0, 250.5];
        let ids_c = load_region(&path, r).unwrap().ids();
        std::fs::write(&path, crate::persist::to_bytes(&m)).unwrap();
        let ids_1 = load_region(&path, r).unwrap().ids();
        assert_eq!(ids_c, ids_1);
        assert!(!ids_1.is_empty());
        // Bad regions.
        for bad in [
            [f64::NAN, 0.0, 1.0, 1.0],
            [0.0, 0.0, 1.0, f64::NAN],
            [2.0, 0.0, 1.0, 1.0],
            [0.0, 2.0, 1.0, 1.0],
        ] {
            assert!(load_region(&path, bad).is_err(), "{bad:?}");
        }
        assert!(matches!(
            load_region(&dir.join("missing.icmap"), r),
            Err(GeomError::Io { .. })
        ));
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// A region load reads only the blocks it needs: a corrupt block elsewhere goes unnoticed by
    /// it (and is found by a full load).
    #[test]
    fn region_load_skips_other_blocks() {
        let dir = std::env::temp_dir().join(format!("icmap-persist2r-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("m.icmap");
        let m = grid_map(4 * BLOCK_INSTANCES, 0.0);
        let mut bytes = to_bytes(&m, Encoding::Exact);
        let head = parse_head(&bytes).unwrap();
        assert_eq!(head.blocks.len(), 4);
        let last = head.blocks[3];
        let at = (head.len() + last.offset + last.len / 2) as usize;
        bytes[at] ^= 0x40;
        std::fs::write(&path, &bytes).unwrap();
        let far = entry_box(&last);
        let region = head
            .blocks
            .iter()
            .map(entry_box)
            .find(|b| !b.intersects(&far))
            .expect("a block away from the last one");
        let r = [region.mins.x, region.mins.y, region.maxs.x, region.maxs.y];
        let got = load_region(&path, r).unwrap();
        assert!(!got.is_empty());
        assert!(reason(load(&path).unwrap_err()).contains("checksum mismatch in block 3"));
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn truncation_and_flipped_bytes_are_detected() {
        for encoding in [Encoding::Exact, Encoding::Compact] {
            let bytes = to_bytes(&sample_map(), encoding);
            for cut in 0..bytes.len() {
                let msg = reason(from_bytes(&bytes[..cut]).unwrap_err());
                assert!(
                    msg.contains("truncated") || msg.contains("empty file"),
                    "cut {cut}: {msg}"
                );
            }
            let mut longer = bytes.clone();
            longer.push(0);
            assert!(reason(from_bytes(&longer).unwrap_err()).contains("trailing"));
            for i in 0..bytes.len() {
                for bit in [0u8, 3, 7] {
                    let mut b = bytes.clone();
                    b[i] ^= 1 << bit;
                    assert!(
                        matches!(from_bytes(&b), Err(GeomError::Format { .. })),
                        "byte {i} bit {bit}"
                    );
                }
            }
        }
        let mut b = to_bytes(&sample_map(), Encoding::Exact);
        b[8..12].copy_from_slice(&3u32.to_le_bytes());
        assert!(reason(from_bytes(&b).unwrap_err()).contains("unsupported format version 3"));
        assert!(reason(from_bytes(b"{\"type\": 1}").unwrap_err()).contains("not an icmapper"));
    }

    /// Rewrites the head checksum after an edit of the header or index. An absurd block count
    /// wraps (as in a release build), so the debug build runs the same tests.
    fn reseal_head(b: &mut [u8]) {
        let n_blocks = u64::from_le_bytes(b[52..60].try_into().unwrap()) as usize;
        let end = (PREFIX + HEADER).wrapping_add(n_blocks.wrapping_mul(INDEX_ENTRY));
        let sum = hash64(&b[..end]);
        b[end..end + 8].copy_from_slice(&sum.to_le_bytes());
    }

    /// Rewrites the checksum of block 0 after an edit of its bytes.
    fn reseal_block0(b: &mut [u8]) {
        let head = PREFIX + HEADER + INDEX_ENTRY + 8;
        let len = u64::from_le_bytes(
            b[PREFIX + HEADER + 40..PREFIX + HEADER + 48]
                .try_into()
                .unwrap(),
        ) as usize;
        let sum = hash64(&b[head..head + len]);
        b[PREFIX + HEADER + 56..PREFIX + HEADER + 64].copy_from_slice(&sum.to_le_bytes());
        reseal_head(b);
    }

    #[test]
    fn a_coordinate_outside_the_domain_is_refused_on_load() {
        // Issue 14.3: a record holding |x| > 1e7 m, with valid checksums, is not a valid map.
        let cfg = MapConfig {
            smoothing: 0.5,
            spacing: 1.0,
        };
        let line = vec![p(1234.5, 0.0), p(1300.25, 1.0)];
        let m = GlobalMap::from_parts(cfg, 1, vec![inst(0, MapClass::Divider, line, (0, 0), 1)])
            .unwrap();
        let mut b = to_bytes(&m, Encoding::Exact);
        assert!(from_bytes(&b).is_ok());
        let needle = 1234.5f64.to_le_bytes();
        let rec = PREFIX + HEADER + INDEX_ENTRY + 8; // block 0's first record
        let at = rec
            + b[rec..]
                .windows(8)
                .position(|w| w == needle)
                .expect("an exact record stores the coordinate's bits");
        b[at..at + 8].copy_from_slice(&5e7f64.to_le_bytes());
        // the block's box in the index (min x, min y, max x, max y) follows the record
        let bx = PREFIX + HEADER;
        b[bx + 16..bx + 24].copy_from_slice(&1e9f64.to_le_bytes());
        reseal_block0(&mut b);
        let err = from_bytes(&b).unwrap_err();
        assert!(
            format!("{err}").contains("outside the valid domain"),
            "unexpected error: {err}"
        );
    }

    #[test]
    fn absurd_headers_and_values_with_valid_checksums() {
        let bytes = to_bytes(&sample_map(), Encoding::Exact);
        let set = |off: usize, v: u64| {
            let mut b = bytes.clone();
            b[off..off + 8].copy_from_slice(&v.to_le_bytes());
            reseal_head(&mut b);
            reason(from_bytes(&b).unwrap_err())
        };
        // Header fields: next_id 28, count 36, quantum 44, n_blocks 52, body_len 60, reserved 68.
        assert!(set(36, u64::MAX).contains("instances"));
        assert!(set(52, u64::MAX >> 1).contains("blocks declared"));
        assert!(set(60, u64::MAX).contains("truncated"));
        assert!(set(68, 1).contains("reserved"));
        assert!(set(44, f64::NAN.to_bits()).contains("quantum"));
        assert!(set(28, 1).contains("next_id"));
        assert!(set(20, (-1.0f64).to_bits()).contains("spacing"));
        // Index entry 0: count 112, box 76.
        assert!(set(PREFIX + HEADER + 48, u64::MAX).contains("instances"));
        assert!(set(PREFIX + HEADER, f64::NAN.to_bits()).contains("box"));
        // Block 0 starts with the first record; its first byte is the id varint, then flags.
        let rec = PREFIX + HEADER + INDEX_ENTRY + 8;
        let mut b = bytes.clone();
        b[rec + 1] = 0b0111; // class 3
        reseal_block0(&mut b);
        assert!(reason(from_bytes(&b).unwrap_err()).contains("flags"));
        let mut b = bytes.clone();
        b[rec + 1] ^= 0b100; // closed flag against the class
        reseal_block0(&mut b);
        assert!(matches!(from_bytes(&b), Err(GeomError::Format { .. })));
        // A point count of 2^63 with a valid checksum: an error, no allocation.
        let mut b = bytes.clone();
        let mut c = Cursor {
            bytes: &b[rec..],
            pos: 0,
        };
        c.varint("id").unwrap();
        c.u8("flags").unwrap();
        for what in ["first", "span", "obs"] {
            c.varint(what).unwrap();
        }
        let nd = c.varint("drives").unwrap();
        for _ in 0..nd {
            c.varint("drive").unwrap();
        }
        let at = rec + c.pos;
        let mut huge = Vec::new();
        put_varint(&mut huge, 1 << 62);
        b.splice(at..at + 1, huge.iter().copied());
        // (Lengths now disagree with the index as well; either check may fire first.)
        assert!(matches!(from_bytes(&b), Err(GeomError::Format { .. })));
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]
        #[test]
        fn arbitrary_bytes_never_panic(mut b in prop::collection::vec(any::<u8>(), 0..400), keep in 0u8..3) {
            if keep > 0 && b.len() >= PREFIX + HEADER + 8 {
                b[..8].copy_from_slice(MAGIC);
                b[8..12].copy_from_slice(&FORMAT_VERSION_2.to_le_bytes());
                b[52..60].copy_from_slice(&((keep - 1) as u64).to_le_bytes());
                if b.len() >= PREFIX + HEADER + 8 + (keep as usize - 1) * INDEX_ENTRY {
                    reseal_head(&mut b);
                }
            }
            let _ = from_bytes(&b);
        }

        #[test]
        fn random_maps_round_trip(insts in prop::collection::vec(
            (0u8..3, prop::collection::vec((-1e5..1e5f64, -1e5..1e5f64), 3..30), -100i64..100, 0i64..50, 1u32..1000,
             prop::collection::vec(0u32..20, 0..4)), 0..40), compact in any::<bool>()) {
            let mut drives = Vec::new();
            let instances: Vec<Instance> = insts.into_iter().enumerate().map(|(k, (c, pts, f, d, o, dr))| {
                drives.push(dr);
                inst(k as u64 * 3, MapClass::ALL[c as usize], pts.into_iter().map(|(x, y)| p(x, y)).collect(), (f, f + d), o)
            }).collect();
            let next = instances.len() as u64 * 3 + 1;
            let mut m = GlobalMap::from_parts(MapConfig::default(), next, instances).unwrap();
            for (k, dr) in drives.iter().enumerate() {
                m.set_drives(k as u64 * 3, dr).unwrap();
            }
            let encoding = if compact { Encoding::Compact } else { Encoding::Exact };
            let back = from_bytes(&to_bytes(&m, encoding)).unwrap();
            prop_assert_eq!(back.ids(), m.ids());
            for a in m.instances() {
                let b = back.get(a.id).unwrap();
                prop_assert_eq!(m.drives(a.id), back.drives(a.id));
                prop_assert_eq!((a.first_frame, a.last_frame, a.observations), (b.first_frame, b.last_frame, b.observations));
                for (q, r) in a.points.iter().zip(&b.points) {
                    let tol = if compact { QUANTUM / 2.0 + 1e-9 } else { 0.0 };
                    prop_assert!((q - r).abs().max() <= tol);
                }
            }
        }
    }
}

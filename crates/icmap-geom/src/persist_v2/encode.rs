//! Writing: instance records, blocks in Hilbert order, the header, index and checksums.

use super::codec::{hash64, hilbert_key, put_varint, quantisable, round_i64, zigzag, Predictor};
use super::{
    Encoding, BLOCK_INSTANCES, FORMAT_VERSION_2, HEADER, INDEX_ENTRY, INV_QUANTUM, PREFIX, QUANTUM,
};
use crate::error::Result;
use crate::persist::{write_atomic_parts, MAGIC};
use crate::store::{GlobalMap, Instance};
use crate::types::Point;
use parry2d_f64::bounding_volume::{Aabb, BoundingVolume};
use rayon::prelude::*;
use std::path::Path;

/// Appends the record of `inst`; returns the bounding box of its coordinates as they will be
/// decoded (quantised or not).
pub(super) fn encode_instance(
    out: &mut Vec<u8>,
    inst: &Instance,
    drives: &[u32],
    encoding: Encoding,
) -> Aabb {
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
    let mut pred = Predictor::default();
    for p in &inst.points {
        let (x, y) = (round_i64(p.x * INV_QUANTUM), round_i64(p.y * INV_QUANTUM));
        let (px, py) = pred.predict();
        put_varint(out, zigzag(x.wrapping_sub(px)));
        put_varint(out, zigzag(y.wrapping_sub(py)));
        pred.push(x, y);
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
pub(super) fn encode(map: &GlobalMap, encoding: Encoding) -> (Vec<u8>, Vec<Vec<u8>>) {
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

//! Decoding: instance records and blocks (checked against the index), the map assembled from
//! them, and the dispatch between versions 1 and 2.

use super::codec::{hash64, unzigzag, Predictor};
use super::cursor::{Cursor, Parse};
use super::head::{parse_head, BlockEntry, Head};
use super::{FORMAT_VERSION_2, PREFIX};
use crate::error::{GeomError, Result};
use crate::persist::MAGIC;
use crate::store::{GlobalMap, Instance};
use crate::types::{MapClass, Point};
use parry2d_f64::bounding_volume::{Aabb, BoundingVolume};
use rayon::prelude::*;

/// An instance as decoded, with its drives (and, once checked, its bounding box).
pub(super) type Decoded = (Instance, Vec<u32>);
/// A decoded block after the checks: the instances with their boxes, and the drive lists.
pub(super) type Checked = (Vec<(Instance, Aabb)>, Vec<(u64, Box<[u32]>)>);

pub(super) fn decode_instance(c: &mut Cursor<'_>, quantum: f64) -> Parse<Decoded> {
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
            points.push(c.point()?);
        }
    } else {
        if quantum == 0.0 {
            return Err(format!(
                "instance {id} is quantised but the file has no quantum"
            ));
        }
        let mut pred = Predictor::default();
        for _ in 0..n {
            let rx = unzigzag(c.varint("coordinate")?);
            let ry = unzigzag(c.varint("coordinate")?);
            let (px, py) = pred.predict();
            let (x, y) = (px.wrapping_add(rx), py.wrapping_add(ry));
            points.push(Point::new(x as f64 * quantum, y as f64 * quantum));
            pred.push(x, y);
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
pub(super) fn decode_block(
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
    let mut c = Cursor::new(bytes);
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
pub(super) fn assemble(head: &Head, blocks: Vec<Checked>) -> Parse<GlobalMap> {
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

pub(super) fn format_error(path: &str) -> impl Fn(String) -> GeomError + '_ {
    move |reason| GeomError::Format {
        path: path.to_string(),
        reason,
    }
}

/// The format version of a file that starts with `prefix` (at least the magic and the version),
/// or the error for a foreign / truncated start.
pub(super) fn version_of(prefix: &[u8]) -> Parse<u32> {
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
pub(super) fn with_path(e: GeomError, path: &str) -> GeomError {
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
pub(super) enum Parsed {
    Map(Box<GlobalMap>),
    Blocks(Head, Vec<Checked>),
}

pub(super) fn decode_any(bytes: &[u8], path: &str, region: Option<&Aabb>) -> Result<Parsed> {
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

pub(super) fn finish(parsed: Parsed, path: &str) -> Result<GlobalMap> {
    match parsed {
        Parsed::Map(map) => Ok(*map),
        Parsed::Blocks(head, blocks) => assemble(&head, blocks).map_err(format_error(path)),
    }
}

pub(super) fn parse_any(bytes: &[u8], path: &str, region: Option<&Aabb>) -> Result<GlobalMap> {
    finish(decode_any(bytes, path, region)?, path)
}

pub(super) fn entry_box(e: &BlockEntry) -> Aabb {
    Aabb::new(
        Point::new(e.bbox[0], e.bbox[1]),
        Point::new(e.bbox[2], e.bbox[3]),
    )
}

/// The map of the instances of `map` whose box meets `region` (same config and next id).
pub(super) fn filter_region(map: GlobalMap, region: &Aabb) -> GlobalMap {
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

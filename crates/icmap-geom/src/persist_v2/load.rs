//! Reading files: whole maps, and regions (only the blocks that meet the region are read).

use super::decode::{
    assemble, decode_any, decode_block, entry_box, finish, format_error, version_of, Checked,
};
use super::head::{parse_header, parse_index};
use super::{FORMAT_VERSION_2, HEADER, INDEX_ENTRY, PREFIX};
use crate::error::{GeomError, Result};
use crate::store::GlobalMap;
use crate::types::Point;
use parry2d_f64::bounding_volume::{Aabb, BoundingVolume};
use rayon::prelude::*;
use std::fs::File;
use std::io::Read;
use std::path::Path;

/// Reads a map file of version 1 or 2; a foreign, truncated or corrupt file gives
/// `GeomError::Format`, a missing or unreadable one `GeomError::Io`. A version-2 file is read
/// block by block (in parallel, into reused buffers), not into one buffer of its size.
pub fn load(path: &Path) -> Result<GlobalMap> {
    load_file(path, None)
}

/// Reads `buf.len()` bytes of `f` at offset `at` (a positioned read: threads share the file).
#[cfg(unix)]
pub(super) fn read_block(f: &File, at: u64, buf: &mut [u8]) -> std::io::Result<()> {
    use std::os::unix::fs::FileExt;
    f.read_exact_at(buf, at)
}

#[cfg(not(unix))]
pub(super) fn read_block(f: &File, at: u64, buf: &mut [u8]) -> std::io::Result<()> {
    use std::io::{Seek, SeekFrom};
    let mut f = f;
    f.seek(SeekFrom::Start(at))?;
    f.read_exact(buf)
}

/// [`load`] (`region` None) and [`load_region`]: a version-2 file's header and index, then the
/// blocks that meet the region, read and decoded in parallel; other versions are read whole.
pub(super) fn load_file(path: &Path, region: Option<Aabb>) -> Result<GlobalMap> {
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

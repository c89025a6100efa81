//! The head of a version-2 file: the fixed header and the block index, checked.

use super::codec::hash64;
use super::cursor::{Cursor, Parse};
use super::{HEADER, INDEX_ENTRY, PREFIX};
use crate::store::MapConfig;

/// The head of a version-2 file: config, counts and the block index.
pub(super) struct Head {
    pub(super) config: MapConfig,
    pub(super) next_id: u64,
    pub(super) count: u64,
    pub(super) quantum: f64,
    pub(super) body_len: u64,
    pub(super) blocks: Vec<BlockEntry>,
}

#[derive(Debug, Clone, Copy)]
pub(super) struct BlockEntry {
    pub(super) bbox: [f64; 4],
    pub(super) offset: u64,
    pub(super) len: u64,
    pub(super) count: u64,
    pub(super) sum: u64,
}

impl Head {
    /// Bytes of the head (magic .. head checksum).
    pub(super) fn len(&self) -> u64 {
        (PREFIX + HEADER + 8) as u64 + (self.blocks.len() * INDEX_ENTRY) as u64
    }
}

/// Reads the fixed header after magic and version (`bytes` = the first PREFIX + HEADER bytes):
/// returns the header fields and the number of blocks, checked against `file_len`.
pub(super) fn parse_header(bytes: &[u8], file_len: u64) -> Parse<(Head, usize)> {
    let mut c = Cursor::new(&bytes[PREFIX..]);
    let (config, next_id, count) = c.map_head()?;
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
            config,
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
pub(super) fn parse_index(head_bytes: &[u8], mut head: Head, n_blocks: usize) -> Parse<Head> {
    let body = head_bytes.len() - 8;
    let stored = u64::from_le_bytes(head_bytes[body..].try_into().expect("8 bytes"));
    let computed = hash64(&head_bytes[..body]);
    if stored != computed {
        return Err(format!(
            "header checksum mismatch (stored {stored:#018x}, computed {computed:#018x}): the file is corrupt"
        ));
    }
    let mut c = Cursor::new(&head_bytes[PREFIX + HEADER..body]);
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
pub(super) fn parse_head(bytes: &[u8]) -> Parse<Head> {
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

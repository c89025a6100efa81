//! The bounds-checked little-endian reader of the map files (the version-2 head and blocks, and
//! the whole version-1 file), with the parse error type.

use crate::store::MapConfig;
use crate::types::Point;
use std::fmt::Arguments;

pub(crate) type Parse<T> = std::result::Result<T, String>;

/// A bounds-checked reader over one block or the head of a version-2 file, or over a whole
/// version-1 file (its errors then speak of the file).
pub(crate) struct Cursor<'a> {
    pub(crate) bytes: &'a [u8],
    pub(crate) pos: usize,
    whole_file: bool,
}

impl<'a> Cursor<'a> {
    /// A reader at the start of a section (a block or the head).
    pub(crate) fn new(bytes: &'a [u8]) -> Self {
        Cursor {
            bytes,
            pos: 0,
            whole_file: false,
        }
    }
    /// A reader at the start of a whole file.
    pub(crate) fn whole_file(bytes: &'a [u8]) -> Self {
        Cursor {
            bytes,
            pos: 0,
            whole_file: true,
        }
    }
    pub(crate) fn remaining(&self) -> usize {
        self.bytes.len() - self.pos
    }
    pub(crate) fn take(&mut self, n: usize, what: &str) -> Parse<&'a [u8]> {
        if self.remaining() < n {
            let end = if self.whole_file {
                "but the file ends at"
            } else {
                "of a section of"
            };
            return Err(format!(
                "truncated: {what} needs {n} byte(s) at offset {} {end} {}",
                self.pos,
                self.bytes.len()
            ));
        }
        let s = &self.bytes[self.pos..self.pos + n];
        self.pos += n;
        Ok(s)
    }
    #[inline]
    pub(crate) fn u8(&mut self, what: &str) -> Parse<u8> {
        match self.bytes.get(self.pos) {
            Some(&b) => {
                self.pos += 1;
                Ok(b)
            }
            None => Err(self.take(1, what).err().unwrap_or_default()),
        }
    }
    /// `N` bytes.
    fn array<const N: usize>(&mut self, what: &str) -> Parse<[u8; N]> {
        Ok(self.take(N, what)?.try_into().expect("N bytes"))
    }
    pub(crate) fn u32(&mut self, what: &str) -> Parse<u32> {
        Ok(u32::from_le_bytes(self.array(what)?))
    }
    pub(crate) fn u64(&mut self, what: &str) -> Parse<u64> {
        Ok(u64::from_le_bytes(self.array(what)?))
    }
    pub(crate) fn i64(&mut self, what: &str) -> Parse<i64> {
        Ok(i64::from_le_bytes(self.array(what)?))
    }
    pub(crate) fn f64(&mut self, what: &str) -> Parse<f64> {
        Ok(f64::from_le_bytes(self.array(what)?))
    }
    /// A point stored exactly (two f64).
    pub(crate) fn point(&mut self) -> Parse<Point> {
        let x = self.f64("coordinate")?;
        let y = self.f64("coordinate")?;
        Ok(Point::new(x, y))
    }
    /// The fields both file versions start with after the version: the map's configuration,
    /// its next id and its instance count.
    pub(crate) fn map_head(&mut self) -> Parse<(MapConfig, u64, u64)> {
        let smoothing = self.f64("smoothing")?;
        let spacing = self.f64("spacing")?;
        let next_id = self.u64("next_id")?;
        let count = self.u64("instance count")?;
        Ok((MapConfig { smoothing, spacing }, next_id, count))
    }
    #[inline]
    pub(crate) fn varint(&mut self, what: &str) -> Parse<u64> {
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
    pub(crate) fn varint_long(&mut self, what: &str) -> Parse<u64> {
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
    pub(crate) fn count(&mut self, what: &str, min_bytes: usize) -> Parse<usize> {
        let n = self.varint(what)?;
        self.fits(n, min_bytes, format_args!("{n} {what} declared"))?;
        Ok(n as usize)
    }
    /// Checks that `n` items of at least `min_bytes` each fit in the rest; the error says
    /// `declared` (what the file declares) and how many bytes remain.
    pub(crate) fn fits(&self, n: u64, min_bytes: usize, declared: Arguments<'_>) -> Parse<()> {
        if n > (self.remaining() / min_bytes.max(1)) as u64 {
            let place = if self.whole_file { "" } else { " in the block" };
            return Err(format!(
                "truncated or corrupt: {declared} but only {} bytes remain{place}",
                self.remaining()
            ));
        }
        Ok(())
    }
}

//! The bounds-checked reader of the head and the blocks, with the parse error type.

pub(super) type Parse<T> = std::result::Result<T, String>;

/// A bounds-checked reader over one block or the head.
pub(super) struct Cursor<'a> {
    pub(super) bytes: &'a [u8],
    pub(super) pos: usize,
}

impl<'a> Cursor<'a> {
    pub(super) fn remaining(&self) -> usize {
        self.bytes.len() - self.pos
    }
    pub(super) fn take(&mut self, n: usize, what: &str) -> Parse<&'a [u8]> {
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
    pub(super) fn u8(&mut self, what: &str) -> Parse<u8> {
        match self.bytes.get(self.pos) {
            Some(&b) => {
                self.pos += 1;
                Ok(b)
            }
            None => Err(self.take(1, what).err().unwrap_or_default()),
        }
    }
    pub(super) fn u64(&mut self, what: &str) -> Parse<u64> {
        Ok(u64::from_le_bytes(
            self.take(8, what)?.try_into().expect("8 bytes"),
        ))
    }
    pub(super) fn f64(&mut self, what: &str) -> Parse<f64> {
        Ok(f64::from_le_bytes(
            self.take(8, what)?.try_into().expect("8 bytes"),
        ))
    }
    #[inline]
    pub(super) fn varint(&mut self, what: &str) -> Parse<u64> {
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
    pub(super) fn varint_long(&mut self, what: &str) -> Parse<u64> {
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
    pub(super) fn count(&mut self, what: &str, min_bytes: usize) -> Parse<usize> {
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

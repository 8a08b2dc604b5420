//! OMG CDR (XCDR1), the wire form of ROS 2 messages in DDS and in bags.
//!
//! A serialized message starts with a 4-byte encapsulation header (`00 01`
//! little-endian, `00 00` big-endian, then two option bytes); every
//! primitive is aligned to its own size (at most 8) counted from the byte
//! after that header. Strings are a `u32` length that counts a trailing
//! NUL, the bytes, and the NUL; sequences a `u32` element count, then the
//! elements; fixed arrays have no count.
//!
//! The writer always writes little-endian (what every ROS 2 middleware on
//! x86 and ARM sends); the reader takes either byte order.

use thiserror::Error;

/// Why bytes are not a message of the expected type.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum CdrError {
    #[error("{len} bytes are too few for a CDR encapsulation header")]
    NoHeader { len: usize },
    #[error("encapsulation {0:02x?} is not plain CDR (00 00 or 00 01)")]
    Encapsulation([u8; 2]),
    #[error("message ends at byte {at}: {needed} more bytes were expected")]
    Truncated { at: usize, needed: usize },
    #[error("string at byte {at} is not NUL-terminated UTF-8")]
    BadString { at: usize },
    #[error("sequence at byte {at} claims {count} elements, more than the {left} bytes left")]
    SequenceTooLong { at: usize, count: u32, left: usize },
    #[error("{extra} bytes after the end of the message")]
    TrailingBytes { extra: usize },
}

/// Builds one serialized message.
#[derive(Debug, Clone)]
pub struct CdrWriter {
    buf: Vec<u8>,
}

/// Offset of the body: alignment is counted from here.
const ORIGIN: usize = 4;

impl Default for CdrWriter {
    fn default() -> Self {
        Self::new()
    }
}

impl CdrWriter {
    pub fn new() -> Self {
        CdrWriter {
            buf: vec![0x00, 0x01, 0x00, 0x00],
        }
    }

    fn align(&mut self, n: usize) {
        while !(self.buf.len() - ORIGIN).is_multiple_of(n) {
            self.buf.push(0);
        }
    }

    pub fn u8(&mut self, v: u8) {
        self.buf.push(v);
    }

    pub fn bool(&mut self, v: bool) {
        self.buf.push(u8::from(v));
    }

    pub fn u32(&mut self, v: u32) {
        self.align(4);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    pub fn i32(&mut self, v: i32) {
        self.align(4);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    pub fn f32(&mut self, v: f32) {
        self.align(4);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    pub fn f64(&mut self, v: f64) {
        self.align(8);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    /// A sequence's element count; panics never: a longer sequence than
    /// `u32::MAX` cannot be built in memory for these messages, and is
    /// written as `u32::MAX` (the reader then refuses it).
    pub fn count(&mut self, n: usize) {
        self.u32(u32::try_from(n).unwrap_or(u32::MAX));
    }

    pub fn string(&mut self, s: &str) {
        self.count(s.len() + 1);
        self.buf.extend_from_slice(s.as_bytes());
        self.buf.push(0);
    }

    pub fn f32_seq(&mut self, v: &[f32]) {
        self.count(v.len());
        for &x in v {
            self.f32(x);
        }
    }

    pub fn u8_seq(&mut self, v: &[u8]) {
        self.count(v.len());
        self.buf.extend_from_slice(v);
    }

    pub fn i8_seq(&mut self, v: &[i8]) {
        self.count(v.len());
        self.buf.extend(v.iter().map(|&x| x as u8));
    }

    /// The message's bytes, header included.
    pub fn finish(self) -> Vec<u8> {
        self.buf
    }
}

/// Reads one serialized message.
#[derive(Debug, Clone)]
pub struct CdrReader<'a> {
    data: &'a [u8],
    pos: usize,
    big_endian: bool,
}

impl<'a> CdrReader<'a> {
    /// Checks the encapsulation header.
    pub fn new(data: &'a [u8]) -> Result<Self, CdrError> {
        let header = data
            .get(..ORIGIN)
            .ok_or(CdrError::NoHeader { len: data.len() })?;
        let big_endian = match [header[0], header[1]] {
            [0x00, 0x00] => true,
            [0x00, 0x01] => false,
            other => return Err(CdrError::Encapsulation(other)),
        };
        Ok(CdrReader {
            data,
            pos: ORIGIN,
            big_endian,
        })
    }

    fn take<const N: usize>(&mut self) -> Result<[u8; N], CdrError> {
        let bytes = self
            .data
            .get(self.pos..self.pos + N)
            .ok_or(CdrError::Truncated {
                at: self.pos,
                needed: N,
            })?;
        self.pos += N;
        let mut out = [0u8; N];
        out.copy_from_slice(bytes);
        if self.big_endian {
            out.reverse();
        }
        Ok(out)
    }

    fn align(&mut self, n: usize) {
        let body = self.pos - ORIGIN;
        self.pos += (n - body % n) % n;
    }

    pub fn u8(&mut self) -> Result<u8, CdrError> {
        Ok(self.take::<1>()?[0])
    }

    pub fn bool(&mut self) -> Result<bool, CdrError> {
        Ok(self.u8()? != 0)
    }

    pub fn u32(&mut self) -> Result<u32, CdrError> {
        self.align(4);
        Ok(u32::from_le_bytes(self.take()?))
    }

    pub fn i32(&mut self) -> Result<i32, CdrError> {
        self.align(4);
        Ok(i32::from_le_bytes(self.take()?))
    }

    pub fn f32(&mut self) -> Result<f32, CdrError> {
        self.align(4);
        Ok(f32::from_le_bytes(self.take()?))
    }

    pub fn f64(&mut self) -> Result<f64, CdrError> {
        self.align(8);
        Ok(f64::from_le_bytes(self.take()?))
    }

    /// A sequence's element count, refused when `element_size`-byte
    /// elements that many could not fit in what is left (a corrupt count
    /// must not drive a huge allocation).
    pub fn count(&mut self, element_size: usize) -> Result<usize, CdrError> {
        let count = self.u32()?;
        let at = self.pos;
        let left = self.data.len().saturating_sub(at);
        let n = count as usize;
        if n.saturating_mul(element_size.max(1)) > left {
            return Err(CdrError::SequenceTooLong { at, count, left });
        }
        Ok(n)
    }

    pub fn string(&mut self) -> Result<String, CdrError> {
        let n = self.count(1)?;
        let at = self.pos;
        let bytes = &self.data[at..at + n];
        self.pos += n;
        match bytes.split_last() {
            Some((0, text)) => std::str::from_utf8(text)
                .map(str::to_owned)
                .map_err(|_| CdrError::BadString { at }),
            // An empty string is sometimes written with length 0.
            None => Ok(String::new()),
            Some(_) => Err(CdrError::BadString { at }),
        }
    }

    pub fn f32_seq(&mut self) -> Result<Vec<f32>, CdrError> {
        let n = self.count(4)?;
        (0..n).map(|_| self.f32()).collect()
    }

    pub fn u8_seq(&mut self) -> Result<Vec<u8>, CdrError> {
        let n = self.count(1)?;
        let v = self.data[self.pos..self.pos + n].to_vec();
        self.pos += n;
        Ok(v)
    }

    pub fn i8_seq(&mut self) -> Result<Vec<i8>, CdrError> {
        Ok(self.u8_seq()?.into_iter().map(|b| b as i8).collect())
    }

    /// Checks that only alignment padding (at most 7 bytes) follows.
    pub fn finish(self) -> Result<(), CdrError> {
        let extra = self.data.len().saturating_sub(self.pos);
        if extra >= 8 {
            return Err(CdrError::TrailingBytes { extra });
        }
        Ok(())
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn primitives_are_aligned_from_the_body() {
        let mut w = CdrWriter::new();
        w.u8(7);
        w.f64(1.5);
        w.string("ab");
        w.u32(9);
        let bytes = w.finish();
        // header, u8, 7 bytes padding, f64, len 3, "ab\0", 1 byte padding, u32.
        assert_eq!(bytes.len(), 4 + 1 + 7 + 8 + 4 + 3 + 1 + 4);
        assert_eq!(&bytes[..4], &[0, 1, 0, 0]);
        let mut r = CdrReader::new(&bytes).unwrap();
        assert_eq!(r.u8().unwrap(), 7);
        assert_eq!(r.f64().unwrap(), 1.5);
        assert_eq!(r.string().unwrap(), "ab");
        assert_eq!(r.u32().unwrap(), 9);
        r.finish().unwrap();
    }

    #[test]
    fn big_endian_messages_are_read() {
        let bytes = [
            0, 0, 0, 0, 0, 0, 0, 5, 0, 0, 0, 0, 0x3f, 0xf8, 0, 0, 0, 0, 0, 0,
        ];
        let mut r = CdrReader::new(&bytes).unwrap();
        assert_eq!(r.u32().unwrap(), 5);
        assert_eq!(r.f64().unwrap(), 1.5);
    }

    #[test]
    fn damage_is_named() {
        assert_eq!(
            CdrReader::new(&[0, 1]).unwrap_err(),
            CdrError::NoHeader { len: 2 }
        );
        assert!(matches!(
            CdrReader::new(&[0, 7, 0, 0]).unwrap_err(),
            CdrError::Encapsulation(_)
        ));
        let mut r = CdrReader::new(&[0, 1, 0, 0, 0xff, 0xff, 0xff, 0x7f]).unwrap();
        assert!(matches!(
            r.f32_seq().unwrap_err(),
            CdrError::SequenceTooLong { .. }
        ));
        let mut r = CdrReader::new(&[0, 1, 0, 0, 3, 0, 0, 0, b'a', b'b', b'c']).unwrap();
        assert_eq!(r.string().unwrap_err(), CdrError::BadString { at: 8 });
        let mut r = CdrReader::new(&[0, 1, 0, 0, 1, 0]).unwrap();
        assert!(matches!(r.u32().unwrap_err(), CdrError::Truncated { .. }));
    }

    proptest! {
        #[test]
        fn what_is_written_reads_back(
            a in any::<u8>(), b in any::<f64>(), s in "[ -~]{0,20}",
            v in proptest::collection::vec(any::<f32>(), 0..20), c in any::<i32>(),
        ) {
            let mut w = CdrWriter::new();
            w.u8(a);
            w.f64(b);
            w.string(&s);
            w.f32_seq(&v);
            w.i32(c);
            let bytes = w.finish();
            let mut r = CdrReader::new(&bytes).unwrap();
            prop_assert_eq!(r.u8().unwrap(), a);
            prop_assert_eq!(r.f64().unwrap().to_bits(), b.to_bits());
            prop_assert_eq!(r.string().unwrap(), s);
            let back = r.f32_seq().unwrap();
            prop_assert_eq!(back.iter().map(|x| x.to_bits()).collect::<Vec<_>>(),
                v.iter().map(|x| x.to_bits()).collect::<Vec<_>>());
            prop_assert_eq!(r.i32().unwrap(), c);
            r.finish().unwrap();
        }

        #[test]
        fn any_bytes_give_an_answer_or_an_error(bytes in proptest::collection::vec(any::<u8>(), 0..64)) {
            if let Ok(mut r) = CdrReader::new(&bytes) {
                let _ = r.string();
                let _ = r.f32_seq();
                let _ = r.u8_seq();
                let _ = r.f64();
            }
        }
    }
}

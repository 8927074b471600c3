//! The CDR encoding of ROS 2 messages (OMG XCDR1, as rmw's Fast DDS and Cyclone DDS write it):
//! a 4-byte encapsulation header, then every primitive aligned to its own size counted from
//! the end of that header; strings and sequences are a `u32` length followed by the items.

/// Why a message could not be decoded.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CdrError(pub String);

impl std::fmt::Display for CdrError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for CdrError {}

/// Reads a CDR message field by field; every read checks the bytes left, so a truncated or
/// hostile message is an error, never a panic or a huge allocation.
#[derive(Debug)]
pub struct CdrReader<'a> {
    data: &'a [u8],
    pos: usize,
    little: bool,
}

impl<'a> CdrReader<'a> {
    /// Starts after the encapsulation header (plain CDR, little- or big-endian).
    pub fn new(message: &'a [u8]) -> Result<Self, CdrError> {
        let Some((header, data)) = message.split_at_checked(4) else {
            return Err(CdrError(format!(
                "a CDR message of {} bytes has no encapsulation header",
                message.len()
            )));
        };
        let little = match (header[0], header[1]) {
            (0, 0) => false,
            (0, 1) => true,
            (a, b) => {
                return Err(CdrError(format!(
                    "encapsulation {a:#04x}{b:02x} is not plain CDR (0x0000 or 0x0001)"
                )));
            }
        };
        Ok(Self {
            data,
            pos: 0,
            little,
        })
    }

    fn take<const N: usize>(&mut self, what: &str) -> Result<[u8; N], CdrError> {
        // Primitives are aligned to their size from the start of the body.
        let start = self.pos.div_ceil(N) * N;
        let bytes = self
            .data
            .get(start..start + N)
            .ok_or_else(|| CdrError(format!("message ends inside {what} (byte {start})")))?;
        self.pos = start + N;
        let mut out = [0; N];
        out.copy_from_slice(bytes);
        if !self.little {
            out.reverse();
        }
        Ok(out)
    }

    /// An `int32`.
    pub fn i32(&mut self, what: &str) -> Result<i32, CdrError> {
        self.take::<4>(what).map(i32::from_le_bytes)
    }
    /// A `uint32`.
    pub fn u32(&mut self, what: &str) -> Result<u32, CdrError> {
        self.take::<4>(what).map(u32::from_le_bytes)
    }
    /// A `float32`.
    pub fn f32(&mut self, what: &str) -> Result<f32, CdrError> {
        self.take::<4>(what).map(f32::from_le_bytes)
    }
    /// A `float64`.
    pub fn f64(&mut self, what: &str) -> Result<f64, CdrError> {
        self.take::<8>(what).map(f64::from_le_bytes)
    }

    /// A sequence's length, checked against the bytes left for items of `item` bytes.
    fn len(&mut self, what: &str, item: usize) -> Result<usize, CdrError> {
        let n = self.u32(what)? as usize;
        let left = self.data.len().saturating_sub(self.pos);
        if n.saturating_mul(item) > left {
            return Err(CdrError(format!(
                "{what} announces {n} items, but only {left} bytes are left"
            )));
        }
        Ok(n)
    }

    /// A `string` (its terminating NUL dropped).
    pub fn string(&mut self, what: &str) -> Result<String, CdrError> {
        let n = self.len(what, 1)?;
        let bytes = &self.data[self.pos..self.pos + n];
        self.pos += n;
        let bytes = bytes.strip_suffix(&[0]).unwrap_or(bytes);
        String::from_utf8(bytes.to_vec()).map_err(|_| CdrError(format!("{what} is not UTF-8")))
    }

    /// A `float32[]`.
    pub fn f32_seq(&mut self, what: &str) -> Result<Vec<f32>, CdrError> {
        let n = self.len(what, 4)?;
        (0..n).map(|_| self.f32(what)).collect()
    }

    /// Skips `n` `float64`s (a fixed array such as a covariance).
    pub fn skip_f64(&mut self, n: usize, what: &str) -> Result<(), CdrError> {
        for _ in 0..n {
            self.f64(what)?;
        }
        Ok(())
    }

    /// A sequence's length for items of at least `min_item` bytes.
    pub fn seq_len(&mut self, what: &str, min_item: usize) -> Result<usize, CdrError> {
        self.len(what, min_item)
    }
}

/// Writes a little-endian CDR message.
#[derive(Debug)]
pub struct CdrWriter {
    buf: Vec<u8>,
}

impl Default for CdrWriter {
    fn default() -> Self {
        Self {
            buf: vec![0, 1, 0, 0],
        }
    }
}

impl CdrWriter {
    fn put<const N: usize>(&mut self, bytes: [u8; N]) {
        let body = self.buf.len() - 4;
        let pad = body.div_ceil(N) * N - body;
        self.buf.extend(std::iter::repeat_n(0, pad));
        self.buf.extend_from_slice(&bytes);
    }
    /// An `int32`.
    pub fn i32(&mut self, v: i32) {
        self.put(v.to_le_bytes());
    }
    /// A `uint32`.
    pub fn u32(&mut self, v: u32) {
        self.put(v.to_le_bytes());
    }
    /// A `float32`.
    pub fn f32(&mut self, v: f32) {
        self.put(v.to_le_bytes());
    }
    /// A `float64`.
    pub fn f64(&mut self, v: f64) {
        self.put(v.to_le_bytes());
    }
    /// A `string`.
    pub fn string(&mut self, s: &str) {
        self.u32(u32::try_from(s.len() + 1).unwrap_or(u32::MAX));
        self.buf.extend_from_slice(s.as_bytes());
        self.buf.push(0);
    }
    /// A `float32[]`.
    pub fn f32_seq(&mut self, v: &[f32]) {
        self.u32(u32::try_from(v.len()).unwrap_or(u32::MAX));
        for &x in v {
            self.f32(x);
        }
    }
    /// The message.
    #[must_use]
    pub fn finish(self) -> Vec<u8> {
        self.buf
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fields_round_trip_with_their_alignment() {
        let mut w = CdrWriter::default();
        w.i32(-7);
        w.string("laser");
        w.f64(1.5);
        w.f32_seq(&[1.0, 2.5]);
        w.u32(9);
        let bytes = w.finish();
        // "laser\0" ends at body byte 14; the f64 starts at 16.
        assert_eq!(bytes.len(), 4 + 16 + 8 + 4 + 8 + 4);
        let mut r = CdrReader::new(&bytes).unwrap();
        assert_eq!(r.i32("a").unwrap(), -7);
        assert_eq!(r.string("b").unwrap(), "laser");
        assert_eq!(r.f64("c").unwrap(), 1.5);
        assert_eq!(r.f32_seq("d").unwrap(), vec![1.0, 2.5]);
        assert_eq!(r.u32("e").unwrap(), 9);
        assert!(r.u32("f").is_err());
    }

    #[test]
    fn a_hostile_sequence_length_is_an_error_not_an_allocation() {
        let mut w = CdrWriter::default();
        w.u32(u32::MAX);
        let bytes = w.finish();
        let err = CdrReader::new(&bytes)
            .unwrap()
            .f32_seq("ranges")
            .unwrap_err();
        assert!(err.0.contains("announces 4294967295 items"), "{err}");
        assert!(CdrReader::new(&[0, 1]).is_err());
        assert!(CdrReader::new(&[0, 9, 0, 0]).is_err());
    }
}

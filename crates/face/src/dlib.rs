//! A reader for dlib's binary serialisation (`dlib/serialize.h`), the format of dlib's `.dat`
//! model files. Integers are a control byte (byte count in the low nibble, sign in bit 7) and
//! that many little-endian bytes; floats are a mantissa and a base-2 exponent, each such an
//! integer; strings are a length and bytes; booleans are the characters '1' and '0'; DNN tensors
//! are a version, four dimensions and raw little-endian f32 values. Every error names the file
//! and the byte offset, so a truncated or foreign file is reported, never half-read.

use std::path::{Path, PathBuf};

use crate::FaceError;

pub(crate) struct Reader<'a> {
    path: &'a Path,
    bytes: &'a [u8],
    pos: usize,
}

/// A DNN tensor's values as dlib stores them, in (num_samples, k, nr, nc) order.
pub(crate) struct DlibTensor {
    pub values: Vec<f32>,
}

impl DlibTensor {
    pub fn len(&self) -> usize {
        self.values.len()
    }
}

impl<'a> Reader<'a> {
    pub fn new(path: &'a Path, bytes: &'a [u8]) -> Self {
        Reader {
            path,
            bytes,
            pos: 0,
        }
    }

    pub fn error(&self, reason: impl Into<String>) -> FaceError {
        FaceError::Model {
            path: PathBuf::from(self.path),
            reason: format!("at byte {}: {}", self.pos, reason.into()),
        }
    }

    pub fn at_end(&self) -> bool {
        self.pos == self.bytes.len()
    }

    fn take(&mut self, n: usize, what: &str) -> Result<&'a [u8], FaceError> {
        let end = self
            .pos
            .checked_add(n)
            .filter(|&e| e <= self.bytes.len())
            .ok_or_else(|| self.error(format!("file ends inside {what} (truncated download?)")))?;
        let slice = &self.bytes[self.pos..end];
        self.pos = end;
        Ok(slice)
    }

    /// A signed integer of at most eight bytes.
    pub fn int(&mut self) -> Result<i64, FaceError> {
        let control = self.take(1, "an integer")?[0];
        let size = usize::from(control & 0x0f);
        if size == 0 || size > 8 || control & 0x70 != 0 {
            self.pos -= 1;
            return Err(self.error(format!("byte {control:#04x} does not start a dlib integer")));
        }
        let mut value: u64 = 0;
        for (i, &b) in self.take(size, "an integer")?.iter().enumerate() {
            value |= u64::from(b) << (8 * i);
        }
        let value = i64::try_from(value).map_err(|_| self.error("integer out of range"))?;
        Ok(if control & 0x80 != 0 { -value } else { value })
    }

    /// A non-negative integer that counts or sizes something, at most `max`.
    pub fn size(&mut self, what: &str, max: usize) -> Result<usize, FaceError> {
        let v = self.int()?;
        usize::try_from(v)
            .ok()
            .filter(|&v| v <= max)
            .ok_or_else(|| self.error(format!("{what} is {v}, expected 0..={max}")))
    }

    /// A version number that must be one of `allowed`.
    pub fn version(&mut self, what: &str, allowed: &[i64]) -> Result<i64, FaceError> {
        let v = self.int()?;
        if allowed.contains(&v) {
            Ok(v)
        } else {
            Err(self.error(format!(
                "{what} has version {v}, expected one of {allowed:?}"
            )))
        }
    }

    pub fn float(&mut self) -> Result<f32, FaceError> {
        if self.bytes.get(self.pos).is_some_and(|b| b & 0x70 != 0) {
            return Err(self.error("a floating-point number in dlib's old text format"));
        }
        let mantissa = self.int()?;
        let exponent = self.int()?;
        // float_details marks infinities and NaN with the largest exponents of an int16.
        if exponent >= i64::from(i16::MAX) - 2 {
            return Err(self.error("a non-finite floating-point number"));
        }
        let exponent = i32::try_from(exponent).map_err(|_| self.error("exponent out of range"))?;
        Ok((mantissa as f64 * 2f64.powi(exponent)) as f32)
    }

    pub fn string(&mut self) -> Result<String, FaceError> {
        let len = self.size("a string length", 4096)?;
        let bytes = self.take(len, "a string")?;
        String::from_utf8(bytes.to_vec()).map_err(|_| self.error("a string that is not UTF-8"))
    }

    /// The next string, which must be `expected` (dlib's per-object version tag).
    pub fn tag(&mut self, expected: &[&str]) -> Result<String, FaceError> {
        let start = self.pos;
        let s = self.string()?;
        if expected.contains(&s.as_str()) {
            Ok(s)
        } else {
            self.pos = start;
            Err(self.error(format!("found object `{s}`, expected {expected:?}")))
        }
    }

    pub fn boolean(&mut self) -> Result<bool, FaceError> {
        match self.take(1, "a boolean")?[0] {
            b'1' => Ok(true),
            b'0' => Ok(false),
            other => {
                self.pos -= 1;
                Err(self.error(format!("byte {other:#04x} is not a dlib boolean")))
            }
        }
    }

    /// A `std::vector`: its length, then each element.
    pub fn list<T>(
        &mut self,
        mut item: impl FnMut(&mut Self) -> Result<T, FaceError>,
    ) -> Result<Vec<T>, FaceError> {
        let n = self.size("a list length", self.bytes.len())?;
        let mut out = Vec::with_capacity(n.min(1 << 16));
        for _ in 0..n {
            out.push(item(self)?);
        }
        Ok(out)
    }

    /// A `matrix<float,0,1>`: rows and columns (negated in dlib's newer format), then the
    /// values; a column vector.
    pub fn column(&mut self) -> Result<Vec<f32>, FaceError> {
        let (nr, nc) = (self.int()?.unsigned_abs(), self.int()?.unsigned_abs());
        if nc != 1 || nr > 1 << 20 {
            return Err(self.error(format!("a {nr}×{nc} matrix where a column was expected")));
        }
        (0..nr).map(|_| self.float()).collect()
    }

    /// A `resizable_tensor` (version 2).
    pub fn tensor(&mut self) -> Result<DlibTensor, FaceError> {
        self.version("a tensor", &[2])?;
        let mut dims = [0usize; 4];
        for d in &mut dims {
            *d = self.size("a tensor dimension", 1 << 28)?;
        }
        let count = dims
            .iter()
            .try_fold(1usize, |acc, &d| acc.checked_mul(d))
            .filter(|&c| c <= 1 << 28)
            .ok_or_else(|| self.error(format!("tensor of dimensions {dims:?} is too large")))?;
        let raw = self.take(count * 4, "tensor data")?;
        let values: Vec<f32> = raw
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
            .collect();
        if values.iter().any(|v| !v.is_finite()) {
            return Err(self.error("tensor with a non-finite value"));
        }
        Ok(DlibTensor { values })
    }

    /// An `alias_tensor` (a shape only, version 1).
    pub fn alias_tensor(&mut self) -> Result<[usize; 4], FaceError> {
        self.version("an alias tensor", &[1])?;
        let mut dims = [0usize; 4];
        for d in &mut dims {
            *d = self.size("a tensor dimension", 1 << 28)?;
        }
        Ok(dims)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn reader(bytes: &[u8]) -> Reader<'_> {
        Reader::new(Path::new("test.dat"), bytes)
    }

    #[test]
    fn integers_floats_strings_and_booleans() {
        // 1; -300; "abc"; 0.04 (mantissa 0xa3d70a, exponent -28); '1'
        let bytes = [
            0x01, 0x01, 0x82, 0x2c, 0x01, 0x01, 0x03, b'a', b'b', b'c', 0x03, 0x0a, 0xd7, 0xa3,
            0x81, 0x1c, b'1',
        ];
        let mut r = reader(&bytes);
        assert_eq!(r.int().unwrap(), 1);
        assert_eq!(r.int().unwrap(), -300);
        assert_eq!(r.string().unwrap(), "abc");
        assert!((r.float().unwrap() - 0.04).abs() < 1e-9);
        assert!(r.boolean().unwrap());
        assert!(r.at_end());
    }

    #[test]
    fn malformed_input_names_file_and_offset() {
        let err = reader(&[0x03, 0x01]).int().unwrap_err().to_string();
        assert!(
            err.contains("test.dat") && err.contains("truncated"),
            "{err}"
        );
        let err = reader(&[0x31]).int().unwrap_err().to_string();
        assert!(err.contains("at byte 0") && err.contains("0x31"), "{err}");
        let err = reader(b"\x01\x02xy")
            .tag(&["con_4"])
            .unwrap_err()
            .to_string();
        assert!(err.contains("`xy`") && err.contains("con_4"), "{err}");
        let err = reader(b"x").boolean().unwrap_err().to_string();
        assert!(err.contains("boolean"), "{err}");
        // A tensor claiming more data than the file holds.
        let err = reader(&[
            0x01, 0x02, 0x01, 0x01, 0x01, 0x01, 0x01, 0x10, 0x01, 0x10, 0, 0,
        ])
        .tensor()
        .err()
        .map(|e| e.to_string())
        .unwrap_or_default();
        assert!(err.contains("truncated"), "{err}");
    }
}

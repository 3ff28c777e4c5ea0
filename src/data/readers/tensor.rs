//! Tensor files: the container of RGL `.bsdf` materials (and of Mitsuba's other tabulated
//! data). Little-endian throughout:
//!
//! | bytes | what |
//! |---|---|
//! | 12 | the magic `tensor_file\0` |
//! | 2 | format version, `1 0` |
//! | 4 | number of fields (u32) |
//! | per field | name length (u16), name (UTF-8), rank (u16), element type (u8), offset of the data from the start of the file (u64), shape (rank × u64) |
//!
//! The data of a field are its elements in row-major order (the last index fastest). The
//! element types are the format's eleven, numbered as Mitsuba's `Struct::Type`; real RGL
//! database files mix several (text as uint8, a uint32 version, float32 tables), so
//! every one is read, and a field's values are converted to f64 when asked for.

use std::collections::BTreeMap;

/// The tensor file's magic.
pub const MAGIC: &[u8; 12] = b"tensor_file\0";

/// An element type of the format, with its code in the file.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ElementType {
    U8 = 1,
    I8 = 2,
    U16 = 3,
    I16 = 4,
    U32 = 5,
    I32 = 6,
    U64 = 7,
    I64 = 8,
    F16 = 9,
    F32 = 10,
    F64 = 11,
}

impl ElementType {
    /// Every element type, in code order.
    pub const ALL: [ElementType; 11] = [
        ElementType::U8,
        ElementType::I8,
        ElementType::U16,
        ElementType::I16,
        ElementType::U32,
        ElementType::I32,
        ElementType::U64,
        ElementType::I64,
        ElementType::F16,
        ElementType::F32,
        ElementType::F64,
    ];

    pub fn from_code(code: u8) -> Option<ElementType> {
        ElementType::ALL.iter().copied().find(|t| *t as u8 == code)
    }

    /// Bytes per element.
    pub fn size(self) -> usize {
        match self {
            ElementType::U8 | ElementType::I8 => 1,
            ElementType::U16 | ElementType::I16 | ElementType::F16 => 2,
            ElementType::U32 | ElementType::I32 | ElementType::F32 => 4,
            ElementType::U64 | ElementType::I64 | ElementType::F64 => 8,
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            ElementType::U8 => "uint8",
            ElementType::I8 => "int8",
            ElementType::U16 => "uint16",
            ElementType::I16 => "int16",
            ElementType::U32 => "uint32",
            ElementType::I32 => "int32",
            ElementType::U64 => "uint64",
            ElementType::I64 => "int64",
            ElementType::F16 => "float16",
            ElementType::F32 => "float32",
            ElementType::F64 => "float64",
        }
    }

    /// Whether the type holds bytes of text (a `description`).
    pub fn is_byte(self) -> bool {
        matches!(self, ElementType::U8 | ElementType::I8)
    }

    /// One element, from exactly [`ElementType::size`] bytes, as f64 (64-bit integers
    /// beyond 2⁵³ round to the nearest f64).
    fn decode(self, b: &[u8]) -> f64 {
        let arr = |n: usize| -> [u8; 8] {
            let mut a = [0u8; 8];
            a[..n].copy_from_slice(&b[..n]);
            a
        };
        let a = arr(self.size());
        match self {
            ElementType::U8 => b[0] as f64,
            ElementType::I8 => b[0] as i8 as f64,
            ElementType::U16 => u16::from_le_bytes([a[0], a[1]]) as f64,
            ElementType::I16 => i16::from_le_bytes([a[0], a[1]]) as f64,
            ElementType::U32 => u32::from_le_bytes([a[0], a[1], a[2], a[3]]) as f64,
            ElementType::I32 => i32::from_le_bytes([a[0], a[1], a[2], a[3]]) as f64,
            ElementType::U64 => u64::from_le_bytes(a) as f64,
            ElementType::I64 => i64::from_le_bytes(a) as f64,
            ElementType::F16 => half::f16::from_le_bytes([a[0], a[1]]).to_f64(),
            ElementType::F32 => f32::from_le_bytes([a[0], a[1], a[2], a[3]]) as f64,
            ElementType::F64 => f64::from_le_bytes(a),
        }
    }
}

/// One field's header: element type, shape and where its data lie.
#[derive(Clone, Debug)]
pub struct FieldInfo {
    pub element: ElementType,
    pub shape: Vec<usize>,
    offset: usize,
    count: usize,
}

impl FieldInfo {
    /// Number of elements (the product of the shape).
    pub fn len(&self) -> usize {
        self.count
    }

    pub fn is_empty(&self) -> bool {
        self.count == 0
    }
}

/// A tensor file whose header has been read and checked: every field's data lie within
/// the file. Values are decoded only when asked for.
pub struct TensorFile<'a> {
    bytes: &'a [u8],
    fields: BTreeMap<String, FieldInfo>,
}

/// A cursor over the header, whose reads fail with "truncated" past the end.
struct Cursor<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl<'a> Cursor<'a> {
    fn take(&mut self, n: usize, what: &str) -> Result<&'a [u8], String> {
        let end = self.at.checked_add(n).filter(|&e| e <= self.bytes.len());
        let Some(end) = end else {
            return Err(format!(
                "truncated: the header ends inside {what} (byte {} of {})",
                self.at,
                self.bytes.len()
            ));
        };
        let out = &self.bytes[self.at..end];
        self.at = end;
        Ok(out)
    }

    fn u16(&mut self, what: &str) -> Result<u16, String> {
        let b = self.take(2, what)?;
        Ok(u16::from_le_bytes([b[0], b[1]]))
    }

    fn u64(&mut self, what: &str) -> Result<u64, String> {
        let b = self.take(8, what)?;
        Ok(u64::from_le_bytes(b.try_into().expect("8 bytes")))
    }
}

impl<'a> TensorFile<'a> {
    /// Read the header of a tensor file. The error says what is wrong, and with which
    /// field; the caller adds the file name.
    pub fn parse(bytes: &'a [u8]) -> Result<TensorFile<'a>, String> {
        let mut c = Cursor { bytes, at: 0 };
        if c.take(12, "the magic").ok() != Some(MAGIC.as_slice()) {
            return Err("not a tensor file (no 'tensor_file' header)".into());
        }
        let version = c.take(2, "the version")?;
        if version != [1, 0] {
            return Err(format!(
                "tensor file version {}.{}, expected 1.0",
                version[0], version[1]
            ));
        }
        let count = c.take(4, "the field count")?;
        let n = u32::from_le_bytes(count.try_into().expect("4 bytes"));
        let mut fields = BTreeMap::new();
        for k in 0..n {
            let (name, info) = Self::field_header(&mut c, k)?;
            if fields.insert(name.clone(), info).is_some() {
                return Err(format!("field {name} appears twice"));
            }
        }
        Ok(TensorFile { bytes, fields })
    }

    /// The header of field number `k` (0-based), its data range checked.
    fn field_header(c: &mut Cursor<'a>, k: u32) -> Result<(String, FieldInfo), String> {
        let what = format!("field {}", k + 1);
        let len = c.u16(&what)? as usize;
        let raw = c.take(len, &what)?;
        let name = std::str::from_utf8(raw)
            .map_err(|_| format!("{what}: its name is not UTF-8"))?
            .to_string();
        let what = format!("field {name}");
        let rank = c.u16(&what)? as usize;
        let code = c.take(1, &what)?[0];
        let element = ElementType::from_code(code).ok_or_else(|| {
            format!(
                "{what}: element type code {code} is not one of the format's (1–11: uint8, int8, uint16, int16, uint32, int32, uint64, int64, float16, float32, float64)"
            )
        })?;
        let offset = c.u64(&what)?;
        let mut shape = Vec::with_capacity(rank.min(64));
        for _ in 0..rank {
            let s = c.u64(&what)?;
            shape.push(
                usize::try_from(s).map_err(|_| format!("{what}: dimension {s} is too large"))?,
            );
        }
        let count = shape
            .iter()
            .try_fold(1usize, |a, &s| a.checked_mul(s))
            .ok_or_else(|| format!("{what}: shape {shape:?} overflows"))?;
        let end = count
            .checked_mul(element.size())
            .and_then(|b| b.checked_add(usize::try_from(offset).ok()?));
        if end.is_none_or(|e| e > c.bytes.len()) {
            return Err(format!(
                "truncated: {what} ({} × {}, shape {shape:?}) runs past the end of the file ({} bytes)",
                element.name(),
                count,
                c.bytes.len()
            ));
        }
        let info = FieldInfo {
            element,
            shape,
            offset: offset as usize,
            count,
        };
        Ok((name, info))
    }

    pub fn field(&self, name: &str) -> Option<&FieldInfo> {
        self.fields.get(name)
    }

    /// The field names, in sorted order.
    pub fn names(&self) -> impl Iterator<Item = &str> {
        self.fields.keys().map(String::as_str)
    }

    /// A field's values as f64, whatever its element type.
    pub fn values(&self, name: &str) -> Option<Vec<f64>> {
        let f = self.fields.get(name)?;
        let size = f.element.size();
        let data = &self.bytes[f.offset..f.offset + f.count * size];
        Some(
            data.chunks_exact(size)
                .map(|b| f.element.decode(b))
                .collect(),
        )
    }

    /// A text field (`description`): its bytes as UTF-8 (lossily), if it is of a byte type.
    pub fn text(&self, name: &str) -> Option<String> {
        let f = self.fields.get(name).filter(|f| f.element.is_byte())?;
        Some(String::from_utf8_lossy(&self.bytes[f.offset..f.offset + f.count]).into_owned())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn codes_round_trip_and_sizes_match_the_format() {
        for (k, t) in ElementType::ALL.iter().enumerate() {
            assert_eq!(ElementType::from_code(k as u8 + 1), Some(*t));
        }
        assert_eq!(ElementType::from_code(0), None);
        assert_eq!(ElementType::from_code(12), None);
        let sizes: Vec<usize> = ElementType::ALL.iter().map(|t| t.size()).collect();
        assert_eq!(sizes, [1, 1, 2, 2, 4, 4, 8, 8, 2, 4, 8]);
    }
}

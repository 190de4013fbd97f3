//! A reader of MATLAB level-5 MAT files (the format `save -v7` and `-v6` write, and the one
//! RiverSurveyor Live exports): numeric arrays of every class, character arrays, structs and cell
//! arrays, zlib-compressed or not, either byte order. Sparse arrays, objects and function
//! handles are read as [`MatValue::Unsupported`] (their bytes skipped) rather than refused, so
//! that one such variable does not hide the rest of the file.
//!
//! Every length in the file is checked against the bytes that hold it, decompression is bounded,
//! and nesting is limited: a truncated or corrupted file is an error naming where it broke, never
//! a panic or an unbounded allocation.

use flate2::read::ZlibDecoder;
use std::io::Read;

/// One variable or field of a MAT file.
#[derive(Debug, Clone, PartialEq)]
pub enum MatValue {
    /// A numeric or logical array, real part only, column-major, every class as `f64` (integers
    /// up to 2^53 exactly). `complex` says the file also held an imaginary part (not kept).
    Numeric {
        dims: Vec<usize>,
        data: Vec<f64>,
        complex: bool,
    },
    /// A character array as one string (rows joined in column-major order, as MATLAB stores it).
    Char { dims: Vec<usize>, text: String },
    /// A struct array: its field names and, per element (column-major), one value per field.
    Struct {
        dims: Vec<usize>,
        fields: Vec<String>,
        elements: Vec<Vec<MatValue>>,
    },
    /// A cell array, column-major.
    Cell {
        dims: Vec<usize>,
        items: Vec<MatValue>,
    },
    /// A class this reader does not decode (sparse, object, function handle, opaque).
    Unsupported { class: u8 },
}

impl MatValue {
    /// The field `name` of a 1×1 struct.
    pub fn field(&self, name: &str) -> Option<&MatValue> {
        match self {
            MatValue::Struct {
                fields, elements, ..
            } if elements.len() == 1 => {
                let i = fields.iter().position(|f| f == name)?;
                elements[0].get(i)
            }
            _ => None,
        }
    }

    /// A numeric array's dimensions and column-major values.
    pub fn numeric(&self) -> Option<(&[usize], &[f64])> {
        match self {
            MatValue::Numeric { dims, data, .. } => Some((dims, data)),
            _ => None,
        }
    }

    /// A numeric array holding exactly one value.
    pub fn scalar(&self) -> Option<f64> {
        match self.numeric()? {
            (_, [x]) => Some(*x),
            _ => None,
        }
    }
}

/// A MAT file: its header text and its variables in file order.
#[derive(Debug, Clone)]
pub struct MatFile {
    pub header: String,
    pub variables: Vec<(String, MatValue)>,
}

impl MatFile {
    /// The variable `name`.
    pub fn get(&self, name: &str) -> Option<&MatValue> {
        self.variables
            .iter()
            .find(|(n, _)| n == name)
            .map(|(_, v)| v)
    }
}

/// Data types of the file's elements (the `mi*` constants of the format).
mod mi {
    pub const INT8: u32 = 1;
    pub const UINT8: u32 = 2;
    pub const INT16: u32 = 3;
    pub const UINT16: u32 = 4;
    pub const INT32: u32 = 5;
    pub const UINT32: u32 = 6;
    pub const SINGLE: u32 = 7;
    pub const DOUBLE: u32 = 9;
    pub const INT64: u32 = 12;
    pub const UINT64: u32 = 13;
    pub const MATRIX: u32 = 14;
    pub const COMPRESSED: u32 = 15;
    pub const UTF8: u32 = 16;
    pub const UTF16: u32 = 17;
    pub const UTF32: u32 = 18;
}

/// Array classes (the `mx*_CLASS` constants).
mod mx {
    pub const CELL: u8 = 1;
    pub const STRUCT: u8 = 2;
    pub const CHAR: u8 = 4;
    pub const DOUBLE: u8 = 6;
    pub const UINT64: u8 = 15;
}

/// The most bytes one compressed variable may expand to (a bound against zip bombs far above
/// any instrument export).
const MAX_INFLATED: u64 = 1 << 31;
/// The deepest nesting of structs and cells read.
const MAX_DEPTH: usize = 32;

/// Parses a whole MAT file.
pub fn parse(bytes: &[u8]) -> Result<MatFile, String> {
    if bytes.len() < 128 {
        return Err(format!(
            "{} bytes: shorter than the 128-byte MAT header",
            bytes.len()
        ));
    }
    let big_endian = match &bytes[126..128] {
        b"IM" => false,
        b"MI" => true,
        other => {
            return Err(format!(
                "bytes 126..128 are {other:?}, not the MAT-file endian indicator \"IM\" or \"MI\" \
                 (a level-4 or HDF5-based v7.3 file?)"
            ));
        }
    };
    let header = String::from_utf8_lossy(&bytes[..116])
        .trim_end_matches(['\0', ' '])
        .to_string();
    if !header.starts_with("MATLAB 5.0 MAT-file") {
        return Err(format!(
            "header text {header:?} does not start with \"MATLAB 5.0 MAT-file\""
        ));
    }
    let mut variables = Vec::new();
    let mut r = Reader {
        bytes: &bytes[128..],
        pos: 0,
        big_endian,
        base: 128,
    };
    while r.remaining() > 0 {
        let at = r.offset();
        if r.remaining() < 8 {
            return Err(format!(
                "{} trailing bytes at offset {at}: not a whole element tag",
                r.remaining()
            ));
        }
        let (ty, body) = r.element().map_err(|e| format!("offset {at}: {e}"))?;
        let decoded;
        let (ty, body, base) = if ty == mi::COMPRESSED {
            decoded = inflate(body).map_err(|e| format!("offset {at}: {e}"))?;
            let mut inner = Reader {
                bytes: &decoded,
                pos: 0,
                big_endian,
                base: 0,
            };
            let (t, b) = inner
                .element()
                .map_err(|e| format!("offset {at} (compressed): {e}"))?;
            (t, b, 0)
        } else {
            (ty, body, at + 8)
        };
        if ty != mi::MATRIX {
            // The format allows other top-level elements; they are not variables.
            continue;
        }
        let (name, value) = matrix(body, big_endian, 0)
            .map_err(|e| format!("variable at offset {at}{}: {e}", offset_note(base)))?;
        variables.push((name, value));
    }
    Ok(MatFile { header, variables })
}

fn offset_note(base: usize) -> &'static str {
    if base == 0 { " (compressed)" } else { "" }
}

fn inflate(body: &[u8]) -> Result<Vec<u8>, String> {
    let mut out = Vec::new();
    ZlibDecoder::new(body)
        .take(MAX_INFLATED + 1)
        .read_to_end(&mut out)
        .map_err(|e| format!("compressed element does not inflate: {e}"))?;
    if out.len() as u64 > MAX_INFLATED {
        return Err(format!(
            "compressed element inflates beyond {MAX_INFLATED} bytes"
        ));
    }
    Ok(out)
}

/// A cursor over a run of elements.
struct Reader<'a> {
    bytes: &'a [u8],
    pos: usize,
    big_endian: bool,
    /// Offset of `bytes` in the file, for messages (0 inside compressed data).
    base: usize,
}

impl<'a> Reader<'a> {
    fn remaining(&self) -> usize {
        self.bytes.len() - self.pos
    }

    fn offset(&self) -> usize {
        self.base + self.pos
    }

    fn u32_at(&self, at: usize) -> u32 {
        let b = [
            self.bytes[at],
            self.bytes[at + 1],
            self.bytes[at + 2],
            self.bytes[at + 3],
        ];
        if self.big_endian {
            u32::from_be_bytes(b)
        } else {
            u32::from_le_bytes(b)
        }
    }

    /// The next element: its type and its data bytes (padding skipped).
    fn element(&mut self) -> Result<(u32, &'a [u8]), String> {
        if self.remaining() < 8 {
            return Err(format!(
                "element tag needs 8 bytes, {} remain",
                self.remaining()
            ));
        }
        let first = self.u32_at(self.pos);
        if first >> 16 != 0 {
            // Small data element: type and length in the first word, data in the second.
            let (ty, n) = (first & 0xffff, (first >> 16) as usize);
            if n > 4 {
                return Err(format!(
                    "small element of type {ty} claims {n} bytes (at most 4)"
                ));
            }
            let data = &self.bytes[self.pos + 4..self.pos + 4 + n];
            self.pos += 8;
            return Ok((ty, data));
        }
        let n = self.u32_at(self.pos + 4) as usize;
        let start = self.pos + 8;
        if n > self.bytes.len() - start {
            return Err(format!(
                "element of type {first} claims {n} bytes, {} remain",
                self.bytes.len() - start
            ));
        }
        let data = &self.bytes[start..start + n];
        // Compressed elements are not padded; all others to a multiple of 8 bytes.
        let padded = if first == mi::COMPRESSED {
            n
        } else {
            n.div_ceil(8) * 8
        };
        self.pos = (start + padded).min(self.bytes.len());
        Ok((first, data))
    }
}

/// Numbers of an element of numeric type `ty`, as f64.
fn numbers(ty: u32, data: &[u8], big_endian: bool) -> Result<Vec<f64>, String> {
    macro_rules! conv {
        ($t:ty) => {{
            const N: usize = std::mem::size_of::<$t>();
            if !data.len().is_multiple_of(N) {
                return Err(format!(
                    "{} bytes of type {ty} are not a whole number of {N}-byte values",
                    data.len()
                ));
            }
            data.chunks_exact(N)
                .map(|c| {
                    let a: [u8; N] = c.try_into().expect("chunk of N bytes");
                    (if big_endian {
                        <$t>::from_be_bytes(a)
                    } else {
                        <$t>::from_le_bytes(a)
                    }) as f64
                })
                .collect()
        }};
    }
    Ok(match ty {
        mi::INT8 => conv!(i8),
        mi::UINT8 | mi::UTF8 => conv!(u8),
        mi::INT16 => conv!(i16),
        mi::UINT16 | mi::UTF16 => conv!(u16),
        mi::INT32 => conv!(i32),
        mi::UINT32 | mi::UTF32 => conv!(u32),
        mi::SINGLE => conv!(f32),
        mi::DOUBLE => conv!(f64),
        mi::INT64 => conv!(i64),
        mi::UINT64 => conv!(u64),
        other => return Err(format!("data type {other} is not numeric")),
    })
}

/// Decodes the body of a miMATRIX element: its name and value.
fn matrix(body: &[u8], big_endian: bool, depth: usize) -> Result<(String, MatValue), String> {
    if depth > MAX_DEPTH {
        return Err(format!("nested deeper than {MAX_DEPTH} levels"));
    }
    if body.is_empty() {
        // An empty element stands for an empty array (a cell or field never assigned).
        return Ok((
            String::new(),
            MatValue::Numeric {
                dims: vec![0, 0],
                data: Vec::new(),
                complex: false,
            },
        ));
    }
    let mut r = Reader {
        bytes: body,
        pos: 0,
        big_endian,
        base: 0,
    };
    let (ty, flags) = r.element().map_err(|e| format!("array flags: {e}"))?;
    if ty != mi::UINT32 || flags.len() < 4 {
        return Err(format!("array flags of type {ty}, {} bytes", flags.len()));
    }
    let word = numbers(mi::UINT32, &flags[..4], big_endian)?[0] as u32;
    let class = (word & 0xff) as u8;
    let complex = word & 0x800 != 0;
    let (ty, d) = r.element().map_err(|e| format!("dimensions: {e}"))?;
    let dims: Vec<usize> = numbers(ty, d, big_endian)
        .map_err(|e| format!("dimensions: {e}"))?
        .into_iter()
        .map(|x| {
            if x >= 0.0 && x <= u32::MAX as f64 {
                Ok(x as usize)
            } else {
                Err(format!("dimension {x} is not a count"))
            }
        })
        .collect::<Result<_, _>>()?;
    if dims.len() < 2 {
        return Err(format!("{} dimensions (at least 2)", dims.len()));
    }
    let count = dims
        .iter()
        .try_fold(1usize, |a, &b| a.checked_mul(b))
        .ok_or("dimensions overflow")?;
    let (_, name) = r.element().map_err(|e| format!("array name: {e}"))?;
    let name = String::from_utf8_lossy(name).into_owned();
    let within = |what: &str, e: String| format!("{name:?}: {what}{e}");
    let value = match class {
        mx::DOUBLE..=mx::UINT64 => {
            let (ty, d) = r.element().map_err(|e| within("real part: ", e))?;
            let data = numbers(ty, d, big_endian).map_err(|e| within("real part: ", e))?;
            if data.len() != count {
                return Err(within(
                    "",
                    format!("{} values for dimensions {dims:?}", data.len()),
                ));
            }
            MatValue::Numeric {
                dims,
                data,
                complex,
            }
        }
        mx::CHAR => {
            let (ty, d) = r.element().map_err(|e| within("characters: ", e))?;
            let text = if ty == mi::UTF8 || ty == mi::UINT8 || ty == mi::INT8 {
                String::from_utf8_lossy(d).into_owned()
            } else {
                numbers(ty, d, big_endian)
                    .map_err(|e| within("characters: ", e))?
                    .into_iter()
                    .map(|c| char::from_u32(c as u32).unwrap_or(char::REPLACEMENT_CHARACTER))
                    .collect()
            };
            // RiverSurveyor Live writes 1×1 character arrays with no characters for its blank
            // units; they read as blanks (as scipy reads them).
            let mut text = text;
            let short = count.saturating_sub(text.chars().count());
            if short <= 1 << 16 {
                text.extend(std::iter::repeat_n(' ', short));
            }
            MatValue::Char { dims, text }
        }
        mx::STRUCT => struct_array(&mut r, dims, count, big_endian, depth, &within)?,
        mx::CELL => cell_array(&mut r, dims, count, big_endian, depth, &within)?,
        other => MatValue::Unsupported { class: other },
    };
    Ok((name, value))
}

/// The fields of a struct array, after its dimensions and name.
fn struct_array(
    r: &mut Reader,
    dims: Vec<usize>,
    count: usize,
    big_endian: bool,
    depth: usize,
    within: &dyn Fn(&str, String) -> String,
) -> Result<MatValue, String> {
    let (ty, d) = r.element().map_err(|e| within("field name length: ", e))?;
    let len = numbers(ty, d, big_endian)
        .map_err(|e| within("field name length: ", e))?
        .first()
        .copied()
        .unwrap_or(0.0) as usize;
    let (_, names) = r.element().map_err(|e| within("field names: ", e))?;
    if len == 0 || !names.len().is_multiple_of(len) {
        return Err(within(
            "",
            format!("{} bytes of field names in slots of {len}", names.len()),
        ));
    }
    let fields: Vec<String> = names
        .chunks_exact(len)
        .map(|c| {
            let end = c.iter().position(|&b| b == 0).unwrap_or(c.len());
            String::from_utf8_lossy(&c[..end]).into_owned()
        })
        .collect();
    // Each element of a struct with fields takes at least 8 bytes per field, so a
    // count the bytes cannot hold fails below; a struct without fields has no bytes
    // to bound its count by.
    if fields.is_empty() && count > 1 << 16 {
        return Err(within("", format!("{count} elements without fields")));
    }
    let mut elements = Vec::with_capacity(count.min(r.remaining() / 8 + 1));
    for _ in 0..count {
        let values = fields
            .iter()
            .map(|f| nested(r, big_endian, depth, &format!("field {f}"), within))
            .collect::<Result<Vec<_>, _>>()?;
        elements.push(values);
    }
    Ok(MatValue::Struct {
        dims,
        fields,
        elements,
    })
}

/// The items of a cell array, after its dimensions and name.
fn cell_array(
    r: &mut Reader,
    dims: Vec<usize>,
    count: usize,
    big_endian: bool,
    depth: usize,
    within: &dyn Fn(&str, String) -> String,
) -> Result<MatValue, String> {
    let mut items = Vec::with_capacity(count.min(r.remaining() / 8 + 1));
    for i in 0..count {
        items.push(nested(r, big_endian, depth, &format!("cell {i}"), within)?);
    }
    Ok(MatValue::Cell { dims, items })
}

/// The next element of `r` as an array nested in a struct or a cell (`what` names it in errors:
/// `field x`, `cell 3`).
fn nested(
    r: &mut Reader,
    big_endian: bool,
    depth: usize,
    what: &str,
    within: &dyn Fn(&str, String) -> String,
) -> Result<MatValue, String> {
    let (ty, b) = r.element().map_err(|e| within(&format!("{what}: "), e))?;
    if ty != mi::MATRIX {
        return Err(within(
            "",
            format!("{what} is an element of type {ty}, not an array"),
        ));
    }
    matrix(b, big_endian, depth + 1)
        .map(|(_, v)| v)
        .map_err(|e| within(&format!("{what}: "), e))
}

#[cfg(test)]
#[path = "mat5_tests.rs"]
mod tests;

//! Tests of the MAT reader on files written here the way MATLAB writes them.
use super::*;

/// Writes MAT elements the way MATLAB does, for the tests.
struct Writer(Vec<u8>);

impl Writer {
    fn element(&mut self, ty: u32, data: &[u8]) {
        self.0.extend(ty.to_le_bytes());
        self.0.extend((data.len() as u32).to_le_bytes());
        self.0.extend(data);
        while !self.0.len().is_multiple_of(8) {
            self.0.push(0);
        }
    }
}

fn header() -> Vec<u8> {
    let mut h = b"MATLAB 5.0 MAT-file, test".to_vec();
    h.resize(116, b' ');
    h.extend([0; 8]);
    h.extend(0x0100u16.to_le_bytes());
    h.extend(b"IM");
    h
}

fn array(class: u8, dims: &[i32], name: &str, rest: &[u8]) -> Vec<u8> {
    let mut w = Writer(Vec::new());
    let mut flags = u32::from(class).to_le_bytes().to_vec();
    flags.extend([0; 4]);
    w.element(mi::UINT32, &flags);
    w.element(
        mi::INT32,
        &dims
            .iter()
            .flat_map(|d| d.to_le_bytes())
            .collect::<Vec<_>>(),
    );
    w.element(mi::INT8, name.as_bytes());
    w.0.extend(rest);
    w.0
}

fn doubles(values: &[f64]) -> Vec<u8> {
    let mut w = Writer(Vec::new());
    w.element(
        mi::DOUBLE,
        &values
            .iter()
            .flat_map(|v| v.to_le_bytes())
            .collect::<Vec<_>>(),
    );
    w.0
}

fn file(vars: &[Vec<u8>], compress: bool) -> Vec<u8> {
    let mut out = header();
    for v in vars {
        let mut w = Writer(Vec::new());
        w.element(mi::MATRIX, v);
        if compress {
            use std::io::Write;
            let mut z = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::fast());
            z.write_all(&w.0).expect("compress");
            let c = z.finish().expect("compress");
            out.extend(mi::COMPRESSED.to_le_bytes());
            out.extend((c.len() as u32).to_le_bytes());
            out.extend(c);
        } else {
            out.extend(w.0);
        }
    }
    out
}

fn sample() -> Vec<Vec<u8>> {
    let v = array(
        mx::DOUBLE,
        &[2, 3],
        "v",
        &doubles(&[1., 2., 3., 4., 5., 6.]),
    );
    // A struct with a scalar field and a char field.
    let mut fields = Writer(Vec::new());
    fields.element(mi::INT32, &8i32.to_le_bytes()[..]);
    let mut names = b"a\0\0\0\0\0\0\0".to_vec();
    names.extend(b"unit\0\0\0\0");
    fields.element(mi::INT8, &names);
    let mut a = Writer(Vec::new());
    a.element(
        mi::MATRIX,
        &array(mx::DOUBLE, &[1, 1], "", &doubles(&[4.5])),
    );
    let mut chars = Writer(Vec::new());
    chars.element(
        mi::UINT16,
        &"m/s"
            .encode_utf16()
            .flat_map(u16::to_le_bytes)
            .collect::<Vec<_>>(),
    );
    a.element(mi::MATRIX, &array(mx::CHAR, &[1, 3], "", &chars.0));
    let mut rest = fields.0;
    rest.extend(a.0);
    let s = array(mx::STRUCT, &[1, 1], "S", &rest);
    vec![v, s]
}

#[test]
fn arrays_structs_and_chars_read_back_compressed_or_not() {
    for compress in [false, true] {
        let m = parse(&file(&sample(), compress)).expect("parse");
        assert_eq!(m.header, "MATLAB 5.0 MAT-file, test");
        let (dims, data) = m.get("v").and_then(MatValue::numeric).expect("v");
        assert_eq!(dims, &[2, 3]);
        assert_eq!(data, &[1., 2., 3., 4., 5., 6.]);
        let s = m.get("S").expect("S");
        assert_eq!(s.field("a").and_then(MatValue::scalar), Some(4.5));
        assert_eq!(
            s.field("unit"),
            Some(&MatValue::Char {
                dims: vec![1, 3],
                text: "m/s".into()
            })
        );
        assert!(s.field("missing").is_none());
    }
}

#[test]
fn small_elements_and_integer_classes() {
    // The name "x" and a single int16 as small data elements.
    let mut body = Writer(Vec::new());
    let mut flags = u32::from(10u8).to_le_bytes().to_vec();
    flags.extend([0; 4]);
    body.element(mi::UINT32, &flags);
    body.element(mi::INT32, &[1, 0, 0, 0, 1, 0, 0, 0]);
    body.0.extend((1u32 << 16 | mi::INT8).to_le_bytes());
    body.0.extend([b'x', 0, 0, 0]);
    body.0.extend((2u32 << 16 | mi::INT16).to_le_bytes());
    body.0.extend([0xfe, 0xff, 0, 0]);
    let m = parse(&file(&[body.0], false)).expect("parse");
    assert_eq!(m.get("x").and_then(MatValue::scalar), Some(-2.0));
}

#[test]
fn truncated_or_corrupted_files_are_errors_not_panics() {
    let whole = file(&sample(), false);
    for n in [0, 10, 127, 128, 131, 140, 200, whole.len() - 1] {
        let cut = &whole[..n.min(whole.len())];
        let r = parse(cut);
        assert!(r.is_err() || n == 128, "length {n}: {r:?}");
    }
    let compressed = file(&sample(), true);
    assert!(parse(&compressed[..compressed.len() - 5]).is_err());
    let mut flipped = compressed.clone();
    for i in (136..flipped.len()).step_by(7) {
        flipped[i] ^= 0x5a;
    }
    let _ = parse(&flipped);
    // Every single-byte change of an uncompressed file parses or fails cleanly.
    for i in 128..whole.len() {
        let mut b = whole.clone();
        b[i] = b[i].wrapping_add(0x81);
        let _ = parse(&b);
    }
    assert!(parse(b"MATLAB 7.3 MAT-file").is_err());
}

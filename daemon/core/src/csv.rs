//! CSV output of navigation solutions and aid diagnostics, shared by the daemon and the replay.
//! Floats are written with Rust's shortest round-trip formatting, so equal solutions give
//! byte-identical files.
//!
//! A row is formatted into a buffer on the stack and written at once. Its floats are written as
//! `{:?}` writes them (the shortest digits that read back to the same value; exponential
//! notation below 1e-4 and from 1e16), from `zmij`'s shortest digits, several times faster than
//! `core::fmt` (a smoothing run writes some eight million of them per hour). Where two shortest
//! texts are equally near the value, `zmij` takes the even last digit and `core::fmt` the one of
//! larger magnitude; such ties are recognised exactly and written as `core::fmt` writes them.

use auvnav_shm_schema::{AidDiagnosticsV1, NavSolutionV1};
use std::io::Write;

/// A CSV row under construction: fields separated by commas, ended by a newline.
struct Row {
    bytes: [u8; 640],
    len: usize,
}

impl Row {
    fn new() -> Self {
        Row {
            bytes: [0; 640],
            len: 0,
        }
    }

    fn put(&mut self, text: &[u8]) {
        self.bytes[self.len..self.len + text.len()].copy_from_slice(text);
        self.len += text.len();
    }

    fn separate(&mut self) {
        if self.len > 0 {
            self.put(b",");
        }
    }

    fn integer(&mut self, v: impl itoa::Integer) {
        self.separate();
        let mut b = itoa::Buffer::new();
        self.put(b.format(v).as_bytes());
    }

    fn float(&mut self, v: f64) {
        self.separate();
        let start = self.len;
        let n = write_f64_debug(&mut self.bytes[start..], v);
        self.len += n;
    }

    fn finish(mut self, w: &mut dyn Write) -> std::io::Result<()> {
        self.put(b"\n");
        w.write_all(&self.bytes[..self.len])
    }
}

/// Writes `v` as `format!("{v:?}")` does into the front of `out` (at least 32 bytes), returns
/// the length.
fn write_f64_debug(out: &mut [u8], v: f64) -> usize {
    if !v.is_finite() {
        let text: &[u8] = if v.is_nan() {
            b"NaN"
        } else if v > 0.0 {
            b"inf"
        } else {
            b"-inf"
        };
        out[..text.len()].copy_from_slice(text);
        return text.len();
    }
    let mut buffer = zmij::Buffer::new();
    let shortest = buffer.format_finite(v).as_bytes();
    // From 1e-4 to 1e16 `zmij` writes decimals as `core::fmt` does; where the text does not end
    // in ".0", its last digit is 10^-(digits after the point).
    let magnitude = v.abs();
    if (1e-4..1e16).contains(&magnitude) && shortest[shortest.len() - 1] != b'0' {
        out[..shortest.len()].copy_from_slice(shortest);
        // Here the last digit is 10^q with q ≥ -20 (at most 17 digits from 1e-4), and a tie needs
        // s = q (see `tie_rounded_down`): for nearly every value s is far below.
        if lowest_bit_exponent(v).is_some_and(|s| s >= -21)
            && let Some(dot) = shortest.iter().position(|&c| c == b'.')
        {
            let q = dot as i32 + 1 - shortest.len() as i32;
            if tie_rounded_down(v, &shortest[shortest.len() - 1..], q) {
                out[shortest.len() - 1] += 1;
            }
        }
        return shortest.len();
    }
    // The shortest digits, without leading or trailing zeros, and `point`: the value is
    // 0.DIGITS × 10^point.
    let mut digits = [0u8; 24];
    let mut count = 0usize;
    let mut point: i32 = 0;
    let mut before_point = true;
    let mut exponent: i32 = 0;
    let mut k = usize::from(shortest.first() == Some(&b'-'));
    while k < shortest.len() {
        match shortest[k] {
            b'.' => before_point = false,
            b'e' | b'E' => {
                exponent = parse_exponent(&shortest[k + 1..]);
                break;
            }
            d => {
                if count == 0 && d == b'0' {
                    if !before_point {
                        point -= 1;
                    }
                } else {
                    digits[count] = d;
                    count += 1;
                    if before_point {
                        point += 1;
                    }
                }
            }
        }
        k += 1;
    }
    while count > 0 && digits[count - 1] == b'0' {
        count -= 1;
    }
    point += exponent;
    if count > 0 && tie_rounded_down(v, &digits[..count], point - count as i32) {
        // The last digit cannot be 9: a tie's digit was chosen even.
        digits[count - 1] += 1;
    }
    let mut n = 0usize;
    let mut put = |out: &mut [u8], b: u8| {
        out[n] = b;
        n += 1;
    };
    if v.is_sign_negative() {
        put(out, b'-');
    }
    if count == 0 {
        for &b in b"0.0" {
            put(out, b);
        }
        return n;
    }
    if point <= -4 || point >= 17 {
        put(out, digits[0]);
        if count > 1 {
            put(out, b'.');
            for &d in &digits[1..count] {
                put(out, d);
            }
        }
        put(out, b'e');
        let mut b = itoa::Buffer::new();
        for &c in b.format(point - 1).as_bytes() {
            put(out, c);
        }
    } else if point <= 0 {
        put(out, b'0');
        put(out, b'.');
        for _ in point..0 {
            put(out, b'0');
        }
        for &d in &digits[..count] {
            put(out, d);
        }
    } else {
        let whole = point as usize;
        let padded = digits[..count]
            .iter()
            .copied()
            .chain(std::iter::repeat(b'0'));
        for (i, d) in padded.take(whole.max(count)).enumerate() {
            if i == whole {
                put(out, b'.');
            }
            put(out, d);
        }
        if whole >= count {
            put(out, b'.');
            put(out, b'0');
        }
    }
    n
}

/// Whether |v| lies exactly halfway between DIGITS × 10^q and the next number on that grid,
/// above DIGITS (where `core::fmt` takes the upper one). With |v| = m·2^s / 2, m odd, a tie
/// means 2|v| / 10^q is an odd integer N: s = q, and 5^q divides m where q > 0. N is then 2D ± 1
/// and, since 5 ≡ 1 (mod 4), N ≡ m (mod 4), which says which.
fn tie_rounded_down(v: f64, digits: &[u8], q: i32) -> bool {
    if lowest_bit_exponent(v) != Some(q) {
        return false;
    }
    let bits = v.to_bits();
    let hidden = u64::from((bits >> 52) & 0x7ff != 0) << 52;
    let mantissa = (bits & ((1 << 52) - 1)) | hidden;
    let odd = mantissa >> mantissa.trailing_zeros();
    if q > 0 && (q > 22 || !odd.is_multiple_of(5u64.pow(q as u32))) {
        return false;
    }
    let last_odd = u64::from(digits[digits.len() - 1] - b'0') % 2;
    odd % 4 == (2 * last_odd + 1) % 4
}

/// s with 2|v| = m·2^s, m odd (`None` for zero).
fn lowest_bit_exponent(v: f64) -> Option<i32> {
    let bits = v.to_bits();
    let biased = ((bits >> 52) & 0x7ff) as i32;
    let fraction = bits & ((1 << 52) - 1);
    let (mantissa, e) = if biased == 0 {
        (fraction, -1074)
    } else {
        (fraction | (1 << 52), biased - 1075)
    };
    (mantissa != 0).then(|| e + mantissa.trailing_zeros() as i32 + 1)
}

fn parse_exponent(text: &[u8]) -> i32 {
    let (negative, digits) = match text.first() {
        Some(b'-') => (true, &text[1..]),
        Some(b'+') => (false, &text[1..]),
        _ => (false, text),
    };
    let magnitude = digits
        .iter()
        .fold(0i32, |e, &d| e * 10 + i32::from(d.wrapping_sub(b'0')));
    if negative { -magnitude } else { magnitude }
}

pub const NAV_HEADER: &str = "time_ns,sequence,latitude_rad,longitude_rad,height_m,v_n_m_s,v_e_m_s,v_d_m_s,roll_rad,pitch_rad,yaw_rad,std_n_m,std_e_m,std_d_m,mode,sensor_health";

pub fn write_nav_row(w: &mut dyn Write, s: &NavSolutionV1) -> std::io::Result<()> {
    let mut row = Row::new();
    row.integer(s.host_time_ns);
    row.integer(s.sequence);
    for v in [s.latitude_rad, s.longitude_rad, s.height_m]
        .into_iter()
        .chain(s.velocity_ned_m_s)
        .chain(s.euler_rad)
        .chain(s.position_std_ned_m)
    {
        row.float(v);
    }
    row.integer(s.mode);
    row.integer(s.sensor_health);
    row.finish(w)
}

pub const DIAGNOSTICS_HEADER: &str = "time_ns,sequence,source,dimension,flags,observation_0,observation_1,observation_2,innovation_0,innovation_1,innovation_2,innovation_variance_0,innovation_variance_1,innovation_variance_2,test_ratio";

pub fn write_diagnostics_row(w: &mut dyn Write, d: &AidDiagnosticsV1) -> std::io::Result<()> {
    let mut row = Row::new();
    row.integer(d.host_time_ns);
    row.integer(d.sequence);
    row.integer(d.source);
    row.integer(d.dimension);
    row.integer(d.flags);
    for v in d
        .observation
        .into_iter()
        .chain(d.innovation)
        .chain(d.innovation_variance)
        .chain([d.test_ratio])
    {
        row.float(v);
    }
    row.finish(w)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn debug_text(v: f64) -> String {
        let mut out = [0u8; 32];
        let n = write_f64_debug(&mut out, v);
        String::from_utf8(out[..n].to_vec()).expect("ascii")
    }

    /// Every kind of value, a million random bit patterns and magnitudes, and ties between two
    /// shortest texts give `{:?}`'s text.
    #[test]
    fn floats_are_written_as_debug_writes_them() {
        let mut special = vec![
            0.0,
            -0.0,
            1.0,
            -1.0,
            0.1,
            1e-4,
            -1e-4,
            9.999999999999999e-5,
            1.0000000000000002e-4,
            1e16,
            9999999999999998.0,
            1e15,
            123456789012345.6,
            1e-7,
            1.5e-7,
            5e-324,
            f64::MIN_POSITIVE,
            f64::MAX,
            f64::MIN,
            f64::EPSILON,
            f64::NAN,
            f64::INFINITY,
            f64::NEG_INFINITY,
            100.0,
            1e22,
            0.30000000000000004,
            f64::from_bits(0x4317_9085_685d_83c9),
            1658206780088562.2,
            -1658206780088562.2,
            2.5e15 + 0.25,
            2.5e15 + 0.75,
        ];
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        let mut next = || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            state
        };
        for _ in 0..500_000 {
            special.push(f64::from_bits(next()));
        }
        for _ in 0..500_000 {
            let mantissa = (next() >> 11) as f64 / (1u64 << 53) as f64;
            let exponent = (next() % 50) as i32 - 25;
            special.push(mantissa * 10f64.powi(exponent));
        }
        for v in special {
            assert_eq!(debug_text(v), format!("{v:?}"), "{:#x}", v.to_bits());
        }
    }

    /// A row is the fields in order, floats as `{:?}` writes them.
    #[test]
    fn a_solution_row_has_every_field() {
        let s = NavSolutionV1 {
            host_time_ns: 5_000_000,
            sequence: 2,
            latitude_rad: 0.541_052_069_695_801,
            longitude_rad: 2.094_395_102_393_713_5,
            height_m: -29.979_103_563_396_638,
            velocity_ned_m_s: [2.0, -0.0, 8.1e-7],
            euler_rad: [-1.1e-5, 1e-4, 3.1],
            position_std_ned_m: [1.0, 1e16, 0.019],
            mode: 2,
            sensor_health: 3,
            ..Default::default()
        };
        let mut text = Vec::new();
        write_nav_row(&mut text, &s).expect("row");
        assert_eq!(
            String::from_utf8(text).expect("utf-8"),
            "5000000,2,0.541052069695801,2.0943951023937135,-29.979103563396638,2.0,-0.0,8.1e-7,\
             -1.1e-5,0.0001,3.1,1.0,1e16,0.019,2,3\n"
        );
        assert_eq!(NAV_HEADER.split(',').count(), 16);
    }
}

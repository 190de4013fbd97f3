//! The World Magnetic Model (WMM): the Earth's main field from a degree-12 spherical-harmonic
//! model with linear secular variation, as published by NOAA NCEI and BGS in `WMM.COF` files.
//!
//! The model is evaluated as in the WMM technical report: the geodetic position is converted to
//! geocentric spherical coordinates on WGS-84, the Gauss coefficients are advanced from the
//! model epoch to the date (g(t) = g + (t − t0)·ġ), the field is summed with Schmidt
//! semi-normalised associated Legendre functions, and the spherical components are rotated back
//! to the geodetic north-east-down frame. A model is valid for five years from its epoch; a date
//! outside that window is an error, not an extrapolation.
//!
//! The current model (WMM2025, valid 2025.0–2030.0) is built in ([`WorldMagneticModel::builtin`]),
//! and so are WMM2010 (2010.0–2015.0) and WMM2020 (2020.0–2025.0) for older recordings
//! ([`WorldMagneticModel::builtin_for`]);
//! the WMM coefficients are a work of the US government (public domain). Another model is read
//! from its `WMM.COF` file ([`WorldMagneticModel::from_cof`]).

use nalgebra::Vector3;
use std::fmt;

/// Degree of the WMM.
pub const DEGREE: usize = 12;
/// Geomagnetic reference radius (km).
const REFERENCE_RADIUS_KM: f64 = 6371.2;
/// Number of (n, m) pairs up to [`DEGREE`] (index n(n+1)/2 + m).
const TERMS: usize = (DEGREE + 1) * (DEGREE + 2) / 2;
/// Years a model is valid after its epoch.
pub const VALIDITY_YEARS: f64 = 5.0;

const WMM2025_COF: &str = include_str!("wmm/WMM2025.COF");
const WMM2010_COF: &str = include_str!("wmm/WMM2010.COF");
const WMM2020_COF: &str = include_str!("wmm/WMM2020.COF");

fn index(n: usize, m: usize) -> usize {
    n * (n + 1) / 2 + m
}

/// A world magnetic model: Gauss coefficients (nT) and their secular variation (nT/year).
#[derive(Debug, Clone, PartialEq)]
pub struct WorldMagneticModel {
    /// Model name from the file header (e.g. "WMM-2025").
    pub name: String,
    /// Model epoch (decimal year).
    pub epoch: f64,
    g: [f64; TERMS],
    h: [f64; TERMS],
    g_dot: [f64; TERMS],
    h_dot: [f64; TERMS],
}

/// The field at a position and date.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MagneticField {
    /// Field in geodetic north, east, down (nT).
    pub ned_nt: Vector3<f64>,
    /// Its yearly change (nT/year).
    pub ned_rate_nt_per_year: Vector3<f64>,
}

impl MagneticField {
    /// Horizontal intensity H (nT).
    pub fn horizontal_nt(&self) -> f64 {
        self.ned_nt.x.hypot(self.ned_nt.y)
    }
    /// Total intensity F (nT).
    pub fn intensity_nt(&self) -> f64 {
        self.ned_nt.norm()
    }
    /// Declination D: the angle of the horizontal field east of true north (deg).
    pub fn declination_deg(&self) -> f64 {
        self.ned_nt.y.atan2(self.ned_nt.x).to_degrees()
    }
    /// Inclination (dip) I: the angle of the field below the horizontal (deg, positive down).
    pub fn inclination_deg(&self) -> f64 {
        self.ned_nt.z.atan2(self.horizontal_nt()).to_degrees()
    }
}

/// Why a model cannot be read or evaluated.
#[derive(Debug, Clone, PartialEq)]
pub enum WmmError {
    /// The coefficient file is malformed (line number, what is wrong).
    Malformed { line: usize, reason: String },
    /// The date is outside the model's validity window.
    OutsideValidity {
        model: String,
        date: f64,
        from: f64,
        to: f64,
    },
    /// A position or date that is not a finite number, or a latitude beyond ±90°.
    BadInput(String),
}

impl fmt::Display for WmmError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            WmmError::Malformed { line, reason } => {
                write!(f, "magnetic model file line {line}: {reason}")
            }
            WmmError::OutsideValidity {
                model,
                date,
                from,
                to,
            } => write!(
                f,
                "date {date:.3} is outside the validity of {model} ({from:.1} to {to:.1}); give \
                 the coefficient file of the model for that date"
            ),
            WmmError::BadInput(s) => write!(f, "magnetic model input: {s}"),
        }
    }
}

impl std::error::Error for WmmError {}

impl WorldMagneticModel {
    /// The built-in WMM2025 (valid 2025.0 to 2030.0).
    pub fn builtin() -> WorldMagneticModel {
        // The embedded file is checked by a unit test; a failure here is a build defect.
        Self::from_cof(WMM2025_COF).expect("the built-in WMM2025 coefficients parse")
    }

    /// The built-in model whose validity holds `date` (decimal year): WMM2010 for 2010.0–2015.0,
    /// WMM2020 for 2020.0–2025.0 (WMM2025 from 2025.0 on), WMM2025 to 2030.0; None for other
    /// dates (their model's `WMM.COF` must be given).
    pub fn builtin_for(date: f64) -> Option<WorldMagneticModel> {
        [WMM2010_COF, WMM2025_COF, WMM2020_COF]
            .iter()
            .map(|text| Self::from_cof(text).expect("the built-in WMM coefficients parse"))
            .find(|m| {
                let (from, to) = m.validity();
                (from..=to).contains(&date)
            })
    }

    /// Reads a model from the text of a `WMM.COF` file: a header line "epoch name date", one
    /// line "n m g h ġ ḣ" per coefficient, and an end marker of 9s.
    pub fn from_cof(text: &str) -> Result<WorldMagneticModel, WmmError> {
        let mut lines = text.lines().enumerate();
        let (_, header) = lines.next().ok_or(WmmError::Malformed {
            line: 1,
            reason: "empty file".into(),
        })?;
        let mut words = header.split_whitespace();
        let epoch: f64 = words
            .next()
            .and_then(|w| w.parse().ok())
            .filter(|e: &f64| (1900.0..3000.0).contains(e))
            .ok_or(WmmError::Malformed {
                line: 1,
                reason: "the header does not start with the model epoch (a year)".into(),
            })?;
        let name = words.next().unwrap_or("WMM").to_string();
        let mut model = WorldMagneticModel {
            name,
            epoch,
            g: [0.0; TERMS],
            h: [0.0; TERMS],
            g_dot: [0.0; TERMS],
            h_dot: [0.0; TERMS],
        };
        let mut seen = [false; TERMS];
        for (i, line) in lines {
            let t = line.trim();
            if t.is_empty() {
                continue;
            }
            if t.starts_with("9999") {
                break;
            }
            let bad = |reason: String| WmmError::Malformed {
                line: i + 1,
                reason,
            };
            let v: Vec<f64> = t
                .split_whitespace()
                .map(|w| w.parse::<f64>())
                .collect::<Result<_, _>>()
                .map_err(|e| bad(format!("{e}: {t:?}")))?;
            if v.len() != 6 || v.iter().any(|x| !x.is_finite()) {
                return Err(bad(format!("expected n m g h gdot hdot, got {t:?}")));
            }
            let (n, m) = (v[0] as usize, v[1] as usize);
            if v[0] != n as f64 || v[1] != m as f64 || n == 0 || n > DEGREE || m > n {
                return Err(bad(format!(
                    "degree/order ({}, {}) out of range",
                    v[0], v[1]
                )));
            }
            let k = index(n, m);
            model.g[k] = v[2];
            model.h[k] = v[3];
            model.g_dot[k] = v[4];
            model.h_dot[k] = v[5];
            seen[k] = true;
        }
        let missing = (1..=DEGREE)
            .flat_map(|n| (0..=n).map(move |m| (n, m)))
            .filter(|&(n, m)| !seen[index(n, m)])
            .count();
        if missing > 0 {
            return Err(WmmError::Malformed {
                line: text.lines().count(),
                reason: format!("{missing} coefficients up to degree {DEGREE} are missing"),
            });
        }
        Ok(model)
    }

    /// The validity window (decimal years).
    pub fn validity(&self) -> (f64, f64) {
        (self.epoch, self.epoch + VALIDITY_YEARS)
    }

    /// The field at geodetic latitude, longitude (deg), height above the WGS-84 ellipsoid (m) and
    /// date (decimal year).
    pub fn field(
        &self,
        latitude_deg: f64,
        longitude_deg: f64,
        height_m: f64,
        date: f64,
    ) -> Result<MagneticField, WmmError> {
        if !(latitude_deg.is_finite() && longitude_deg.is_finite() && height_m.is_finite()) {
            return Err(WmmError::BadInput("position is not finite".into()));
        }
        if latitude_deg.abs() > 90.0 {
            return Err(WmmError::BadInput(format!(
                "latitude {latitude_deg}° beyond ±90°"
            )));
        }
        let (from, to) = self.validity();
        if !(date.is_finite() && (from..=to).contains(&date)) {
            return Err(WmmError::OutsideValidity {
                model: self.name.clone(),
                date,
                from,
                to,
            });
        }
        let dt = date - self.epoch;
        let mut g = [0.0; TERMS];
        let mut h = [0.0; TERMS];
        for k in 0..TERMS {
            g[k] = self.g[k] + dt * self.g_dot[k];
            h[k] = self.h[k] + dt * self.h_dot[k];
        }
        let geo = Geocentric::from_geodetic(latitude_deg, longitude_deg, height_m * 1e-3);
        let b = geo.sum(&g, &h);
        let b_dot = geo.sum(&self.g_dot, &self.h_dot);
        Ok(MagneticField {
            ned_nt: geo.to_geodetic_ned(&b),
            ned_rate_nt_per_year: geo.to_geodetic_ned(&b_dot),
        })
    }
}

/// A position in geocentric spherical coordinates with what the summation needs.
struct Geocentric {
    /// Geocentric latitude minus geodetic latitude (rad).
    lat_difference: f64,
    /// Radius (km).
    r_km: f64,
    /// sin and cos of the geocentric latitude.
    sin_lat: f64,
    cos_lat: f64,
    longitude_rad: f64,
}

impl Geocentric {
    fn from_geodetic(latitude_deg: f64, longitude_deg: f64, height_km: f64) -> Geocentric {
        let a = crate::earth::A * 1e-3;
        let e2 = crate::earth::E2;
        let phi = latitude_deg.to_radians();
        let (s, c) = phi.sin_cos();
        let rc = a / (1.0 - e2 * s * s).sqrt();
        let p = (rc + height_km) * c;
        let z = (rc * (1.0 - e2) + height_km) * s;
        let r = p.hypot(z);
        let lat_c = (z / r).asin();
        Geocentric {
            lat_difference: lat_c - phi,
            r_km: r,
            sin_lat: lat_c.sin(),
            cos_lat: lat_c.cos(),
            longitude_rad: longitude_deg.to_radians(),
        }
    }

    /// The field of coefficients `g`, `h` in the spherical frame (north, east, down; nT).
    fn sum(&self, g: &[f64; TERMS], h: &[f64; TERMS]) -> Vector3<f64> {
        // Legendre functions of cos θ = sin(geocentric latitude), Schmidt semi-normalised, and
        // their derivatives with respect to the colatitude θ.
        let (x, s) = (self.sin_lat, self.cos_lat);
        let mut p = [0.0; TERMS];
        let mut dp = [0.0; TERMS];
        p[0] = 1.0;
        for n in 1..=DEGREE {
            for m in 0..=n {
                let k = index(n, m);
                if n == m {
                    let j = index(n - 1, m - 1);
                    p[k] = s * p[j];
                    dp[k] = s * dp[j] + x * p[j];
                } else if n == 1 || m == n - 1 {
                    let j = index(n - 1, m);
                    p[k] = x * p[j];
                    dp[k] = x * dp[j] - s * p[j];
                } else {
                    let j1 = index(n - 1, m);
                    let j2 = index(n - 2, m);
                    let c =
                        (((n - 1) * (n - 1) - m * m) as f64) / (((2 * n - 1) * (2 * n - 3)) as f64);
                    p[k] = x * p[j1] - c * p[j2];
                    dp[k] = x * dp[j1] - s * p[j1] - c * dp[j2];
                }
            }
        }
        // Gauss-normalised → Schmidt semi-normalised.
        let mut schmidt = [0.0; TERMS];
        schmidt[0] = 1.0;
        for n in 1..=DEGREE {
            schmidt[index(n, 0)] = schmidt[index(n - 1, 0)] * (2 * n - 1) as f64 / n as f64;
            for m in 1..=n {
                let factor = if m == 1 { 2.0 } else { 1.0 };
                schmidt[index(n, m)] = schmidt[index(n, m - 1)]
                    * ((n - m + 1) as f64 * factor / (n + m) as f64).sqrt();
            }
        }
        let ratio = REFERENCE_RADIUS_KM / self.r_km;
        let (mut north, mut east, mut down) = (0.0, 0.0, 0.0);
        let mut ar = ratio * ratio;
        for n in 1..=DEGREE {
            ar *= ratio;
            for m in 0..=n {
                let k = index(n, m);
                let (sm, cm) = (m as f64 * self.longitude_rad).sin_cos();
                let pk = p[k] * schmidt[k];
                let dpk = dp[k] * schmidt[k];
                let gh_cos = g[k] * cm + h[k] * sm;
                let gh_sin = g[k] * sm - h[k] * cm;
                north += ar * gh_cos * dpk;
                east += ar * m as f64 * gh_sin * pk;
                down -= (n + 1) as f64 * ar * gh_cos * pk;
            }
        }
        // At a pole the east component is the limit along the meridian; cos φ' is never exactly
        // zero in floating point away from the exact pole.
        east /= s.max(1e-12);
        Vector3::new(north, east, down)
    }

    /// Rotates a spherical north-east-down vector to the geodetic frame.
    fn to_geodetic_ned(&self, b: &Vector3<f64>) -> Vector3<f64> {
        let (sd, cd) = self.lat_difference.sin_cos();
        Vector3::new(b.x * cd - b.z * sd, b.y, b.x * sd + b.z * cd)
    }
}

/// The decimal year of a calendar date (UTC): year + (day of year − 1 + fraction of day) / days
/// in the year. `None` for an impossible date.
pub fn decimal_year(year: i32, month: u32, day: u32, seconds_of_day: f64) -> Option<f64> {
    use chrono::Datelike;
    let date = chrono::NaiveDate::from_ymd_opt(year, month, day)?;
    if !(0.0..86_400.0 + 1.0).contains(&seconds_of_day) {
        return None;
    }
    let days_in_year = if date.leap_year() { 366.0 } else { 365.0 };
    Some(year as f64 + (f64::from(date.ordinal0()) + seconds_of_day / 86_400.0) / days_in_year)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn builtin_model_parses_and_knows_its_window() {
        let m = WorldMagneticModel::builtin();
        assert_eq!(m.name, "WMM-2025");
        assert_eq!(m.validity(), (2025.0, 2030.0));
        let e = m.field(45.0, 10.0, 0.0, 2031.0).expect_err("outside");
        assert!(matches!(e, WmmError::OutsideValidity { .. }), "{e}");
        assert!(e.to_string().contains("outside the validity of WMM-2025"));
        assert!(m.field(91.0, 0.0, 0.0, 2026.0).is_err());
        assert!(m.field(f64::NAN, 0.0, 0.0, 2026.0).is_err());
    }

    /// The test values of the WMM2010 technical report (NOAA NGDC / BGS, 2010): declination at
    /// 0 and 100 km above the ellipsoid, 2010.0 and 2012.5.
    #[test]
    fn wmm2010_gives_its_reports_test_values() {
        let m = WorldMagneticModel::builtin_for(2012.5).expect("WMM2010 for 2012.5");
        assert_eq!(m.name, "WMM-2010");
        for (date, height_m, lat, lon, declination) in [
            (2010.0, 0.0, 80.0, 0.0, -6.13),
            (2010.0, 0.0, 0.0, 120.0, 0.97),
            (2010.0, 0.0, -80.0, 240.0, 70.21),
            (2010.0, 100e3, 80.0, 0.0, -6.57),
            (2010.0, 100e3, 0.0, 120.0, 0.94),
            (2010.0, 100e3, -80.0, 240.0, 69.62),
            (2012.5, 0.0, 80.0, 0.0, -5.21),
            (2012.5, 0.0, 0.0, 120.0, 0.88),
            (2012.5, 0.0, -80.0, 240.0, 70.04),
            (2012.5, 100e3, 80.0, 0.0, -5.63),
            (2012.5, 100e3, 0.0, 120.0, 0.86),
            (2012.5, 100e3, -80.0, 240.0, 69.45),
        ] {
            let d = m
                .field(lat, lon, height_m, date)
                .expect("inside")
                .declination_deg();
            assert!((d - declination).abs() < 0.01, "{date} {lat} {lon}: {d}");
        }
        assert_eq!(
            WorldMagneticModel::builtin_for(2026.0).map(|m| m.name),
            Some("WMM-2025".into())
        );
        assert!(WorldMagneticModel::builtin_for(2019.0).is_none());
    }

    /// WMM2020 carried to its end agrees with WMM2025 at its start away from the poles (within
    /// 0.5° of declination: the two fits and five years of secular variation differ by a few
    /// tenths), which a wrong coefficient would break; it covers 2020–2025.
    #[test]
    fn wmm2020_meets_wmm2025_at_2025() {
        let old = WorldMagneticModel::builtin_for(2022.6).expect("WMM2020 for 2022");
        assert_eq!(old.name, "WMM-2020");
        let new = WorldMagneticModel::builtin();
        for (lat, lon) in [
            (45.0, 10.0),
            (-33.9, 18.4),
            (40.0, -105.0),
            (35.7, 139.7),
            (0.0, -60.0),
            (64.6, -149.1),
        ] {
            let a = old
                .field(lat, lon, 0.0, 2025.0)
                .expect("inside")
                .declination_deg();
            let b = new
                .field(lat, lon, 0.0, 2025.0)
                .expect("inside")
                .declination_deg();
            assert!((a - b).abs() < 0.5, "{lat} {lon}: {a} against {b}");
        }
    }

    #[test]
    fn malformed_files_are_named_errors() {
        assert!(WorldMagneticModel::from_cof("").is_err());
        assert!(WorldMagneticModel::from_cof("hello\n").is_err());
        let short = "2025.0 WMM-2025 x\n 1 0 -29351.8 0.0 12.0 0.0\n999999\n";
        let e = WorldMagneticModel::from_cof(short).expect_err("short");
        assert!(e.to_string().contains("missing"), "{e}");
        let bad = "2025.0 WMM-2025 x\n 1 0 abc 0.0 12.0 0.0\n";
        assert!(matches!(
            WorldMagneticModel::from_cof(bad),
            Err(WmmError::Malformed { line: 2, .. })
        ));
    }

    #[test]
    fn decimal_years() {
        assert_eq!(decimal_year(2025, 1, 1, 0.0), Some(2025.0));
        assert_eq!(decimal_year(2024, 7, 2, 0.0), Some(2024.0 + 183.0 / 366.0));
        assert_eq!(decimal_year(2025, 2, 29, 0.0), None);
        assert_eq!(decimal_year(2025, 13, 1, 0.0), None);
    }
}

//! WGS-84 Earth model: radii of curvature, normal gravity with height, Earth rate and transport
//! rate in the local NED frame. Latitude and longitude in radians, height above the ellipsoid in
//! metres (depth = -height at sea level).

use nalgebra::{Matrix3, Vector3};

/// Semi-major axis (m).
pub const A: f64 = 6_378_137.0;
/// Flattening.
pub const F: f64 = 1.0 / 298.257_223_563;
/// First eccentricity squared.
pub const E2: f64 = F * (2.0 - F);
/// Earth rotation rate w.r.t. inertial space (rad/s).
pub const OMEGA_IE: f64 = 7.292_115e-5;
/// Normal gravity at the equator (m/s^2).
pub const GAMMA_E: f64 = 9.780_325_335_9;
/// Somigliana's constant k = (b*gamma_p)/(a*gamma_e) - 1.
pub const SOMIGLIANA_K: f64 = 0.001_931_852_652_41;
/// m = omega^2 a^2 b / GM.
pub const M_RATIO: f64 = 0.003_449_786_506_84;

/// Geodetic position: latitude, longitude (rad), height above the ellipsoid (m).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Geodetic {
    pub latitude_rad: f64,
    pub longitude_rad: f64,
    pub height_m: f64,
}

/// An angle wrapped to −π..π (rad).
pub fn wrap_pi(a: f64) -> f64 {
    (a + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU) - std::f64::consts::PI
}

/// Meridian radius of curvature R_M (m).
pub fn meridian_radius(lat: f64) -> f64 {
    let s = lat.sin();
    A * (1.0 - E2) / (1.0 - E2 * s * s).powf(1.5)
}

/// Prime-vertical (transverse) radius of curvature R_N (m).
pub fn prime_vertical_radius(lat: f64) -> f64 {
    let s = lat.sin();
    A / (1.0 - E2 * s * s).sqrt()
}

/// Normal gravity magnitude at latitude and height (m/s^2): Somigliana's closed formula at the
/// ellipsoid with the second-order free-air correction for height (NIMA TR8350.2 eq. 4-3).
pub fn normal_gravity(lat: f64, height_m: f64) -> f64 {
    let s2 = lat.sin().powi(2);
    let g0 = GAMMA_E * (1.0 + SOMIGLIANA_K * s2) / (1.0 - E2 * s2).sqrt();
    let h = height_m;
    g0 * (1.0 - 2.0 / A * (1.0 + F + M_RATIO - 2.0 * F * s2) * h + 3.0 / (A * A) * h * h)
}

/// Gravity vector in NED (m/s^2): normal gravity along the ellipsoid normal (down).
pub fn gravity_ned(lat: f64, height_m: f64) -> Vector3<f64> {
    Vector3::new(0.0, 0.0, normal_gravity(lat, height_m))
}

/// Earth rate expressed in NED, omega_ie^n (rad/s).
pub fn earth_rate_ned(lat: f64) -> Vector3<f64> {
    Vector3::new(OMEGA_IE * lat.cos(), 0.0, -OMEGA_IE * lat.sin())
}

/// Transport rate omega_en^n (rad/s): rotation of NED w.r.t. the Earth for velocity v_ned.
pub fn transport_rate_ned(lat: f64, height_m: f64, v_ned: &Vector3<f64>) -> Vector3<f64> {
    let rm = meridian_radius(lat) + height_m;
    let rn = prime_vertical_radius(lat) + height_m;
    Vector3::new(v_ned.y / rn, -v_ned.x / rm, -v_ned.y * lat.tan() / rn)
}

/// Rates of latitude, longitude (rad/s) and height (m/s) for NED velocity.
pub fn position_rates(lat: f64, height_m: f64, v_ned: &Vector3<f64>) -> Vector3<f64> {
    let rm = meridian_radius(lat) + height_m;
    let rn = prime_vertical_radius(lat) + height_m;
    Vector3::new(v_ned.x / rm, v_ned.y / (rn * lat.cos()), -v_ned.z)
}

/// The Earth model at one latitude and height, from one sine and cosine and one square root:
/// what the strapdown step needs at the IMU rate. The same quantities as the functions above
/// (to rounding: `x sqrt(x)` for `x^1.5`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LocalEarth {
    pub sin_lat: f64,
    pub cos_lat: f64,
    /// Meridian radius plus height, R_M + h (m).
    pub rm_h: f64,
    /// Prime-vertical radius plus height, R_N + h (m).
    pub rn_h: f64,
    /// Normal gravity (m/s^2).
    pub gravity: f64,
}

impl LocalEarth {
    pub fn at(lat: f64, height_m: f64) -> LocalEarth {
        let (s, c) = lat.sin_cos();
        let s2 = s * s;
        let d = 1.0 - E2 * s2;
        let sd = d.sqrt();
        let g0 = GAMMA_E * (1.0 + SOMIGLIANA_K * s2) / sd;
        let h = height_m;
        LocalEarth {
            sin_lat: s,
            cos_lat: c,
            rm_h: A * (1.0 - E2) / (d * sd) + h,
            rn_h: A / sd + h,
            gravity: g0
                * (1.0 - 2.0 / A * (1.0 + F + M_RATIO - 2.0 * F * s2) * h + 3.0 / (A * A) * h * h),
        }
    }

    /// Earth rate in NED, omega_ie^n (rad/s).
    pub fn earth_rate(&self) -> Vector3<f64> {
        Vector3::new(OMEGA_IE * self.cos_lat, 0.0, -OMEGA_IE * self.sin_lat)
    }

    /// Transport rate omega_en^n (rad/s) for NED velocity `v`.
    pub fn transport_rate(&self, v: &Vector3<f64>) -> Vector3<f64> {
        Vector3::new(
            v.y / self.rn_h,
            -v.x / self.rm_h,
            -v.y * (self.sin_lat / self.cos_lat) / self.rn_h,
        )
    }

    /// Rates of latitude, longitude (rad/s) and height (m/s) for NED velocity `v`.
    pub fn position_rates(&self, v: &Vector3<f64>) -> Vector3<f64> {
        Vector3::new(v.x / self.rm_h, v.y / (self.rn_h * self.cos_lat), -v.z)
    }
}

/// Earth-centred Earth-fixed coordinates (m) of a geodetic position.
pub fn to_ecef(p: &Geodetic) -> Vector3<f64> {
    let (sl, cl) = p.latitude_rad.sin_cos();
    let (so, co) = p.longitude_rad.sin_cos();
    let rn = prime_vertical_radius(p.latitude_rad);
    Vector3::new(
        (rn + p.height_m) * cl * co,
        (rn + p.height_m) * cl * so,
        (rn * (1.0 - E2) + p.height_m) * sl,
    )
}

/// Rotation from ECEF to the NED frame at (lat, lon).
pub fn c_ecef_to_ned(lat: f64, lon: f64) -> Matrix3<f64> {
    let (sl, cl) = lat.sin_cos();
    let (so, co) = lon.sin_cos();
    Matrix3::new(
        -sl * co,
        -sl * so,
        cl, //
        -so,
        co,
        0.0, //
        -cl * co,
        -cl * so,
        -sl,
    )
}

/// Vector from `origin` to `target` expressed in the NED frame at `origin` (m); exact.
pub fn ned_offset(origin: &Geodetic, target: &Geodetic) -> Vector3<f64> {
    c_ecef_to_ned(origin.latitude_rad, origin.longitude_rad) * (to_ecef(target) - to_ecef(origin))
}

/// Small-offset inverse: the position `north`, `east` metres and `down` metres from `origin`,
/// using the local radii; second-order terms are ignored (about 2 cm at 500 m, height included).
pub fn offset_position(origin: &Geodetic, ned: &Vector3<f64>) -> Geodetic {
    let rm = meridian_radius(origin.latitude_rad) + origin.height_m;
    let rn = prime_vertical_radius(origin.latitude_rad) + origin.height_m;
    Geodetic {
        latitude_rad: origin.latitude_rad + ned.x / rm,
        longitude_rad: origin.longitude_rad + ned.y / (rn * origin.latitude_rad.cos()),
        height_m: origin.height_m - ned.z,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gravity_matches_published_values() {
        // Normal gravity: equator 9.7803253359, pole 9.8321849378 (WGS-84 TR8350.2).
        assert!((normal_gravity(0.0, 0.0) - 9.780_325_335_9).abs() < 1e-9);
        assert!((normal_gravity(std::f64::consts::FRAC_PI_2, 0.0) - 9.832_184_937_8).abs() < 1e-8);
        // Free-air gradient about -3.086e-6 /s^2 per metre.
        let d = normal_gravity(0.7, 100.0) - normal_gravity(0.7, 0.0);
        assert!((d / 100.0 + 3.086e-6).abs() < 0.01e-6, "{d}");
    }

    #[test]
    fn ned_offset_inverts_offset_position() {
        let o = Geodetic {
            latitude_rad: 31f64.to_radians(),
            longitude_rad: 120f64.to_radians(),
            height_m: -20.0,
        };
        let d = Vector3::new(350.0, -420.0, 12.0);
        let p = offset_position(&o, &d);
        let back = ned_offset(&o, &p);
        // Second-order terms: about 2 cm horizontally at 550 m; vertical differs by the Earth curvature d^2/(2R), 2.4 cm here.
        assert!((back.xy() - d.xy()).norm() < 0.03, "{back}");
        assert!((back.z - d.z - 0.024).abs() < 0.005, "{back}");
    }
}

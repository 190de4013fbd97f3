//! A surface run's reference from its GPS: what the importers of boat ADCP runs write as the
//! truth channel (position and velocity over ground from the fixes, attitude from the vessel's
//! own compass), and the same from any run's GNSS fixes and compass readings
//! ([`reference_from_fixes`]: a simulated boat turned into what an importer would have written).

use auvnav_shm_schema::{AttitudeV1, GnssFixV1, TruthStateV1};
use nalgebra::UnitQuaternion;

/// A GPS sample on the ensemble clock: time (s), north and east (m from the first fix), or
/// north and east velocity (m/s).
pub type GpsSample = (f64, f64, f64);

/// `(time, latitude deg, longitude deg)` as `(time, north m, east m)` on the plane tangent at
/// the first.
pub fn north_east_of(fixes: impl Iterator<Item = (f64, f64, f64)>) -> Vec<GpsSample> {
    let mut fixes = fixes.peekable();
    let Some(&(_, lat0, lon0)) = fixes.peek() else {
        return Vec::new();
    };
    let (lat0, lon0) = (lat0.to_radians(), lon0.to_radians());
    let (rm, rn) = (
        auvnav_core::earth::meridian_radius(lat0),
        auvnav_core::earth::prime_vertical_radius(lat0),
    );
    fixes
        .map(|(t, lat, lon)| {
            (
                t,
                (lat.to_radians() - lat0) * rm,
                (lon.to_radians() - lon0) * rn * lat0.cos(),
            )
        })
        .collect()
}

/// A surface vessel's GPS reference record: position (latitude, longitude deg) and height
/// interpolated between fixes, velocity over ground (north, east; vertical 0), the attitude
/// its own sensor gives (roll, pitch, heading rad), rates unknown (NaN).
pub fn surface_reference(
    host_time_ns: u64,
    sequence: u64,
    (latitude_deg, longitude_deg): (f64, f64),
    height_m: f64,
    (vn, ve): (f64, f64),
    euler_rad: [f64; 3],
) -> TruthStateV1 {
    let q = UnitQuaternion::from_euler_angles(euler_rad[0], euler_rad[1], euler_rad[2]);
    TruthStateV1 {
        host_time_ns,
        sequence,
        latitude_rad: latitude_deg.to_radians(),
        longitude_rad: longitude_deg.to_radians(),
        height_m,
        velocity_ned_m_s: [vn, ve, 0.0],
        quaternion_body_to_ned: [q.w, q.i, q.j, q.k],
        euler_rad,
        angular_rate_rad_s: [f64::NAN; 3],
        specific_force_m_s2: [f64::NAN; 3],
    }
}

/// Linear interpolation of `s` at `t` between samples at most `max_gap` s apart.
pub fn interpolate_gps(s: &[GpsSample], t: f64, max_gap: f64) -> Option<(f64, f64)> {
    let i = s.partition_point(|x| x.0 <= t);
    let (a, b) = (s.get(i.checked_sub(1)?)?, s.get(i)?);
    if b.0 - a.0 > max_gap || b.0 <= a.0 {
        return None;
    }
    let f = (t - a.0) / (b.0 - a.0);
    Some((a.1 + (b.1 - a.1) * f, a.2 + (b.2 - a.2) * f))
}

/// Velocity from positions: least-squares line through the samples within ±`half` s of `t`
/// (at least three, spanning at least `half`).
pub fn velocity_from_positions(s: &[GpsSample], t: f64, half: f64) -> Option<(f64, f64)> {
    let lo = s.partition_point(|x| x.0 < t - half);
    let hi = s.partition_point(|x| x.0 <= t + half);
    let w = &s[lo..hi];
    if w.len() < 3 || w[w.len() - 1].0 - w[0].0 < half {
        return None;
    }
    let n = w.len() as f64;
    let mt = w.iter().map(|x| x.0).sum::<f64>() / n;
    let stt: f64 = w.iter().map(|x| (x.0 - mt).powi(2)).sum();
    let slope = |k: usize| {
        let m = w
            .iter()
            .map(|x| if k == 1 { x.1 } else { x.2 })
            .sum::<f64>()
            / n;
        w.iter()
            .map(|x| (x.0 - mt) * (if k == 1 { x.1 } else { x.2 } - m))
            .sum::<f64>()
            / stt
    };
    Some((slope(1), slope(2)))
}

/// Fixes further apart than this (s) are not interpolated between, as the PD0 importer does.
const MAX_FIX_GAP_S: f64 = 1.5;
/// The velocity over ground is a line through the fixes within this many seconds either side.
const VELOCITY_HALF_WINDOW_S: f64 = 1.0;

/// The reference an importer of a surface run writes, at each of `times_ns` (the DVL's pings):
/// position and height interpolated between `fixes` (those with a position), the velocity over
/// ground from the positions within ±1 s (as `auvnav import pd0 --velocity gga`), and the
/// attitude of the `compass` reading nearest in time, within half a second. Times the fixes or
/// the compass do not cover get no record.
pub fn reference_from_fixes(
    fixes: &[GnssFixV1],
    compass: &[AttitudeV1],
    times_ns: &[u64],
) -> Vec<TruthStateV1> {
    let seconds = |ns: u64| ns as f64 * 1e-9;
    let with_position: Vec<&GnssFixV1> = fixes
        .iter()
        .filter(|f| f.validity & GnssFixV1::VALID_POSITION != 0)
        .collect();
    let lat_lon_deg: Vec<GpsSample> = with_position
        .iter()
        .map(|f| {
            (
                seconds(f.host_time_ns),
                f.latitude_rad.to_degrees(),
                f.longitude_rad.to_degrees(),
            )
        })
        .collect();
    let heights: Vec<GpsSample> = with_position
        .iter()
        .map(|f| (seconds(f.host_time_ns), f.height_m, 0.0))
        .collect();
    let positions = north_east_of(lat_lon_deg.iter().copied());
    let mut out = Vec::new();
    for &ns in times_ns {
        let t = seconds(ns);
        let i = compass.partition_point(|a| a.host_time_ns < ns);
        let nearest = [i.checked_sub(1), Some(i)]
            .into_iter()
            .flatten()
            .filter_map(|j| compass.get(j))
            .min_by_key(|a| a.host_time_ns.abs_diff(ns))
            .filter(|a| a.host_time_ns.abs_diff(ns) <= 500_000_000);
        let (Some(a), Some(v_ne), Some(lat_lon), Some((h, _))) = (
            nearest,
            velocity_from_positions(&positions, t, VELOCITY_HALF_WINDOW_S),
            interpolate_gps(&lat_lon_deg, t, MAX_FIX_GAP_S),
            interpolate_gps(&heights, t, MAX_FIX_GAP_S),
        ) else {
            continue;
        };
        out.push(surface_reference(
            ns,
            out.len() as u64,
            lat_lon,
            h,
            v_ne,
            a.euler_rad,
        ));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gps_velocity_from_positions_and_interpolation() {
        // 1 m/s north, 0.5 m/s east, sampled at 5 Hz.
        let s: Vec<GpsSample> = (0..20)
            .map(|i| {
                let t = i as f64 * 0.2;
                (t, t, 0.5 * t)
            })
            .collect();
        let (vn, ve) = velocity_from_positions(&s, 2.0, 1.0).expect("velocity");
        assert!((vn - 1.0).abs() < 1e-12 && (ve - 0.5).abs() < 1e-12);
        assert!(velocity_from_positions(&s, 10.0, 1.0).is_none());
        let (n, e) = interpolate_gps(&s, 1.1, 1.5).expect("inside");
        assert!((n - 1.1).abs() < 1e-12 && (e - 0.55).abs() < 1e-12);
        assert!(interpolate_gps(&s, -0.1, 1.5).is_none());
        assert!(interpolate_gps(&[(0.0, 0.0, 0.0), (3.0, 1.0, 1.0)], 1.0, 1.5).is_none());
    }

    /// A boat going north at 1 m/s and east at 2 m/s, fixed once a second, heading 30°: the
    /// reference at a ping on a fix has the fixes' velocity, the position and the nearest
    /// compass reading's attitude; a ping at the last fix (no fix after it) or far from a compass
    /// reading has none.
    #[test]
    fn the_reference_of_fixes_and_compass_is_the_importers() {
        let lat0 = 52f64.to_radians();
        let rm = auvnav_core::earth::meridian_radius(lat0);
        let rn = auvnav_core::earth::prime_vertical_radius(lat0);
        let fixes: Vec<GnssFixV1> = (0..10)
            .map(|k| {
                let t = k as f64;
                GnssFixV1 {
                    host_time_ns: k * 1_000_000_000,
                    latitude_rad: lat0 + t / rm,
                    longitude_rad: 13f64.to_radians() + 2.0 * t / (rn * lat0.cos()),
                    height_m: 40.0,
                    validity: GnssFixV1::VALID_POSITION | GnssFixV1::VALID_HEIGHT,
                    ..Default::default()
                }
            })
            .collect();
        let compass: Vec<AttitudeV1> = (0..3)
            .map(|k| AttitudeV1 {
                host_time_ns: 4_000_000_000 + k * 400_000_000,
                euler_rad: [0.01, -0.02, 30f64.to_radians()],
                validity: AttitudeV1::VALID_ATTITUDE,
                ..Default::default()
            })
            .collect();
        let r = reference_from_fixes(
            &fixes,
            &compass,
            &[5_000_000_000, 9_500_000_000, 2_000_000_000],
        );
        assert_eq!(r.len(), 1, "{r:?}");
        let x = &r[0];
        assert_eq!(x.host_time_ns, 5_000_000_000);
        assert!((x.velocity_ned_m_s[0] - 1.0).abs() < 1e-6, "{x:?}");
        assert!((x.velocity_ned_m_s[1] - 2.0).abs() < 1e-6, "{x:?}");
        assert!(((x.latitude_rad - lat0) * rm - 5.0).abs() < 1e-6, "{x:?}");
        assert_eq!(x.euler_rad, [0.01, -0.02, 30f64.to_radians()]);
        assert!((x.height_m - 40.0).abs() < 1e-9);
    }
}

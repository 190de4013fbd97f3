//! GNSS receivers: a fix encoded as a receiver's NMEA 0183 epoch or u-blox `NAV-PVT`
//! (emulation), the inverse of [`super::fix_from_epoch`] and [`super::fix_from_nav_pvt`].

use auvnav_shm_schema::GnssFixV1;

/// `ddmm.mmmmmmm,N` / `dddmm.mmmmmmm,E`.
fn nmea_angle(deg: f64, width: usize, pos: char, neg: char) -> String {
    let a = deg.abs();
    let mut d = a.trunc();
    let mut minutes = ((a - d) * 60.0 * 1e7).round() / 1e7;
    if minutes >= 60.0 {
        d += 1.0;
        minutes -= 60.0;
    }
    format!(
        "{:0width$}{:010.7},{}",
        d as u32,
        minutes,
        if deg < 0.0 { neg } else { pos }
    )
}

/// A GNSS fix as a receiver's NMEA epoch — `RMC`, `GGA`, `GST`, `ZDA` — stamped with the UTC
/// `utc_unix_ns` (the emulator's wall clock, as a live receiver's). The height goes out as the
/// altitude with a zero geoid separation; GST carries the fix's standard deviations.
pub fn nmea_from_gnss(m: &GnssFixV1, utc_unix_ns: i64) -> Vec<u8> {
    let t = chrono::DateTime::from_timestamp_nanos(utc_unix_ns);
    let time = format!(
        "{}{:02}",
        t.format("%H%M%S."),
        t.timestamp_subsec_millis() / 10
    );
    let lat = nmea_angle(m.latitude_rad.to_degrees(), 2, 'N', 'S');
    let lon = nmea_angle(m.longitude_rad.to_degrees(), 3, 'E', 'W');
    let [vn, ve, _] = m.velocity_ned_m_s;
    let knots = vn.hypot(ve) * 3600.0 / 1852.0;
    let course = ve.atan2(vn).to_degrees().rem_euclid(360.0);
    let quality = if m.validity & GnssFixV1::DIFFERENTIAL != 0 {
        2
    } else {
        1
    };
    let hdop = (m.horizontal_std_m / crate::gnss::GnssSettings::default().uere_m).max(0.5);
    let mut out = Vec::new();
    for body in [
        format!(
            "GNRMC,{time},A,{lat},{lon},{knots:.3},{course:.2},{},,,A",
            t.format("%d%m%y")
        ),
        format!(
            "GNGGA,{time},{lat},{lon},{quality},{:02},{hdop:.2},{:.3},M,0.000,M,,",
            m.satellites.min(99),
            m.height_m
        ),
        format!(
            "GNGST,{time},{h:.3},{h:.3},{h:.3},0.0,{h:.3},{h:.3},{:.3}",
            m.vertical_std_m,
            h = m.horizontal_std_m
        ),
        format!("GNZDA,{time},{},00,00", t.format("%d,%m,%Y")),
    ] {
        out.extend(crate::nmea::sentence(&body));
    }
    out
}

/// A GNSS fix as a u-blox `NAV-PVT` stamped with the UTC `utc_unix_ns`.
pub fn ubx_from_gnss(m: &GnssFixV1, utc_unix_ns: i64) -> Vec<u8> {
    use chrono::{Datelike, Timelike};
    let t = chrono::DateTime::from_timestamp_nanos(utc_unix_ns);
    let gps_ms = crate::gnss::gps_time_ns(utc_unix_ns, crate::gnss::GPS_MINUS_UTC_S)
        .map_or(0, |g| g / 1_000_000);
    let p = crate::ubx::NavPvt {
        itow_ms: (gps_ms % (7 * 86_400_000)) as u32,
        year: t.year() as u16,
        month: t.month() as u8,
        day: t.day() as u8,
        hour: t.hour() as u8,
        minute: t.minute() as u8,
        second: t.second() as u8,
        valid: crate::ubx::NavPvt::VALID_DATE
            | crate::ubx::NavPvt::VALID_TIME
            | crate::ubx::NavPvt::FULLY_RESOLVED,
        time_accuracy_ns: 30,
        nano_ns: t.nanosecond() as i32,
        fix_type: 3,
        flags: crate::ubx::NavPvt::GNSS_FIX_OK
            | if m.validity & GnssFixV1::DIFFERENTIAL != 0 {
                crate::ubx::NavPvt::DIFF_SOLN
            } else {
                0
            },
        satellites: m.satellites.min(255) as u8,
        longitude_deg: m.longitude_rad.to_degrees(),
        latitude_deg: m.latitude_rad.to_degrees(),
        height_m: m.height_m,
        height_msl_m: m.height_m,
        horizontal_accuracy_m: m.horizontal_std_m,
        vertical_accuracy_m: m.vertical_std_m,
        velocity_ned_m_s: m.velocity_ned_m_s,
        speed_accuracy_m_s: 0.05,
        pdop: 1.2,
    };
    crate::ubx::encode_nav_pvt(&p)
}

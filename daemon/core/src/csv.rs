//! CSV output of navigation solutions and aid diagnostics, shared by the daemon and the replay.
//! Floats are written with Rust's shortest round-trip formatting, so equal solutions give
//! byte-identical files.

use auvnav_shm_schema::{AidDiagnosticsV1, NavSolutionV1};
use std::io::Write;

pub const NAV_HEADER: &str = "time_ns,sequence,latitude_rad,longitude_rad,height_m,v_n_m_s,v_e_m_s,v_d_m_s,roll_rad,pitch_rad,yaw_rad,std_n_m,std_e_m,std_d_m,mode,sensor_health";

pub fn write_nav_row(w: &mut dyn Write, s: &NavSolutionV1) -> std::io::Result<()> {
    let [vn, ve, vd] = s.velocity_ned_m_s;
    let [r, p, y] = s.euler_rad;
    let [sn, se, sd] = s.position_std_ned_m;
    writeln!(
        w,
        "{},{},{:?},{:?},{:?},{:?},{:?},{:?},{:?},{:?},{:?},{:?},{:?},{:?},{},{}",
        s.host_time_ns,
        s.sequence,
        s.latitude_rad,
        s.longitude_rad,
        s.height_m,
        vn,
        ve,
        vd,
        r,
        p,
        y,
        sn,
        se,
        sd,
        s.mode,
        s.sensor_health
    )
}

pub const DIAGNOSTICS_HEADER: &str = "time_ns,sequence,source,dimension,flags,observation_0,observation_1,observation_2,innovation_0,innovation_1,innovation_2,innovation_variance_0,innovation_variance_1,innovation_variance_2,test_ratio";

pub fn write_diagnostics_row(w: &mut dyn Write, d: &AidDiagnosticsV1) -> std::io::Result<()> {
    writeln!(
        w,
        "{},{},{},{},{},{:?},{:?},{:?},{:?},{:?},{:?},{:?},{:?},{:?},{:?}",
        d.host_time_ns,
        d.sequence,
        d.source,
        d.dimension,
        d.flags,
        d.observation[0],
        d.observation[1],
        d.observation[2],
        d.innovation[0],
        d.innovation[1],
        d.innovation[2],
        d.innovation_variance[0],
        d.innovation_variance[1],
        d.innovation_variance[2],
        d.test_ratio
    )
}

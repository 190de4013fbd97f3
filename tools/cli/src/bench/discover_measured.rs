//! `auvnav bench discover --data DIR`: the wall time of discovery on each measured data set
//! (imported in memory, then discovered), and what it names there.

use serde::Serialize;

#[derive(Debug, Serialize)]
pub(super) struct MeasuredTiming {
    pub(super) data_set: String,
    pub(super) items: usize,
    pub(super) median_wall_s: f64,
    pub(super) max_wall_s: f64,
    pub(super) total_wall_s: f64,
    /// Effects found per item (names).
    pub(super) found: Vec<Vec<String>>,
}

/// Times discovery on the Snapir segments and the RDI PD0 transect found under `data`.
pub(super) fn measured_timings(data: &std::path::Path) -> anyhow::Result<Vec<MeasuredTiming>> {
    let run = |messages: &[(&str, auvnav_log::LogMessage)]| {
        crate::discover::command::discover_messages(messages.iter().map(|(_, m)| m))
            .effects
            .into_iter()
            .map(|e| e.name)
            .collect::<Vec<_>>()
    };
    let timing = |name: &str, items: Vec<(f64, Vec<String>)>| {
        let mut t: Vec<f64> = items.iter().map(|x| x.0).collect();
        t.sort_by(f64::total_cmp);
        MeasuredTiming {
            data_set: name.into(),
            items: t.len(),
            median_wall_s: t.get(t.len() / 2).copied().unwrap_or(0.0),
            max_wall_s: t.last().copied().unwrap_or(0.0),
            total_wall_s: t.iter().sum(),
            found: items.into_iter().map(|x| x.1).collect(),
        }
    };
    let mut out = Vec::new();
    let snapir = data.join("snapir-auv");
    if snapir.join("imu_01.csv").exists() {
        let mut items = Vec::new();
        for segment in 1..=13 {
            let t0 = std::time::Instant::now();
            let (messages, _) = crate::import::snapir_messages(
                &snapir,
                segment,
                crate::import::TimeBase::Nominal,
                true,
            )?;
            let found = run(&messages);
            items.push((t0.elapsed().as_secs_f64(), found));
        }
        out.push(timing("snapir-auv (13 segments of 400 s)", items));
    }
    let pd0 = data.join("rdi-pd0/raw/winriver02_transect.PD0");
    if pd0.exists() {
        let t0 = std::time::Instant::now();
        let bytes = std::fs::read(&pd0)?;
        let (messages, _) = crate::import::pd0_messages(&bytes, crate::import::GpsVelocity::Auto)?;
        let found = run(&messages);
        out.push(timing(
            "rdi-pd0 winriver02_transect (463 s)",
            vec![(t0.elapsed().as_secs_f64(), found)],
        ));
    }
    if out.is_empty() {
        anyhow::bail!("{}: no measured data set found", data.display());
    }
    Ok(out)
}

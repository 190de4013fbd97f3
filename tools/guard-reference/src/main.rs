//! `auvnav-guard-reference --hours H`: runs the performance guard's reference workload for `H`
//! hours of a 200 Hz log and prints its wall time as JSON (`{"format_version": 1, "wall_s": …}`).
//!
//! A program of its own, with no workspace or outside dependency: `auvnav bench guard` divides
//! the replay's and the smoothing's times by this one, and the baselines are such ratios, so its
//! machine code must not change with the project's. Compiled into `auvnav`, the same source ran
//! 17 % faster after an unrelated change to the command-line crate (0.171 → 0.143 s for a quarter
//! hour, 2026-12-07, dev build, Intel Xeon): where the linker puts a hot loop, and how the dev
//! build splits a crate into code-generation units, change with every edit of that crate. Here
//! only this program's own source and the toolchain place it.
#![forbid(unsafe_code)]

mod workload;

fn main() -> std::process::ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let hours = match args.as_slice() {
        [flag, h] if flag == "--hours" => h.parse::<f64>().ok(),
        _ => None,
    };
    let Some(hours) = hours.filter(|h| h.is_finite() && *h > 0.0 && *h <= 100.0) else {
        eprintln!(
            "usage: auvnav-guard-reference --hours H (0 < H <= 100): runs the performance \
             guard's reference workload and prints its wall time as JSON"
        );
        return std::process::ExitCode::from(2);
    };
    let start = std::time::Instant::now();
    std::hint::black_box(workload::reference_workload(hours));
    println!(
        "{{\"format_version\": 1, \"wall_s\": {}}}",
        start.elapsed().as_secs_f64()
    );
    std::process::ExitCode::SUCCESS
}

//! `auvnav-ugps`: the Water Linked Underwater GPS driver process. See
//! `auvnav_drivers::ugps_driver`.
#![forbid(unsafe_code)]

fn main() -> std::process::ExitCode {
    auvnav_drivers::ugps_driver::main()
}

//! `auvnav-can`: the CAN sensor driver process. See `auvnav_drivers::can_driver`.
#![forbid(unsafe_code)]

fn main() -> std::process::ExitCode {
    auvnav_drivers::can_driver::main()
}

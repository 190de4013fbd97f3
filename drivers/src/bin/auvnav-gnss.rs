//! `auvnav-gnss`: the GNSS receiver driver process. See `auvnav_drivers::serial_driver`.
#![forbid(unsafe_code)]

fn main() -> std::process::ExitCode {
    auvnav_drivers::serial_driver::main_for(auvnav_drivers::device::DeviceClass::Gnss)
}

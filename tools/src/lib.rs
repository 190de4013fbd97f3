pub mod accuracy;
pub mod bench;
pub mod csv;
pub mod demo;
pub mod log;
pub mod sim;

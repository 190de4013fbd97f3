pub mod accuracy;
pub mod bench;
pub mod csv;
pub mod demo;
pub mod import;
pub mod log;
pub mod replay;
pub mod sim;

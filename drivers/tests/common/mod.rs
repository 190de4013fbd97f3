//! Shared by the tests that read ../shared: the workspace's one locator, included from the
//! end-to-end test crate so both find the data the same way.

#[path = "../../../tests/src/shared.rs"]
mod locator;

pub use locator::shared;

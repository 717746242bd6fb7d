//! Headless `App` tests of the real plugin (one test binary, so Bevy is
//! linked once).

mod assignment;
mod common;
mod plugin;
mod scenes;
